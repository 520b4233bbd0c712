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

The hold (docs/theory.md 6.14), from the measured state x_k and the observer's estimate tau_hat_k:

* where the robot comes to rest: for ``hold_settle_s`` after v* reaches 0 (and from the start), theta_w* moves to
  the wheel's angle of the first period its rate reaches zero (theta_w'_k theta_w'_{k-1} <= 0), and of a later rest
  more than :data:`REST_MOVE` from it, within :data:`ANCHOR_BLEND_S`; then it stays (:func:`anchor_step`);
* with the observer term (a law that uses tau_hat): tau_bar, the observer's estimate low-passed with the time
  constant ``hold_filter_s`` (:func:`hold_estimate`); from the robot's first rest after v* reached 0 until v* moves
  again the law regulates about the nominal model's equilibrium under w tau_bar, the lean theta_eq of
  sin(theta_eq) = -w tau_bar_2 / G_b and the torque -w tau_bar_1 (:class:`Hold`, :func:`.loop.command`), the weight
  w going to 1 from the rest and to 0 on the move with :data:`ANCHOR_BLEND_S` (:func:`hold_weight`); while theta_b
  is more than :data:`HOLD_NEAR` from theta_eq, tau_bar and w do not grow.

No ROS here: the controller node and the offline loop (:class:`.loop.Period`) call the same :class:`Shaper`; the
compiled batch (:mod:`.compiled_motion`) runs its speed step (:func:`profile_at`, :func:`speed_start`,
:func:`speed_step`) and the hold (:func:`anchor_step`, :func:`hold_estimate`, :func:`hold_weight`,
:func:`hold_lean`), compiled from this code.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Optional, Tuple

# |v| <= lim (every limit here is > 0); numba compiles it (core.kernels.compiled_motion)
from ..plants.plant import saturate as _clip

__all__ = ["MotionConfig", "Reference", "Hold", "Shaper", "rate_reference", "error_state", "profile_at",
           "speed_start", "speed_step", "anchor_step", "hold_estimate", "hold_weight", "hold_lean", "ABSURD_SPEED",
           "ABSURD_YAW_RATE", "HOLD_SIN_MAX", "REST_MOVE", "ANCHOR_BLEND_S", "HOLD_NEAR"]

ABSURD_SPEED = 1e3       # m/s: a command beyond this is no robot's: rejected, not clipped
ABSURD_YAW_RATE = 1e3    # rad/s
HOLD_SIN_MAX = 0.5       # the hold's lean at most asin(0.5) = 30 deg from the vertical (:func:`hold_lean`)
REST_MOVE = 0.1          # m: a rest after the first moves theta_w* only this far from it (a swing about it does not)
ANCHOR_BLEND_S = 0.5     # s: theta_w* moves to where the robot came to rest with this time constant (anchor_step)
HOLD_NEAR = 0.1          # rad: the hold's estimate and weight change only with theta_b this near its lean


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
    hold_settle_s: float = 5.0    # s: theta_w* moves to where the robot comes to rest this long after a stop; 0: never
    hold_filter_s: float = 1.0    # s: the hold's disturbance filter (theory 6.14); 0: no equilibrium, the law's own


class Reference(NamedTuple):
    """The references of one period and the outer loop's gains every law reads (docs/theory.md 6.11)."""

    theta_w: float          # theta_w* [rad]
    dtheta_w: float         # theta_w'* = v* / r [rad/s]
    v: float                # v* [m/s]
    dpsi: float             # psi'* [rad/s]
    position_gain: float    # lambda [1/s]
    lean_gain: float        # k_x


class Hold(NamedTuple):
    """The hold's equilibrium of one period (docs/theory.md 6.14): the lean theta_eq and the torque -tau_bar_1 the law
    regulates about, and tau_bar the observer term leaves out (:func:`.loop.command`)."""

    lean: float             # theta_eq [rad]
    torque: float           # -tau_bar_1 [N m]
    tau1: float             # tau_bar_1 [N m]
    tau2: float             # tau_bar_2 [N m]


def anchor_step(theta_w: float, dtheta_w: float, prev_rate: float, ref_theta_w: float, offset: float,
                pending: float, held: bool, rested: bool, move: float, blend: float):
    """One period of the hold's anchor (docs/theory.md 6.14): (theta_w* to use, its offset from the integrated
    reference ``ref_theta_w``, what of the offset's last move is still to come, whether the robot is at rest: its
    wheel's rate reached zero, its product with the previous period's ``prev_rate`` <= 0; NaN, no rate yet, is not).
    ``held`` (within ``hold_settle_s`` of the stop, v* = 0): at its first rest since the stop (``rested`` false), and
    at a later one more than ``move`` [rad] of the wheel from where theta_w* is going, theta_w* is to move to the
    wheel's angle ``theta_w``; it gets there as ``pending`` decays, the fraction ``blend`` = 1 - exp(-h / T_b) of it
    a period (a step in theta_w* would be one in the law's wheel error).  Plain arithmetic: the compiled batch
    (:mod:`.compiled_motion`) runs this code too."""
    rest = dtheta_w * prev_rate <= 0.0   # NaN compares false
    if held and rest and (not rested or abs(theta_w - (ref_theta_w + offset + pending)) > move):
        pending = theta_w - (ref_theta_w + offset)
    if pending != 0.0:
        step = blend * pending
        offset, pending = offset + step, pending - step
    return ref_theta_w + offset, offset, pending, rest


def hold_estimate(tau_hat1: float, tau_hat2: float, tau1: float, tau2: float, a: float):
    """tau_bar one period on (docs/theory.md 6.14): the observer's estimate (``tau_hat1``, ``tau_hat2``) through the
    first-order filter of gain ``a`` = 1 - exp(-h / hold_filter_s), from (``tau1``, ``tau2``)."""
    return tau1 + a * (tau_hat1 - tau1), tau2 + a * (tau_hat2 - tau2)


def hold_weight(weight: float, on: bool, near: bool, blend: float) -> float:
    """How much of the hold's equilibrium applies next (docs/theory.md 6.14): ``weight`` moved the fraction ``blend``
    toward 1 (``on``: the robot came to rest; only when ``near`` the equilibrium, else it stays) or 0, and 0 once
    below 1e-9: the equilibrium comes in and goes with the anchor's time constant :data:`ANCHOR_BLEND_S`, no step in
    the law's lean or torque."""
    if on and not near:
        return weight
    weight += blend * ((1.0 if on else 0.0) - weight)
    return weight if weight > 1e-9 else 0.0


def hold_lean(nominal, tau2: float, m=math) -> float:
    """theta_eq: the nominal model's lean at rest under the sum-row disturbance ``tau2``, sin(theta_eq) = -tau2 / G_b
    (eq. 7 at rest: -G_b sin theta_b = tau_d2), its sine within +-:data:`HOLD_SIN_MAX`."""
    s = -tau2 / nominal.G_b
    return m.asin(HOLD_SIN_MAX if s > HOLD_SIN_MAX else (-HOLD_SIN_MAX if s < -HOLD_SIN_MAX else s))


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
    """Commands in, one :class:`Reference` per period out (module docstring).  ``h`` the control period [s];
    ``nominal`` the law's model (anything with ``G_b``: :class:`~.model.PhysicalParams`), which the hold's
    equilibrium needs (None: none)."""

    def __init__(self, cfg: MotionConfig, h: float, nominal=None):
        self.cfg, self.h, self.nominal = cfg, h, nominal
        self.hold_gain = (1.0 - math.exp(-h / cfg.hold_filter_s)) if cfg.hold_filter_s > 0.0 else 0.0
        self.blend = 1.0 - math.exp(-h / ANCHOR_BLEND_S)
        self.accepted = 0        # commands taken (clipped ones too)
        self.rejected = 0        # commands refused (not finite, absurd)
        self.clipped = 0         # commands clipped to the limits
        self.timeouts = 0        # stops because no command came for timeout_s
        self.reset()

    def reset(self) -> None:
        """Forget the run: the next :meth:`reference` is period 0 again (the counters stay)."""
        self.k: Optional[int] = None   # the last period a reference was made for
        self.ref: Optional[Reference] = None
        self.cmd = (0.0, 0.0)    # the target (v, psi'), clipped
        self.cmd_k: Optional[int] = None   # the period the newest command came in (None: none yet)
        self.stopped = True      # no command in force (none yet, or timed out)
        self.stopped_now = False   # True for the period the timeout stopped the robot (log it once)
        self.hold: Optional[Hold] = None   # this period's equilibrium (theory 6.14), None: none (moving, or off)
        self.offset = 0.0        # theta_w* - the integrated reference: where the robot came to rest
        self.pending = 0.0       # what of the offset's last move is still to come (anchor_step)
        self.k_stop = 0          # the period v* reached 0 (0: the start is a stop)
        self.prev_rate = math.nan   # the previous period's wheel rate while v* = 0 (NaN: none)
        self.rested = False      # the robot came to rest since v* reached 0 (the hold's equilibrium applies)
        self.weight = 0.0        # how much of the equilibrium applies: to 1 from the rest, to 0 on the move
        self.tau_bar = (0.0, 0.0)

    def idle(self) -> None:
        """No torque acts (the driver disabled, in fault, the emergency stop held: docs/theory.md 6.8): the run and
        the command are forgotten (:meth:`reset`), so the position target, v*, psi'* and the hold do not advance,
        and the next :meth:`reference` starts from the state it is given, at rest; a command must come again, after
        the torque is back, to move the robot."""
        self.reset()

    _COMMANDS = ("cfg", "h", "nominal", "hold_gain", "blend", "accepted", "rejected", "clipped")

    def snapshot(self) -> dict:
        """What :meth:`reference` changes (all but the configuration and the commands' counters), for
        :meth:`restore` (a period whose command was refused)."""
        return {k: v for k, v in self.__dict__.items() if k not in self._COMMANDS}

    def restore(self, snap: dict) -> None:
        """Back to a :meth:`snapshot`: the period that took it did not happen."""
        self.__dict__.update(snap)

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

    def reference(self, k: int, theta_w0: float = 0.0, x=None, tau_hat=None) -> Reference:
        """The references of period ``k`` (advancing through any skipped period); ``theta_w0`` the first state's
        wheel angle (where the robot holds at v* = 0), read at the first call after :meth:`reset`.  With the measured
        state ``x`` the hold runs too (module docstring): theta_w* where the robot comes to rest, and with the
        observer's estimate ``tau_hat`` (a law with the observer term) :attr:`hold`, the equilibrium it regulates
        about once the robot came to rest."""
        c, h = self.cfg, self.h
        self.stopped_now = False
        if self.ref is None or self.k is None:   # (the two are None together: reset)
            v, w = self._target(k)
            tw, dtw, v = speed_start(v, float(theta_w0 if x is None else x[0]), c.max_accel, h, c.r)   # from rest
            w = _clip(w, c.max_yaw_rate * h)
            self.ref = Reference(tw, dtw, v, w, c.position_gain, c.lean_gain)
            self.k = self.k_stop = k
        else:
            while self.k < k:
                self.k += 1
                r = self.ref
                vt, wt = self._target(self.k)
                tw, dtw, v = speed_step(r.theta_w, r.dtheta_w, r.v, vt, c.max_accel, h, c.r)
                w = _toward(r.dpsi, wt, c.max_yaw_rate * h)
                self.ref = Reference(tw, dtw, v, w, c.position_gain, c.lean_gain)
                if v == 0.0 and r.v != 0.0:
                    self.k_stop = self.k   # a stop: v* reached 0
        return self.ref if x is None else self._held(self.ref, self.k, x, tau_hat)

    def _held(self, ref: Reference, k: int, x, tau_hat) -> Reference:
        """The hold of this period for the measured state ``x`` and the estimate ``tau_hat`` (None: no observer
        term, no equilibrium) (docs/theory.md 6.14): theta_w* and :attr:`hold`."""
        c, h = self.cfg, self.h
        equilibrium = tau_hat is not None and self.hold_gain > 0.0 and self.nominal is not None
        near = abs(x[1] - (self.hold.lean if self.hold is not None else 0.0)) <= HOLD_NEAR
        if equilibrium and near:   # far from the equilibrium (a recovery, a drive at its limit) tau_bar is held
            self.tau_bar = hold_estimate(tau_hat[0], tau_hat[1], *self.tau_bar, self.hold_gain)
        still = ref.v == 0.0
        held = still and (k - self.k_stop) * h < c.hold_settle_s - 1e-9
        tw, self.offset, self.pending, rest = anchor_step(x[0], x[2], self.prev_rate, ref.theta_w, self.offset,
                                                          self.pending, held, self.rested, REST_MOVE / c.r, self.blend)
        self.prev_rate = x[2] if still else math.nan
        self.rested = still and (self.rested or rest)
        self.weight = hold_weight(self.weight, self.rested and equilibrium, near, self.blend)
        self.hold = None
        if self.weight > 0.0:
            t1, t2 = self.weight * self.tau_bar[0], self.weight * self.tau_bar[1]
            self.hold = Hold(hold_lean(self.nominal, t2), -t1, t1, t2)
        return ref if tw == ref.theta_w else ref._replace(theta_w=tw)
