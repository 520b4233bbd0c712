"""``plant_sim``'s two modes as runners over one node: when a period of the plant's stages is finished.

The node (:mod:`.plant_sim`) holds the plant's stages (:class:`mwip_ros.core.loop.PlantSide`), its
topics, ``~/reset`` and the end-of-run report; a runner decides what starts a run, what a command
does and what ends a period:

* :class:`LockstepRunner`: publish ``/clock`` and state k, wait for the command that answers it
  (the lockstep driver, :mod:`.lockstep`, told the answering stages of ``core.loop``), finish the
  period, send the next state.  The graph then reproduces ``mwip_sim`` sample by sample.
* :class:`RealtimeRunner`: a timer at ``control_rate_hz`` on the node's clock finishes the period
  of the state published at the last tick with the newest command (zero torque once it is older
  than ``stale_command_periods``) and publishes the next state.

Both feed the driver's state machine (docs/theory.md 6.8, the node's ``safety``) what only the mode knows: the
lockstep timeout is the lockstep watchdog (a ``watchdog`` fault recorded, then exit 1 as before); the
realtime runner checks the command watchdog (``watchdog_s``) at every tick (a late tick defers the verdict
by one tick: the controller first gets the state the plant was late with), counting from the first state
it publishes, so a controller that never answers is a ``watchdog`` fault that names the first stage of the chain
(``core.loop.STAGES``) from which no answer came, not an open loop that runs until the robot falls.  A bad
command (non-finite or implausible, a ``bad_command`` fault) answers the lockstep state it came for with zero
torque (the driver is in fault), so the run goes on; in realtime it is dropped, as before.

:data:`RUNNERS` maps the ``mode`` parameter to its runner.
"""
from __future__ import annotations

import random
import time
from typing import Dict, Optional

import numpy as np

from mwip_ros.nodes.runtime.process import EXIT_ERROR

__all__ = ["LockstepRunner", "RealtimeRunner", "RUNNERS"]


class _Runner:
    """What the node asks of its mode."""

    mode = ""
    publishes_clock = False
    reset_when = ""    # when a ``~/reset`` takes effect, in words

    def __init__(self, node):
        self.node = node

    def start(self) -> None:
        raise NotImplementedError

    def on_command(self, u: float) -> None:
        raise NotImplementedError

    def graph_timed_out(self) -> None:
        raise NotImplementedError

    def on_bad_command(self) -> None:
        """A command the driver refused (non-finite, implausible: already a fault)."""

    def watch(self, crowded: Dict[str, list]) -> None:
        """Between callbacks, once started (``crowded``: topics with more than one publisher)."""

    def diagnostic_values(self) -> dict:
        return {}

    def diagnostic_problem(self) -> Optional[str]:
        return None

    def summary(self) -> dict:
        return {}


class LockstepRunner(_Runner):
    mode = "lockstep"
    publishes_clock = True
    reset_when = "once the state in flight is answered"

    def _send(self) -> None:
        n = self.node
        n.lockstep.send(n.plant.k, n._stamp(), n._sample_messages())
        n.truth.flush()

    def start(self) -> None:
        self._send()

    def on_command(self, u: float) -> None:
        n = self.node
        if not n.lockstep.take_answer():
            n.rejects("wheel_torque_cmd", "command while no state is waiting for one")
            return
        if n._reset_pending:   # pending only from k >= 1 on: the new state 0 goes back below the answered stamp
            n._reset()
            self._send()
        elif not n._finish_period(u):
            self._send()

    def on_bad_command(self) -> None:
        if self.node.lockstep.awaiting is not None:   # it answers the state: zero torque acts (in fault)
            self.on_command(0.0)

    def graph_timed_out(self) -> None:   # lockstep cannot run without the graph
        self.node.finish(EXIT_ERROR, "lockstep timeout: " + self.node.lockstep.graph_timeout_text())

    def watch(self, crowded: Dict[str, list]) -> None:
        failure = self.node.lockstep.check()
        if failure:   # the lockstep timeout is the watchdog: recorded as the driver's fault, then the run ends
            self.node.note_unanswered_state()
            self.node._fault("watchdog", failure)
        if crowded:
            failure = ("lockstep refuses mixed streams: " + "; ".join(
                f"{len(names)} publishers on {topic} ({', '.join(names)})" for topic, names in crowded.items())
                + "; run each graph in its own ROS_DOMAIN_ID or namespace")
        if failure:
            self.node.finish(EXIT_ERROR, failure)

    def diagnostic_problem(self) -> Optional[str]:
        d = self.node.lockstep
        if d.awaiting is not None and time.monotonic() - d.sent_at > 1.0:
            return f"no answer for over a second (missing: {d.missing()})"
        return None


class TickLog:
    """The realtime loop's tick times in bounded memory, whatever the run's length.

    Keeps the newest :attr:`RECENT` tick times (a ring: the watchdog looks back over them, the diagnostics over the
    last 400 periods), the count of ticks, the longest period and when it ended, the first :attr:`MISSED` periods
    longer than ``late_after`` and, for the percentiles, every period up to :attr:`RESERVOIR` of them, then a uniform
    sample of that many of all (reservoir sampling, Vitter's algorithm R, a fixed seed): a run of up to
    ``RESERVOIR`` periods (41 s at 200 Hz) gets its percentiles exactly, a longer one from that sample.
    ``log[-1]``, ``log[-n:]`` (n at most ``RECENT``), ``len(log)`` and ``bool(log)`` read as on the list of every
    tick time it replaces."""

    RECENT = 4096
    RESERVOIR = 8192
    MISSED = 50

    def __init__(self, late_after: float):
        self.late_after = late_after
        self.recent = np.zeros(self.RECENT)
        self.ticks = 0
        self.sample = np.zeros(self.RESERVOIR)
        self.periods = 0
        self.max_period, self.max_index = 0.0, 0
        self.late = []          # indices (from 0) of the first MISSED late periods
        self._rng = random.Random(0)

    def append(self, t: float) -> None:
        if self.ticks:
            p, i = t - self.recent[(self.ticks - 1) % self.RECENT], self.periods
            self.periods += 1
            j = i if i < self.RESERVOIR else self._rng.randrange(i + 1)
            if j < self.RESERVOIR:
                self.sample[j] = p
            if p > self.max_period:
                self.max_period, self.max_index = p, i
            if p > self.late_after and len(self.late) < self.MISSED:
                self.late.append(i)
        self.recent[self.ticks % self.RECENT] = t
        self.ticks += 1

    def __len__(self) -> int:
        return self.ticks

    def __getitem__(self, key):
        """``[-k]``: the k-th newest tick time; ``[-n:]``: the newest n (at most RECENT) in order, a list."""
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
        """Every period [ms] (the sample of them past RESERVOIR)."""
        return self.sample[:min(self.periods, self.RESERVOIR)] * 1e3


class RealtimeRunner(_Runner):
    mode = "realtime"
    reset_when = "at the next tick"

    def __init__(self, node):
        super().__init__(node)
        self.cmd: Optional[float] = None
        self.cmd_at = 0.0
        self.tick_times = TickLog(1.5 * node.h)   # bounded: a run of days keeps the same few arrays
        self.stale = 0
        self.missed = 0
        self.watchdog_deferred = False   # a late tick deferred the watchdog's verdict to the next (_check_watchdog)

    def start(self) -> None:
        from mwip_ros.msgs.qos import REALTIME_INPUT_QOS
        n = self.node
        n.stamp0 = n.get_clock().now().nanoseconds
        n.lockstep.listen(REALTIME_INPUT_QOS)   # the chain's intermediate answers: a watchdog fault names who is silent
        n.create_timer(n.h, self._tick)

    def on_command(self, u: float) -> None:
        self.cmd, self.cmd_at = u, time.monotonic()

    def graph_timed_out(self) -> None:
        n = self.node
        n.get_logger().warning(f"graph not ready after {n.lockstep.timeout_s:g} s (missing: {n.lockstep.missing()}); "
                               f"starting the realtime run anyway")
        n._start("realtime without the whole graph")

    def _tick(self) -> None:
        n = self.node
        now = time.monotonic()
        late = bool(self.tick_times) and now - self.tick_times[-1] > 1.5 * n.h
        if self.tick_times:
            if late:
                self.missed += 1
        else:   # state 0 goes out at this tick: the watchdog counts from it, a controller that never answers faults
            n.t_wall0 = now
            n._arm_watchdog()
        self.tick_times.append(now)
        if n.done:
            return
        if n._reset_pending:   # a period boundary: the new run's state 0 instead of the next state
            n._reset()
        elif len(self.tick_times) > 1:  # finish the period of the state published at the last tick
            self._check_watchdog(now, late)
            u = self.cmd
            if u is None or now - self.cmd_at > n.v["stale_command_periods"] * n.h:
                self.stale += 1
                if self.stale <= 3 or self.stale % 200 == 0:
                    n.get_logger().warning(f"no fresh wheel_torque_cmd (#{self.stale}); applying zero torque")
                u = 0.0
            if n._finish_period(u):
                return
        for pub, data in n._sample_messages():
            pub.publish(data)
        n.truth.flush()

    def _check_watchdog(self, now: float, late: bool = False) -> None:
        """At every tick: no good command for ``watchdog_s`` (counted from the first state) is a fault.
        A tick that came late (``late``: a missed deadline, the plant itself stalled) defers the verdict to the
        next tick, once: the controller cannot answer states the plant did not publish, so it first gets the one
        this tick publishes (a dead controller is then caught one period later).  The detail names the first
        stage of the chain that answered no state since then (the lockstep driver's :meth:`silent_stage`)."""
        n = self.node
        wd, ticks = n.watchdog, self.tick_times
        if n.safety.faulted or not wd.expired(now):
            self.watchdog_deferred = False
        elif late and not self.watchdog_deferred:
            self.watchdog_deferred = True
        else:
            silence = wd.silence(now)
            # the plant's ticks since the last command (from its receipt: a stall may follow it at once)
            since = [wd.last] + [t for t in ticks[-(int(silence / n.h) + 3):] if t >= wd.last] + [now]
            periods = [b - a for a, b in zip(since, since[1:])]
            gap = max(periods, default=0.0)                       # meanwhile: its longest stall
            stalled = sum(max(0.0, p - n.h) for p in periods)     # and its time past its periods, all told
            stage, why = n.lockstep.silent_stage(n._watch_stamp, n.stamp0)
            what = ("since the last" if wd.answered else "since the first state: none ever came")
            n._fault("watchdog", f"no wheel_torque_cmd for {silence * 1e3:.1f} ms > watchdog_s = "
                                 f"{wd.timeout * 1e3:g} ms ({what}); the stage that did not answer: {why}",
                     silence_s=round(silence, 6), max_tick_gap_s=round(gap, 6), stalled_s=round(stalled, 6),
                     silent_stage=stage)

    def diagnostic_values(self) -> dict:
        if len(self.tick_times) <= 2:
            return {}
        per = np.diff(self.tick_times[-400:]) * 1e3   # the last 400 periods
        return {"loop_period_p99_ms": f"{np.percentile(per, 99):.3f}", "missed_deadlines": self.missed,
                "stale_commands": self.stale}

    def summary(self) -> dict:
        if len(self.tick_times) <= 2:
            return {}
        h = self.node.h
        log = self.tick_times
        per = log.periods_ms()   # every period, or a uniform sample of them on a long run (TickLog)
        rt = {"period_ms_p50": float(np.percentile(per, 50)), "period_ms_p99": float(np.percentile(per, 99)),
              "period_ms_max": log.max_period * 1e3, "ticks": len(log),
              "period_max_at_s": float(log.max_index + 1) * h,  # sim time of the tick that ended it
              "missed_deadlines": self.missed, "stale_command_substitutions": self.stale,
              "missed_at_s": [round(float(i + 1) * h, 6) for i in log.late]}  # the ticks that came late (first 50)
        self.node.get_logger().info(
            f"realtime: loop period p50 = {rt['period_ms_p50']:.3f} ms, p99 = {rt['period_ms_p99']:.3f} ms, "
            f"max = {rt['period_ms_max']:.3f} ms (nominal {h * 1e3:g} ms); missed deadlines = "
            f"{self.missed}; stale-command substitutions = {self.stale}")
        return {"realtime": rt}


RUNNERS = {r.mode: r for r in (LockstepRunner, RealtimeRunner)}
