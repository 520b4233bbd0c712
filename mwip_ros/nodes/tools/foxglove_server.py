"""``foxglove_server``: the graph's topics, live, to Foxglove over a WebSocket.

    python -m mwip_ros.nodes.tools.foxglove_server [--ros-args -p port:=8765 -p host:=127.0.0.1]

Then, in Foxglove: *Open connection* > *Foxglove WebSocket* > ``ws://127.0.0.1:8765``, and
import ``config/foxglove_layout.json`` (docs/graph.md: Live view).

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
max_clients : int
    Most TCP connections kept open on the port, 1..100000 (default 32); a connection beyond
    them (the newest; subscribed clients are kept first) is closed at once.
idle_timeout_s : float
    A connection that subscribes to no channel and sends nothing for this long [s] is closed
    (default 60; 0.5 .. 86400): one that never completes the WebSocket handshake, or never
    subscribes, holds a descriptor for no longer than that.  A subscribed client that reads nothing
    for this long while data waits for it is closed too (its slot and the SDK's queue for it freed).

Notes
-----
The server is the ``foxglove-sdk``'s (``foxglove.start_server``, subprotocol ``foxglove.sdk.v1``,
the successor of ``foxglove.websocket.v1`` with the same frames), behind the node's own port
(:mod:`.foxglove_relay`), which accepts both subprotocols: a client that offers only the classic
``foxglove.websocket.v1`` (Lichtblick, older Foxglove apps, tools on @foxglove/ws-protocol) gets it.
Every message is forwarded as the exact CDR bytes received (raw subscriptions through
:class:`mwip_ros.nodes.tools.tap.TopicTap`, the recorder's: the loop's topics at once with the
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

Connections (:mod:`.foxglove_connections`): the SDK has no limit on its connections, no timeout, no call that
closes one, and its accept loop ends at the first failed ``accept()``; a thread of the node bounds them
(``max_clients``, ``idle_timeout_s``) and starts the server again when its listening socket is gone; each
refusal, closure and restart is logged as a warning and counted in ``/diagnostics``.

On SIGINT/SIGTERM the server is stopped (the clients see the connection close); exit 0.  The SDK's
stop waits for every connection's task, a handshake that never comes included (one idle TCP
connection kept the node from ever ending): the node shuts its connections down meanwhile.
"""
from __future__ import annotations

import os
import socket
import sys
import time

from rclpy.node import Node

from mwip_ros.bag import message_definition
from mwip_ros.nodes.runtime.diagnostics import OK, WARN
from mwip_ros.msgs.topics import leaf
from mwip_ros.nodes.tools.foxglove_frames import FRAME_TOPICS, TF_TOPIC, FrameView, to_foxglove
from mwip_ros.nodes.tools.foxglove_relay import CLASSIC_SUBPROTOCOL, DESCRIPTORS_PER_CLIENT, SDK_SUBPROTOCOL, Relay
from mwip_ros.nodes.runtime.params import declare
from mwip_ros.nodes.runtime.process import EXIT_ERROR, GracefulNodeMixin, for_every_thread, run_node
from mwip_ros.nodes.tools.tap import TopicTap, resolve_topics
from mwip_ros.optional import required
from mwip_ros.params import ParamError

NAME = "foxglove_server"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
LATCHED_TOPICS = ("robot_description",)   # published once, transient local: resent to each new subscriber
LATCHED_RESEND_S = 0.2                    # how often new subscriptions are looked at for those
SDK_HOST = "127.0.0.1"        # the SDK's server listens here, on a port of its own, behind the relay


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


def _sdk():
    """The foxglove SDK and :mod:`.foxglove_connections` (which subclasses the SDK's listener), imported when the
    node starts: the SDK is optional (:mod:`mwip_ros.optional`), so ``--help`` answers without it and the node
    stops in one line naming it (exit 2)."""
    with required("foxglove", "foxglove_server (the live view)"):
        import foxglove

        from mwip_ros.nodes.tools import foxglove_connections
    return foxglove, foxglove_connections


class FoxgloveServer(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        self.sdk, conns = _sdk()
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        self.host = str(self.v["host"]).strip()
        if not self.host:
            raise ParamError("host", "must not be empty (127.0.0.1: this machine only; 0.0.0.0: every interface)")
        self.port = int(self.v["port"])
        wanted = resolve_topics(self, self.v["topics"])   # before the server: a bad name leaves nothing open

        self.max_clients = int(self.v["max_clients"])
        self.idle_timeout_s = float(self.v["idle_timeout_s"])
        conns.check_room(self.get_logger(), self.max_clients, DESCRIPTORS_PER_CLIENT)

        self.fx = self.sdk.Context()                       # this node's own channels and server only
        self.sdk_log = conns.SdkLog()
        self.sdk_log.install()
        self.listener = conns.Subscriptions(self.get_logger(), self.sdk_log)
        self.relay = None
        try:   # the port the clients see is the relay's (both subprotocols), the SDK's server is behind it
            self.relay = Relay(self.host, self.port, lambda: (SDK_HOST, self.server.port), self.get_logger(),
                               stall_s=self.idle_timeout_s)   # a client that reads nothing that long is closed
            self.server = self.start_server()
        except (RuntimeError, OSError, OverflowError, ValueError) as exc:
            self.sdk_log.uninstall()
            if self.relay is not None:
                self.relay.close()
            text = str(exc).replace("FoxgloveError: ", "")
            about_host = isinstance(exc, socket.gaierror) or any(
                s in text for s in ("lookup address", "assign requested address", "invalid"))
            raise ParamError("host" if about_host else "port",
                             f"cannot serve on {self.host}:{self.port}: {text}"
                             + ("" if about_host else " (choose a free port, e.g. -p port:=8766)")) from None
        _renice(self.get_logger(), int(self.v["nice"]))   # now: the SDK's threads exist, later ones inherit it
        self.clock = self.get_clock()
        # the schemas now (resolve_topics checked that each type has one): the first message of a topic only
        # creates its channel, no .msg file is read while the loop runs
        self.schemas = {type_name: self.sdk.Schema(name=type_name, encoding=SCHEMA_ENCODING,
                                                   data=message_definition(type_name).encode("utf-8"))
                        for type_name in sorted({t for _, _, t in wanted})}
        self.channels = {}   # topic -> its foxglove.Channel
        self.received = 0
        self.frames, self.tf_channel = FrameView(), None   # robot_state's frames as foxglove.FrameTransforms
        self.latched = {}   # topic -> the last message of a latched topic, sent again to each new subscriber
        self.create_timer(LATCHED_RESEND_S, self._resend_latched)
        self.tap = TopicTap(self, wanted, self._on_message, what="forwarded")
        self.watch = conns.ConnectionWatch(self, self.max_clients, self.idle_timeout_s)
        self.watch.start()   # after _renice: the thread inherits the main thread's nice value
        self.relay.start()
        self.get_logger().info(
            f"serving {len(self.tap.types)} topic(s) on ws://{self.host}:{self.relay.port} (subprotocols "
            f"{SDK_SUBPROTOCOL} and {CLASSIC_SUBPROTOCOL}): " + ", ".join(sorted(self.tap.types))
            + f"; at most {self.max_clients} connections, idle ones closed after {self.idle_timeout_s:g} s")

    def start_server(self):
        """The SDK's server, on this machine on a port of its own: the clients reach it through the relay."""
        return self.sdk.start_server(name=f"mwip_ros {self.get_fully_qualified_name()}", host=SDK_HOST,
                                     port=0, context=self.fx, server_listener=self.listener)

    # --- forwarding ------------------------------------------------------------------------------

    def _on_message(self, topic: str, type_name: str, data: bytes) -> None:
        channel = self.channels.get(topic)
        if channel is None:
            channel = self._advertise(topic, type_name)
        self.received += 1
        if channel.has_sinks():   # a channel no client subscribed: nothing to send, no clock to read
            channel.log(data, log_time=self._now())
        name = leaf(topic)
        if name in LATCHED_TOPICS:
            self.latched[topic] = data
        if name in FRAME_TOPICS:
            self._frames(name, data)

    def _resend_latched(self) -> None:
        """A latched topic's last message to a client that subscribed after it came (a late joiner gets the URDF)."""
        for topic in self.listener.take_subscribed():
            if topic in self.latched and topic in self.channels:
                self.channels[topic].log(self.latched[topic], log_time=self._now())

    def _now(self) -> int:
        # the node clock's time; without use_sim_time that is the system time, read 40 times faster directly
        return self.clock.now().nanoseconds if self.clock.ros_time_is_active else time.time_ns()

    def _frames(self, name: str, data: bytes) -> None:
        """robot_state's odom and wheel joints as foxglove.FrameTransforms on /tf (:mod:`.foxglove_frames`)."""
        if self.tf_channel is None:
            self.tf_channel = self.sdk.channels.FrameTransformsChannel(TF_TOPIC, context=self.fx)
            self.get_logger().info(f"advertised {TF_TOPIC} [foxglove.FrameTransforms] from {', '.join(FRAME_TOPICS)}")
        if name != "robot_description" and not self.tf_channel.has_sinks():
            return   # nobody looks: nothing decoded
        out = self.frames.feed(name, data)
        if out is not None:
            self.tf_channel.log(to_foxglove(self.sdk.messages, *out), log_time=self._now())

    def _advertise(self, topic: str, type_name: str):
        channel = self.sdk.Channel(topic, schema=self.schemas[type_name], message_encoding=MESSAGE_ENCODING,
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
                f"client(s), {subscribed} channel subscription(s), {self.watch.counts()['connections']} "
                f"connection(s)")

    def diagnostic_count(self) -> int:
        return self.received

    def diagnostic_status(self):
        clients, subscribed = self.listener.counts()
        watch = self.watch.counts()
        values = {"url": f"ws://{self.host}:{self.port}", "messages_received": self.received,
                  "channels_advertised": len(self.channels), "subscribed_clients": clients,
                  "channel_subscriptions": subscribed, "topics_subscribed": len(self.tap.subs),
                  "topics_waiting_for_a_publisher": len(self.tap.pending),
                  "max_clients": self.max_clients, "idle_timeout_s": f"{self.idle_timeout_s:g}", **watch,
                  "descriptor_limit": self.watch.limit, "sdk_warnings": self.sdk_log.problems_total,
                  **self.relay.counts()}
        message = (f"serving ws://{self.host}:{self.port} to {clients} subscribed client(s), "
                   f"{watch['connections']} connection(s)")
        last = getattr(self, "_last_watch", None)
        self._last_watch = watch
        stalled = self.watch.stalled_s()
        if stalled:
            return WARN, (f"the connection watch has not looked at the connections for {stalled:.0f} s; "
                          f"{message}"), values
        if last is not None:
            fresh = {k: watch[k] - last[k] for k in ("refused_connections", "listener_restarts")}
            if any(fresh.values()):
                return WARN, (f"{fresh['refused_connections']} connection(s) refused (max_clients "
                              f"{self.max_clients}), {fresh['listener_restarts']} listener restart(s) since the "
                              f"last report; {message}"), values
        return OK, message, values

    def on_shutdown(self) -> None:
        clients, _ = self.listener.counts()
        self.watch.stop()   # first: a stopped server has no listening socket, which the watch would restart
        self.relay.close()  # the clients' connections end, and so the SDK's ends of them
        self.watch.stop_servers([self.server] + [server for server, _ in self.watch.retired])
        self.sdk_log.uninstall()
        for channel in (*self.channels.values(), *([self.tf_channel] if self.tf_channel is not None else [])):
            channel.close()
        self.get_logger().info(f"stopped ws://{self.host}:{self.port}: {self.received} messages received on "
                               f"{len(self.channels)} channel(s); {clients} client(s) were subscribed at the end")


def main(argv=None) -> int:
    return run_node(FoxgloveServer, argv)


if __name__ == "__main__":
    sys.exit(main())
