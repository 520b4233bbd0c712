"""The true plant as a discrete-time stepper (SPEC sections 1 and 4).

``PlantSim`` integrates eq. (1) with classic RK4 in ``substeps`` equal sub-steps
per control period, holding ``u`` and ``D_w`` over the period and evaluating
tau_ext at each stage time.  ``D_w`` is drawn once per period from a seeded
generator (Gaussian, clipped at 0).  The offline simulator and the
``plant_sim`` node both drive this class, so they integrate the same numbers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Tuple

import numpy as np

from mwip_ros.model import Friction, PhysicalParams, Sinusoid, lumped_disturbance, plant_accel


@dataclass(frozen=True)
class PlantConfig:
    actual: PhysicalParams
    nominal: PhysicalParams          # only to report the true lumped disturbance
    D_b: float
    D_w_mean: float
    D_w_variance: float
    tau_ext1: Sinusoid
    tau_ext2: Sinusoid
    h: float                         # control period [s]
    substeps: int = 5
    seed: int = 0
    initial: Tuple[float, float, float, float] = (0.0, -0.1745, 0.0, 0.0)  # theta_w, theta_b, dtheta_w, dtheta_b
    torque_limit: float = 0.0        # 0 = none
    fall_angle: float = 1.0472


def config_from_values(v) -> PlantConfig:
    """PlantConfig from a plant_sim parameter dict (see ``mwip_ros.params``)."""
    from mwip_ros import params as P
    return PlantConfig(
        actual=P.physical(v, "actual"), nominal=P.physical(v, "nominal"),
        D_b=v["actual.D_b"], D_w_mean=v["actual.D_w_mean"], D_w_variance=v["actual.D_w_variance"],
        tau_ext1=P.sinusoid(v, "tau_ext1"), tau_ext2=P.sinusoid(v, "tau_ext2"),
        h=P.period(v), substeps=v["substeps"], seed=v["seed"],
        initial=(v["initial.theta_w"], v["initial.theta_b"], v["initial.dtheta_w"], v["initial.dtheta_b"]),
        torque_limit=v["torque_limit"], fall_angle=v["fall_angle"])


def saturate(u: float, limit: float) -> float:
    """Apply ``torque_limit`` (0 = no limit)."""
    if limit > 0.0:
        return max(-limit, min(limit, u))
    return u


@dataclass
class PlantSim:
    """State x = [theta_w, theta_b, dtheta_w, dtheta_b] at t_k = k h."""

    cfg: PlantConfig
    k: int = 0
    x: np.ndarray = field(default=None)
    D_w: float = 0.0                 # ground friction over the current period
    u_prev: float = 0.0              # torque applied over the previous period (0 at k = 0)
    _rng: np.random.Generator = field(default=None, repr=False)

    def __post_init__(self):
        if self.x is None:
            self.x = np.array(self.cfg.initial, dtype=float)
        self._rng = np.random.default_rng(self.cfg.seed)
        self.D_w = self._draw_D_w()

    @property
    def t(self) -> float:
        return self.k * self.cfg.h

    @property
    def q(self) -> np.ndarray:
        return self.x[:2]

    @property
    def dq(self) -> np.ndarray:
        return self.x[2:]

    @property
    def fallen(self) -> bool:
        return abs(self.x[1]) > self.cfg.fall_angle

    def _draw_D_w(self) -> float:
        c = self.cfg
        if c.D_w_variance == 0.0:
            return c.D_w_mean
        return max(0.0, c.D_w_mean + math.sqrt(c.D_w_variance) * self._rng.standard_normal())

    def tau_ext(self, t: float, extra: Tuple[float, float] = (0.0, 0.0)) -> Tuple[float, float]:
        return self.cfg.tau_ext1(t) + extra[0], self.cfg.tau_ext2(t) + extra[1]

    def deriv(self, t: float, x: np.ndarray, u: float, extra=(0.0, 0.0)) -> np.ndarray:
        e1, e2 = self.tau_ext(t, extra)
        ddq = plant_accel(self.cfg.actual, Friction(self.cfg.D_b, self.D_w), x[:2], x[2:], u, e1, e2)
        return np.array([x[2], x[3], ddq[0], ddq[1]])

    def lumped_disturbance(self, u: float, extra=(0.0, 0.0)) -> np.ndarray:
        """True tau_d at t_k with u_k applied (what the observer should estimate)."""
        d = self.deriv(self.t, self.x, u, extra)
        return lumped_disturbance(self.cfg.nominal, self.x[:2], self.x[2:], d[2:], u)

    def step(self, u: float, extra=(0.0, 0.0)) -> None:
        """Integrate t_k -> t_{k+1} with u (already saturated) and D_w held; RK4, ``substeps`` steps."""
        n = self.cfg.substeps
        dt = self.cfg.h / n
        x = self.x
        t0 = self.t
        for i in range(n):
            t = t0 + i * dt
            k1 = self.deriv(t, x, u, extra)
            k2 = self.deriv(t + dt / 2, x + dt / 2 * k1, u, extra)
            k3 = self.deriv(t + dt / 2, x + dt / 2 * k2, u, extra)
            k4 = self.deriv(t + dt, x + dt * k3, u, extra)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        self.x = x
        self.k += 1
        self.u_prev = u
        self.D_w = self._draw_D_w()
