"""The motor and its driver between the body and the wheel (docs/theory.md 6.7), off by default.

Both wheels' motors lumped, gears included, every quantity at the wheel.  The electrical model is
quasi-static (L/R is far below the control period): at each RK4 stage the driver turns the command
into a current set-point, applies the voltage it can, and the current that flows makes the torque::

    w     = th_w' - th_b'                       speed of the rotor relative to the stator  [rad/s]
    i*    = clip(u_cmd / K_t, +-I_max)          the driver's current set-point             [A]
    V     = clip(R i* + K_t w, +-V_max)         the voltage it can apply (battery)         [V]
    i     = clip((V - K_t w) / R, +-I_max)      the current that flows                     [A]
    u     = K_t i                               the torque on the wheel (reaction on the body) [N m]

So the torque falls with speed (back-EMF) and is capped by the current limit.  :func:`motor_torque`
is a pure function of floats (numba compiles it as it is: ``core.kernels.compiled`` may inline it in the RK4),
and says which limit bound (:data:`SAT_NONE`, :data:`SAT_CURRENT`, :data:`SAT_VOLTAGE`), so the
metrics can count the time the drive spent saturated.  :func:`acted_torque` is the RK4-weighted mean of
a period's stage torques, the torque that acted over the period (what the plant reports as ``effort``
and the observer must integrate).  :func:`holding_torque`, :func:`limit_warning` and :func:`torque_warning`
tell when the drive (or any torque limit) is too weak for the robot it moves.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

from .model import PhysicalParams

__all__ = ["MotorConfig", "SAT_NONE", "SAT_CURRENT", "SAT_VOLTAGE", "SATURATION_NAMES", "motor_torque",
           "acted_torque", "holding_torque", "recoverable_angle", "limit_warning", "torque_warning"]

SAT_NONE = 0      # the torque is the command
SAT_CURRENT = 1   # the command asks more than I_max K_t: the set-point is clipped, the voltage suffices
SAT_VOLTAGE = 2   # the battery voltage binds: the current that flows is below the set-point (back-EMF)
SATURATION_NAMES = ("none", "current", "voltage")


@dataclass(frozen=True)
class MotorConfig:
    """``motor.*`` of the plant (theory.md 6.7).  Every value must be finite and > 0 (ValueError naming the key)."""

    enabled: bool = False
    torque_constant: float = 2.0    # K_t [N m/A] at the wheel; also the back-EMF constant [V s/rad]
    resistance: float = 0.15        # R [ohm]
    voltage_limit: float = 48.0     # V_max [V]
    current_limit: float = 60.0     # I_max [A]

    def __post_init__(self):
        for name in ("torque_constant", "resistance", "voltage_limit", "current_limit"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ValueError(f"motor.{name}: must be a finite number > 0, got {v!r}")

    @property
    def peak_torque(self) -> float:
        """The most the drive gives [N m], at rest: K_t min(I_max, V_max / R) (:func:`motor_torque` at w = 0;
        I_max K_t unless the battery cannot drive I_max through the winding)."""
        return self.torque_constant * min(self.current_limit, self.voltage_limit / self.resistance)

    def torque(self, u_cmd: float, w: float) -> Tuple[float, int]:
        """:func:`motor_torque` with this drive's constants."""
        return motor_torque(u_cmd, w, self.torque_constant, self.resistance, self.voltage_limit, self.current_limit)


def motor_torque(u_cmd, w, K_t, R, V_max, I_max):
    """The torque the drive puts on the wheel for the command ``u_cmd`` at relative speed ``w`` (docs/theory.md 6.7).

    Parameters
    ----------
    u_cmd : float
        The command after ``torque_limit`` [N m].
    w : float
        th_w' - th_b', the rotor's speed relative to the stator [rad/s].
    K_t, R, V_max, I_max : float
        Torque (= back-EMF) constant [N m/A], resistance [ohm], voltage limit [V], current limit [A]; all > 0.

    Returns
    -------
    (u, code) : (float, int)
        The torque [N m] and which limit bound: :data:`SAT_NONE` (0), :data:`SAT_CURRENT` (1: the
        set-point is clipped at +-I_max and the voltage suffices), :data:`SAT_VOLTAGE` (2: the voltage
        is clipped at +-V_max; the current is then below the set-point, or, in over-speed, where the
        back-EMF alone passes V_max + R I_max, clipped at -+I_max too).  Per period the worst stage's
        code (the largest) is the period's.

    Pure float arithmetic (no ``math`` call): numba compiles it unchanged.
    """
    i_set = u_cmd / K_t
    code = SAT_NONE
    if i_set > I_max:                       # i* = clip(u_cmd / K_t, +-I_max)
        i_set = I_max
        code = SAT_CURRENT
    elif i_set < -I_max:
        i_set = -I_max
        code = SAT_CURRENT
    emf = K_t * w
    v = R * i_set + emf                     # V = clip(R i* + K_t w, +-V_max)
    if v > V_max:
        v = V_max
        code = SAT_VOLTAGE
    elif v < -V_max:
        v = -V_max
        code = SAT_VOLTAGE
    i = (v - emf) / R                       # i = clip((V - K_t w) / R, +-I_max)
    if i > I_max:
        i = I_max
    elif i < -I_max:
        i = -I_max
    return K_t * i, code                    # u = K_t i


def acted_torque(stage_u: Sequence[float], n: int) -> float:
    """The torque that acted over one period: ``sum over sub-steps of (u1 + 2 u2 + 2 u3 + u4) / (6 n)``.

    ``stage_u`` holds the 4 ``n`` stage torques in the order RK4 evaluates them (sub-step 1's k1..k4,
    then sub-step 2's, ...); ValueError unless there are exactly 4 ``n``.  With a constant torque it is
    that torque (the weights sum to 6 per sub-step)."""
    if n < 1 or len(stage_u) != 4 * n:
        raise ValueError(f"acted_torque: {len(stage_u)} stage torques for {n} sub-steps; expected 4 x {n}")
    s = 0.0
    for i in range(n):
        j = 4 * i
        s += stage_u[j] + 2.0 * stage_u[j + 1] + 2.0 * stage_u[j + 2] + stage_u[j + 3]
    return s / (6.0 * n)


def holding_torque(p: PhysicalParams, angle: float, m=math) -> float:
    """The least torque that stops the body of ``p`` falling further at tilt ``angle``, the robot at rest.

    From eq. (1) with q' = 0 (no friction, no centripetal term), the wheel free to roll::

        th_b'' det = m11 (G_b sin a - u) - m12 cos(a) u        (det = m11 m22 - m12^2 cos^2 a > 0)

    so th_b'' turns towards upright only for ``|u| > G_b sin|a| m11 / (m11 + m12 cos a)``: the torque
    that holds the weight while the wheel accelerates under it.  The wheel-locked figure ``G_b sin a``
    (the body row alone) overstates it by the factor ``1 + m12 cos(a) / m11`` (about 2 for the paper's
    robot near upright), which is why that is not the one used.  [N m]"""
    a = abs(angle)
    return p.G_b * m.sin(a) * p.m11 / (p.m11 + p.m12 * m.cos(a))


def recoverable_angle(p: PhysicalParams, torque: float) -> float:
    """The largest tilt [rad] in [0, pi/2] from which, at rest, ``torque`` still turns the body of ``p`` back
    (:func:`holding_torque` of it equals ``torque``; it grows with the angle there); pi/2 when ``torque``
    holds even that."""
    if torque <= 0.0:
        return 0.0
    lo, hi = 0.0, math.pi / 2
    if holding_torque(p, hi) <= torque:
        return hi
    for _ in range(60):   # bisection to ~1e-18 rad
        mid = 0.5 * (lo + hi)
        if holding_torque(p, mid) <= torque:
            lo = mid
        else:
            hi = mid
    return lo


def limit_warning(what: str, limit: float, p: PhysicalParams, angle: float, where: str) -> Optional[str]:
    """A one-line warning when the torque ``limit`` (``what``: the words naming it) is below :func:`holding_torque`
    of the robot ``p`` at the tilt ``angle`` (``where``: the words naming it), with both figures and the tilt beyond
    which the limit cannot turn the body back; None when it is not.  At rest: a bound, not a promise."""
    need = holding_torque(p, angle)
    if limit >= need:
        return None
    a = recoverable_angle(p, limit)
    return (f"{what} = {limit:.4g} N m is below the {need:.4g} N m that holds the body at {where} (at rest, G_b sin(a) "
            f"m11 / (m11 + m12 cos a), G_b = {p.G_b:.4g} N m): beyond |theta_b| = {a:.4f} rad "
            f"({math.degrees(a):.1f} deg) it cannot turn the body back")


def torque_warning(motor: MotorConfig, p: PhysicalParams, fall_angle: float) -> Optional[str]:
    """:func:`limit_warning` of the drive's peak torque (:attr:`MotorConfig.peak_torque`) at the fall angle (the
    robot ``p``: the true one for the plant); None when the motor is off.  The back-EMF lowers the peak at speed."""
    if not motor.enabled:
        return None
    amps = min(motor.current_limit, motor.voltage_limit / motor.resistance)
    return limit_warning(f"motor: the drive's peak torque K_t min(I_max, V_max / R) = {motor.torque_constant:g} N m/A "
                         f"x {amps:.4g} A", motor.peak_torque, p, fall_angle, f"fall_angle {fall_angle:g} rad")
