"""``plant_sim``'s two modes as runners over one node: when a period of the plant's stages is finished.

The node (:mod:`.plant_sim`) holds the plant's stages (:class:`mwip_ros.core.closed_loop.loop.PlantSide`), its
topics, ``~/reset`` and the end-of-run report; a runner decides what starts a run, what a command
does and what ends a period:

* :class:`LockstepRunner`: publish ``/clock`` and state k, wait for the command that answers it
  (the lockstep driver, :mod:`.lockstep`, told the answering stages of ``core.closed_loop.loop``), finish the
  period, send the next state.  The graph then reproduces ``mwip_sim`` sample by sample.
* :class:`RealtimeRunner`: period k is due at t_0 + k h on the node's clock (:mod:`..runtime.schedule`: absolute
  deadlines); at each wake of a timer at ``control_rate_hz`` it finishes the period of the state published at the
  last wake with the newest command (zero torque once it is older than ``stale_command_periods`` at the period's
  deadline) and publishes the next state.  A late wake finishes every period that became due meanwhile (they are
  counted as missed deadlines; the plant integrates them with the command it holds, as a robot's physics would), so
  the grid never slides: after T s the plant has run floor(T / h) periods and its newest stamp is within a period of
  the clock.

Both feed the driver's state machine (docs/theory.md 6.8, the node's ``safety``) what only the mode knows: the
lockstep timeout is the lockstep watchdog (a ``watchdog`` fault recorded, then exit 1 as before); the
realtime runner checks the command watchdog (``watchdog_s``) at every tick (a late tick defers the verdict
by one tick: the controller first gets the state the plant was late with), counting from the first state
it publishes, so a controller that never answers is a ``watchdog`` fault that names the first stage of the chain
(``core.closed_loop.loop.STAGES``) from which no answer came, not an open loop that runs until the robot falls.  A bad
command (non-finite or implausible, a ``bad_command`` fault) answers the lockstep state it came for with zero
torque (the driver is in fault), so the run goes on; in realtime it is dropped, as before.

:data:`RUNNERS` maps the ``mode`` parameter to its runner.
"""
from __future__ import annotations

import time
from typing import Dict, Optional

import numpy as np

from mwip_ros.nodes.runtime import stallprobe
from mwip_ros.nodes.runtime.process import EXIT_ERROR
from mwip_ros.nodes.runtime.schedule import Schedule, TickLog

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


class RealtimeRunner(_Runner):
    mode = "realtime"
    reset_when = "at the next tick"

    def __init__(self, node):
        super().__init__(node)
        self.cmd: Optional[float] = None
        self.cmd_at = 0          # when the newest command came [ns, the node's clock]
        self.schedule: Optional[Schedule] = None   # the deadlines, on the node's clock (from start())
        self.tick_times = TickLog(1.5 * node.h)    # the wakes on the steady clock (the watchdog's), bounded
        self.stale = 0
        self.watchdog_deferred = False   # a late tick deferred the watchdog's verdict to the next (_check_watchdog)

    def _now(self) -> int:
        """The node's clock [ns]: the schedule's and the stamps' (wall time, or simulated under use_sim_time)."""
        return self.node.get_clock().now().nanoseconds

    def start(self) -> None:
        from mwip_ros.msgs.qos import REALTIME_INPUT_QOS
        n = self.node
        n.lockstep.listen(REALTIME_INPUT_QOS)   # the chain's intermediate answers: a watchdog fault names who is silent
        timer = n.create_timer(n.h, self._tick)
        now = self._now()
        # the deadlines on the timer's own grid (its first call one period after its creation, read before now
        # is): period k due at stamp0 + k h, state k's stamp; the wake latency is then the timer's, not an offset
        n.stamp0 = min(now, now + (timer.time_until_next_call() or n.period_ns) - n.period_ns)
        self.schedule = Schedule(n.period_ns, n.stamp0)
        self._tick()   # state 0, at its deadline

    def on_command(self, u: float) -> None:
        self.cmd, self.cmd_at = u, self._now()

    def graph_timed_out(self) -> None:
        n = self.node
        n.get_logger().warning(f"graph not ready after {n.lockstep.timeout_s:g} s (missing: {n.lockstep.missing()}); "
                               f"starting the realtime run anyway")
        n._start("realtime without the whole graph")

    def _command(self, due: int):
        """The command that acts over the period ending at ``due`` [ns]: the newest, or zero torque when it is older
        than ``stale_command_periods`` periods at that deadline (counted, warned)."""
        n = self.node
        if self.cmd is not None and due - self.cmd_at <= n.v["stale_command_periods"] * n.period_ns:
            return self.cmd
        self.stale += 1
        if self.stale <= 3 or self.stale % 200 == 0:
            n.get_logger().warning(f"no fresh wheel_torque_cmd (#{self.stale}); applying zero torque")
        return 0.0

    def _tick(self) -> None:
        """A wake of the timer: finish every period that became due since the last wake (the schedule keeps the
        clock's grid: a late wake catches up, its missed periods counted), then publish the newest state."""
        n = self.node
        stallprobe.beat()   # a debugging aid: nothing unless MWIP_STALL_PROBE is set
        wake = self.schedule.wake(self._now())
        if not wake.periods:   # before the next deadline: nothing is due
            return
        now = time.monotonic()
        first = not self.tick_times
        self.tick_times.append(now)
        if first:   # state 0 goes out at this tick: the watchdog counts from it, a controller that never answers faults
            n.t_wall0 = now
            n._arm_watchdog()
        if n.done:
            return
        if n._reset_pending:   # a period boundary: the new run's state 0 instead of the next state
            n._reset()
        elif not first:  # finish the period of the state published at the last wake, and any missed since
            self._check_watchdog(now, wake.late)
            for k in range(wake.k - wake.periods + 1, wake.k + 1):   # the periods ending at these deadlines
                if n._finish_period(self._command(self.schedule.due(k))):
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
        if self.schedule is None or self.schedule.wakes <= 2:
            return {}
        s = self.schedule
        wakes = np.array(s.log[-400:])   # the last 400 wakes [s]; a wake's latency is its time past the grid
        late = np.mod(wakes - s.t0_ns * 1e-9, s.period_ns * 1e-9) * 1e3
        return {"loop_period_p99_ms": f"{np.percentile(np.diff(wakes) * 1e3, 99):.3f}",
                "loop_latency_p99_ms": f"{np.percentile(late, 99):.3f}", "missed_deadlines": s.missed,
                "stale_commands": self.stale}

    def summary(self) -> dict:
        s = self.schedule
        if s is None or s.wakes <= 2:
            return {}
        h = self.node.h
        rt = s.report()
        rt.update({"ticks": s.wakes,
                   "period_max_at_s": float(s.log.max_index + 1) * h,  # about the time of the wake that ended it
                   "stale_command_substitutions": self.stale,
                   "missed_at_s": [round(k * h, 6) for k in s.missed_k]})   # the first 50 periods missed
        self.node.get_logger().info(
            f"realtime: {rt['periods_due']} periods due, {s.missed} missed (deadline passed with no wake; run late, on "
            f"schedule); wake latency after the deadline p50 = {rt['latency_ms_p50']:.3f} ms, p99 = "
            f"{rt['latency_ms_p99']:.3f} ms, max = {rt['latency_ms_max']:.3f} ms; period between wakes p50 = "
            f"{rt['period_ms_p50']:.3f} ms, p99 = {rt['period_ms_p99']:.3f} ms, max = {rt['period_ms_max']:.3f} ms "
            f"(nominal {h * 1e3:g} ms); stale-command substitutions = {self.stale}")
        return {"realtime": rt}


RUNNERS = {r.mode: r for r in (LockstepRunner, RealtimeRunner)}
