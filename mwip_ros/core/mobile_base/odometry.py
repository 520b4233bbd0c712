"""Wheel odometry (docs/theory.md 6.12): the robot's pose on the ground, x, y and yaw, from its wheels and gyro.

Each wheel's encoder measures its angle *relative to the body* (the stator is bolted to the body, docs/theory.md
6.4), so a wheel's absolute rate is the encoder's rate plus the body's pitch rate, and the forward speed is the
mean of the two (REP-103: x forward, y left, z up; ``theta > 0`` rolls forward)::

    theta_i' = phi_i' + theta_b'                        i = L, R
    v        = r (theta_L' + theta_R') / 2
    psi'     = gyro's yaw rate, or r (theta_R' - theta_L') / track_width without a gyro about z
    x' = v cos(psi),  y' = v sin(psi)

The pose is integrated exactly over a period for a constant ``v`` and ``psi'`` (an arc of radius v / psi', a
straight line when psi' = 0), as ROS's diff_drive_controller does: a straight run, a turn in place and a circle
come out exact, whatever the period.  Which constant depends on what the rates are (``rule``): ``rectangle``
holds each sample's rates over the period that ends at it (a driver's differenced encoder rate is that period's
mean; so is, to within its own error, the state estimator's), ``trapezoid`` takes the mean of the two ends (an
instantaneous rate, as the plant's ideal state has it: over the paper's 10 s the drift falls from 0.58 mm with
the rectangle to 2 um).

The planar robot (one encoder, no yaw) is the case L = R: :meth:`Odometry.update` takes one rate for both wheels,
its yaw rate stays 0.

**Covariances** (:func:`odometry_noise`).  A measurement's white noise gives the speed's and the yaw rate's
variances (the twist covariance) and, propagated through the linearised integration, the pose covariance::

    sigma_phi'^2 = q^2 / (6 h^2),   q = 2 pi / counts     (two independent rounding errors of U(-q/2, q/2) per rate)
    var v        = r^2 (sigma_phi'^2 / n + sigma_gyro^2)   n = 2 encoders (1 when both wheels share one)
    var psi'     = sigma_gyro^2 with a yaw gyro, else 2 (r / track_width)^2 sigma_phi'^2
    P_k = F P_{k-1} F^T + G diag(var v, var psi') G^T     F, G: the step's Jacobians in the pose and in (v, psi')

Ideal sensors (0 counts, 0 noise) give zero covariance.  Two things are left out on purpose and documented: a
gyro's bias (a systematic error, not noise: it enters v as r bias and makes x drift linearly; the state
estimator's bias-corrected pitch rate removes it), and the correlation of successive quantization errors (they
telescope: the encoder's own contribution to x is bounded by r q, which the white model over-estimates, so the
pose covariance is conservative).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Tuple

import numpy as np

__all__ = ["OdometryNoise", "odometry_noise", "encoder_rate_std", "absolute_wheel_rates", "body_twist", "arc_step",
           "Odometry", "RULES", "yaw_quaternion", "gyro_yaw_rate", "state_update", "rule_for", "odometry_drift"]

RULES = ("rectangle", "trapezoid")


@dataclass(frozen=True)
class OdometryNoise:
    """The white noise of the two integrated inputs: the forward speed [m/s] and the yaw rate [rad/s] (one sample)."""

    speed_std: float = 0.0
    yaw_rate_std: float = 0.0


def encoder_rate_std(counts_per_rev: int, h: float) -> float:
    """The standard deviation of a differenced encoder's rate, (phi_k - phi_{k-1}) / h, from its rounding to
    ``counts_per_rev`` counts (0 = ideal: 0): q / (h sqrt 6), q = 2 pi / counts."""
    if counts_per_rev <= 0:
        return 0.0
    q = 2.0 * math.pi / counts_per_rev
    return q / (h * math.sqrt(6.0))


def odometry_noise(r: float, track_width: float, h: float, counts_per_rev: int = 0, gyro_noise_std: float = 0.0,
                   encoders: int = 2, yaw_gyro: bool = True) -> OdometryNoise:
    """The odometry's input noise from the sensors' (module docstring).

    Parameters
    ----------
    r, track_width : float
        Wheel radius and wheel-to-wheel distance [m].
    h : float
        The period of the encoder's rate [s].
    counts_per_rev : int
        Encoder counts per revolution (0 = ideal).
    gyro_noise_std : float
        The gyro's white noise per sample [rad/s], on the pitch and on the yaw axis.
    encoders : int
        2 (one per wheel) or 1 (both wheels share one, the planar robot).
    yaw_gyro : bool
        Does a gyro measure the yaw rate (else it comes from the wheels)?
    """
    if encoders not in (1, 2):
        raise ValueError(f"encoders: {encoders} (1 or 2)")
    s_phi = encoder_rate_std(counts_per_rev, h)
    speed = r * math.sqrt(s_phi ** 2 / encoders + gyro_noise_std ** 2)
    yaw = gyro_noise_std if yaw_gyro else math.sqrt(2.0) * r / track_width * s_phi
    return OdometryNoise(speed, yaw)


def absolute_wheel_rates(phi_rate_left: float, phi_rate_right: float, pitch_rate: float) -> Tuple[float, float]:
    """(theta_L', theta_R'): each wheel's absolute rate, its encoder's rate relative to the body plus the pitch rate."""
    return phi_rate_left + pitch_rate, phi_rate_right + pitch_rate


def body_twist(rate_left: float, rate_right: float, r: float, track_width: float,
               yaw_rate: Optional[float] = None) -> Tuple[float, float]:
    """(v, psi'): the forward speed r (theta_L' + theta_R') / 2 and the yaw rate (the gyro's ``yaw_rate`` when
    given, else r (theta_R' - theta_L') / track_width) of the absolute wheel rates."""
    v = r * (rate_left + rate_right) / 2.0
    w = yaw_rate if yaw_rate is not None else r * (rate_right - rate_left) / track_width
    return v, w


def arc_step(x: float, y: float, yaw: float, v: float, w: float, dt: float) -> Tuple[float, float, float]:
    """The pose after ``dt`` at constant speed ``v`` and yaw rate ``w``: exact (an arc; a line when w dt is 0)."""
    dyaw = w * dt
    if abs(dyaw) < 1e-9:   # the arc's series to second order: exact to rounding for a line
        c = v * dt * (1.0 - dyaw * dyaw / 6.0)
        mid = yaw + dyaw / 2.0
        return x + c * math.cos(mid), y + c * math.sin(mid), yaw + dyaw
    rho = v / w
    y1 = yaw + dyaw
    return x + rho * (math.sin(y1) - math.sin(yaw)), y - rho * (math.cos(y1) - math.cos(yaw)), y1


def yaw_quaternion(yaw: float) -> Tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` about +z."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


@dataclass
class Odometry:
    """One robot's odometry: the pose (x, y, yaw) in the frame ``odom`` (its start), the last twist and the
    covariances (module docstring).  ``yaw`` is not wrapped (a quaternion takes any angle)."""

    r: float
    track_width: float
    noise: OdometryNoise = field(default_factory=OdometryNoise)
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    v: float = 0.0
    yaw_rate: float = 0.0
    t: Optional[float] = None
    P: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    updates: int = 0
    rule: str = "rectangle"   # rectangle | trapezoid (module docstring)

    def __post_init__(self):
        if self.rule not in RULES:
            raise ValueError(f"rule: {self.rule!r} (one of {', '.join(RULES)})")

    def reset(self) -> None:
        """Back to the origin, no time, zero covariance."""
        self.x = self.y = self.yaw = self.v = self.yaw_rate = 0.0
        self.t, self.P, self.updates = None, np.zeros((3, 3)), 0

    def update(self, t: float, rate_left: float, rate_right: Optional[float] = None,
               yaw_rate: Optional[float] = None) -> bool:
        """Integrate up to time ``t`` [s] with the absolute wheel rates (``rate_right`` None: the planar robot, both
        wheels at ``rate_left``) and the gyro's ``yaw_rate`` (None: from the wheels).  The rates are held over
        the interval since the previous update (a driver reports the rate over the period that ends at its
        sample).  The first call only sets the time.  Returns False, changing nothing, for a non-finite input
        or a time that does not advance."""
        rr = rate_left if rate_right is None else rate_right
        vals = (t, rate_left, rr) + (() if yaw_rate is None else (yaw_rate,))
        if not all(math.isfinite(a) for a in vals):
            return False
        if self.t is not None and t <= self.t:
            return False
        v1, w1 = body_twist(rate_left, rr, self.r, self.track_width, yaw_rate)
        v0, w0 = self.v, self.yaw_rate
        self.v, self.yaw_rate = v1, w1
        if self.t is None:
            self.t = t
            return True
        v, w = ((v0 + v1) / 2.0, (w0 + w1) / 2.0) if self.rule == "trapezoid" else (v1, w1)
        dt = t - self.t
        yaw0 = self.yaw
        self.x, self.y, self.yaw = arc_step(self.x, self.y, self.yaw, v, w, dt)
        # the covariance through the linearised step (midpoint heading): d(pose)/d(pose) and d(pose)/d(v, w)
        mid = yaw0 + w * dt / 2.0
        c, s = math.cos(mid), math.sin(mid)
        F = np.array([[1.0, 0.0, -v * dt * s], [0.0, 1.0, v * dt * c], [0.0, 0.0, 1.0]])
        G = np.array([[dt * c, -v * dt * dt * s / 2.0], [dt * s, v * dt * dt * c / 2.0], [0.0, dt]])
        Q = np.diag([self.noise.speed_std ** 2, self.noise.yaw_rate_std ** 2])
        self.P = F @ self.P @ F.T + G @ Q @ G.T
        self.t = t
        self.updates += 1
        return True

    def pose_covariance(self) -> list:
        """The 6x6 row-major covariance of (x, y, z, roll, pitch, yaw), as nav_msgs/Odometry carries it: the
        planar (x, y, yaw) block, z, roll and pitch zero (not estimated)."""
        out = [0.0] * 36
        idx = (0, 1, 5)
        for i, a in enumerate(idx):
            for j, b in enumerate(idx):
                out[a * 6 + b] = float(self.P[i, j])
        return out

    def twist_covariance(self) -> list:
        """The 6x6 covariance of (v_x, v_y, v_z, w_x, w_y, w_z): var v and var psi' on the diagonal."""
        out = [0.0] * 36
        out[0] = self.noise.speed_std ** 2
        out[35] = self.noise.yaw_rate_std ** 2
        return out


def gyro_yaw_rate(gyro_z: float, theta_b: float) -> float:
    """The yaw rate psi' about the vertical from a body-fixed gyro's z rate: the body pitched by theta_b turning at psi'
    reads cos(theta_b) psi' about its own z (docs/theory.md 6.13), so psi' = gyro_z / cos(theta_b)."""
    return gyro_z / math.cos(theta_b)


def state_update(odom: Odometry, t: float, dtheta_w: float, theta_b: float, gyro_z: Optional[float] = None) -> bool:
    """One state into the odometry, as ``robot_state`` takes it: both wheels at the state's theta_w' (their mean: v =
    r theta_w' whatever their difference) and, from a 3D plant's state (its gyro's yaw rate ``gyro_z``), the yaw rate
    :func:`gyro_yaw_rate`; without one the planar robot's 0."""
    w = 0.0 if gyro_z is None else gyro_yaw_rate(gyro_z, theta_b)
    return odom.update(t, dtheta_w, yaw_rate=w)


def rule_for(sensors_model: str) -> str:
    """The integration rule of the odometry of ``sensors.model``'s states (module docstring): ``raw``, the state
    estimator's rates, each the period's (rectangle); otherwise the plant's state, instantaneous (trapezoid)."""
    return "rectangle" if sensors_model == "raw" else "trapezoid"


def odometry_drift(cols, r: float, track_width: float, sensors_model: str = "state") -> dict:
    """The odometry of a run's measured states (columns t, dtheta_w, theta_b, gyro_z; :func:`state_update` by the
    rule of ``sensors_model``, :func:`rule_for`, as ``robot_state`` integrates them) against its true pose (x, y,
    yaw, relative to the first): ``final_pos`` and ``max_pos`` [m], the distance of odom's (x, y) to the true
    displacement at the end and at worst; ``final_yaw`` [rad], odom's yaw minus the true one at the end.  Rows after
    the first non-finite one are left out; ValueError (one line) when that leaves none (the first row's state or
    pose is not finite): no drift is computed from nothing."""
    t, dw, tb, gz = (np.asarray(cols[c], float) for c in ("t", "dtheta_w", "theta_b", "gyro_z"))
    x, y, yaw = (np.asarray(cols[c], float) for c in ("x", "y", "yaw"))
    yaw = np.unwrap(yaw)
    odom = Odometry(r, track_width, rule=rule_for(sensors_model))
    err = []
    for k in range(len(t)):
        if not (state_update(odom, float(t[k]), float(dw[k]), float(tb[k]), float(gz[k]))
                and math.isfinite(x[k] + y[k] + yaw[k])):
            break
        err.append((math.hypot(odom.x - (x[k] - x[0]), odom.y - (y[k] - y[0])), odom.yaw - (yaw[k] - yaw[0])))
    if not err:
        raise ValueError("odometry drift: the run's first row is not finite (its state or its pose): nothing to "
                         "integrate")
    e = np.asarray(err)
    return {"final_pos": float(e[-1, 0]), "max_pos": float(e[:, 0].max()), "final_yaw": float(e[-1, 1])}
