"""The check of an identified model on a log it was not fitted on (docs/theory.md 6.9): open-loop prediction of the
pitch over short windows.

The log is cut into windows of ``window_s`` (1 s); each window starts from its first row's measured state and
integrates eq. (1) with the log's own torque (``u_applied``: the torque that acted over each period), no external
torque, D_w held at its mean, by :func:`mwip_ros.core.plants.plant.rk4_period` (the plant's own integrator, ``substeps``
RK4 steps a period).  The error is the predicted minus the measured pitch at every row of the window.  The
open-loop robot is unstable, so an error in the model grows through the window: the figure compares models
fairly only on the same log, windows and torque (:func:`prediction_errors` for each model).

**From the raw log alone** (:func:`raw_prediction_errors`): a robot knows its state only through its estimator,
whose rates are no start for an unstable open loop (1 s from the estimate: 18 deg RMS whatever the model).  So each
window's start is fitted instead, to the window's first ``fit_s`` (0.2 s) of raw samples under the model being
checked (its four states by least squares, the sensor models of 6.4 as the raw fit has them:
``gyro = th_b' + bias``, the specific force at the IMU, ``encoder = th_w - th_b``), and the pitch it then predicts
over the rest of the window is compared with the state estimator's pitch (``theta_b_hat``, a reference good to
about 0.1 deg: the floor of the figure).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List

import numpy as np
from numpy.typing import ArrayLike

from .identify_raw import NOISE
from ..plants.model import PhysicalParams, accel
from ..plants.plant import rk4_period
from ..plants.raw_sensors import specific_force

__all__ = ["PredictionError", "prediction_errors", "raw_prediction_errors", "WINDOW_S", "FIT_S"]

WINDOW_S = 1.0
FIT_S = 0.2   # s of raw samples each window's start is fitted to (raw_prediction_errors)


@dataclass(frozen=True)
class PredictionError:
    """Pitch prediction error over the log's windows [rad]: RMS over every predicted row, the worst |error|, and
    how many windows."""

    rms: float
    worst: float
    windows: int


def _summary(errs, windows: int, window_s: float) -> PredictionError:
    """The errors of every predicted row as a :class:`PredictionError`; ValueError when there are none."""
    if not errs:
        raise ValueError(f"no window of at least {window_s / 2:g} s with finite values in the log")
    e = np.asarray(errs)
    e = np.where(np.isfinite(e), e, np.inf)     # a prediction that diverged is the worst error, not a NaN
    return PredictionError(float(np.sqrt(np.mean(e ** 2))), float(np.max(np.abs(e))), windows)


MIN_PITCH_SPAN = 1e-3   # rad: a log whose pitch moves less than this validates nothing (the robot at rest predicts
                        # itself at rest, whatever the model: an error of 0)


def _checked(t: np.ndarray, pitch: np.ndarray) -> float:
    """The log's period h; ValueError (one line) when its times do not advance, or its pitch does not move (at least
    :data:`MIN_PITCH_SPAN`): there is then nothing to predict, and no error to judge a model by."""
    finite = np.isfinite(t)
    steps = np.diff(t[finite])
    if len(steps) == 0 or not np.all(steps > 0):
        raise ValueError("the log's times do not advance (each row's t after the one before)")
    b = pitch[np.isfinite(pitch)]
    span = float(np.ptp(b)) if len(b) else 0.0
    if not span >= MIN_PITCH_SPAN:
        raise ValueError(f"the log's pitch does not move (it spans {span:.3g} rad, less than {MIN_PITCH_SPAN:g}): a "
                         f"robot at rest validates no model; give a log with excitation")
    return float(np.median(steps))


def prediction_errors(t: ArrayLike, theta_w, theta_b, dtheta_w, dtheta_b, u, p: PhysicalParams, D_w: float,
                      D_b: float, window_s: float = WINDOW_S, substeps: int = 4) -> PredictionError:
    """The pitch prediction error of the model ``(p, D_w, D_b)`` over the windows of a log (module doc).

    ``u[k]`` is the torque that acted over [t_k, t_k+1).  Rows with a value that is not finite end a window; a
    window shorter than half of ``window_s`` is not used.  ValueError when no window is left, or when the log's times
    do not advance or its pitch does not move (:func:`_checked`)."""
    t, w, b, dw, db, u = (np.asarray(a, dtype=float) for a in (t, theta_w, theta_b, dtheta_w, dtheta_b, u))
    h = _checked(t, b)
    per = max(1, int(round(window_s / h)))
    ok = np.isfinite(t) & np.isfinite(w) & np.isfinite(b) & np.isfinite(dw) & np.isfinite(db) & np.isfinite(u)
    zeros = [0.0] * (2 * substeps + 1)
    errs: List[float] = []
    windows = 0
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
    return _summary(errs, windows, window_s)


def raw_prediction_errors(t: ArrayLike, gyro, accel_x, accel_z, encoder, encoder_rate, u, theta_b_ref,
                          p: PhysicalParams, D_w: float, D_b: float, gyro_bias: float, imu_offset: float,
                          noise=NOISE, window_s: float = WINDOW_S,
                          fit_s: float = FIT_S) -> PredictionError:
    """The pitch prediction error of the model ``(p, D_w, D_b)`` with the sensors' ``gyro_bias`` and ``imu_offset``
    over the windows of a raw log (module doc: each start fitted to the window's first ``fit_s``), against
    ``theta_b_ref`` after the fit.  ``u[k]`` acted over [t_k, t_k+1); ``noise``: the gyro's, the accelerometer's and
    the encoder's standard deviations weighing the fit.  Rows with a value that is not finite end a window; a window
    shorter than half of ``window_s`` is not used.  ValueError when no window is left."""
    from scipy.optimize import least_squares   # here, not at import: the nodes never identify
    t, gy, ax, az, enc, er, u, ref = (np.asarray(a, dtype=float) for a in (t, gyro, accel_x, accel_z, encoder,
                                                                           encoder_rate, u, theta_b_ref))
    h = _checked(t, ref)
    per, fit = max(2, int(round(window_s / h))), max(2, int(round(fit_s / h)))
    ok = np.isfinite(t) & np.isfinite(gy) & np.isfinite(ax) & np.isfinite(az) & np.isfinite(enc) & np.isfinite(u) \
        & np.isfinite(ref)
    sg, sa, se = noise
    zeros = [0.0, 0.0, 0.0]

    def run(x, a, z, out=None):
        """Rows a .. z-1 from state x at row a: the raw residuals (or, with ``out``, the pitch into it)."""
        res = []
        for k in range(a, z):
            if out is not None:
                out.append(x[1] - ref[k])
            else:
                fx, fz = specific_force(x, accel(p, D_w, D_b, x, u[k - 1], 0.0, 0.0, np), p.r, imu_offset, p.g, np)
                res += [(x[3] + gyro_bias - gy[k]) / sg, (fx - ax[k]) / sa, (fz - az[k]) / sa,
                        (x[0] - x[1] - enc[k]) / se]
            if k < z - 1:
                x = rk4_period(p, D_w, D_b, zeros, zeros, x, u[k], t[k + 1] - t[k], 1, np)
        return np.asarray(res, dtype=float), x

    errs: List[float] = []
    windows = 0
    for a in range(1, len(t) - 1, per):
        z = min(a + per, len(t))
        bad = np.flatnonzero(~ok[a - 1:z])
        if len(bad):
            z = a - 1 + int(bad[0])
        if z - a < per // 2 or z - a <= fit:
            continue
        tilt = -np.arctan2(ax[a], az[a])
        x0 = np.array([enc[a] + tilt, tilt, er[a] + gy[a] - gyro_bias, gy[a] - gyro_bias])
        sol = least_squares(lambda x: run(tuple(x), a, a + fit)[0], x0, method="lm")
        _, x_fit = run(tuple(sol.x), a, a + fit)          # the state at the fit's last row ...
        run(x_fit, a + fit - 1, z, out=errs)                # ... predicted on, against the reference
        windows += 1
    return _summary(errs, windows, window_s)
