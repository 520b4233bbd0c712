"""``foxglove_server``: the graph's topics, live, to Foxglove over a WebSocket.

    python -m mwip_ros.nodes.foxglove_server [--ros-args -p port:=8765 -p host:=127.0.0.1]

Then, in Foxglove: *Open connection* > *Foxglove WebSocket* > ``ws://127.0.0.1:8765``, and
import ``config/foxglove_layout.json`` (README: Live view).

Parameters
----------
host : str
    Address to listen on (default ``127.0.0.1``: this machine only; ``0.0.0.0`` serves
    every interface, and the server has no authentication).
port : int
    TCP port, 1..65535 (default 8765).  A port out of range, one already in use, or a host
    that cannot be bound stops the node at start-up with exit code 2 and a message naming
    the parameter.
topics : list of str
    Names from :data:`mwip_ros.msgs.topics.GRAPH_TOPICS` and ``SYSTEM_TOPICS``; empty
    (the default) = all of them.
nice : int
    Nice value of every thread of the node (rclpy's, Fast DDS's, the SDK's), 0..19
    (default 10): the viewer yields the CPU to the control loop when they compete for it.

Notes
-----
The server is the ``foxglove-sdk``'s (``foxglove.start_server``, subprotocol
``foxglove.sdk.v1``, the successor of ``foxglove.websocket.v1`` with the same binary
message frames; a client that offers only ``foxglove.websocket.v1`` is refused by the SDK).
Every message is forwarded as the exact CDR bytes received (raw subscriptions through
:class:`mwip_ros.nodes.tap.TopicTap`, the recorder's: the loop's topics at once with the
graph's QoS, ``external_wrench`` and the system topics with a QoS adapted to their
publishers once they appear), nothing is decoded or re-encoded.  A topic's channel is
advertised at its first message, with the ``ros2msg`` schema the recorder writes into a
bag (:func:`mwip_ros.bag.message_definition`) and message encoding ``cdr``, so Foxglove
decodes it as the ROS 2 message it is; a topic that appears later is advertised then, to
the clients already connected.  The log time of a message is the node clock's receive time
(sim time under ``use_sim_time``), which Foxglove's plots use as *receive time*.

Cost to the loop: one more reader of each topic, and per message one Python callback that
hands the bytes to the SDK (which copies them into each subscribed client's queue and sends
them from its own threads; a channel no client subscribed costs only the callback).  On a
machine with few cores that CPU time is what slows a lockstep run (the loop's processes wait
for the CPU, not for the server): hence ``nice``.  A slow client loses its oldest messages
(the SDK's per-client backlog), never the loop its pace.  ``scripts/bench.sh`` measures the
lockstep rate with and without the server and a connected client.

Known defect of foxglove-sdk 0.30.3 (``connected_client.rs``, ``advertise_channels``): the
server sends a client a channel's advertisement before it registers the channel for that
client, so a subscription that arrives within that moment is refused with the status
"Unknown channel ID" (a lower priority widens the moment).  A client that subscribes again,
or reconnects, gets the channel.

On SIGINT/SIGTERM the server is stopped (the clients see the connection close); exit 0.
"""
from __future__ import annotations

import os
import sys
import threading
import time
from typing import Dict, Set, Tuple

import foxglove
from foxglove.websocket import ServerListener
from rclpy.node import Node

from mwip_ros.bag import message_definition
from mwip_ros.nodes.diagnostics import OK
from mwip_ros.nodes.params import declare
from mwip_ros.nodes.runtime import EXIT_ERROR, GracefulNodeMixin, for_every_thread, run_node
from mwip_ros.nodes.tap import TopicTap, resolve_topics
from mwip_ros.params import ParamError

NAME = "foxglove_server"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"


def _renice(log, value: int) -> None:
    """Every thread of this process at nice ``value`` at least."""
    if not value:
        return
    def lower(tid: int) -> None:
        if os.getpriority(os.PRIO_PROCESS, tid) < value:
            os.setpriority(os.PRIO_PROCESS, tid, value)
    try:
        for_every_thread(lower)
    except OSError as exc:
        log.warning(f"nice {value}: cannot lower the priority of the node's threads ({exc}); running as is")
        return
    log.info(f"nice {value}: the node's threads yield the CPU to the control loop")


class _Subscriptions(ServerListener):
    """Which client subscribed which channel; called from the SDK's threads."""

    def __init__(self, log):
        self.log = log
        self.lock = threading.Lock()
        self.pairs: Set[Tuple[int, int]] = set()
        self.clients: Set[int] = set()

    def on_subscribe(self, client, channel) -> None:
        with self.lock:
            self.pairs.add((client.id, channel.id))
            new = client.id not in self.clients
            self.clients.add(client.id)
        if new:
            self.log.info(f"client {client.id} subscribed its first channel ({channel.topic})")

    def on_unsubscribe(self, client, channel) -> None:
        with self.lock:
            self.pairs.discard((client.id, channel.id))
            if not any(c == client.id for c, _ in self.pairs):
                self.clients.discard(client.id)

    def counts(self) -> Tuple[int, int]:
        with self.lock:
            return len(self.clients), len(self.pairs)


class FoxgloveServer(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        self.host = str(self.v["host"]).strip()
        if not self.host:
            raise ParamError("host", "must not be empty (127.0.0.1: this machine only; 0.0.0.0: every interface)")
        self.port = int(self.v["port"])
        wanted = resolve_topics(self, self.v["topics"])   # before the server: a bad name leaves nothing open

        self.fx = foxglove.Context()                       # this node's own channels and server only
        self.listener = _Subscriptions(self.get_logger())
        try:
            self.server = foxglove.start_server(name=f"mwip_ros {self.get_fully_qualified_name()}", host=self.host,
                                                port=self.port, context=self.fx,
                                                server_listener=self.listener)
        except (RuntimeError, OSError, OverflowError, ValueError) as exc:
            text = str(exc).replace("FoxgloveError: ", "")
            about_host = any(s in text for s in ("lookup address", "assign requested address", "invalid"))
            raise ParamError("host" if about_host else "port",
                             f"cannot serve on {self.host}:{self.port}: {text}"
                             + ("" if about_host else " (choose a free port, e.g. -p port:=8766)")) from None
        _renice(self.get_logger(), int(self.v["nice"]))   # now: the SDK's threads exist, later ones inherit it
        self.clock = self.get_clock()
        # the schemas now (resolve_topics checked that each type has one): the first message of a topic only
        # creates its channel, no .msg file is read while the loop runs
        self.schemas = {type_name: foxglove.Schema(name=type_name, encoding=SCHEMA_ENCODING,
                                                   data=message_definition(type_name).encode("utf-8"))
                        for type_name in sorted({t for _, _, t in wanted})}
        self.channels: Dict[str, foxglove.Channel] = {}
        self.received = 0
        self.tap = TopicTap(self, wanted, self._on_message, what="forwarded")
        self.get_logger().info(
            f"serving {len(self.tap.types)} topic(s) on ws://{self.host}:{self.server.port} (subprotocol "
            f"foxglove.sdk.v1): " + ", ".join(sorted(self.tap.types)))

    # --- forwarding ------------------------------------------------------------------------------

    def _on_message(self, topic: str, type_name: str, data: bytes) -> None:
        channel = self.channels.get(topic)
        if channel is None:
            channel = self._advertise(topic, type_name)
        self.received += 1
        if channel.has_sinks():   # a channel no client subscribed: nothing to send, no clock to read
            # the node clock's time; without use_sim_time that is the system time, read 40 times faster directly
            now = self.clock.now().nanoseconds if self.clock.ros_time_is_active else time.time_ns()
            channel.log(data, log_time=now)

    def _advertise(self, topic: str, type_name: str) -> foxglove.Channel:
        channel = foxglove.Channel(topic, schema=self.schemas[type_name], message_encoding=MESSAGE_ENCODING,
                                   context=self.fx)
        self.channels[topic] = channel
        self.get_logger().info(f"advertised {topic} [{type_name}]")
        return channel

    # --- loop and shutdown --------------------------------------------------------------------------

    def spin_step(self, executor) -> None:
        self.tap.spin(executor, lambda: self.received, self._progress,
                      lambda text: self.finish(EXIT_ERROR, f"foxglove_server error: {text}; stopping"))

    def _progress(self) -> str:
        clients, subscribed = self.listener.counts()
        return (f"{self.received} messages received on {len(self.channels)} channel(s); {clients} subscribed "
                f"client(s), {subscribed} channel subscription(s)")

    def diagnostic_count(self) -> int:
        return self.received

    def diagnostic_status(self):
        clients, subscribed = self.listener.counts()
        values = {"url": f"ws://{self.host}:{self.server.port}", "messages_received": self.received,
                  "channels_advertised": len(self.channels), "subscribed_clients": clients,
                  "channel_subscriptions": subscribed, "topics_subscribed": len(self.tap.subs),
                  "topics_waiting_for_a_publisher": len(self.tap.pending)}
        return OK, f"serving ws://{self.host}:{self.server.port} to {clients} subscribed client(s)", values

    def on_shutdown(self) -> None:
        clients, _ = self.listener.counts()
        self.server.stop()
        for channel in self.channels.values():
            channel.close()
        self.get_logger().info(f"stopped ws://{self.host}:{self.port}: {self.received} messages received on "
                               f"{len(self.channels)} channel(s); {clients} client(s) were subscribed at the end")


def main(argv=None) -> int:
    return run_node(FoxgloveServer, argv)


if __name__ == "__main__":
    sys.exit(main())
