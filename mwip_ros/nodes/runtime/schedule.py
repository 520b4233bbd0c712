"""The realtime loop's schedule: absolute deadlines on one grid, and the loop's timing (plain Python, no ROS).

Period k is due at ``t_0 + k h`` (docs/graph.md, "Modes": a realtime plant stamps state k with that time).  The loop
wakes when its timer fires; :meth:`Schedule.wake` says which period is due at that instant, ``k = floor((t - t_0) /
h)``, and how many periods became due since the last wake.  A wake that comes late does not move the grid: the next
period is still due at ``t_0 + (k + 1) h`` (no sliding), and the periods whose deadline passed while the loop was
away are *missed*: their states were never published on time.  A simulated plant still runs them (it catches up,
integrating them with the command it holds, as the robot's physics goes on), so after T seconds of wall time it has
run ``floor(T / h)`` periods and its newest stamp is within one period of the clock, however it was scheduled; a
robot's driver, which can read its devices only now, runs the newest period (:attr:`Wake.k`) and counts the missed.

What one wake measures (:class:`Wake`): its latency, ``t - (t_0 + k h)``, the time from the deadline to the start of
the period's work (the loop's jitter; in ``[0, h)`` by construction), and the periods it missed.  :class:`Schedule`
keeps them over the run in bounded memory (:class:`TickLog` for the wakes, :class:`Reservoir` for the latencies) and
reports them (:meth:`Schedule.report`).  Time is integer nanoseconds of whatever clock the caller reads (the node's
clock in ``plant_sim``: wall time, or simulated time under ``use_sim_time``): the grid is exact, and a test drives
the schedule with made-up times instead of sleeping.
"""
from __future__ import annotations

import random
from dataclasses import dataclass
from typing import List, Optional, Union

import numpy as np

__all__ = ["Reservoir", "TickLog", "Wake", "Schedule"]


class Reservoir:
    """A uniform sample of at most ``size`` values out of all added (Vitter's algorithm R, a fixed seed).

    Exact until ``size`` values have been added (a run of up to ``size`` periods gets its percentiles exactly),
    a uniform sample of all of them after that, in constant memory.

    Parameters
    ----------
    size : int
        How many values are kept.
    seed : int
        The seed of the sampling (a run's report is reproducible).
    """

    def __init__(self, size: int, seed: int = 0):
        self.size = size
        self.sample = np.zeros(size)
        self.count = 0
        self._rng = random.Random(seed)

    def add(self, x: float) -> None:
        """Offer one value."""
        i = self.count
        self.count += 1
        j = i if i < self.size else self._rng.randrange(i + 1)
        if j < self.size:
            self.sample[j] = x

    def values(self) -> np.ndarray:
        """The values kept (every one added, up to ``size`` of them)."""
        return self.sample[:min(self.count, self.size)]


class TickLog:
    """A loop's wake times in bounded memory, whatever the run's length.

    Keeps the newest :attr:`RECENT` wake times (a ring: the watchdog looks back over them, the diagnostics over the
    last 400 periods), the count of wakes, the longest interval between two wakes and when it ended, the first
    :attr:`MISSED` intervals longer than ``late_after`` and, for the percentiles, a :class:`Reservoir` of
    :attr:`RESERVOIR` intervals.  ``log[-1]``, ``log[-n:]`` (n at most ``RECENT``), ``len(log)`` and ``bool(log)``
    read as on the list of every wake time it replaces.

    Parameters
    ----------
    late_after : float
        An interval longer than this is listed in :attr:`late` (the first :attr:`MISSED` of them).
    """

    RECENT = 4096
    RESERVOIR = 8192
    MISSED = 50

    def __init__(self, late_after: float):
        self.late_after = late_after
        self.recent = np.zeros(self.RECENT)
        self.ticks = 0
        self.intervals = Reservoir(self.RESERVOIR)
        self.max_period, self.max_index = 0.0, 0
        self.late: List[int] = []          # indices (from 0) of the first MISSED late intervals

    @property
    def periods(self) -> int:
        """How many intervals (wakes after the first) were logged."""
        return self.intervals.count

    def append(self, t: float) -> None:
        """Log a wake at time ``t``."""
        if self.ticks:
            p, i = t - self.recent[(self.ticks - 1) % self.RECENT], self.intervals.count
            self.intervals.add(p)
            if p > self.max_period:
                self.max_period, self.max_index = p, i
            if p > self.late_after and len(self.late) < self.MISSED:
                self.late.append(i)
        self.recent[self.ticks % self.RECENT] = t
        self.ticks += 1

    def __len__(self) -> int:
        return self.ticks

    def __getitem__(self, key: Union[int, slice]):
        """``[-k]``: the k-th newest wake time; ``[-n:]``: the newest n (at most RECENT) in order, a list."""
        kept = min(self.ticks, self.RECENT)
        if isinstance(key, slice):
            if key.stop is not None or key.step is not None or key.start is None or key.start >= 0:
                raise IndexError("a TickLog gives its newest ticks only: log[-n:]")
            n = min(-key.start, kept)
            return [float(self.recent[k % self.RECENT]) for k in range(self.ticks - n, self.ticks)]
        if not -kept <= key < 0:
            raise IndexError(f"a TickLog keeps its newest {kept} ticks: log[-1] .. log[-{kept}]")
        return float(self.recent[(self.ticks + key) % self.RECENT])

    def periods_ms(self) -> np.ndarray:
        """Every interval between wakes in ms, if the time unit is seconds (a uniform sample past RESERVOIR)."""
        return self.intervals.values() * 1e3


@dataclass(frozen=True)
class Wake:
    """What one wake of the loop has to do (:meth:`Schedule.wake`).

    Attributes
    ----------
    k : int
        The newest period due: its deadline ``t_0 + k h`` is the latest at or before the wake.
    periods : int
        How many periods became due since the last wake (0: the wake came before the next deadline, nothing to do).
    late_ns : int
        The wake's latency after period ``k``'s deadline [ns], in ``[0, h)``.
    late : bool
        The wake missed a period or came more than half a period after its deadline (a stalled loop).
    """

    k: int
    periods: int
    late_ns: int
    late: bool

    @property
    def missed(self) -> int:
        """The periods whose deadline passed with no wake (their states were never published on time)."""
        return max(0, self.periods - 1)


class Schedule:
    """Absolute deadlines: period k due at ``t0_ns + k period_ns`` (module doc), and the loop's timing.

    The first :meth:`wake` (at or after ``t0_ns``) is period 0's; every later wake hands out the periods that
    became due since the one before.  Counts: :attr:`wakes`, :attr:`missed` (periods whose deadline passed with
    no wake; :attr:`missed_k`, the first :attr:`TickLog.MISSED` of them), the latency of every wake after its
    deadline (:attr:`latency`, a :class:`Reservoir`; its largest, :attr:`max_late_ns`) and the intervals between
    wakes (:attr:`log`, a :class:`TickLog` in seconds).

    Parameters
    ----------
    period_ns : int
        The period h [ns], > 0.
    t0_ns : int
        Period 0's deadline [ns] on the caller's clock.
    """

    def __init__(self, period_ns: int, t0_ns: int):
        if int(period_ns) <= 0:
            raise ValueError(f"schedule: the period must be > 0 ns, got {period_ns!r}")
        self.period_ns, self.t0_ns = int(period_ns), int(t0_ns)
        self.k: Optional[int] = None     # the newest period handed out (None before the first wake)
        self.wakes = 0
        self.missed = 0
        self.missed_k: List[int] = []
        self.latency = Reservoir(TickLog.RESERVOIR, seed=1)
        self.max_late_ns = 0
        self.last_wake_ns: Optional[int] = None
        self.log = TickLog(1.5 * period_ns * 1e-9)

    def due(self, k: int) -> int:
        """Period ``k``'s deadline [ns]."""
        return self.t0_ns + k * self.period_ns

    def wake(self, now_ns: int) -> Wake:
        """The loop woke at ``now_ns``: which period is due, how many became due since the last wake (counted, with
        the latency, when there is any)."""
        now_ns = int(now_ns)
        k = max(0, (now_ns - self.t0_ns) // self.period_ns)
        periods = k + 1 if self.k is None else k - self.k
        if periods <= 0:   # before the next deadline (or the clock went back): nothing is due, nothing counted
            return Wake(self.k if self.k is not None else 0, 0, 0, False)
        late_ns = max(0, now_ns - self.due(k))
        wake = Wake(k, periods, late_ns, periods > 1 or 2 * late_ns > self.period_ns)
        first_missed = k - wake.missed
        self.missed_k.extend(range(first_missed, first_missed + min(wake.missed, TickLog.MISSED - len(self.missed_k))))
        self.missed += wake.missed
        self.k = k
        self.wakes += 1
        self.latency.add(late_ns * 1e-9)
        self.max_late_ns = max(self.max_late_ns, late_ns)
        self.last_wake_ns = now_ns
        self.log.append(now_ns * 1e-9)
        return wake

    def behind_ns(self, now_ns: int) -> int:
        """How far the clock is past the newest deadline handed out [ns] (in [0, h) for a loop on schedule)."""
        return int(now_ns) - self.due(self.k if self.k is not None else 0)

    def report(self) -> dict:
        """The timing over the run (times in ms): the intervals between wakes (p50, p99, max), the latency after the
        deadline (p50, p99, max: the jitter), the periods due and missed, the wakes, and how far the newest deadline
        handed out was behind the last wake."""
        per = self.log.periods_ms()
        lat = self.latency.values() * 1e3
        def pct(a: np.ndarray, q: float) -> float:
            return float(np.percentile(a, q)) if len(a) else 0.0

        return {"period_ms_p50": pct(per, 50), "period_ms_p99": pct(per, 99),
                "period_ms_max": self.log.max_period * 1e3,
                "latency_ms_p50": pct(lat, 50), "latency_ms_p99": pct(lat, 99),
                "latency_ms_max": self.max_late_ns * 1e-6,
                "periods_due": 0 if self.k is None else self.k + 1, "missed_deadlines": self.missed,
                "wakes": self.wakes,
                "behind_ms": 0.0 if self.last_wake_ns is None else self.behind_ns(self.last_wake_ns) * 1e-6}
