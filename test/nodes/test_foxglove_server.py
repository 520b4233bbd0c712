"""foxglove_server hands a WebSocket client the graph's messages byte for byte, with the recorder's ros2msg schemas.

A lockstep graph (plant, observer, controller; 801 states, so every publisher's history of 1000
holds the whole run and nothing can be lost before the server) with robot_markers and
foxglove_server; a
``websockets`` client speaks the Foxglove protocol (subprotocol ``foxglove.sdk.v1``:
JSON ``serverInfo``/``advertise``/``subscribe``, binary message frames ``0x01``, subscription
id u32, log time u64, payload).  The test's own node records the same topics raw; the
client's payloads must be a gap-free run of exactly those bytes, and an independent CDR
reader (rosbags) must read them as the messages they are.
"""
from __future__ import annotations

import json
import os
import socket
import struct
import threading
import time
from typing import Dict, List, Optional

import pytest
import websockets
from geometry_msgs.msg import Wrench
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray
from websockets.sync.client import connect

from bagcheck import typestore
from graphproc import Graph
from injector import Injector
from mwip_ros.bag import message_definition
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.topics import GRAPH_TOPICS, SYSTEM_TOPICS, topic_type


SUBPROTOCOL = "foxglove.sdk.v1"
CLASSIC = "foxglove.websocket.v1"   # the subprotocol before the SDK's: the same frames
MESSAGE_DATA = 0x01   # binary opcode of a message frame
RUN_S, PERIOD_NS = 4.0, 5_000_000           # the lockstep run: 4 s of simulated time at 200 Hz
STATES = int(RUN_S * 1e9) // PERIOD_NS + 1  # k = 0 .. 800
EXPECTED = {"/joint_states", "/wheel_torque_cmd", "/disturbance_estimate", "/lumped_disturbance",   # advertised
            "/controller_internals", "/robot_markers", "/external_wrench", "/clock", "/rosout", "/diagnostics"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class FoxgloveClient:
    """A Foxglove WebSocket client on its own thread, reading the open connection ``ws``: subscribes ``topics``
    as they are advertised and keeps every advertisement and every message frame."""

    def __init__(self, ws, topics=()):
        self.ws = ws
        self.want = set(topics)
        self.lock = threading.Lock()
        self.server_info: Optional[dict] = None
        self.channels: Dict[int, dict] = {}            # channel id -> its advertisement
        self.advertisements: List[List[str]] = []      # the topics of each advertise message, in order
        self.messages: Dict[str, List[bytes]] = {}     # topic -> payloads, in arrival order
        self.log_times: Dict[str, List[int]] = {}
        self.sub_topic: Dict[int, str] = {}
        self.sub_of_channel: Dict[int, int] = {}
        self.resubscribed: List[str] = []              # see _control
        self.errors: List[str] = []
        self.closed = threading.Event()
        self.thread = threading.Thread(target=self._run, name="foxglove-client", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            for frame in self.ws:
                if isinstance(frame, str):
                    self._control(json.loads(frame))
                elif frame[0] == MESSAGE_DATA:
                    sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
                    with self.lock:
                        topic = self.sub_topic[sub_id]
                        self.messages.setdefault(topic, []).append(bytes(frame[13:]))
                        self.log_times.setdefault(topic, []).append(log_time)
        except websockets.ConnectionClosed:
            pass
        except Exception as exc:  # reported by the test, not lost in a thread
            self.errors.append(f"{type(exc).__name__}: {exc}")
        finally:
            self.closed.set()

    def _control(self, m: dict) -> None:
        if m["op"] == "serverInfo":
            self.server_info = m
        elif m["op"] == "advertise":
            subs = []
            with self.lock:
                self.advertisements.append([c["topic"] for c in m["channels"]])
                for c in m["channels"]:
                    self.channels[c["id"]] = c
                    if c["topic"] in self.want:
                        sub_id = len(self.sub_topic) + 1
                        self.sub_topic[sub_id] = c["topic"]
                        self.sub_of_channel[c["id"]] = sub_id
                        subs.append({"id": sub_id, "channelId": c["id"]})
            if subs:
                self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        elif m["op"] == "status" and m.get("message", "").startswith("Unknown channel ID: "):
            # foxglove-sdk 0.30.3 sends an advertisement before it registers the channel for the client
            # (connected_client.rs, advertise_channels): a subscription that answers within that moment is
            # refused.  The server's fault, not the node's: subscribe once more, as a user would by hand.
            cid = int(m["message"].rsplit(" ", 1)[1])
            with self.lock:
                sub_id = self.sub_of_channel.get(cid)
                if sub_id is None or cid not in self.channels:
                    self.errors.append(f"status: {m}")
                    return
                self.resubscribed.append(self.channels[cid]["topic"])
            self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": sub_id, "channelId": cid}]}))
        elif m["op"] == "status" and m.get("level", 0) >= 2:
            self.errors.append(f"status: {m}")
        elif m["op"] == "unadvertise":
            with self.lock:
                for cid in m["channelIds"]:
                    self.channels.pop(cid, None)

    def topics(self) -> set:
        with self.lock:
            return {c["topic"] for c in self.channels.values()}

    def got(self, topic: str) -> List[bytes]:
        with self.lock:
            return list(self.messages.get(topic, []))

    def close(self) -> None:
        self.ws.close()
        self.closed.wait(10)
        self.thread.join(10)


def _run_of(sub: List[bytes], full: List[bytes]) -> bool:
    """``sub`` is a gap-free run of ``full`` (the same bytes in the same order)."""
    if not sub:
        return False
    starts = [i for i, b in enumerate(full) if b == sub[0]]
    return any(full[i:i + len(sub)] == sub for i in starts)


@pytest.mark.graph
def test_the_client_gets_every_message_as_published_with_the_recorders_schemas(tmp_path):
    port = free_port()
    url = f"ws://127.0.0.1:{port}"
    t_start = time.time_ns()
    with Graph(tmp_path) as g, Injector(g.domain_id) as inj:
        js = inj.record("joint_states", JointState)
        markers = inj.record("robot_markers", MarkerArray)
        fox = g.start("foxglove_server", "-p", f"port:={port}")
        drawer = g.start("robot_markers")
        assert fox.wait_for_output(f"on ws://127.0.0.1:{port}", 60), fox.output()
        assert drawer.wait_for_output("robot markers ready", 60), drawer.output()
        # every thread of the server (rclpy's, Fast DDS's, the SDK's) yields the CPU to the loop: nice 10 by default
        tids = [int(t) for t in os.listdir(f"/proc/{fox.pid}/task")]
        assert len(tids) > 3 and all(os.getpriority(os.PRIO_PROCESS, t) == 10 for t in tids), fox.output()

        # Both subprotocols are spoken: a client that offers only the classic one (Lichtblick, @foxglove/ws-protocol)
        # gets it, one that offers both (as the Foxglove app does) gets the SDK's; one that offers neither is refused.
        with pytest.raises(websockets.InvalidStatus):
            with connect(url, subprotocols=["foxglove.other.v1"], open_timeout=30):
                pass
        with connect(url, subprotocols=[CLASSIC, SUBPROTOCOL], open_timeout=30) as both:
            assert both.subprotocol == SUBPROTOCOL

        with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=30) as ws, \
                connect(url, subprotocols=[CLASSIC], open_timeout=30) as old:
            assert old.subprotocol == CLASSIC and ws.subprotocol == SUBPROTOCOL
            classic = FoxgloveClient(old, topics=("/joint_states",))
            client = FoxgloveClient(ws, topics=("/joint_states", "/robot_markers", "/external_wrench"))
            assert inj.wait(lambda: client.server_info is not None, 30), fox.output()
            assert "/joint_states" not in client.topics()      # nothing publishes it yet
            first_adverts = len(client.advertisements)

            g.start("disturbance_observer")
            g.start("dscndo_controller")
            # joint_states' readers: observer, controller, robot_markers, foxglove_server and the test's node (the
            # plant's wait for a settled graph can miss a node discovered late on a busy machine: count them)
            plant = g.start("plant_sim", "-p", f"duration_s:={RUN_S}", "-p", "expected_subscribers:=5")
            # topics that appear while the client is connected are advertised to it then
            assert inj.wait(lambda: {"/joint_states", "/robot_markers"} <= client.topics(), 90), fox.output()
            assert any("/joint_states" in a for a in client.advertisements[first_adverts:])

            # a user's topic, subscribed by the server only once its first publisher shows up (volatile QoS)
            ext = inj.node.create_publisher(Wrench, "external_wrench", 10)
            sent: List[bytes] = []

            def wrench_arrived() -> bool:
                if len(client.got("/external_wrench")) >= 2:
                    return True
                sent.append(L.encode_external_wrench(0.001 * len(sent), 0.0))   # what nobody matched yet is lost
                ext.publish(sent[-1])
                inj.spin(0.05)                                                   # 20 messages/s
                return False
            assert inj.wait(wrench_arrived, 60), fox.output()
            assert _run_of(client.got("/external_wrench"), sent)

            assert inj.wait(lambda: plant.poll() is not None, 120) and plant.poll() == 0, plant.output()
            # the last state, and the markers drawn for it, reach the client too; and every topic of the run is
            # advertised (a server at nice 10 on a busy machine may still be working through its queues)
            assert inj.wait(lambda: js and markers and client.got("/joint_states")[-1:] == js[-1:]
                            and client.got("/robot_markers")[-1:] == markers[-1:], 60), fox.output()
            assert inj.wait(lambda: EXPECTED <= client.topics(), 60), (sorted(client.topics()), fox.output())
            assert inj.wait(lambda: classic.got("/joint_states")[-1:] == js[-1:], 60), fox.output()
            client.close()
            classic.close()
        assert not client.errors, client.errors
        assert not classic.errors, classic.errors
        assert fox.stop() == 0, fox.output()
    t_end = time.time_ns()

    # advertised: the topics of this graph, each with the recorder's schema, and nothing else
    ads = {c["topic"]: c for c in client.channels.values()}
    assert EXPECTED <= set(ads) <= {"/" + t.lstrip("/") for t in [*GRAPH_TOPICS, *SYSTEM_TOPICS]}, sorted(ads)
    for topic, c in ads.items():
        assert c["encoding"] == "cdr" and c["schemaEncoding"] == "ros2msg", c
        assert c["schemaName"] == topic_type(topic), c
        assert c["schema"] == message_definition(c["schemaName"]), topic

    # The payloads, read by an independent CDR reader (rosbags): the client has every state from shortly after
    # /joint_states appeared (its channel is made at the first message; what comes before the client's
    # subscription is not sent) to the end, one per period, and a marker array for each; and each message is
    # byte for byte the one the plant or the marker node published (as the test's own node received it).  A
    # state the plant resent (lockstep, after 0.5 s without an answer) is the same bytes again.
    ts = typestore()

    def by_stamp(payloads, type_name, stamp_of):
        out = {}
        for b in payloads:
            out.setdefault(stamp_of(ts.deserialize_cdr(b, type_name)), []).append(b)
        return out

    def header_stamp(m):
        return m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec

    def marker_stamp(a):
        assert all(m.header.frame_id == "world" for m in a.markers)
        return header_stamp(a.markers[0])

    got_js, got_markers = client.got("/joint_states"), client.got("/robot_markers")
    assert len(by_stamp(js, "sensor_msgs/msg/JointState", header_stamp)) == STATES   # the whole run was published
    states = [ts.deserialize_cdr(b, "sensor_msgs/msg/JointState") for b in got_js]
    assert all(list(s.name) == ["wheel", "body_pitch"] and len(s.position) == 2 for s in states)
    for got, mine, type_name, stamp_of in ((got_js, js, "sensor_msgs/msg/JointState", header_stamp),
                                           (got_markers, markers, "visualization_msgs/msg/MarkerArray", marker_stamp)):
        theirs, ours = by_stamp(got, type_name, stamp_of), by_stamp(mine, type_name, stamp_of)
        order = [stamp_of(ts.deserialize_cdr(b, type_name)) for b in got]
        stamps = sorted(theirs)
        assert order == sorted(order), type_name                                                 # in order
        assert all(b - a == PERIOD_NS for a, b in zip(stamps, stamps[1:])), type_name           # no gap
        # (the marker node may have matched the plant late, and drawn fewer: the client is judged on what it drew)
        assert len(stamps) >= len(ours) // 4 and stamps[-1] == max(ours) == (STATES - 1) * PERIOD_NS, \
            (type_name, len(stamps), len(ours))
        assert all(len(set(theirs[t])) == 1 for t in stamps), type_name                       # a resend: same bytes
        assert set(theirs) <= set(ours) and all(theirs[t][0] == ours[t][0] for t in stamps), type_name
    # the classic client: the same channels advertised, and the states as published, decodable, to the last
    assert EXPECTED <= classic.topics() and classic.channels.keys() <= client.channels.keys(), sorted(classic.topics())
    theirs = by_stamp(classic.got("/joint_states"), "sensor_msgs/msg/JointState", header_stamp)
    ours = by_stamp(js, "sensor_msgs/msg/JointState", header_stamp)
    stamps = sorted(theirs)
    assert len(stamps) >= STATES // 4 and stamps[-1] == (STATES - 1) * PERIOD_NS, len(stamps)
    assert all(b - a == PERIOD_NS for a, b in zip(stamps, stamps[1:]))                       # no gap
    assert all(theirs[t][0] == ours[t][0] for t in stamps)                                   # as published
    assert all(t_start <= t <= t_end for t in client.log_times["/joint_states"])   # receive time, wall clock
    wrenches = [ts.deserialize_cdr(b, "geometry_msgs/msg/Wrench") for b in client.got("/external_wrench")]
    assert all(w.torque.y == 0.0 and w.torque.x >= 0.0 for w in wrenches)


@pytest.mark.node
def test_a_bad_or_busy_port_stops_the_node_at_start_naming_the_parameter():
    """(The process around a refusal, exit 2 and the one line: test_startup.py.)"""
    from nodeharness import node_class, refused
    server = node_class("foxglove_server")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        taken = refused(server, "-p", f"port:={busy.getsockname()[1]}")
    assert "parameter 'port'" in taken and "Address already in use" in taken, taken
    for port in (0, 65536):
        line = refused(server, "-p", f"port:={port}")
        assert "parameter 'port'" in line, line


@pytest.mark.node
@pytest.mark.skipif(os.geteuid() != 0, reason="raising a thread's priority back needs CAP_SYS_NICE")
def test_built_in_a_test_its_nice_does_not_outlive_it():
    """foxglove_server lowers every thread of its process to its ``nice`` (10): built in a test worker's process, the
    harness puts the worker's threads back when it closes (before: the worker ran every later test at nice 10, starved
    beside two busy loops)."""
    from nodeharness import NodeHarness, node_class
    before = os.getpriority(os.PRIO_PROCESS, 0)
    with NodeHarness(node_class("foxglove_server"), "-p", f"port:={free_port()}") as h:
        assert os.getpriority(os.PRIO_PROCESS, 0) == max(before, 10), h.logs()   # the node did lower it
    assert os.getpriority(os.PRIO_PROCESS, 0) == before
