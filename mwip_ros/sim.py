"""Offline closed-loop simulator: the discrete-time contract of SPEC section 4, without ROS.

Row k of the result is the state at t_k, the command u_k computed from it, the
estimate tau_hat_k and the true lumped disturbance at t_k.  The ``plant_sim``,
``disturbance_observer`` and ``dscndo_controller`` nodes call the same classes in
the same order, so a lockstep graph reproduces these numbers.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional

import numpy as np

from mwip_ros import params as P
from mwip_ros.controller import DscController
from mwip_ros.observer import DiscreteObserver, gain_matrix
from mwip_ros.plant import PlantSim, config_from_values, saturate

# Column order of the CSV (and of SimResult.columns). The first ten are the trajectory every
# source has (simulator, plant_sim's CSV, a bag); the rest are the controller's internals.
TRAJECTORY_COLUMNS = ["t", "theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_hat1", "tau_hat2",
                      "tau_d1", "tau_d2"]
COLUMNS = TRAJECTORY_COLUMNS + ["u_dsc", "u_taud", "S1", "S2", "x4_bar", "x4d"]


@dataclass
class SimResult:
    label: str
    columns: Dict[str, np.ndarray]
    fallen: bool
    h: float

    @property
    def t(self) -> np.ndarray:
        return self.columns["t"]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __len__(self) -> int:
        return len(self.columns["t"])

    def write_csv(self, path) -> None:
        """The columns this run has, in ``COLUMNS`` order, floats written exactly (repr)."""
        names = [c for c in COLUMNS if c in self.columns]
        with open(path, "w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(names)
            for row in zip(*(self.columns[c] for c in names)):
                w.writerow([repr(float(x)) for x in row])


def read_csv(path, label: Optional[str] = None) -> SimResult:
    """Read a CSV written by ``SimResult.write_csv`` (or by ``plant_sim``'s ``csv`` parameter)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or "t" not in rows[0]:
        raise ValueError(f"{path}: not an mwip_sim CSV (no header with a 't' column)")
    header = rows[0]
    data = np.array([[float(x) for x in r] for r in rows[1:]], dtype=float).reshape(-1, len(header))
    cols = {name: data[:, i] for i, name in enumerate(header)}
    h = float(cols["t"][1] - cols["t"][0]) if len(data) > 1 else float("nan")
    return SimResult(label or str(path), cols, False, h)  # a CSV does not say; metrics.compute judges |theta_b|


def simulate(values: Mapping, use_observer: Optional[bool] = None, duration: Optional[float] = None,
             label: str = "", progress: Optional[Callable[[float], None]] = None) -> SimResult:
    """Run the closed loop from a merged parameter dict (plant + observer + controller values).

    ``values`` holds every key of the plant_sim, disturbance_observer and
    dscndo_controller sections (see ``merged_values``).
    """
    pc = config_from_values(values)
    h = pc.h
    use_obs = values["use_observer"] if use_observer is None else use_observer
    T = values["duration_s"] if duration is None else duration
    n_steps = int(round(T / h))
    plant = PlantSim(pc)
    obs = DiscreteObserver(pc.nominal, gain_matrix(values["X"]), h)
    ctrl = DscController(pc.nominal, P.gains(values), h, use_observer=use_obs)
    rows: List[tuple] = []
    fallen = False
    every = max(1, n_steps // 10)
    for k in range(n_steps + 1):
        x = plant.x
        tau_hat = obs.update(x[:2], x[2:], plant.u_prev)
        out = ctrl.step(x[1], x[3], x[2], tau_hat)
        u = saturate(out.u, pc.torque_limit)
        tau_d = plant.lumped_disturbance(u)
        rows.append((plant.t, *x, u, *tau_hat, *tau_d, out.u_dsc, out.u_taud, out.S1, out.S2, out.x4_bar, out.x4d))
        if plant.fallen:
            fallen = True
            break
        if k == n_steps:
            break
        plant.step(u)
        if progress is not None and k % every == 0:
            progress(k / n_steps)
    data = np.array(rows, dtype=float)
    cols = {c: data[:, i] for i, c in enumerate(COLUMNS)}
    return SimResult(label or ("dscndo" if use_obs else "dsc"), cols, fallen, h)


def merged_values(pf: P.ParamFile, overrides: Optional[Mapping] = None) -> Dict:
    """One dict with the plant's, observer's and controller's values from one parameter file."""
    v: Dict = {}
    for node in ("dscndo_controller", "disturbance_observer", "plant_sim"):
        v.update(pf.for_node(node))
    v.update(overrides or {})
    return v
