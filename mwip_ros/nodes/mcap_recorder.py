"""``mcap_recorder``: record the graph's topics into a rosbag2-compatible MCAP bag.

    python -m mwip_ros.nodes.mcap_recorder --ros-args -p output:=bags/run1 [-p compression:=zstd]

Parameters: ``output`` (the bag directory to create; required, must not exist),
``topics`` (names from :data:`mwip_ros.msgs.topics.GRAPH_TOPICS`; empty = all of them),
``compression`` ('' or 'zstd', per MCAP chunk), ``chunk_size`` (bytes).

Every message is stored as the exact CDR bytes received (raw subscriptions), with the
node clock's receive time as log time (sim time under ``use_sim_time``, as rosbag2 does)
and as publish time (rclpy's EventsExecutor gives raw subscriptions no MessageInfo).

The loop's own topics (every graph topic but ``external_wrench``) are subscribed at start
with :data:`~mwip_ros.msgs.qos.RECORD_QOS` (reliable, keep last 1000, transient local, as
the graph's nodes publish them): the subscription exists before the nodes do, so a plant
told to wait for it (``expected_subscribers``) starts only once the recorder listens, and
a writer that matches a moment late still hands over its last 1000 messages.  Should a
publisher offer a QoS that cannot match it (``ros2 topic pub`` or ``ros2 bag play --clock``
are volatile), the topic is subscribed again with a QoS adapted to its publishers, as
``ros2 bag record`` does: keep last 1000, reliable unless a publisher is best effort,
transient local only when every publisher is.  ``external_wrench``, which users publish by
hand, is subscribed that way once its first publisher is discovered.  A topic's channel is
created at its first message, with the QoS the publishers offer and the type hash they
announce.

On SIGINT/SIGTERM the queued messages are drained, the MCAP file is finished and
``metadata.yaml`` written; exit code 0.  The closing summary gives the messages per topic;
for a lockstep run (the plant publishes ``/clock`` only then) it checks that every topic of
the loop has one message per state (:mod:`mwip_ros.bag.ledger`) and, where one lacks some, logs a
warning naming the topics and the first missing stamp and writes the same line into the
bag's metadata (``custom_data``, key ``mwip_ros.lockstep_gaps``), which ``mwip_report``
shows.  A recorder killed with SIGKILL leaves every finished chunk on disk:
``mwip_bag_repair <output>`` recovers them.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Dict, List, Optional, Tuple

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from mwip_ros.bag import BagError, BagWriter, message_definition, qos_profiles_yaml
from mwip_ros.bag import type_hash as installed_type_hash
from mwip_ros.msgs.qos import DEPTH, RECORD_QOS
from mwip_ros.msgs.topics import GRAPH_TOPICS, USER_TOPICS, graph_type, leaf, msg_class
from mwip_ros.bag.ledger import GAPS_KEY, MAX_STAMPS, Ledger
from mwip_ros.nodes.diagnostics import OK
from mwip_ros.nodes.guards import Rejects
from mwip_ros.nodes.params import declare
from mwip_ros.nodes.runtime import EXIT_ERROR, GracefulNodeMixin, run_node
from mwip_ros.params import ParamError

NAME = "mcap_recorder"
PROGRESS_PERIOD_S = 5.0
DRAIN_IDLE_S = 0.3      # on shutdown: stop draining after this long without a message
DRAIN_MAX_S = 5.0       # ... or after this long in all
DISCOVERY_POLL_S = 0.02  # how often to look for the first publisher of a topic not yet subscribed


def adapted_qos(infos) -> QoSProfile:
    """The subscription QoS that matches every publisher in ``infos`` and loses nothing they keep."""
    profiles = [i.qos_profile for i in infos]
    reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in profiles)
    transient = all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in profiles)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)


class McapRecorder(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        output = str(self.v["output"]).strip()
        if not output:
            raise ParamError("output", "required: the bag directory to create (e.g. -p output:=bags/run1)")
        self.output = Path(output).expanduser()
        if self.output.exists() or self.output.is_symlink():
            raise ParamError("output", f"{self.output} already exists; refusing to overwrite it "
                                       f"(choose a new bag directory)")
        wanted = self._topics(self.v["topics"])

        try:
            self.writer = BagWriter(self.output, compression=self.v["compression"] or None,
                                    chunk_size=self.v["chunk_size"])
        except BagError as exc:
            raise ParamError("output", str(exc)) from None
        self.rejects = Rejects(self.get_logger())   # what the node's own clock refuses (/clock, see guards)
        self.ledger = Ledger()              # what was written, per topic, to judge a lockstep run (subscribed topics)
        self.types: Dict[str, str] = {}
        self.received = 0
        self.failed = False
        self._executor = None
        self._last_progress = time.monotonic()
        self._last_progress_count = 0
        self.subs = {}
        self.pending = {}                   # resolved name -> (name as given, type): no publisher seen yet
        self._readapt = set()               # subscribed with RECORD_QOS, but a publisher cannot match it
        self._next_poll = 0.0
        for name, resolved, type_name in wanted:
            self.types[resolved] = type_name
            self.ledger.counts[resolved] = 0   # expected: a loop topic never subscribed is a gap, not forgotten
            if leaf(resolved) in USER_TOPICS:
                self.pending[resolved] = (name, type_name)
            else:
                self._subscribe(resolved, name, type_name, RECORD_QOS)
        self._subscribe_discovered()
        self.get_logger().info(
            f"recording {len(self.types)} topic(s) to {self.output} ({self.writer.relative_path}; compression "
            f"{self.writer.compression or 'none'}, chunk size {self.writer.chunk_size} B): "
            + ", ".join(sorted(self.types)))

    # --- set-up ---------------------------------------------------------------------------------

    def _topics(self, names: Optional[List[str]]) -> List[Tuple[str, str, str]]:
        """[(name as given, fully resolved name, type)] of the topics to record."""
        names = [n.strip() for n in (names or []) if n.strip()] or list(GRAPH_TOPICS)
        out: List[Tuple[str, str, str]] = []
        seen = set()
        for name in names:
            type_name = graph_type(name)
            if type_name is None:
                raise ParamError("topics", f"unknown topic {name!r}; the graph's topics are: "
                                           + ", ".join(GRAPH_TOPICS))
            try:
                resolved = self.resolve_topic_name(name)
            except Exception as exc:
                raise ParamError("topics", f"invalid topic name {name!r}: {exc}") from None
            if resolved in seen:
                continue
            seen.add(resolved)
            try:
                message_definition(type_name)  # fail now, not at the first message
                msg_class(type_name)
            except (BagError, ValueError) as exc:
                raise ParamError("topics", f"cannot record {name!r}: {exc}") from None
            out.append((name, resolved, type_name))
        return out

    def _subscribe(self, resolved: str, name: str, type_name: str, qos: QoSProfile) -> None:
        self.subs[resolved] = self.create_subscription(
            msg_class(type_name), name, self._callback(resolved, type_name), qos, raw=True,
            event_callbacks=self._events(resolved, adapted=qos is not RECORD_QOS))

    def _subscribe_discovered(self) -> None:
        """Subscribe each pending topic that has a publisher now, with a QoS that matches them."""
        for resolved in list(self.pending):
            infos = self.get_publishers_info_by_topic(resolved)
            if not infos:
                continue
            name, type_name = self.pending.pop(resolved)
            qos = adapted_qos(infos)
            self._subscribe(resolved, name, type_name, qos)
            self.get_logger().info(f"subscribed {resolved} ({len(infos)} publisher(s); {qos.reliability.name.lower()}, "
                                   f"{qos.durability.name.lower()})")

    def _adapt(self) -> None:
        """Subscribe again, with a QoS adapted to the publishers, each topic whose RECORD_QOS one a publisher
        cannot match (the event comes in a callback: the subscription is replaced here, between callbacks)."""
        for resolved in sorted(self._readapt):
            self.destroy_subscription(self.subs.pop(resolved))
            self.pending[resolved] = (resolved, self.types[resolved])
        self._readapt.clear()
        self._subscribe_discovered()

    def _events(self, name: str, adapted: bool):
        try:
            from rclpy.event_handler import SubscriptionEventCallbacks
        except ImportError:  # pragma: no cover
            return None

        def incompatible(event) -> None:
            kind = getattr(event, "last_policy_kind", "?")
            if not adapted:
                if name not in self._readapt:
                    self.get_logger().info(f"a publisher on {name} cannot match the graph's QoS (reliable, transient "
                                           f"local; policy kind {kind}): subscribing with a QoS adapted to the "
                                           f"publishers instead")
                self._readapt.add(name)
                return
            self.get_logger().warning(
                f"a publisher on {name} offers a QoS incompatible with the recorder's (chosen for the publishers "
                f"it found first; last policy kind {kind}): its messages are NOT recorded")

        return SubscriptionEventCallbacks(incompatible_qos=incompatible)

    def _callback(self, topic: str, type_name: str):
        # One argument: rclpy's EventsExecutor cannot hand a raw subscription its MessageInfo
        # (SystemError), so the publish time is the receive time too.
        def on_message(data) -> None:
            self._on_message(topic, type_name, data)
        return on_message

    # --- recording -------------------------------------------------------------------------------

    def _on_message(self, topic: str, type_name: str, data: bytes) -> None:
        if self.failed or self.writer.closed:
            return
        log_time = self.get_clock().now().nanoseconds
        try:
            if not self.writer.has_topic(topic):
                self._add_topic(topic, type_name)
            self.writer.write(topic, data, log_time)
        except (BagError, OSError) as exc:
            self.failed = True
            self.finish(EXIT_ERROR, f"cannot write to {self.writer.mcap_path}: {exc}; stopping")
            return
        self.ledger.add(topic, type_name, data)
        self.received += 1

    def _add_topic(self, topic: str, type_name: str) -> None:
        infos = []
        try:
            infos = self.get_publishers_info_by_topic(topic)
        except Exception as exc:  # pragma: no cover - graph queries do not fail in practice
            self.get_logger().warning(f"cannot query the publishers of {topic}: {exc}")
        qos_yaml = qos_profiles_yaml([i.qos_profile for i in infos])
        hashes = [str(i.topic_type_hash) for i in infos if str(i.topic_type_hash).startswith("RIHS")]
        type_hash = hashes[0] if hashes else installed_type_hash(type_name)
        self.writer.add_topic(topic, type_name, qos_yaml, type_hash)
        self.get_logger().info(f"recording {topic} [{type_name}] from {len(infos)} publisher(s)")

    # --- loop and shutdown --------------------------------------------------------------------------

    def spin_step(self, executor) -> None:
        self._executor = executor
        if self._readapt:
            self._adapt()
        if self.pending and time.monotonic() >= self._next_poll:
            self._next_poll = time.monotonic() + DISCOVERY_POLL_S
            self._subscribe_discovered()
        try:
            executor.spin_once(timeout_sec=DISCOVERY_POLL_S if self.pending else 0.1)
        except Exception as exc:  # keep the bag: on_shutdown still finishes it
            self.failed = True
            self.finish(EXIT_ERROR, f"recorder error: {type(exc).__name__}: {exc}; stopping")
            return
        now = time.monotonic()
        if now - self._last_progress >= PROGRESS_PERIOD_S:
            self._last_progress = now
            if self.received != self._last_progress_count:
                self._last_progress_count = self.received
                self.get_logger().info(f"{self.received} messages written: {self._per_topic()}")

    def _per_topic(self) -> str:
        return ", ".join(f"{t} {n}" for t, n in sorted(self.ledger.counts.items()))

    def _drain(self) -> None:
        """Run the callbacks of messages already received but not yet handled."""
        ex = self._executor
        if ex is None or self.failed:
            return
        start = last = time.monotonic()
        seen = self.received
        while True:
            now = time.monotonic()
            if now - last > DRAIN_IDLE_S or now - start > DRAIN_MAX_S:
                break
            try:
                ex.spin_once(timeout_sec=0.02)
            except Exception as exc:  # pragma: no cover - context already shut down
                self.get_logger().warning(f"stopped draining: {exc}")
                break
            if self.received != seen:
                seen, last = self.received, time.monotonic()

    def diagnostic_count(self) -> int:
        return self.received

    def diagnostic_status(self):
        values = {"messages_written": self.received, "topics_subscribed": len(self.subs),
                  "topics_waiting_for_a_publisher": len(self.pending)}
        return OK, f"recording to {self.output}", values

    def on_shutdown(self) -> None:
        log = self.get_logger()
        self._drain()
        gaps = self.ledger.gaps_text()
        if self.ledger.overflow:
            log.info(f"completeness not checked: a topic has more than {MAX_STAMPS:,} stamps")
        elif gaps:
            self.writer.custom_data[GAPS_KEY] = gaps
            log.warning(f"INCOMPLETE lockstep recording: {gaps}")
        elif "/clock" in self.ledger.stamps:
            log.info(f"lockstep recording complete: every topic has all {len(self.ledger.expected())} states"
                     + (f" ({sum(self.ledger.repeats.values())} resent message(s) recorded twice, read once)"
                        if self.ledger.repeats else ""))
        try:
            self.writer.close()
        except (BagError, OSError) as exc:
            self.finish(EXIT_ERROR, f"cannot finish the bag {self.output}: {exc}; run mwip_bag_repair {self.output}")
            return
        log.info(f"bag {self.output}: {self.writer.message_count} messages: {self._per_topic()}"
                 + (f"; the clock rejected: {self.rejects.summary()}" if self.rejects.counts else ""))


def main(argv=None) -> int:
    return run_node(McapRecorder, argv)


if __name__ == "__main__":
    sys.exit(main())
