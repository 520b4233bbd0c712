"""The wheel driver's period, without ROS: what the node that owns a robot's clock (``wheel_driver``,
docs/hardware.md) does with a :class:`~.backend.Backend`, and the timing it reports.

A :class:`WheelDriver` holds the backend, the driver's state machine
(:class:`mwip_ros.core.control.safety.DriverStateMachine`, one for the driver's life), the command watchdog
(:class:`mwip_ros.core.control.safety.Watchdog`) and the newest command. Each period (:meth:`WheelDriver.period`) is:

1. **the command that acts**: the newest command, gated by the state machine (a stop, ``None``, unless enabled;
   always a stop with ``read_only``), each wheel clipped to ``wheel_torque_limit``;
2. **one exchange with the robot**: :meth:`Backend.step` writes that command and returns the read.  On moteus it is
   one ``transport.cycle`` carrying both controllers' commands with their queries: each controller applies the
   command on receipt and answers with its state at that instant, before the new torque acts; on Upkie's spine the
   action is written and the spine's observation comes back; a simulator integrates the period with the command
   and reads the next state.  So every backend's period is "the newest command, and the read", in one exchange.
   The command that answers read k can only exist after read k is published (the graph's estimator, observer and
   law compute it), so it goes out with exchange k + 1: its age when written is about one period.  A separate
   read before each write would double a device's traffic and latency for no fresher command;
3. **the read judged**: a device's own fault (:attr:`Observation.fault`: a moteus fault code, a controller that
   stopped answering, a transport that failed) latches fault ``device`` with the backend's line as its detail; a
   fall (|theta_b| > ``fall_angle``: the simulator's truth where the backend has one, else the newest estimate the
   node was given, :meth:`WheelDriver.estimate`) latches ``fall``.

The node publishes the read, stamped at the read, and then hands in the command that comes
(:meth:`WheelDriver.take_command`; a torque that is not finite or is implausible latches ``bad_command``).  Any
fault, a disable or an e-stop (a level, :meth:`DriverStateMachine.set_level`) makes the next period's command a
stop: moteus ``make_stop``, Upkie's zero-torque action, a simulator's open bridge.  :attr:`WheelDriver.stop_after`
keeps how long after the transition the first stop went out.

The node times each period (the exchange, the read-to-publish time, the command's age, the wake's jitter) and
publishes; this module imports no ROS.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, List, Optional, Tuple

from mwip_ros.core.control.safety import ENABLED, PLAUSIBLE_TORQUE, DriverStateMachine, Transition, Watchdog

from .backend import Backend, Command, Observation

__all__ = ["DriverConfig", "WheelDriver", "timing_lines"]


@dataclass(frozen=True)
class DriverConfig:
    """The driver's own settings.

    Parameters
    ----------
    h : float
        The period [s].
    wheel_torque_limit : float
        Each wheel's |torque| limit [N m]; 0 = none.
    read_only : bool
        Never send torque (every period a stop).
    require_enable : bool
        Start disabled until ``enable``.
    watchdog_s : float
        No command for this long is a ``watchdog`` fault [s] (0: off).
    fall_angle : float
        |theta_b| beyond this is a ``fall`` fault [rad].
    """

    h: float
    wheel_torque_limit: float = 0.0
    read_only: bool = False
    require_enable: bool = True
    watchdog_s: float = 0.1
    fall_angle: float = 1.0472

    def __post_init__(self):
        for key in ("h", "wheel_torque_limit", "watchdog_s", "fall_angle"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0.0):
                raise ValueError(f"driver: {key} must be a finite number >= 0, got {v!r}")
        if not self.h > 0.0:
            raise ValueError(f"driver: h must be > 0, got {self.h!r}")


class WheelDriver:
    """A backend behind the driver's state machine (module docstring).

    Parameters
    ----------
    backend : Backend
        The robot side (opened; the caller closes it).
    cfg : DriverConfig
        The driver's settings.
    clock : callable
        The monotonic clock [s] (the command's age, the stop's latency).
    """

    def __init__(self, backend: Backend, cfg: DriverConfig, clock: Callable[[], float] = time.monotonic):
        self.backend, self.cfg, self.clock = backend, cfg, clock
        self.safety = DriverStateMachine(require_enable=cfg.require_enable, max_command=PLAUSIBLE_TORQUE)
        self.watchdog = Watchdog(cfg.watchdog_s)
        self.command: Optional[Command] = None     # the newest command taken
        self.command_at: Optional[float] = None    # when it came (clock) [s]
        self.commands = 0                          # commands taken
        self.theta_b_estimate: Optional[float] = None   # the newest estimate of theta_b (a backend without truth)
        self.obs: Optional[Observation] = None     # the newest read
        self.written: Optional[Command] = None     # what the last period wrote (None: a stop)
        self.stops = 0                             # periods that wrote a stop
        self.torque_writes = 0                     # periods that wrote a torque
        self._left_enabled_at: Optional[float] = None   # when the state machine last left enabled (clock) [s]
        self.stop_after: List[float] = []          # for each time it left enabled: how long until the first stop
        self.fell_at: Optional[float] = None       # the time the read first showed a fall (None: it has not)

    # -- inputs -------------------------------------------------------------------------------------------------

    def take_command(self, command: Command, t: float) -> Optional[Transition]:
        """The controller's newest command (each wheel's torque [N m]); a torque that is not finite or is
        implausible latches ``bad_command`` (its transition returned) and is not kept.  A good one feeds the
        watchdog."""
        for v in (command.left, command.right):
            tr = self.safety.check_command(t, v)
            if tr is not None or not math.isfinite(v) or abs(v) > self.safety.max_command:
                return self._noted(tr)
        self.command, self.command_at = command, self.clock()
        self.commands += 1
        self.watchdog.feed(self.command_at)
        return None

    def estimate(self, theta_b: float) -> None:
        """The newest estimated pitch [rad] (the state estimator's ``joint_states``): what a fall is judged on when
        the backend has no truth."""
        self.theta_b_estimate = float(theta_b)

    # -- the state machine ---------------------------------------------------------------------------------------

    def _noted(self, tr: Optional[Transition]) -> Optional[Transition]:
        """Note when the machine leaves enabled (the next stop's latency is measured from then)."""
        if tr is not None and tr.from_state == ENABLED and tr.to_state != ENABLED:
            self._left_enabled_at = self.clock()
        return tr

    def fault(self, t: float, reason: str, detail: str = "") -> Optional[Transition]:
        """Latch a fault (:meth:`DriverStateMachine.fault`)."""
        return self._noted(self.safety.fault(t, reason, detail))

    def set_level(self, t: float, reason: str, asserted: bool, detail: str = "") -> Optional[Transition]:
        """A level input: the e-stop, the estimator's health (:meth:`DriverStateMachine.set_level`)."""
        return self._noted(self.safety.set_level(t, reason, asserted, detail))

    def enable(self, t: float):
        """``~/enable`` (:meth:`DriverStateMachine.enable`): the machine's answer."""
        return self.safety.enable(t)

    def disable(self, t: float):
        """``~/disable``: the answer; its transition (if any) noted for the stop's latency."""
        answer = self.safety.disable(t)
        self._noted(answer.transition)
        return answer

    def check_watchdog(self, now: float, t: float) -> Optional[Transition]:
        """A ``watchdog`` fault when no command came for ``watchdog_s`` (counted from :meth:`arm`): the transition,
        or None."""
        if self.safety.faulted or not self.watchdog.expired(now):
            return None
        silence = self.watchdog.silence(now)
        what = "since the last" if self.watchdog.answered else "since the first state: none ever came"
        return self.fault(t, "watchdog", f"no wheel_torque_cmd for {silence * 1e3:.1f} ms > watchdog_s = "
                                         f"{self.cfg.watchdog_s * 1e3:g} ms ({what})")

    # -- the period -----------------------------------------------------------------------------------------------

    def gated(self) -> Optional[Command]:
        """The command that acts this period: None (a stop) unless enabled, with a command, and not read-only; each
        wheel clipped to ``wheel_torque_limit``."""
        if self.cfg.read_only or self.safety.state != ENABLED or self.command is None:
            return None
        c, lim = self.command, self.cfg.wheel_torque_limit
        if lim > 0.0:
            c = Command(min(lim, max(-lim, c.left)), min(lim, max(-lim, c.right)))
        return c

    def start(self) -> Observation:
        """The backend reset (a simulator at its initial state; a device stopped, its faults cleared) and its first
        read."""
        self.obs = self.backend.reset()
        self.command = self.command_at = None
        self.fell_at = None
        return self.obs

    def period(self, t: float) -> Tuple[Observation, Optional[float], List[Transition]]:
        """One period (module docstring): the gated command written and the read taken in one exchange, the read
        judged.

        Parameters
        ----------
        t : float
            The period's time [s] (the transitions' time: simulated time, or seconds since the start).

        Returns
        -------
        (Observation, float or None, list of Transition)
            The read; the written command's age [s] (None: a stop was written); the transitions the read made (a
            device's fault, a fall).
        """
        command = self.gated()
        now = self.clock()
        age = None if command is None else now - self.command_at
        if command is None:
            self.stops += 1
            if self._left_enabled_at is not None:
                self.stop_after.append(now - self._left_enabled_at)
                self._left_enabled_at = None
        else:
            self.torque_writes += 1
        self.written = command
        obs = self.backend.step(command)
        self.obs = obs
        return obs, age, self.judge(obs, t)

    def judge(self, obs: Observation, t: float) -> List[Transition]:
        """The faults a read shows: the device's own (``device``), a fall (``fall``: the truth, else the newest
        estimate)."""
        out = []
        if obs.fault is not None:
            out.append(self.fault(t, "device", obs.fault))
        theta_b = obs.truth[1] if obs.truth is not None else self.theta_b_estimate
        if theta_b is not None and self.fell_at is None and not abs(theta_b) <= self.cfg.fall_angle:
            self.fell_at = t   # also when another fault is latched already (the machine keeps the first reason)
            out.append(self._noted(self.safety.check_fall(t, theta_b, self.cfg.fall_angle)))
        return [tr for tr in out if tr is not None]

    def reset(self, t: float):
        """``~/reset``: the state machine back to its start state (refused while a level is held); the answer.  The
        backend is reset by the caller at a period boundary (:meth:`start`)."""
        answer = self.safety.reset(t)
        if answer.success:
            self.watchdog.reset()
            self.theta_b_estimate = None
        return answer


def timing_lines(report: dict, h: float) -> List[str]:
    """A driver's timing report (the node's ``PeriodTiming.report``: ``periods``, ``missed``, each series' p50, p99 and
    max in ms; ``periods_due`` when realtime) as the lines the node logs and run_experiment.sh prints.

    Parameters
    ----------
    report : dict
        The report (``summary_json``'s ``timing``).
    h : float
        The period [s].

    Returns
    -------
    list of str
        One line per item.
    """
    def ms(f: str) -> str:
        if report.get(f"{f}_ms_p50") is None:
            return "none"
        return (f"p50 {report[f'{f}_ms_p50']:.3f}, p99 {report[f'{f}_ms_p99']:.3f}, max {report[f'{f}_ms_max']:.3f} "
                f"ms")
    due = report.get("periods_due")
    lines = [f"periods: {report['periods']} run" + (f" of {due} due" if due is not None else "")
             + f", {report['missed']} missed (deadline passed with no wake; h = {h * 1e3:g} ms)"]
    lines += [f"{label}: {ms(f)}" for label, f in (("exchange with the robot", "exchange"),
                                                   ("read to publish", "read_to_publish"),
                                                   ("command's age when written", "command_age"),
                                                   ("wake latency after the deadline (jitter)", "wake_latency"))]
    return lines
