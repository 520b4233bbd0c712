"""The check of an identified model on a log it was not fitted on (docs/theory.md 6.9): open-loop prediction of the
pitch over short windows.

The log is cut into windows of ``window_s`` (1 s); each window starts from its first row's measured state and
integrates eq. (1) with the log's own torque (``u_applied``: the torque that acted over each period), no external
torque, D_w held at its mean, by :func:`mwip_ros.core.plant.rk4_period` (the plant's own integrator, ``substeps``
RK4 steps a period).  The error is the predicted minus the measured pitch at every row of the window.  The
open-loop robot is unstable, so an error in the model grows through the window: the figure compares models
fairly only on the same log, windows and torque (:func:`prediction_errors` for each model).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .model import PhysicalParams
from .plant import rk4_period

__all__ = ["PredictionError", "prediction_errors", "WINDOW_S"]

WINDOW_S = 1.0


@dataclass(frozen=True)
class PredictionError:
    """Pitch prediction error over the log's windows [rad]: RMS over every predicted row, the worst |error|, and
    how many windows."""

    rms: float
    worst: float
    windows: int


def prediction_errors(t: Sequence[float], theta_w, theta_b, dtheta_w, dtheta_b, u, p: PhysicalParams, D_w: float,
                      D_b: float, window_s: float = WINDOW_S, substeps: int = 4) -> PredictionError:
    """The pitch prediction error of the model ``(p, D_w, D_b)`` over the windows of a log (module doc).

    ``u[k]`` is the torque that acted over [t_k, t_k+1).  Rows with a value that is not finite end a window; a
    window shorter than half of ``window_s`` is not used.  ValueError when no window is left."""
    t, w, b, dw, db, u = (np.asarray(a, dtype=float) for a in (t, theta_w, theta_b, dtheta_w, dtheta_b, u))
    h = float(np.median(np.diff(t)))
    per = max(1, int(round(window_s / h)))
    ok = np.isfinite(t) & np.isfinite(w) & np.isfinite(b) & np.isfinite(dw) & np.isfinite(db) & np.isfinite(u)
    zeros = [0.0] * (2 * substeps + 1)
    errs, windows = [], 0
    for a in range(0, len(t) - 1, per):
        z = min(a + per, len(t) - 1)
        bad = np.flatnonzero(~ok[a:z + 1])
        if len(bad):
            z = a + int(bad[0]) - 1
        if z - a < per // 2:
            continue
        x = (w[a], b[a], dw[a], db[a])
        for k in range(a, z):
            x = rk4_period(p, D_w, D_b, zeros, zeros, x, u[k], t[k + 1] - t[k], substeps)
            errs.append(x[1] - b[k + 1])
        windows += 1
    if not errs:
        raise ValueError(f"no window of at least {window_s / 2:g} s with finite values in the log")
    e = np.asarray(errs)
    e = np.where(np.isfinite(e), e, np.inf)     # a prediction that diverged is the worst error, not a NaN
    return PredictionError(float(np.sqrt(np.mean(e ** 2))), float(np.max(np.abs(e))), windows)
