"""What every node does with input it cannot trust: stamps, /clock, and a second publisher.

* :class:`StampGuard` accepts a stream of stamps that moves forward by at most a window
  (``STAMP_WINDOW_PERIODS`` control periods): a stamp equal to the last is a resend, an
  older one or one too far ahead is rejected, so one stray message cannot pull a node's
  time away from its stream.  A stream that really restarted (a new plant, a reset, a
  pause longer than the window) shows as ``RESYNC`` consecutive stamps that agree with
  each other (each the same as the one before, a lockstep resend, or at most a window
  after it): then the guard follows it and tells the caller to re-initialise, if its
  ``may_restart`` says the stamps can only be the stream's own: :class:`SolePublisher`,
  the topic has one publisher and it is not one seen beside the stream's (rclpy 7.1.6 tells
  a subscriber no message's publisher: its MessageInfo has no gid, and the EventsExecutor
  takes no MessageInfo callback; the graph's endpoint gids are what it knows).  Stamps
  that agree while a second publisher is on the topic are rejected, counted, and restart
  nothing.  A caller that accepts a stamp only with a partner (the state estimator's pairs)
  checks with ``commit=False`` and calls :meth:`StampGuard.commit` for the stamp it used:
  a lone sample ahead of the stream does not move the stream's time.
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
from typing import Callable, Dict, Optional, Sequence

__all__ = ["Rejects", "StampGuard", "NEW", "REPEAT", "RESTART", "STAMP_WINDOW_PERIODS", "RESYNC",
           "PublisherWatch", "SolePublisher", "sole_publisher"]

STAMP_WINDOW_PERIODS = 20   # a stamp may lead the last accepted one by at most this many control periods
RESYNC = 3                  # consecutive agreeing stamps outside the window that restart the stream
NEW, REPEAT, RESTART = "new", "repeat", "restart"


class StampGuard:
    """Judge each stamp of a stream: :data:`NEW`, :data:`REPEAT`, :data:`RESTART`, or a rejection text.

    Rejected stamps form runs (at most ``MAX_RUNS``: each later than the run's last by at most a window, or the
    same stamp resent; a stream that restarted while strays come in between still agrees with itself).  A run of
    :data:`RESYNC` is a restart if ``may_restart`` allows it (asked then; None: always); refused, the run asks
    again after ``RETRY_S``.
    Before the stream's first stamp, with ``may_restart`` saying no (more than one publisher), the stream starts
    with a run of :data:`RESYNC` strictly increasing stamps (a stray repeated does not start it).
    ``may_restart(own)`` is told whether the run is what the stream's own publisher may do: go back to the
    stream's first stamp (a reset), or jump ahead after the stream stood still for a window's time (a pause)."""

    MAX_RUNS = 8
    RETRY_S = 0.1

    def __init__(self, window_ns: int, what: str = "stamp", may_restart: Optional[Callable[[bool], bool]] = None):
        self.window_ns = int(window_ns)
        self.what = what
        self.may_restart = may_restart   # None: any RESYNC agreeing stamps restart the stream
        self.last: Optional[int] = None
        self.start: Optional[int] = None   # the stream's first stamp (since its last restart): a reset goes back to it
        self._moved_at = 0.0               # when (monotonic s) the stream's time last moved
        self._runs: list = []   # [last stamp, length, strictly increasing, refused until (monotonic s), first stamp]

    def check(self, stamp: int, commit: bool = True) -> str:
        """The verdict on ``stamp``; a :data:`NEW` one becomes the stream's time unless ``commit`` is False."""
        last = self.last
        if last is None:
            if self.may_restart is None or self.may_restart(True):
                if commit:
                    self.commit(stamp)
                return NEW
        elif last < stamp <= last + self.window_ns:
            if commit:
                self.commit(stamp)
            return NEW
        elif stamp == last:
            return REPEAT
        verdict = self._run(stamp, last)
        if verdict is not None:
            return verdict
        if stamp < 0:
            return f"{self.what} {stamp} ns is negative"
        if last is None:
            return (f"{self.what} {stamp * 1e-9:.6f} s: the topic has more than one publisher and the stream has not "
                    f"started ({RESYNC} stamps a period or so apart start it)")
        if stamp < last:
            return f"{self.what} {stamp * 1e-9:.6f} s is older than the stream's {last * 1e-9:.6f} s"
        return (f"{self.what} {stamp * 1e-9:.6f} s jumps ahead of the stream's {last * 1e-9:.6f} s by more than "
                f"{self.window_ns * 1e-9:g} s")

    def _run(self, stamp: int, last: Optional[int]) -> Optional[str]:
        """Count ``stamp`` in the run it agrees with (a resend agrees too); :data:`RESTART`, :data:`NEW` (the first
        start), a refusal, or None (not yet)."""
        runs = self._runs
        # a later stamp extends a run that has moved at each stamp; the same stamp again (a resend) extends its run
        run = next((r for r in reversed(runs) if (r[2] and 0 < stamp - r[0] <= self.window_ns) or stamp == r[0]),
                   None)
        if run is None:
            if len(runs) >= self.MAX_RUNS:
                del runs[0]
            run = [stamp, 0, True, 0.0, stamp]
            runs.append(run)
        run[1], run[2], run[0] = run[1] + 1, run[2] and (run[1] == 0 or stamp > run[0]), stamp
        if run[1] < RESYNC or (run[3] and time.monotonic() < run[3]):
            return None
        if last is None:   # the start, crowded: only a stream that moves
            if not run[2]:
                return None
            self.commit(stamp)
            self.start = run[4]   # the stream starts at the run's first stamp: where a reset comes back to
            return NEW
        # what the stream's own publisher may do: a reset (back to the start: a realtime run's first state may be
        # lost, so to within a window of it), or go on after a pause (ahead of a stream that has not moved for a
        # window's time)
        own = (self.start is not None and abs(run[4] - self.start) <= self.window_ns) or \
            (stamp > last and time.monotonic() - self._moved_at > self.window_ns * 1e-9)
        if self.may_restart is not None and not self.may_restart(own):
            run[3] = time.monotonic() + self.RETRY_S
            why = getattr(self.may_restart, "why", "") or "the topic has more than one publisher"
            return (f"{self.what} {stamp * 1e-9:.6f} s: {run[1]} stamps agree away from the stream's "
                    f"{last * 1e-9:.6f} s, but {why}: no restart")
        self.last, self.start = stamp, run[4]   # the restarted stream's start: its run's first stamp
        self._moved_at = time.monotonic()
        runs.clear()
        return RESTART

    def commit(self, stamp: int) -> None:
        """``stamp`` (judged :data:`NEW`) is the stream's time now."""
        if self.last is None or stamp > self.last:
            if self.last is None:
                self.start = stamp
            self.last = stamp
            self._moved_at = time.monotonic()
            self._runs.clear()


class SolePublisher:
    """A ``may_restart`` for :class:`StampGuard`: whether the stamps can only be the stream's own publisher's.

    ``may_restart(own)``, asked (the graph, then) when a stream starts or restarts: yes when ``topic`` has
    exactly one publisher that never shared the topic with the stream, and it is another than the one the
    stream started from (a new plant) or the run is one the stream's own publisher makes (``own``: back to the
    stream's first stamp, as a plant's ``~/reset`` restarts its stamps at the run's start, or ahead after the
    stream stood still, a pause); no while there are more, and each publisher
    then seen beside the stream's own is remembered as an intruder, which a restart never follows, also when it
    is left alone on the topic.  (The graph can lag the data: a publisher whose messages come before the graph
    lists it looks like the stream's own, which then restarts only back to its start, or after a pause.)"""

    def __init__(self, node, topic: str):
        self.node, self.name = node, node.resolve_topic_name(topic)
        self.own: Optional[tuple] = None   # the endpoint gid of the publisher the stream (re)started from
        self.intruders: set = set()
        self.why = ""   # why the last answer was no (StampGuard's rejection names it)

    def __call__(self, own: bool) -> bool:
        gids = [tuple(i.endpoint_gid) for i in self.node.get_publishers_info_by_topic(self.name)]
        if len(gids) == 1 and gids[0] not in self.intruders and (gids[0] != self.own or own):
            self.own, self.why = gids[0], ""
            return True
        self.why = ("the topic has more than one publisher" if len(gids) > 1 else "the topic has no publisher"
                    if not gids else
                    "its one publisher was seen beside the stream's own" if gids[0] in self.intruders else
                    "the stream's own publisher neither went back to its start nor paused")
        self.intruders.update(g for g in gids if g != self.own)
        return False


def sole_publisher(node, topic: str) -> SolePublisher:
    return SolePublisher(node, topic)


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
