"""Identification of the drive (docs/theory.md 6.7, 6.9) from the commanded torque, the torque that acted and the
wheel speed of a log.

For a command of sign s the drive's torque (:func:`mwip_ros.core.plants.drive.motor_torque`, outside over-speed) is::

    s u = min(s u_cmd, T_I, T_V - a s w)      T_I = K_t I_max,  T_V = K_t V_max / R,  a = K_t^2 / R

(the command, the current limit, the voltage limit with its back-EMF slope).  Only these three combinations
reach the torque: ``(K_t, R, V_max, I_max)`` and ``(c K_t, c^2 R, c V_max, I_max / c)`` give the same torque for
every command and speed, so one of the four must be known.  It is ``V_max``, the battery's voltage (a voltmeter
reads it; the base file's ``motor.voltage_limit``), and then::

    K_t = a V_max / T_V,    R = K_t^2 / a,    I_max = T_I / K_t

**Fit.**  A period is saturated where the torque that acted differs from the command by more than ``rel_tol``
of it.  Of the saturated periods (in ``s u``, ``s w``, w the mean of the period's two sample speeds), those at the
plateau are the current limit and the rest lie on the line ``T_V - a s w``: the two branches are assigned
alternately (each period to the branch of :func:`motor_torque`'s minimum at the current fit; the plateau its
median, the line by least squares) until the assignment no longer changes.  Each branch needs
``min_samples`` periods: an experiment that reaches both limits (``config/identify_drive.yaml``).  The residual
of the torque that acted against :func:`motor_torque` at the fitted drive is reported (the period's torque is
the RK4-weighted mean over its speeds; the model is evaluated at their mean).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..plants.drive import motor_torque

__all__ = ["DriveIdentificationError", "DriveResult", "identify_drive", "REL_TOL", "MIN_DRIVE_SAMPLES"]

REL_TOL = 1e-3           # |u_applied - u_cmd| above this fraction of |u_cmd|: saturated
MIN_DRIVE_SAMPLES = 20   # periods on each limit
_ITERATIONS = 50


class DriveIdentificationError(ValueError):
    """The log cannot identify the drive; ``cause`` is ``not_saturated`` (a limit never bound) or ``bad_data``."""

    def __init__(self, cause: str, message: str):
        self.cause = cause
        super().__init__(message)


@dataclass(frozen=True)
class DriveResult:
    """The identified drive: the four constants of 6.7 (V_max the known one), the three combinations that reach the
    torque, and how many periods each regime had."""

    torque_constant: float   # K_t [N m/A]
    resistance: float        # R [ohm]
    voltage_limit: float     # V_max [V] (known)
    current_limit: float     # I_max [A]
    peak_torque: float       # T_I = K_t I_max [N m]
    stall_torque: float      # T_V = K_t V_max / R [N m]
    slope: float             # a = K_t^2 / R [N m s/rad]
    periods: tuple           # (unsaturated, current limit, voltage limit)
    residual_rms: float      # of u_applied - motor_torque(u_cmd, w) at the fit [N m]


def identify_drive(u_cmd: Sequence[float], u_applied: Sequence[float], dtheta_w: Sequence[float],
                   dtheta_b: Sequence[float], voltage_limit: float, rel_tol: float = REL_TOL,
                   min_samples: int = MIN_DRIVE_SAMPLES) -> DriveResult:
    """Fit K_t, R, I_max with V_max known (module doc).

    Parameters
    ----------
    u_cmd, u_applied : sequence of float
        Per row: the command after ``torque_limit`` and the torque that acted over the period that row starts
        [N m] (a log's ``u`` and ``u_applied``).
    dtheta_w, dtheta_b : sequence of float
        The rates at each row's time [rad/s]; the period's speed is the mean of its two ends' ``th_w' - th_b'``.
    voltage_limit : float
        V_max [V], the known one of the four.

    Raises
    ------
    DriveIdentificationError
        ``not_saturated`` when a limit has fewer than ``min_samples`` periods, ``bad_data`` for columns of
        different lengths or a V_max that is not a positive number.
    """
    cols = [np.asarray(a, dtype=float) for a in (u_cmd, u_applied, dtheta_w, dtheta_b)]
    if any(len(a) != len(cols[0]) for a in cols):
        raise DriveIdentificationError("bad_data", "the columns u, u_applied, dtheta_w, dtheta_b differ in length")
    if not (np.isfinite(voltage_limit) and voltage_limit > 0):
        raise DriveIdentificationError("bad_data", f"motor.voltage_limit: a voltage > 0 V, got {voltage_limit!r}")
    uc, ua, dw, db = (a[:-1] for a in cols)
    rel = cols[2] - cols[3]
    w = 0.5 * (rel[:-1] + rel[1:])
    ok = np.isfinite(uc) & np.isfinite(ua) & np.isfinite(w) & (uc != 0)
    uc, ua, w = uc[ok], ua[ok], w[ok]
    sat = np.abs(ua - uc) > rel_tol * np.abs(uc)
    s = np.sign(uc[sat])
    m, ws = s * ua[sat], s * w[sat]       # the torque's magnitude along the command, the speed along it
    if len(m) < 2 * min_samples:
        raise DriveIdentificationError("not_saturated", f"not saturated: {len(m)} saturated period(s), at least "
                                                        f"{2 * min_samples} needed on the two limits; run "
                                                        f"config/identify_drive.yaml")
    T_I = float(m.max())
    plateau = m >= T_I * (1 - rel_tol)
    for _ in range(_ITERATIONS):
        line = ~plateau
        if plateau.sum() < min_samples or line.sum() < min_samples:
            which = "current" if plateau.sum() < min_samples else "voltage"
            raise DriveIdentificationError("not_saturated", f"not saturated: the {which} limit bound in "
                                                            f"{int(min(plateau.sum(), line.sum()))} period(s), at "
                                                            f"least {min_samples} needed; run "
                                                            f"config/identify_drive.yaml")
        T_I = float(np.median(m[plateau]))
        slope, T_V = np.polyfit(ws[line], m[line], 1)
        a, T_V = float(-slope), float(T_V)
        new = T_I <= T_V - a * ws
        if np.array_equal(new, plateau):
            break
        plateau = new
    if not (a > 0 and T_V > 0 and T_I > 0):
        raise DriveIdentificationError("bad_data", f"the saturated periods do not fit the drive of 6.7: stall torque "
                                                   f"{T_V:.4g} N m, back-EMF slope {a:.4g} N m s/rad")
    K_t = a * voltage_limit / T_V
    R = K_t * K_t / a
    I_max = T_I / K_t
    model = np.array([motor_torque(c, v, K_t, R, voltage_limit, I_max)[0] for c, v in zip(uc, w)])
    return DriveResult(float(K_t), float(R), float(voltage_limit), float(I_max), T_I, T_V, a,
                       (int((~sat).sum()), int(plateau.sum()), int((~plateau).sum())),
                       float(np.sqrt(np.mean((ua - model) ** 2))))
