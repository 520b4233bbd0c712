"""Identification from the raw log alone (docs/theory.md 6.9): m_b, I_b, l, D_w, D_b, the gyro bias and the IMU offset
from the gyro, the accelerometer, the relative encoder and the torque that acted; no state, no estimate.

**Prediction error, multiple shooting.**  The log (from its second row) is cut into windows of ``window_s``
(0.25 s).  Each window j has its own initial state ``x_j = (th_w, th_b, th_w', th_b')`` at its first row, a
nuisance parameter; within it eq. (1) is integrated by the plant's own RK4
(:func:`mwip_ros.core.plants.plant.rk4_period`, one step a period) with the log's torque (``u_applied``: row k's acted
over [t_k, t_k+1)), D_w at its mean and no external torque.  At every row the raw sensors are predicted by their own
model (6.4): ``gyro = th_b' + bias``, ``(accel_x, accel_z) =`` :func:`mwip_ros.core.plants.raw_sensors.specific_force`
at the state and at :func:`mwip_ros.core.plants.model.accel` with the previous period's torque (the sample's instant,
t_k^-), ``encoder = th_w - th_b``.  The residuals, each divided by its sensor's noise (``noise``: the gyro's, the
accelerometer's, the encoder's count / sqrt(12)), are minimized over the seven body and sensor parameters and
every window's state together by ``scipy.optimize.least_squares`` (trust region, a sparse Jacobian: a window's
residuals depend on the globals and on its own state only).  Short windows keep the unstable
open-loop prediction and the friction's per-period noise from running away; many windows share the globals.
The start: the base file's nominal body, D_w 0.5, D_b 0.1, no bias, its IMU offset, each window's state from
its first samples (the accelerometer's tilt, the gyro, the encoder and its rate).

**Finishing.** least_squares stops when a step changes the cost by less than 1e-5 of it (its default, 1e-8, takes
2.6 times as long for the same solution); from there up to five Gauss-Newton steps with each window's state
profiled out, kept while the cost does not grow, reach the stationary point the intervals below are of (the values
are those of ftol 1e-8 to 3e-4 of their standard deviation, over 12 seeds). D_w and D_b are bounded below by -100,
not 0: D_b (0.1) is about a standard deviation from 0 in a 10 s log, and a bound at 0 bound in 21 of 100 such fits,
where the linearization the intervals rest on does not hold. The Jacobian is by central differences, all
perturbations in one batched evaluation (a window's residuals depend on the globals and on its own state only, so
every window's i-th state moves at once).

**Intervals: cluster-robust, CR2 with Bell-McCaffrey degrees of freedom** (R. M. Bell and D. F. McCaffrey, "Bias
reduction in standard errors for linear regression with multi-stage samples", Survey Methodology 28, 2002;
J. E. Pustejovsky and E. Tipton, "Small-sample methods for cluster-robust variance estimation and hypothesis
testing in fixed effects models", J. Bus. Econ. Stat. 36, 2018; A. C. Cameron and D. L. Miller, "A
practitioner's guide to cluster-robust inference", J. Human Resources 50, 2015).  The residuals need not be
white (the bias walk, the friction's per-period noise carried through a window's integration, the model's own
error), which ``s^2 (J^T J)^-1`` assumes (measured, it covers 92 to 99 %: over 0.25 s windows they nearly are).
The windows are the clusters: within one the residuals may be correlated in any way, between two they are taken
as independent.  With ``X_j = M_j G_j`` window j's
Jacobian of the globals with its own state profiled out (``M_j`` the projection off its state's columns),
``S = sum X_j^T X_j`` and ``e_j`` its residuals, the covariance of the globals is the sandwich::

    V = S^-1 (sum_j X_j^T A_j e_j e_j^T A_j X_j) S^-1,   A_j = (I - H_jj)^(+1/2)

``H_jj`` the window's block of the hat matrix (globals and its state) and ``^(+1/2)`` the pseudo-inverse's
symmetric square root (CR2: unbiased when the residuals are white, where the plain sandwich, CR0, is too
small with a few dominant windows).  A parameter's interval is ``+- t_0.975(nu) std`` with its own
Bell-McCaffrey degrees of freedom ``nu = (tr G^T G)^2 / tr (G^T G)^2`` (G's column j is ``(I - H)`` applied to
``A_j X_j S^-1 c``, c the parameter's unit vector): nu is small when few windows carry the parameter (the
start's recovery from a tilt: 3 for m_b), and the quantile grows with it.  Measured over 100 seeds of 10 s
chirps started upright: each 95 % interval of m_b, I_b, l holds the truth in 95 to 96 % of them
(docs/theory.md 6.9, ``test_identify_raw.py``); started tilted, where one window dominates, nu is fewer than
the spread of the standard deviation implies and m_b's interval covers 99 to 100 % (conservative).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Dict, Optional, Tuple, cast

import numpy as np
from numpy.typing import ArrayLike

from ..plants.model import PhysicalParams, accel
from ..plants.plant import rk4_period
from ..plants.raw_sensors import specific_force

__all__ = ["RAW_GLOBALS", "RawIdentificationResult", "identify_raw", "WINDOW_S", "NOISE"]

RAW_GLOBALS = ("m_b", "I_b", "l", "D_w", "D_b", "gyro_bias", "imu_offset")
WINDOW_S = 0.25
NOISE = (0.004, 0.02, 0.00044)   # gyro [rad/s], accelerometer [m/s^2], encoder [rad]: sensors_raw_realistic.yaml
_LOW = (1e-3, 1e-4, 1e-4, -100.0, -100.0, -1.0, -2.0)   # D_w, D_b down to -100: a bound at 0 would bind (D_b ~ 0.1)
_HIGH = (1e5, 1e5, 10.0, 100.0, 100.0, 1.0, 2.0)
_FTOL = 1e-5            # least_squares stops when the cost changes by less than this fraction; Gauss-Newton finishes
_GN_STEPS = 5            # Gauss-Newton finishing steps at least_squares' solution (at most)


@dataclass(frozen=True)
class RawIdentificationResult:
    """The fitted globals (:data:`RAW_GLOBALS`) with their cluster-robust standard deviations and each one's
    Bell-McCaffrey degrees of freedom ``dof`` and Student-t ``quantile`` (95 % half-width: :meth:`half_width`), the
    residual RMS of each channel (gyro, accel_x, accel_z, encoder), and the fit's size."""

    values: Dict[str, float]
    std: Dict[str, float]
    residual_rms: Tuple[float, float, float, float]
    windows: int
    evaluations: int
    known: PhysicalParams
    dof: Dict[str, float] = field(default_factory=dict)
    quantile: Dict[str, float] = field(default_factory=dict)
    covariance: Optional[np.ndarray] = field(repr=False, compare=False, default=None)   # of RAW_GLOBALS, 7 x 7 (CR2)
    condition_number: float = math.nan   # of the globals' profiled Jacobian, its columns scaled to unit norm

    def physical(self) -> PhysicalParams:
        return replace(self.known, m_b=self.values["m_b"], I_b=self.values["I_b"], l=self.values["l"])

    def half_width(self, name: str) -> float:
        """The 95 % interval's half-width of ``name``: its t quantile times its standard deviation."""
        return self.quantile.get(name, 1.959964) * self.std[name]

    def interval(self, name: str) -> Tuple[float, float]:
        """(low, high) of the 95 % interval of ``name``."""
        v, w = self.values[name], self.half_width(name)
        return v - w, v + w


def identify_raw(t: ArrayLike, gyro, accel_x, accel_z, encoder, encoder_rate, u, known: PhysicalParams,
                 start: PhysicalParams, imu_offset: float, window_s: float = WINDOW_S,
                 noise: Tuple[float, float, float] = NOISE, max_evaluations: int = 200) -> RawIdentificationResult:
    """Fit the raw log (module doc).  ``known``'s m_w, I_w, r, g are used; ``start``'s m_b, I_b, l and
    ``imu_offset`` [m] start the fit.  ValueError when the log has fewer than 4 windows."""
    from scipy.optimize import least_squares   # here, not at import: the nodes never identify
    from scipy.sparse import csr_matrix
    from scipy.stats import t as student
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
    n_g = len(RAW_GLOBALS)
    R = W * 4                                  # residuals per window

    def predicted(Z):
        """The residuals of every row of ``Z`` (K x (n_g + 4 J): K parameter vectors at once), K x (J W 4)."""
        g = [Z[:, i:i + 1] for i in range(n_g)]
        p = replace(known, m_b=g[0], I_b=g[1], l=g[2])
        D_w, D_b, bias, d = g[3], g[4], g[5], g[6]
        xs = Z[:, n_g:].reshape(len(Z), J, 4)
        x = tuple(xs[:, :, i] for i in range(4))
        out = np.empty((len(Z), J, W, 4))
        for j in range(W):
            k = rows[:, j]
            fx, fz = specific_force(x, accel(p, D_w, D_b, x, u[k - 1], 0.0, 0.0, np), p.r, d, p.g, np)
            out[:, :, j, 0] = (x[3] + bias - gy[k]) / sg
            out[:, :, j, 1] = (fx - ax[k]) / sa
            out[:, :, j, 2] = (fz - az[k]) / sa
            out[:, :, j, 3] = (x[0] - x[1] - enc[k]) / se
            if j < W - 1:
                x = rk4_period(p, D_w, D_b, zeros, zeros, x, u[k], t[k + 1] - t[k], 1, np)
        return out.reshape(len(Z), -1)

    counted = [0]

    def residuals(z):
        counted[0] += 1
        return predicted(z[None, :])[0]

    def blocks(z):
        """The Jacobian's two blocks by central differences in one batched evaluation: of the globals (J, R, n_g)
        and of each window's own state (J, R, 4); a window's residuals depend on nothing else, so every window's
        c-th state component moves in the same evaluation."""
        step = np.finfo(float).eps ** (1 / 3) * np.maximum(1.0, np.abs(z))
        P = np.zeros((n_g + 4, len(z)))
        for i in range(n_g):
            P[i, i] = step[i]
        for c in range(4):
            P[n_g + c, n_g + c::4] = step[n_g + c::4]
        r = predicted(np.concatenate([z + P, z - P]))
        d = (r[:n_g + 4] - r[n_g + 4:]).reshape(n_g + 4, J, R)
        G = np.transpose(d[:n_g] / (2 * step[:n_g, None, None]), (1, 2, 0))
        L = np.transpose(d[n_g:], (1, 2, 0)) / (2 * step[n_g:].reshape(J, 1, 4))
        return G, L

    col = np.concatenate([np.broadcast_to(np.arange(n_g), (J, R, n_g)),
                          np.broadcast_to(n_g + 4 * np.arange(J)[:, None, None] + np.arange(4), (J, R, 4))],
                         axis=2).ravel()
    row = np.repeat(np.arange(J * R), n_g + 4)

    def jacobian(z):
        G, L = blocks(z)
        return csr_matrix((np.concatenate([G, L], axis=2).ravel(), (row, col)), shape=(J * R, n_g + 4 * J))

    z0 = np.concatenate([[start.m_b, start.I_b, start.l, 0.5, 0.1, 0.0, imu_offset], x0.ravel()])
    lo = np.concatenate([_LOW, np.full(4 * J, -np.inf)])
    hi = np.concatenate([_HIGH, np.full(4 * J, np.inf)])
    z0[:n_g] = np.clip(z0[:n_g], lo[:n_g], hi[:n_g])
    res = least_squares(residuals, z0, jac=jacobian, bounds=(lo, hi), x_scale="jac", method="trf",
                        tr_solver="lsmr", ftol=_FTOL, max_nfev=max_evaluations)
    z, r = res.x, res.fun
    for _ in range(_GN_STEPS):   # Gauss-Newton from the solution: least_squares stops by ftol, not at a zero gradient
        G, L = blocks(z)
        Xt, S, Q = _profiled(G, L)
        e = r.reshape(J, R)
        try:
            dg = -np.linalg.solve(S, np.einsum("jrp,jr->p", Xt, e))
            rest = e + G @ dg
            dl = -np.linalg.solve(np.einsum("jrc,jrd->jcd", L, L),
                                  np.einsum("jrc,jr->jc", L, rest)[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            break
        cand = z + np.concatenate([dg, dl.ravel()])
        if not (np.all(cand[:n_g] >= lo[:n_g]) and np.all(cand[:n_g] <= hi[:n_g])):
            break
        rc = residuals(cand)
        if not rc @ rc <= r @ r:
            break
        small = np.all(np.abs(dg) <= 1e-9 * np.maximum(1.0, np.abs(z[:n_g])))
        z, r = cand, rc
        if small:
            break
    G, L = blocks(z)
    Xt, S, Q = _profiled(G, L)
    try:
        cov, dof = _cr2(Xt, S, Q, r.reshape(J, R))
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:   # a global the log does not move: no interval
        cov, dof, std = np.full((n_g, n_g), np.inf), np.full(n_g, np.nan), np.full(n_g, np.inf)
    q = np.array([student.ppf(0.975, v) if np.isfinite(v) and v > 0 else math.inf for v in dof])
    condition = _condition(S)
    rr = r.reshape(J, W, 4)
    rms = cast(Tuple[float, float, float, float],
               tuple(float(np.sqrt(np.mean(rr[:, :, i] ** 2)) * s) for i, s in enumerate((sg, sa, sa, se))))
    named = lambda a: {k: float(v) for k, v in zip(RAW_GLOBALS, a)}   # noqa: E731
    return RawIdentificationResult(named(z[:n_g]), named(std), rms, J, counted[0], known,
                                   named(dof), named(q), cov, condition)


def _condition(S) -> float:
    """The condition number of the profiled Jacobian with its columns scaled to unit norm, from ``S = Xt^T Xt``
    (the square root of the scaled S's); inf when a column is zero (a global the log does not move)."""
    d = np.sqrt(np.diag(S))
    return float(np.sqrt(np.linalg.cond(S / np.outer(d, d)))) if np.all(d > 0) else math.inf


def _profiled(G, L):
    """The globals' Jacobian with each window's own state profiled out (Frisch-Waugh-Lovell): ``Xt_j = M_j G_j``,
    ``M_j = I - Q_j Q_j^T`` with ``Q_j`` an orthonormal basis of ``L_j``'s columns; ``S = sum Xt_j^T Xt_j``, the
    globals' block of the inverse of ``J^T J`` inverted."""
    Q = np.linalg.qr(L)[0]                                  # (J, R, 4)
    Xt = G - Q @ (np.transpose(Q, (0, 2, 1)) @ G)
    return Xt, np.einsum("jrp,jrq->pq", Xt, Xt), Q


def _cr2(Xt, S, Q, e):
    """The CR2 cluster-robust covariance of the globals (windows the clusters) and each one's Bell-McCaffrey degrees
    of freedom (module doc)."""
    Si = np.linalg.inv(S)
    # the window's block of I - H: I - Q Q^T - B B^T with B = Xt_j S^-1/2 (orthogonal to Q); its pseudo-inverse
    # square root is 0 on Q, (1 - s^2)^-1/2 along B's left singular vectors, 1 elsewhere
    w, V = np.linalg.eigh(S)
    if not w.min() > 0:
        raise np.linalg.LinAlgError("singular")
    Sih = V @ np.diag(w ** -0.5) @ V.T
    U, s, _ = np.linalg.svd(Xt @ Sih, full_matrices=False)  # (J, R, n), (J, n)
    f = 1.0 / np.sqrt(np.maximum(1.0 - s * s, 1e-12)) - 1.0

    def adjust(v):   # A_j v for v (J, R, k)
        v = v - Q @ (np.transpose(Q, (0, 2, 1)) @ v)
        return v + U @ (f[:, :, None] * (np.transpose(U, (0, 2, 1)) @ v))

    ae = adjust(e[:, :, None])[:, :, 0]
    score = np.einsum("jrp,jr->jp", Xt, ae)                 # (J, n)
    cov = Si @ (score.T @ score) @ Si
    # Bell-McCaffrey: for each unit vector c, the J x J matrix G^T G = diag(|M_j v_j|^2) - Q_c^T S^-1 Q_c with
    # v_j = A_j Xt_j S^-1 c and Q_c's columns Xt_j^T v_j; dof = tr^2 / |G^T G|_F^2
    Vc = adjust(Xt @ Si)                                    # (J, R, n): column c is v_j of c
    Vm = Vc - Q @ (np.transpose(Q, (0, 2, 1)) @ Vc)
    a = np.einsum("jrc,jrc->cj", Vm, Vm)                    # (n, J)
    Qc = np.einsum("jrp,jrc->cpj", Xt, Vc)                  # (n, n_g, J)
    dof = np.empty(S.shape[0])
    for c in range(S.shape[0]):
        GG = np.diag(a[c]) - Qc[c].T @ Si @ Qc[c]
        dof[c] = np.trace(GG) ** 2 / np.sum(GG * GG)
    return cov, dof
