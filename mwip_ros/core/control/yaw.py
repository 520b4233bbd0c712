"""The yaw stage (docs/theory.md 6.13): a yaw-rate loop and the two wheel torques of the 3D plant.

Once per control period k, after the law (:data:`.loop.STAGES`, stage ``yaw``), with the reference psi'*_k of the
motion references (:class:`.motion.Shaper`) and the measured yaw rate w_k (the gyro's body-z rate of a spatial
plant, :meth:`.loop.PlantSide.sense_yaw_rate`):

    e_k     = psi'*_k - w_k
    I_k     = I_{k-1} + h e_k                           I_{-1} = 0
    u_psi,k = yaw_kp e_k + yaw_ki I_k                   (PI, the integral by the rectangle rule)

Balance first (``motion.yaw_wheel_limit`` = L > 0, a wheel's torque the drive can give): the pair may only use what
the law's u leaves of each wheel's L, ``|u_psi| <= max(0, 2 L - |u_k|)``, so |u / 2| + |u_psi / 2| <= L and a
saturating wheel never takes torque from the balance; while it is clipped the integral does not grow further in the
clipped direction (conditional integration: the step's h e is taken back).

and the wheels' torques (:func:`wheel_torques`), each clipped to half of ``torque_limit``:

    u_L = clip(u / 2 - u_psi / 2),    u_R = clip(u / 2 + u_psi / 2)

so u = u_L + u_R is the law's command whenever neither wheel clips, and a yaw torque pair +-u_psi / 2 turns the
robot (+psi', to the left, REP-103: the right wheel forward).  No ROS here: the offline loop
(:class:`.loop.Period`) runs it; a planar plant has no yaw and no stage.

With ``calibration_s`` = T > 0 (``motion.yaw_gyro_calibration_s``: a gyro with a bias, the raw sensors' IMU) the
first N = round(T / h) periods calibrate the gyro: u_psi = 0, I stays 0, and from period N on the measurement is
w_k - b with b the mean of w_0 .. w_{N-1} (a gyro's zero-rate offset taken at start-up, while the robot does not
turn: a PI on a biased rate would turn the robot at -bias and wind its integral up against the scrubbing wheels).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

from ..plants.plant import per_wheel, saturate

__all__ = ["YawConfig", "YawLoop", "wheel_torques"]


@dataclass(frozen=True)
class YawConfig:
    """The ``motion.yaw_kp`` [N m per rad/s] and ``motion.yaw_ki`` [N m per rad] gains (params.motion)."""

    kp: float = 400.0
    ki: float = 4000.0
    calibration_s: float = 0.0   # ``motion.yaw_gyro_calibration_s`` [s]: 0 = the gyro is not calibrated
    wheel_limit: float = 0.0     # ``motion.yaw_wheel_limit`` [N m]: a wheel's torque, the law's first; 0 = no limit


class YawLoop:
    """The PI on the yaw rate (module docstring); ``h`` the control period [s]."""

    def __init__(self, cfg: YawConfig, h: float):
        self.cfg, self.h = cfg, h
        self.calibration = int(round(cfg.calibration_s / h))   # N periods
        self.reset()

    def reset(self) -> None:
        """Forget the run: the integral is zero again."""
        self.integral = 0.0
        self.u_psi = 0.0
        self.samples, self.total, self.bias = 0, 0.0, 0.0   # the calibration's count, sum and mean

    def idle(self, dpsi: float) -> float:
        """A period with no torque acting (the driver not enabled, docs/theory.md 6.8): u_psi = 0 and the integral
        stays 0, so it cannot wind up while the wheels cannot turn the robot; the gyro's calibration goes on (the
        robot held still is what it needs).  Returns 0."""
        self.integral = 0.0
        self.u_psi = 0.0
        if self.samples < self.calibration and math.isfinite(dpsi):
            self.samples += 1
            self.total += dpsi
            self.bias = self.total / self.samples
        return 0.0

    def step(self, dpsi_ref: float, dpsi: float, u: float = 0.0) -> float:
        """u_psi of one period for the reference ``dpsi_ref`` and the measured yaw rate ``dpsi`` [rad/s], the law's
        command ``u`` [N m] of the same period taking its share of each wheel first (``wheel_limit``).  A measurement
        that is not finite leaves the integral as it was and gives u_psi = 0 (NaN never reaches a torque)."""
        e = dpsi_ref - dpsi
        if not math.isfinite(e):
            self.u_psi = 0.0
            return 0.0
        if self.samples < self.calibration:   # calibrating: the mean of the first N readings, no torque
            self.samples += 1
            self.total += dpsi
            self.bias = self.total / self.samples
            self.u_psi = 0.0
            return 0.0
        e += self.bias
        self.integral += self.h * e
        u_psi = self.cfg.kp * e + self.cfg.ki * self.integral
        if self.cfg.wheel_limit > 0.0:   # balance first: the pair gets what u leaves of each wheel
            room = max(0.0, 2.0 * self.cfg.wheel_limit - abs(u)) if math.isfinite(u) else 0.0
            if abs(u_psi) > room:
                if u_psi * e > 0.0:      # conditional integration: no further wind-up toward the clip
                    self.integral -= self.h * e
                u_psi = math.copysign(room, u_psi)
        self.u_psi = u_psi
        return u_psi


def wheel_torques(u: float, u_psi: float, torque_limit: float) -> Tuple[float, float]:
    """(u_L, u_R) = (u / 2 - u_psi / 2, u / 2 + u_psi / 2), each clipped to +-``torque_limit`` / 2 (0: no limit)."""
    lim = per_wheel(torque_limit)
    return saturate(0.5 * u - 0.5 * u_psi, lim), saturate(0.5 * u + 0.5 * u_psi, lim)
