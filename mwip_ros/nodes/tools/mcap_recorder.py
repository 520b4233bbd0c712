"""``mcap_recorder``: record the graph's topics into a rosbag2-compatible MCAP bag.

    python -m mwip_ros.nodes.tools.mcap_recorder --ros-args -p output:=bags/run1 [-p compression:=zstd]

Parameters: ``output`` (the bag directory to create; required, must not exist),
``topics`` (names from :data:`mwip_ros.msgs.topics.GRAPH_TOPICS` and ``SYSTEM_TOPICS``; empty = all),
``compression`` ('' or 'zstd', per MCAP chunk), ``chunk_size`` (bytes), ``max_bagfile_size`` (bytes) and
``max_bagfile_duration`` (seconds of log time): split the bag into ``<bag>_0.mcap``, ``<bag>_1.mcap``, ... as rosbag2
does (0: no limit; :mod:`mwip_ros.bag.writer`), so a recording of days keeps its memory bounded; every tool reads
a split bag as one run.

Every message is stored as the exact CDR bytes received (raw subscriptions), with the
node clock's receive time as log time (sim time under ``use_sim_time``, as rosbag2 does)
and as publish time (rclpy's EventsExecutor gives raw subscriptions no MessageInfo).

The topics are subscribed as :mod:`mwip_ros.nodes.tools.tap` says: the loop's own topics at
start with the graph's QoS (so a plant waiting for the recorder starts only once it listens,
and a writer that matched late still hands over its last 1000 messages), ``external_wrench``
and the system topics (``/rosout``, ``/parameter_events``, ``/diagnostics``) with a QoS
adapted to their publishers once they appear.  A topic's channel is created at its first
message, with the QoS the publishers offer and the type hash they announce.

On SIGINT/SIGTERM the queued messages are drained, the MCAP file is finished and
``metadata.yaml`` written; exit code 0.  The closing summary gives the messages per topic;
for a lockstep run (the plant publishes ``/clock`` only then) it checks that every topic of
the loop has one message per state (:mod:`mwip_ros.bag.ledger`) and, where one lacks some, logs a
warning naming the topics and the first missing stamp and writes the same line into the
bag's metadata (``custom_data``, key ``mwip_ros.lockstep_gaps``), which ``mwip_report``
shows.  The writer closes a chunk when it is full or spans
:data:`~mwip_ros.bag.writer.DEFAULT_MAX_CHUNK_DURATION` (0.5 s) of log time, whichever comes
first, and writes it at once: a recorder killed with SIGKILL loses only the chunk it was
filling, at most the last 0.5 s of the run; ``mwip_bag_repair <output>`` recovers the rest.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

from rclpy.node import Node

from mwip_ros.bag import BagError, BagWriter, qos_profiles_yaml
from mwip_ros.bag.ledger import GAPS_KEY, MAX_STAMPS, Ledger
from mwip_ros.nodes.runtime.diagnostics import OK
from mwip_ros.nodes.runtime import memtrace
from mwip_ros.nodes.runtime.guards import Rejects
from mwip_ros.nodes.runtime.params import declare
from mwip_ros.nodes.runtime.process import EXIT_ERROR, GracefulNodeMixin, run_node
from mwip_ros.nodes.tools.tap import TopicTap, resolve_topics
from mwip_ros.params import ParamError

NAME = "mcap_recorder"
DRAIN_IDLE_S = 0.3      # on shutdown: stop draining after this long without a message
DRAIN_MAX_S = 5.0       # ... or after this long in all


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
        wanted = resolve_topics(self, self.v["topics"])

        try:
            self.writer = BagWriter(self.output, compression=self.v["compression"] or None,
                                    chunk_size=self.v["chunk_size"], max_bagfile_size=self.v["max_bagfile_size"],
                                    max_bagfile_duration=float(self.v["max_bagfile_duration"]))
        except BagError as exc:
            raise ParamError("output", str(exc)) from None
        self.rejects = Rejects(self.get_logger())   # what the node's own clock refuses (/clock, see guards)
        self.ledger = Ledger()              # what was written, per topic, to judge a lockstep run (subscribed topics)
        self.received = 0
        self.failed = False
        self._executor = None
        for _, resolved, _ in wanted:
            self.ledger.counts[resolved] = 0   # expected: a loop topic never subscribed is a gap, not forgotten
        self.tap = TopicTap(self, wanted, self._on_message)
        self.types = self.tap.types
        self.get_logger().info(
            f"recording {len(self.types)} topic(s) to {self.output} ({self.writer.relative_path}; compression "
            f"{self.writer.compression or 'none'}, chunks of {self.writer.chunk_size} B or "
            f"{self.writer.max_chunk_duration} s at most"
            + (f"; split at {self.writer.max_bagfile_size} B" if self.writer.max_bagfile_size else "")
            + (f"; split after {self.writer.max_bagfile_duration:g} s" if self.writer.max_bagfile_duration else "")
            + "): "
            + ", ".join(sorted(self.types)))

    # --- recording -------------------------------------------------------------------------------

    def _on_message(self, topic: str, type_name: str, data: bytes) -> None:
        if self.failed or self.writer.closed:
            return
        log_time = self.get_clock().now().nanoseconds
        try:
            if not self.writer.has_topic(topic):
                self._add_topic(topic, type_name)
            files = self.writer.file_count
            self.writer.write(topic, data, log_time)
            if self.writer.file_count != files:   # split: the old file's writer and index are freed, the new one's
                self._split()                     # allocated
        except (BagError, OSError) as exc:
            self.failed = True
            self.finish(EXIT_ERROR, f"cannot write to {self.writer.mcap_path}: {exc}; stopping")
            return
        self.ledger.add(topic, type_name, data)
        self.received += 1

    def _split(self) -> None:
        """The bag was split: say so, and give the heap's pages the finished file's writer and index held back to
        the system (glibc keeps them otherwise: the recorder's RSS stepped up at each split,
        docs/benchmarks-history.md: the soak)."""
        memtrace.trim()
        self.get_logger().info(f"split: now writing {self.writer.files[-1]} (file {self.writer.file_count}; "
                               f"{self.received} messages so far)")

    def _add_topic(self, topic: str, type_name: str) -> None:
        profiles, type_hash = self.tap.publisher_metadata(topic, type_name)
        self.writer.add_topic(topic, type_name, qos_profiles_yaml(profiles), type_hash)
        self.get_logger().info(f"recording {topic} [{type_name}] from {len(profiles)} publisher(s)")

    # --- loop and shutdown --------------------------------------------------------------------------

    def spin_step(self, executor) -> None:
        self._executor = executor
        self.tap.spin(executor, lambda: self.received,
                      lambda: f"{self.received} messages written: {self._per_topic()}", self._failed)

    def _failed(self, text: str) -> None:   # keep the bag: on_shutdown still finishes it
        self.failed = True
        self.finish(EXIT_ERROR, f"recorder error: {text}; stopping")

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
        values = {"messages_written": self.received, "topics_subscribed": len(self.tap.subs),
                  "topics_waiting_for_a_publisher": len(self.tap.pending)}
        return OK, f"recording to {self.output}", values

    def on_shutdown(self) -> None:
        log = self.get_logger()
        self._drain()
        states = None if self.ledger.overflow else self.ledger.lockstep_states()   # the stamps gathered once
        gaps = self.ledger.gaps_text(states) if states is not None else ""
        if self.ledger.overflow:
            log.info(f"completeness not checked: a topic has more than {MAX_STAMPS:,} stamps")
        elif gaps:
            self.writer.custom_data[GAPS_KEY] = gaps
            log.warning(f"INCOMPLETE lockstep recording: {gaps} (a recorder that joins after the plant's run began, "
                        f"or one under a discovery set-up of your own, can miss states: count it in plant_sim's "
                        f"expected_subscribers, docs/recording.md)")
        elif states is not None:
            log.info(f"lockstep recording complete: every topic has all {len(states)} states"
                     + (f" ({sum(self.ledger.repeats.values())} resent message(s) recorded twice, read once)"
                        if self.ledger.repeats else ""))
        try:
            self.writer.close()
        except (BagError, OSError) as exc:
            self.finish(EXIT_ERROR, f"cannot finish the bag {self.output}: {exc}; run mwip_bag_repair {self.output}")
            return
        files = self.writer.files
        log.info(f"bag {self.output}: {self.writer.message_count} messages"
                 + (f" in {len(files)} files ({files[0]} .. {files[-1]})" if len(files) > 1 else "")
                 + f": {self._per_topic()}"
                 + (f"; the clock rejected: {self.rejects.summary()}" if self.rejects.counts else ""))


def main(argv=None) -> int:
    return run_node(McapRecorder, argv)


if __name__ == "__main__":
    sys.exit(main())
