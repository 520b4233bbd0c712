"""Offline closed-loop simulator: the discrete-time contract (docs/theory.md), without ROS.

Row k of the result is the state at t_k, the command u_k computed from it, the estimate
tau_hat_k and the true lumped disturbance at t_k (:mod:`.trajectory`).  With sensing or
actuation options on (:mod:`.sensing`), the observer and the law see the measurement, the
table holds the true state and the torque that acted.  The ``plant_sim``,
``disturbance_observer`` and ``dscndo_controller`` nodes call the same classes in the same
order, so a lockstep graph reproduces these numbers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional, Tuple

from .controller import DscController, DscGains
from .lqr import LqrController
from .observer import DiscreteObserver, gain_matrix
from .plant import PlantConfig, PlantSim, saturate
from .sensing import Actuator, Sensors
from .trajectory import Trajectory, TrajectoryTable

__all__ = ["ClosedLoop", "simulate", "LAWS", "law_name", "make_controller"]

# The laws a user names (mwip_sim --controller, a sweep's controllers): (law, use_observer).
LAWS = {"dsc": ("dsc", False), "dscndo": ("dsc", True), "lqr": ("lqr", False), "lqr_ndo": ("lqr", True)}


def law_name(law: str, use_observer: bool) -> str:
    """('dsc', True) -> 'dscndo', the inverse of :data:`LAWS`."""
    return next(k for k, v in LAWS.items() if v == (law, bool(use_observer)))


def make_controller(law: str, nominal, gains: DscGains, K, h: float, use_observer: bool, m=math):
    """The law's stepper: ``DscController`` (eq. 19-28) or ``LqrController`` (``K`` from ``core.lqr.lqr_gain``)."""
    if law == "lqr":
        if K is None:
            raise ValueError("the lqr law needs its gain K")
        return LqrController(nominal, K, use_observer=use_observer, m=m)
    if law != "dsc":
        raise ValueError(f"unknown law {law!r} (dsc or lqr)")
    return DscController(nominal, gains, h, use_observer=use_observer, m=m)


@dataclass(frozen=True)
class ClosedLoop:
    """One closed-loop scenario: the plant, the observer gain X, the law and its gains, the length."""

    plant: PlantConfig
    X: Tuple[float, float, float, float]   # c1, c2, c3, c4 (eq. 14)
    gains: DscGains
    use_observer: bool                     # True: the law plus the observer term (DSCNDO, LQR+NDO)
    duration_s: float
    law: str = "dsc"                       # 'dsc' (eq. 19-28) or 'lqr' (core.lqr)
    K: Optional[Tuple[float, float, float]] = None   # the LQR gain, for law 'lqr'

    @property
    def name(self) -> str:
        return law_name(self.law, self.use_observer)


def simulate(loop: ClosedLoop, label: str = "", progress: Optional[Callable[[float], None]] = None) -> Trajectory:
    """Run the closed loop; stops early (``fallen``) when |theta_b| passes the fall angle."""
    pc = loop.plant
    h = pc.h
    n_steps = int(round(loop.duration_s / h))
    plant = PlantSim(pc)
    obs = DiscreteObserver(pc.nominal, gain_matrix(loop.X), h)
    ctrl = make_controller(loop.law, pc.nominal, loop.gains, loop.K, h, loop.use_observer)
    table = TrajectoryTable(internals=True)
    sc = pc.sensing
    sensors = Sensors.for_plant(sc, pc.seed) if sc.measuring else None
    actuator = Actuator(sc.actuator_delay_periods) if sc.actuator_delay_periods else None
    fallen = False
    every = max(1, n_steps // 10)
    for k in range(n_steps + 1):
        x = plant.x                      # the true state: the table and the metrics judge it
        x_m, u_m = sensors.sample(x, plant.u_prev) if sensors else (x, plant.u_prev)   # what the loop sees
        tau_hat = obs.update(x_m, u_m)
        out = ctrl.step(x_m, tau_hat)
        u = saturate(out.u, pc.torque_limit)
        if actuator:
            u = actuator.apply(u)        # the torque that acts over [t_k, t_k+1)
        table.append(plant.t, x, u, tau_hat, plant.lumped_disturbance(u), out)
        if plant.fallen:
            fallen = True
            break
        if k == n_steps:
            break
        plant.step(u)
        if progress is not None and k % every == 0:
            progress(k / n_steps)
    return table.trajectory(label or loop.name, fallen, h)
