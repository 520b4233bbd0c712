"""Identification from the raw log alone (docs/theory.md 6.9): m_b, I_b, l, D_w, D_b, the gyro bias and the IMU offset
from the gyro, the accelerometer, the relative encoder and the torque that acted; no state, no estimate.

**Prediction error, multiple shooting.**  The log (from its second row) is cut into windows of ``window_s``
(0.25 s).  Each window j has its own initial state ``x_j = (th_w, th_b, th_w', th_b')`` at its first row, a
nuisance parameter; within it eq. (1) is integrated by the plant's own RK4 (:func:`mwip_ros.core.plant.rk4_period`,
one step a period) with the log's torque (``u_applied``: row k's acted over [t_k, t_k+1)), D_w at its mean and no
external torque.  At every row the raw sensors are predicted by their own model (6.4):
``gyro = th_b' + bias``, ``(accel_x, accel_z) =`` :func:`mwip_ros.core.raw_sensors.specific_force` at the state
and at :func:`mwip_ros.core.model.accel` with the previous period's torque (the sample's instant, t_k^-),
``encoder = th_w - th_b``.  The residuals, each divided by its sensor's noise (``noise``: the gyro's, the
accelerometer's, the encoder's count / sqrt(12)), are minimized over the seven body and sensor parameters and
every window's state together by ``scipy.optimize.least_squares`` (trust region, the Jacobian's sparsity given:
a window's residuals depend on the globals and on its own state only).  Short windows keep the unstable
open-loop prediction and the friction's per-period noise from running away; many windows share the globals.
The start: the base file's nominal body, D_w 0.5, D_b 0.1, no bias, its IMU offset, each window's state from
its first samples (the accelerometer's tilt, the gyro, the encoder and its rate).

**Standard deviations** from the Jacobian at the solution, ``s^2 (J^T J)^-1`` (the globals' block; ``s^2`` the
residual variance per degree of freedom).  They assume white residuals, which the bias walk and the friction's
process noise are not: read them as a lower bound (not checked by Monte Carlo, unlike the state fit's).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Dict, Sequence, Tuple

import numpy as np

from .model import PhysicalParams, accel
from .plant import rk4_period
from .raw_sensors import specific_force

__all__ = ["RAW_GLOBALS", "RawIdentificationResult", "identify_raw", "WINDOW_S", "NOISE"]

RAW_GLOBALS = ("m_b", "I_b", "l", "D_w", "D_b", "gyro_bias", "imu_offset")
WINDOW_S = 0.25
NOISE = (0.004, 0.02, 0.00044)   # gyro [rad/s], accelerometer [m/s^2], encoder [rad]: sensors_raw_realistic.yaml
_LOW = (1e-3, 1e-4, 1e-4, 0.0, 0.0, -1.0, -2.0)
_HIGH = (1e5, 1e5, 10.0, 100.0, 100.0, 1.0, 2.0)


@dataclass(frozen=True)
class RawIdentificationResult:
    """The fitted globals (:data:`RAW_GLOBALS`) with their standard deviations, the residual RMS of each channel
    (gyro, accel_x, accel_z, encoder), and the fit's size."""

    values: Dict[str, float]
    std: Dict[str, float]
    residual_rms: Tuple[float, float, float, float]
    windows: int
    evaluations: int
    known: PhysicalParams

    def physical(self) -> PhysicalParams:
        return replace(self.known, m_b=self.values["m_b"], I_b=self.values["I_b"], l=self.values["l"])


def identify_raw(t: Sequence[float], gyro, accel_x, accel_z, encoder, encoder_rate, u, known: PhysicalParams,
                 start: PhysicalParams, imu_offset: float, window_s: float = WINDOW_S,
                 noise: Tuple[float, float, float] = NOISE, max_evaluations: int = 200) -> RawIdentificationResult:
    """Fit the raw log (module doc).  ``known``'s m_w, I_w, r, g are used; ``start``'s m_b, I_b, l and
    ``imu_offset`` [m] start the fit.  ValueError when the log has fewer than 4 windows."""
    from scipy.optimize import least_squares   # here, not at import: the nodes never identify
    from scipy.sparse import lil_matrix
    t, gy, ax, az, enc, er, u = (np.asarray(a, dtype=float) for a in (t, gyro, accel_x, accel_z, encoder,
                                                                         encoder_rate, u))
    h = float(np.median(np.diff(t)))
    W = max(2, int(round(window_s / h)))
    starts = np.arange(1, len(t) - W, W)
    # a window needs every raw sample and the torque of each of its periods (one unknown: the window is left out)
    ok = np.array([np.isfinite(np.stack([gy, ax, az, enc, er])[:, a - 1:a + W]).all()
                   and np.isfinite(u[a - 1:a + W - 1]).all() for a in starts], dtype=bool)
    u = np.where(np.isfinite(u), u, 0.0)
    starts = starts[ok]
    J = len(starts)
    if J < 4:
        raise ValueError(f"too short: {J} window(s) of {W * h:g} s with finite raw samples, at least 4 needed")
    rows = starts[:, None] + np.arange(W)[None, :]
    tilt = -np.arctan2(ax[starts], az[starts])
    x0 = np.column_stack([enc[starts] + tilt, tilt, er[starts] + gy[starts], gy[starts]])
    sg, sa, se = noise
    zeros = [0.0, 0.0, 0.0]

    def residuals(z):
        p = replace(known, m_b=z[0], I_b=z[1], l=z[2])
        D_w, D_b, bias, d = z[3], z[4], z[5], z[6]
        xs = z[7:].reshape(J, 4)
        x = tuple(xs[:, i] for i in range(4))
        out = np.empty((J, W, 4))
        for j in range(W):
            k = rows[:, j]
            fx, fz = specific_force(x, accel(p, D_w, D_b, x, u[k - 1], 0.0, 0.0, np), p.r, d, p.g, np)
            out[:, j, 0] = (x[3] + bias - gy[k]) / sg
            out[:, j, 1] = (fx - ax[k]) / sa
            out[:, j, 2] = (fz - az[k]) / sa
            out[:, j, 3] = (x[0] - x[1] - enc[k]) / se
            if j < W - 1:
                x = rk4_period(p, D_w, D_b, zeros, zeros, x, u[k], t[k + 1] - t[k], 1, np)
        return out.ravel()

    n_g = len(RAW_GLOBALS)
    S = lil_matrix((J * W * 4, n_g + 4 * J), dtype=np.int8)
    S[:, :n_g] = 1
    for j in range(J):
        S[j * W * 4:(j + 1) * W * 4, n_g + 4 * j:n_g + 4 * j + 4] = 1
    z0 = np.concatenate([[start.m_b, start.I_b, start.l, 0.5, 0.1, 0.0, imu_offset], x0.ravel()])
    lo = np.concatenate([_LOW, np.full(4 * J, -np.inf)])
    hi = np.concatenate([_HIGH, np.full(4 * J, np.inf)])
    z0[:n_g] = np.clip(z0[:n_g], lo[:n_g], hi[:n_g])
    res = least_squares(residuals, z0, jac_sparsity=S, bounds=(lo, hi), x_scale="jac", method="trf",
                        tr_solver="lsmr", max_nfev=max_evaluations)
    r = res.fun.reshape(J, W, 4)
    rms = tuple(float(np.sqrt(np.mean(r[:, :, i] ** 2)) * s) for i, s in enumerate((sg, sa, sa, se)))
    Jm = res.jac.toarray() if hasattr(res.jac, "toarray") else np.asarray(res.jac)
    dof = max(1, Jm.shape[0] - Jm.shape[1])
    s2 = 2.0 * float(res.cost) / dof
    try:
        cov = np.linalg.inv(Jm.T @ Jm)[:n_g, :n_g] * s2
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        std = np.full(n_g, np.inf)
    return RawIdentificationResult({k: float(v) for k, v in zip(RAW_GLOBALS, res.x[:n_g])},
                                   {k: float(v) for k, v in zip(RAW_GLOBALS, std)}, rms, J, int(res.nfev), known)
