"""A batch's scenarios (:mod:`.batch`): what they must share, their values as one column each, the result, and the
scalar loop run scenario by scenario (:func:`_simulate_each`), the form every other one falls back to.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass
from typing import Dict, List, Optional, Sequence

import numpy as np

from .. import laws
from ..closed_loop.metrics import compute as metrics_compute
from ..closed_loop.metrics import MOTION_METRICS, motion_metrics
from ..closed_loop.sim import ClosedLoop
from ..closed_loop.trajectory import FAILURES, FALL, Trajectory

__all__ = ["BatchResult"]


@dataclass
class BatchResult:
    """Per scenario: fell or not, when, and the metrics over the window (arrays of length N)."""

    fallen: np.ndarray          # bool
    t_fall: np.ndarray          # [s], NaN when upright
    upright: np.ndarray         # bool: never fell and ran past the window
    metrics: Dict[str, np.ndarray]
    steps: int                  # scenario-steps integrated (fallen scenarios stop counting)
    trajectories: Optional[List[Trajectory]] = None
    failure: Optional[np.ndarray] = None   # int: why each failed, an index of FAILURES (0: it did not)

    def __post_init__(self):
        if self.failure is None:
            self.failure = np.where(self.fallen, FALL, 0).astype(np.int64)


def _column(values):
    """The scenarios' values of one quantity: one float when they all share it, else an array.

    A shared value stays a scalar, so whatever depends only on shared values (tau_ext with one
    amplitude and frequency, the nominal model's inertia terms) is computed once per step, not
    once per scenario; elementwise it is the same arithmetic, so the results do not change."""
    a = np.asarray(list(values), dtype=float)
    return float(a[0]) if len(a) and (a == a[0]).all() else a


def _stack(items, cls):
    """One ``cls`` (a dataclass or a NamedTuple) whose field f holds the scenarios' values of f (:func:`_column`)."""
    names = [f.name for f in fields(cls)] if is_dataclass(cls) else list(cls._fields)
    return cls(**{f: _column(getattr(i, f) for i in items) for f in names})


def _same(values, what: str):
    values = set(values)
    if len(values) != 1:
        raise ValueError(f"the scenarios of one batch must share {what}; got {sorted(values)}")
    return values.pop()


def _simulate_each(loops: Sequence[ClosedLoop], window: Sequence[float], record: bool = False) -> BatchResult:
    """The scalar loop (:func:`.sim.simulate`) scenario by scenario, its metrics as the batch gives them: the
    form for the stages the array forms do not run (:func:`_beyond_arrays`), the same numbers by construction."""
    from ..closed_loop.sim import simulate
    runs = []
    for i, lp in enumerate(loops):
        try:
            runs.append(simulate(lp, diverged_fails=True))   # a diverged scenario is a failure, not an error
        except laws.LawError as exc:   # the law's own error, with the scenario (its index in ``loops``)
            raise exc.in_scenario(i) from exc
    named = [metrics_compute(r.columns, window, lp.plant.fall_angle, r.record.get("t_fall"))
             for r, lp in zip(runs, loops)]
    fallen = np.array([r.fallen for r in runs], dtype=bool)
    t_fall = np.array([m.t_fall if m.t_fall is not None else np.nan for m in named])
    n_steps = [int(round(lp.duration_s / lp.plant.h)) for lp in loops]
    upright = ~fallen & np.array([n * lp.plant.h >= window[1] - 1e-9 for n, lp in zip(n_steps, loops)])
    keys = ("theta_b_p2p", "theta_b_rms", "theta_b_max_abs", "u_rms", "tau_err1_rms", "tau_err2_rms",
            "theta_b_est_err_rms", "dtheta_b_est_err_rms", "u_applied_rms", "saturated_s")
    out = {k: np.array([getattr(m, k) for m in named], dtype=float) for k in keys}
    out = {k: v for k, v in out.items() if k in keys[:6] or np.isfinite(v).any()}
    # core.closed_loop.metrics.motion_metrics (NaN: a scenario without motion)
    if any(lp.motion is not None for lp in loops):
        mm = [motion_metrics(r.columns, lp.motion.r, lp.plant.fall_angle) if lp.motion else {}
              for r, lp in zip(runs, loops)]
        out.update({k: np.array([m.get(k, np.nan) for m in mm], dtype=float) for k in MOTION_METRICS})
    steps = sum(len(r) - 1 for r in runs)
    failure = np.array([FAILURES.index(r.record.get("failure", "fall")) if r.fallen else 0 for r in runs],
                       dtype=np.int64)
    return BatchResult(fallen, t_fall, upright, out, steps, runs if record else None, failure)
