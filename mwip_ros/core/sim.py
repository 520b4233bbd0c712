"""Offline closed-loop simulator: the discrete-time contract (docs/theory.md), without ROS.

Row k of the result is the state at t_k, the command u_k computed from it, the estimate
tau_hat_k and the true lumped disturbance at t_k (:mod:`.trajectory`).  The ``plant_sim``,
``disturbance_observer`` and ``dscndo_controller`` nodes call the same classes in the same
order, so a lockstep graph reproduces these numbers.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional, Tuple

from .controller import DscController, DscGains
from .observer import DiscreteObserver, gain_matrix
from .plant import PlantConfig, PlantSim, saturate
from .trajectory import Trajectory, TrajectoryTable

__all__ = ["ClosedLoop", "simulate"]


@dataclass(frozen=True)
class ClosedLoop:
    """One closed-loop scenario: the plant, the observer gain X, the DSC gains, the law and the length."""

    plant: PlantConfig
    X: Tuple[float, float, float, float]   # c1, c2, c3, c4 (eq. 14)
    gains: DscGains
    use_observer: bool                     # True = DSCNDO, False = DSC
    duration_s: float


def simulate(loop: ClosedLoop, label: str = "", progress: Optional[Callable[[float], None]] = None) -> Trajectory:
    """Run the closed loop; stops early (``fallen``) when |theta_b| passes the fall angle."""
    pc = loop.plant
    h = pc.h
    n_steps = int(round(loop.duration_s / h))
    plant = PlantSim(pc)
    obs = DiscreteObserver(pc.nominal, gain_matrix(loop.X), h)
    ctrl = DscController(pc.nominal, loop.gains, h, use_observer=loop.use_observer)
    table = TrajectoryTable(internals=True)
    fallen = False
    every = max(1, n_steps // 10)
    for k in range(n_steps + 1):
        x = plant.x
        tau_hat = obs.update(x, plant.u_prev)
        out = ctrl.step(x, tau_hat)
        u = saturate(out.u, pc.torque_limit)
        table.append(plant.t, x, u, tau_hat, plant.lumped_disturbance(u), out)
        if plant.fallen:
            fallen = True
            break
        if k == n_steps:
            break
        plant.step(u)
        if progress is not None and k % every == 0:
            progress(k / n_steps)
    return table.trajectory(label or ("dscndo" if loop.use_observer else "dsc"), fallen, h)
