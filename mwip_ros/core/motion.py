"""Motion references (docs/theory.md 6.11): a speed command shaped into the wheel's reference angle and rate.

A command (``cmd_vel``: linear.x = v [m/s], angular.z = psi' [rad/s]; or the profile of an offline run) becomes, once
per control period k (t_k = k h), the references every law tracks (:meth:`mwip_ros.core.laws.Law.track`):

* the target v_c: the newest command, clipped to +-``max_speed`` (psi'_c to +-``max_yaw_rate``); zero once no
  command came for ``timeout_s`` (the stop, counted once per silence);
* the reference speed follows it at most ``max_accel`` per second:
  v*_k = v*_{k-1} + clip(v_c - v*_{k-1}, -max_accel h, max_accel h) (psi'* at most ``max_yaw_rate`` per second);
* the wheel's reference rate theta_w'*_k = v*_k / r and angle theta_w*_k = theta_w*_{k-1} + h theta_w'*_{k-1}
  (the exact integral of the rate held over each period), theta_w*_0 = the wheel angle of the first state: with
  v* = 0 the angle stays, the robot holds its position.

A command whose numbers are not finite, or beyond :data:`ABSURD_SPEED` / :data:`ABSURD_YAW_RATE`, is rejected and
counted (:attr:`Shaper.rejected`) and changes nothing, not even the timeout: a stream of them stops the robot.  One
within those bounds but over the limits is clipped (:attr:`Shaper.clipped`).  NaN never reaches a reference.

No ROS here: the controller node and the offline loop (:class:`.loop.Period`) call the same :class:`Shaper`; the
compiled batch (:mod:`.compiled_motion`) runs its speed step (:func:`profile_at`, :func:`speed_start`,
:func:`speed_step`), compiled from this code.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Optional, Tuple

from .plant import saturate as _clip   # |v| <= lim (every limit here is > 0); numba compiles it (compiled_motion)

__all__ = ["MotionConfig", "Reference", "Shaper", "rate_reference", "error_state", "profile_at", "speed_start",
           "speed_step", "ABSURD_SPEED", "ABSURD_YAW_RATE"]

ABSURD_SPEED = 1e3       # m/s: a command beyond this is no robot's: rejected, not clipped
ABSURD_YAW_RATE = 1e3    # rad/s


@dataclass(frozen=True)
class MotionConfig:
    """The ``motion.*`` parameters (params.motion) and the nominal wheel radius ``r`` [m]."""

    max_speed: float = 1.5        # m/s
    max_accel: float = 0.5        # m/s^2
    max_yaw_rate: float = 1.0     # rad/s
    timeout_s: float = 0.5        # s
    position_gain: float = 0.2    # lambda [1/s]
    lean_gain: float = 0.03       # k_x [rad per rad/s]
    profile: Tuple[Tuple[float, float], ...] = ()   # ((t, v*), ...): offline/lockstep; () = commands
    r: float = 0.254              # m
    yaw_profile: Tuple[Tuple[float, float], ...] = ()   # ((t, psi'*), ...) beside ``profile`` (theory 6.13)


class Reference(NamedTuple):
    """The references of one period and the outer loop's gains every law reads (docs/theory.md 6.11)."""

    theta_w: float          # theta_w* [rad]
    dtheta_w: float         # theta_w'* = v* / r [rad/s]
    v: float                # v* [m/s]
    dpsi: float             # psi'* [rad/s]
    position_gain: float    # lambda [1/s]
    lean_gain: float        # k_x


def rate_reference(ref: Reference, theta_w):
    """The wheel rate a law drives theta_w' to: theta_w'* - lambda (theta_w - theta_w*), so that the error
    theta_w' - this = (theta_w' - theta_w'*) + lambda (theta_w - theta_w*) (docs/theory.md 6.11)."""
    return ref.dtheta_w - ref.position_gain * (theta_w - ref.theta_w)


def error_state(x, ref: Optional[Reference]):
    """The state in error coordinates (theta_w - theta_w*, theta_b, theta_w' - rate_reference, theta_b'); ``x`` itself
    when ``ref`` is None (no motion: the law regulates, bit for bit as before)."""
    if ref is None:
        return x
    return (x[0] - ref.theta_w, x[1], x[2] - rate_reference(ref, x[0]), x[3])


def profile_at(times, values, t: float) -> float:
    """A profile's value at ``t``: the newest point (``times[j]``, ``values[j]``) at or before it (0 before the
    first).  Plain arithmetic on two sequences: the compiled batch (:mod:`.compiled_motion`) runs this code too."""
    v = 0.0
    for j in range(len(times)):
        if times[j] > t + 1e-12:
            break
        v = values[j]
    return v


def _at(profile, t: float) -> float:
    """:func:`profile_at` of a profile of (t, value) pairs."""
    return profile_at(tuple(tp for tp, _ in profile), tuple(vp for _, vp in profile), t)


def speed_start(v_target: float, theta_w0: float, max_accel: float, h: float, r: float):
    """Period 0's (theta_w*, theta_w'*, v*): v* one period's acceleration from rest toward the target, theta_w* the
    first state's wheel angle (module docstring).  The compiled batch (:mod:`.compiled_motion`) runs this code too."""
    v = _clip(v_target, max_accel * h)
    return theta_w0, v / r, v


def speed_step(theta_w: float, dtheta_w: float, v: float, v_target: float, max_accel: float, h: float, r: float):
    """The next period's (theta_w*, theta_w'*, v*) from this one's: v* at most ``max_accel`` h toward the target,
    theta_w* the exact integral of theta_w'* held over the period (module docstring)."""
    v = _toward(v, v_target, max_accel * h)
    return theta_w + h * dtheta_w, v / r, v


def _toward(now: float, target: float, step: float) -> float:
    """``now`` moved toward ``target`` by at most ``step``; exactly ``target`` once within reach."""
    d = target - now
    return target if -step <= d <= step else (now + step if d > 0 else now - step)


class Shaper:
    """Commands in, one :class:`Reference` per period out (module docstring).  ``h`` the control period [s]."""

    def __init__(self, cfg: MotionConfig, h: float):
        self.cfg, self.h = cfg, h
        self.accepted = 0        # commands taken (clipped ones too)
        self.rejected = 0        # commands refused (not finite, absurd)
        self.clipped = 0         # commands clipped to the limits
        self.timeouts = 0        # stops because no command came for timeout_s
        self.reset()

    def reset(self) -> None:
        """Forget the run: the next :meth:`reference` is period 0 again (the counters stay)."""
        self.k = None            # the last period a reference was made for
        self.ref: Optional[Reference] = None
        self.cmd = (0.0, 0.0)    # the target (v, psi'), clipped
        self.cmd_k = None        # the period the newest command came in (None: none yet)
        self.stopped = True      # no command in force (none yet, or timed out)
        self.stopped_now = False   # True for the period the timeout stopped the robot (log it once)

    def hold(self) -> None:
        """No torque acts (the driver disabled, in fault, the emergency stop held: docs/theory.md 6.8): the run and
        the command are forgotten (:meth:`reset`), so the position target, v* and psi'* do not advance, and the next
        :meth:`reference` starts from the state it is given, at rest; a command must come again, after the torque
        is back, to move the robot."""
        self.reset()

    def snapshot(self) -> tuple:
        """What :meth:`reference` changes, for :meth:`restore` (a period whose command was refused)."""
        return self.k, self.ref, self.cmd, self.cmd_k, self.stopped, self.stopped_now, self.timeouts

    def restore(self, snap: tuple) -> None:
        """Back to a :meth:`snapshot`: the period that took it did not happen."""
        self.k, self.ref, self.cmd, self.cmd_k, self.stopped, self.stopped_now, self.timeouts = snap

    def command(self, v, wz) -> Optional[str]:
        """Take a command (``v`` m/s, ``wz`` rad/s) for the coming periods; None when taken, else why it is rejected
        (counted).  Over-limit values are clipped (counted)."""
        try:
            v, wz = float(v), float(wz)
        except (TypeError, ValueError):
            self.rejected += 1
            return "not a number"
        if not (math.isfinite(v) and math.isfinite(wz)):
            self.rejected += 1
            return f"not finite (linear.x = {v!r}, angular.z = {wz!r})"
        if abs(v) > ABSURD_SPEED or abs(wz) > ABSURD_YAW_RATE:
            self.rejected += 1
            return (f"absurd (linear.x = {v:g} m/s, angular.z = {wz:g} rad/s; at most {ABSURD_SPEED:g} and "
                    f"{ABSURD_YAW_RATE:g})")
        c = self.cfg
        cv, cw = _clip(v, c.max_speed), _clip(wz, c.max_yaw_rate)
        if (cv, cw) != (v, wz):
            self.clipped += 1
        self.cmd = (cv, cw)
        self.cmd_k = -1 if self.k is None else self.k   # it acts from the next period on
        self.stopped = False
        self.accepted += 1
        return None

    def _target(self, k: int) -> Tuple[float, float]:
        c = self.cfg
        if c.profile or c.yaw_profile:   # the newest point at or before t_k
            t = k * self.h
            return _clip(_at(c.profile, t), c.max_speed), _clip(_at(c.yaw_profile, t), c.max_yaw_rate)
        if not self.stopped and self.cmd_k is not None and (k - self.cmd_k) * self.h >= c.timeout_s - 1e-12:
            self.stopped, self.stopped_now = True, True
            self.timeouts += 1
        return (0.0, 0.0) if self.stopped else self.cmd

    def reference(self, k: int, theta_w0: float = 0.0) -> Reference:
        """The references of period ``k`` (advancing through any skipped period); ``theta_w0`` the first state's
        wheel angle (where the robot holds at v* = 0), read at the first call after :meth:`reset`."""
        c, h = self.cfg, self.h
        self.stopped_now = False
        if self.ref is None:
            v, w = self._target(k)
            tw, dtw, v = speed_start(v, float(theta_w0), c.max_accel, h, c.r)   # from rest
            w = _clip(w, c.max_yaw_rate * h)
            self.ref = Reference(tw, dtw, v, w, c.position_gain, c.lean_gain)
            self.k = k
            return self.ref
        while self.k < k:
            self.k += 1
            r = self.ref
            vt, wt = self._target(self.k)
            tw, dtw, v = speed_step(r.theta_w, r.dtheta_w, r.v, vt, c.max_accel, h, c.r)
            w = _toward(r.dpsi, wt, c.max_yaw_rate * h)
            self.ref = Reference(tw, dtw, v, w, c.position_gain, c.lean_gain)
        return self.ref
