"""Every node's health on ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``), once a second of wall time, and
at once when the node says its health changed (``GracefulNodeMixin.report_health_now``: the state estimator's
divergence, which the plant's driver faults on).

``run_node`` calls :meth:`Diagnostics.tick` between callbacks (no timer: the lockstep loop
is not disturbed, and with ``use_sim_time`` the report still comes every wall second) and
once more at shutdown.  A node describes itself with ``diagnostic_status()``, which returns
``(level, message, {key: value})``; the :class:`Diagnostics` adds the rate of the node's
work counter (``diagnostic_count()``), its rejected messages (``node.rejects``) and, for each topic it subscribes
to, the publishers its subscription has matched (``publishers_by_topic``: a reader that has not yet matched a
publisher loses what that publisher sends, even when the publisher already counts the reader).  Levels
are diagnostic_msgs' OK, WARN and ERROR: a node reports ERROR when the robot fell or a
lockstep peer is missing, WARN when it rejected messages in the last second.
"""
from __future__ import annotations

import time
from collections import deque
from typing import Dict, Optional, Tuple

__all__ = ["OK", "WARN", "ERROR", "Diagnostics", "PERIOD_S", "StepRate", "publishers_by_topic", "topic_counts"]

OK, WARN, ERROR = 0, 1, 2      # diagnostic_msgs/DiagnosticStatus levels (bytes 0, 1, 2)
PERIOD_S = 1.0


class Diagnostics:
    def __init__(self, node):
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.qos import QoSProfile

        self.node = node
        self.pub = node.create_publisher(DiagnosticArray, "/diagnostics", QoSProfile(depth=10))
        self.name = f"{node.get_namespace().rstrip('/')}/{node.get_name()}"
        self._next = time.monotonic() + PERIOD_S
        self._last = (time.monotonic(), self._count(), self._rejected())
        self.published = 0

    def _count(self) -> int:
        f = getattr(self.node, "diagnostic_count", None)
        return int(f()) if f else 0

    def _rejected(self) -> int:
        rejects = getattr(self.node, "rejects", None)
        return sum(rejects.counts.values()) if rejects is not None else 0

    def tick(self, force: bool = False, now: bool = False) -> None:
        """The report, once a second; ``now``: at once (the node's health changed); ``force``: at once, and wait
        for the readers to have it (the last report, at shutdown)."""
        at = time.monotonic()
        if not (force or now) and at < self._next:
            return
        self._next = at + PERIOD_S
        self.pub.publish(self.report(at))
        self.published += 1
        if force:   # the last report, just before the process ends: let a listener have it
            from rclpy.duration import Duration
            self.pub.wait_for_all_acked(Duration(seconds=0.5))

    def report(self, now: float):
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

        t0, c0, r0 = self._last
        count, rejected = self._count(), self._rejected()
        self._last = (now, count, rejected)
        level, message, values = self.status()
        fresh_rejects = rejected - r0
        if fresh_rejects and level == OK:
            level, message = WARN, f"{fresh_rejects} message(s) rejected in the last {now - t0:.1f} s; {message}"
        rate = (count - c0) / max(now - t0, 1e-9)
        values = {"rate_per_s": f"{rate:.1f}", "handled": str(count), "rejected_messages": str(rejected), **values}
        rejects = getattr(self.node, "rejects", None)
        if rejects is not None and rejects.counts:
            values["rejected_by_topic"] = rejects.summary()
        matched = publishers_by_topic(self.node)
        if matched:
            values["publishers_by_topic"] = matched
        st = DiagnosticStatus(level=bytes([level]), name=self.name, message=message, hardware_id="mwip_ros",
                              values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])
        arr = DiagnosticArray(status=[st])
        arr.header.stamp = self.node.get_clock().now().to_msg()
        return arr

    def status(self) -> Tuple[int, str, Dict[str, object]]:
        f = getattr(self.node, "diagnostic_status", None)
        level, message, values = f() if f is not None else (OK, "running", {})
        failure = getattr(self.node, "failure", None)
        if failure:
            return ERROR, failure, values
        return level, message, values


def publishers_by_topic(node) -> str:
    """'/cmd_vel: 1, /joint_states: 2': each topic ``node`` subscribes to (its resolved name) and the publishers its
    subscription has matched, as this node's DDS reader sees them (the fewest, when it has two readers on a topic);
    '' with no subscription."""
    counts: Dict[str, int] = {}
    for sub in (*getattr(node, "subscriptions", ()), *getattr(node, "polled_inputs", ())):   # rclpy_compat.PolledInput
        n = sub.get_publisher_count()
        counts[sub.topic_name] = min(n, counts.get(sub.topic_name, n))
    return ", ".join(f"{t}: {n}" for t, n in sorted(counts.items()))


def topic_counts(summary: str) -> Dict[str, int]:
    """{topic: count} of a per-topic summary, :func:`publishers_by_topic`'s or ``Rejects.summary()``'s
    ('/clock: 2, joint_states: 5'; '' or 'none': {})."""
    if summary in ("", "none"):
        return {}
    return {t: int(n) for t, n in (item.rsplit(": ", 1) for item in summary.split(", "))}


class StepRate:
    """Steps per second over a sliding window of wall time, for a node's progress line.

    ``add(now, steps)`` takes the wall time [s] and a count that only grows (the periods stepped since the start,
    across resets: a reset sends the plant's k back to 0, and k over the time since the start then read 4 steps/s
    where the loop ran at 199 Hz); it answers (steps - steps then) / (now - then), ``then`` the oldest sample
    kept: the newest one at least ``window_s`` old (so the rate covers at least that long once it can), or None
    with no time elapsed.  It keeps the samples of one window only."""

    def __init__(self, window_s: float = 5.0):
        self.window_s = float(window_s)
        self.samples: deque = deque()

    def add(self, now: float, steps: int) -> Optional[float]:
        s = self.samples
        s.append((float(now), int(steps)))
        while len(s) > 2 and now - s[1][0] >= self.window_s:
            s.popleft()
        t0, n0 = s[0]
        return (steps - n0) / (now - t0) if now > t0 else None
