"""What every node does with input it cannot trust: stamps, /clock, and a second publisher.

* :class:`StampGuard` accepts a stream of stamps that moves forward by at most a window
  (``STAMP_WINDOW_PERIODS`` control periods): a stamp equal to the last is a resend, an
  older one or one too far ahead is rejected, so one stray message cannot pull a node's
  time away from its stream.  A stream that really restarted (a new plant, a reset, a
  pause longer than the window) shows as ``RESYNC`` consecutive stamps that agree with
  each other (each the same as the one before, a lockstep resend, or at most a window
  after it): then the guard follows it and tells the caller to re-initialise.
* ``joint_states`` as the observer and the controller take it (a stamp guard in front of the message
  layer, the node's clock following the stream) is :class:`.state_input.StateInput`.
* the same check stands in front of rclpy's ``/clock`` subscription (its time source raises
  on a negative time, which kills the node): :func:`.rclpy_compat.guard_clock`.
* :class:`Rejects` counts rejected messages per topic and logs them, rate-limited per kind
  of reason (the first few of each, then every 100th), so a flood costs a line per 100.
* :class:`PublisherWatch` notices a second publisher on a topic that must have one (two
  plants or two controllers in one domain) and names the publishing nodes.
"""
from __future__ import annotations

import re
import time
from typing import Dict, Optional, Sequence

__all__ = ["Rejects", "StampGuard", "NEW", "REPEAT", "RESTART", "STAMP_WINDOW_PERIODS", "RESYNC",
           "PublisherWatch"]

STAMP_WINDOW_PERIODS = 20   # a stamp may lead the last accepted one by at most this many control periods
RESYNC = 3                  # consecutive agreeing stamps outside the window that restart the stream
NEW, REPEAT, RESTART = "new", "repeat", "restart"


class StampGuard:
    """Judge each stamp of a stream: :data:`NEW`, :data:`REPEAT`, :data:`RESTART`, or a rejection text."""

    def __init__(self, window_ns: int, what: str = "stamp"):
        self.window_ns = int(window_ns)
        self.what = what
        self.last: Optional[int] = None
        self._candidate: Optional[int] = None   # last stamp of a run of agreeing rejected stamps
        self._run = 0

    def check(self, stamp: int) -> str:
        last = self.last
        if last is None or last < stamp <= last + self.window_ns:
            self.last, self._candidate, self._run = stamp, None, 0
            return NEW
        if stamp == last:
            return REPEAT
        if self._candidate is not None and 0 <= stamp - self._candidate <= self.window_ns:   # a resend agrees too
            self._run += 1
        else:
            self._run = 1
        self._candidate = stamp
        if self._run >= RESYNC:
            self.last, self._candidate, self._run = stamp, None, 0
            return RESTART
        if stamp < 0:
            return f"{self.what} {stamp} ns is negative"
        if stamp < last:
            return f"{self.what} {stamp * 1e-9:.6f} s is older than the stream's {last * 1e-9:.6f} s"
        return (f"{self.what} {stamp * 1e-9:.6f} s jumps ahead of the stream's {last * 1e-9:.6f} s by more than "
                f"{self.window_ns * 1e-9:g} s")


class PublisherWatch:
    """Check now and then that each of ``topics`` has at most one publisher; name them when not.

    ``check()`` returns {topic: [node names]} for the topics that have more than one publisher
    (and logs a warning when that set changes); it queries the graph at most every ``period_s``.
    """

    def __init__(self, node, topics: Sequence[str], period_s: float = 1.0):
        self.node = node
        self.topics = list(topics)
        self.period_s = period_s
        self._next = 0.0
        self.crowded: Dict[str, list] = {}

    def check(self) -> Dict[str, list]:
        now = time.monotonic()
        if now < self._next:
            return self.crowded
        self._next = now + self.period_s
        crowded = {}
        for topic in self.topics:
            infos = self.node.get_publishers_info_by_topic(self.node.resolve_topic_name(topic))
            if len(infos) > 1:
                crowded[topic] = sorted(f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos)
        if crowded != self.crowded:
            for topic, names in crowded.items():
                self.node.get_logger().warning(
                    f"{len(names)} publishers on {self.node.resolve_topic_name(topic)}: {', '.join(names)}; this graph "
                    f"expects one (two graphs in one ROS domain? give each its own ROS_DOMAIN_ID or namespace)")
        self.crowded = crowded
        return crowded


_VALUE = re.compile(r"[0-9\[\]'\"(),]")


class Rejects:
    """Counts rejected messages per topic; logs the first few of each kind of reason, then at most one
    line per topic every ``PERIOD_S`` (with how many were rejected since), so a flood costs little."""

    FIRST = 3
    PERIOD_S = 2.0
    MAX_KINDS = 64

    def __init__(self, logger):
        self.logger = logger
        self.counts: Dict[str, int] = {}
        self._kinds: Dict[tuple, int] = {}
        self._quiet: Dict[str, list] = {}   # topic -> [time of its last line, rejections not logged since]

    def __call__(self, topic: str, reason: str) -> None:
        n = self.counts.get(topic, 0) + 1
        self.counts[topic] = n
        kind = (topic, " ".join(w for w in reason.split() if not _VALUE.search(w))[:80])  # the words, no values
        if kind not in self._kinds and len(self._kinds) >= self.MAX_KINDS:
            kind = (topic, "")  # a flood of ever new texts: one limit for the rest of the topic
        m = self._kinds[kind] = self._kinds.get(kind, 0) + 1
        quiet = self._quiet.setdefault(topic, [0.0, 0])
        if m <= self.FIRST or time.monotonic() - quiet[0] >= self.PERIOD_S:
            more = f" (+{quiet[1]} more rejected on {topic} since the last such line)" if quiet[1] else ""
            self.logger.warning(f"rejected message #{n} on {topic}: {reason}{more}")
            quiet[0], quiet[1] = time.monotonic(), 0
        else:
            quiet[1] += 1

    def summary(self) -> str:
        return ", ".join(f"{k}: {v}" for k, v in sorted(self.counts.items())) or "none"
