"""Identification of the body's mass, inertia and centre of gravity from a log (docs/theory.md 6.9).

Eq. (1) is linear in ``theta = [m11, m12, m22, G_b, D_w, D_b]`` given the recorded motion and torque::

    m11 th_w'' + m12 (cos th_b th_b'' - sin th_b th_b'^2) + D_w th_w' + D_b (th_w' - th_b') =  u     (row 1)
    m12 cos th_b th_w''  + m22 th_b'' - G_b sin th_b      + D_b (th_b' - th_w')            = -u     (row 2)

(no ``tau_ext``: an unknown external torque biases the fit, so the identification run has none).

**Accelerations, and why there is no phase error.**  Row k of a log holds the state at t_k and the
torque u_k that acted over [t_k, t_k+1) (the mean torque of the period where a motor makes it vary:
``u_applied``).  Each period gives one equation of each row, eq. (1) averaged over the period:
the accelerations are the period's mean accelerations, the first differences of the recorded rates
``(q'_k+1 - q'_k) / h_k`` (a derivative centred on the period's midpoint), and every other term is its
mean over the same period: exactly where it is a derivative (``cos th_b th_b'' - sin th_b th_b'^2 =
d/dt (cos th_b th_b')``), by the trapezoid otherwise (the rates of the friction terms, ``sin th_b``, and
``sin th_b th_b' th_w'`` of ``cos th_b th_w'' = d/dt (cos th_b th_w') + sin th_b th_b' th_w'``).  The trapezoid of
``sin th_b`` is end-corrected (Euler-Maclaurin: ``mean = trapezoid - h (f'_k+1 - f'_k) / 12`` with
``f' = cos th_b th_b'``, known at both ends): the plain trapezoid's error ``G_b h^2 / 12 th_b''`` looks like an
m22 larger by ``G_b h^2 / 12`` (7.7e-4 kg m^2 in the test's robot, 2.5 times the spread of I_b over seeds).  Every
regressor is thus centred on the same instant as the acceleration (no lag to compensate), and the
torque is the one that acted over that very interval (no half-period shift between a held command and
a sampled acceleration).  The angles are never differentiated (theta_w is not used at all).

**Filtered differentiation.**  A first difference amplifies measurement noise in proportion to the
frequency, so the same zero-phase low-pass (a Butterworth of order 2 run forwards and backwards,
``scipy.signal.sosfiltfilt``, cut-off ``cutoff_hz``, default 10 Hz, above a balancing robot's excitation
band) is applied to every regressor column and to the torque alike (it stays the default although it makes
m_b's spread over seeds 6.7 times wider, 0.140 vs 0.021 kg in the test's robot: unfiltered, the period's own
draw of D_w is in its differenced rates and biases the fit, by 0.4 spreads of m_b in the test's scenario and
1.6 in the paper's, where 95 % intervals then hold the truth in 70-80 % of 30 seeds; filtered the bias is 0.1
and 0.5 spreads, the coverage 93-97 %).  A linear filter applied to both
sides of a relation linear in ``theta`` keeps it exactly, and being zero-phase it shifts none of them
against the others.  A period with a value that is not finite is dropped (the filter runs over each
stretch of consecutive periods).  Noise that is left in the regressors still biases least squares
towards zero (errors in variables), which the intervals below do not include: identify from the true
state (a simulator's table, a bag's ``true_joint_states``) or a well-filtered measurement, with an
excitation that moves the robot well above the noise.

**Fit.**  Both rows stacked, weighted least squares: an ordinary fit first, then each row weighted by
the inverse of its residual RMS (both are torques, but the rows' errors differ), solved by
``numpy.linalg.lstsq``.

**Intervals: the delete-a-block jackknife** (Kunsch 1989; Shao and Tu, *The Jackknife and Bootstrap*, 1995,
ch. 9).  The log is cut into B consecutive blocks of ``block_s`` (1 s; shorter when that leaves fewer than
:data:`MIN_BLOCKS`), the weighted fit repeated B times with one block's periods (both rows) left out, and the
covariance of ``theta`` is ``(B - 1) / B sum_b (theta_(b) - mean)(theta_(b) - mean)^T``; 95 % intervals are
+- Student's t quantile with B - 1 degrees of freedom (2.09 for 20 blocks) standard deviations.  Formulas
that take the residuals for independent noise do not hold here: the period's friction draw is in its own
differenced rates (the regressors are endogenous), the filter makes every row depend on its neighbours, and
row 2's residual is a smooth remainder; an AR(1) inflation overstated the spread 1.5 to 3.3x, a Newey-West
sandwich understated it 0.5 to 0.7x.  Refitting without a block carries all of that into the spread of
the refits.  Measured over 100 seeds of the test's chirp scenario: the printed standard deviation is the
spread over seeds to 3-6 %, each 95 % interval of m_b, I_b, l holds the truth in 94-95 % of them
(``test_identify.py``).

**Physical parameters** from ``theta`` with ``m_w``, ``I_w``, ``r``, ``g`` known (eq. 2)::

    m_b = (m11 - I_w) / r^2 - m_w,    l = m12 / (m_b r),    I_b = m22 - m_b l^2 = m22 - m12^2 / (m_b r^2)

their covariance propagated by the **delta method** (the Jacobian of these maps at the estimate), and
``G_b = m_b g l = g m12 / r`` compared with the fitted ``G_b`` as a check.

**Repeated periods** count once: a row whose time an earlier row has (a row written twice, a log appended
to itself) is dropped when its values are the same, and refused (``bad_data``) when they differ; else the
fit would take one period for two independent samples and its interval would shrink (with every row twice,
the stretches between the zero-length periods are one period long: no filter, no autocorrelation inflation).

**Refusals** (:class:`IdentificationError`, its ``cause`` one of ``too_short``, ``not_excited``,
``unresolved``, ``unphysical``, ``bad_data``): fewer than ``min_samples`` periods; a condition number of
the regressor (its columns scaled to unit norm, after weighting) above ``max_condition`` or a regressor
that is zero (the log does not excite the parameters: the robot at rest, or a single tone that moves
too few directions); a 95 % interval of m_b, l or I_b wider than ``max_relative_ci`` of its value; a
non-positive m_b, l or I_b.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

from ..plants.model import PhysicalParams

__all__ = ["IdentificationError", "Estimate", "IdentificationResult", "THETA", "DERIVED", "Z95", "MIN_SAMPLES",
           "MAX_CONDITION", "MAX_RELATIVE_CI", "CUTOFF_HZ", "BLOCK_S", "MIN_BLOCKS", "regression", "identify"]

THETA = ("m11", "m12", "m22", "G_b", "D_w", "D_b")   # the least-squares unknowns, in the regressor's column order
DERIVED = ("m_b", "l", "I_b")
Z95 = 1.959964          # two-sided 95 % normal quantile
MIN_SAMPLES = 400       # periods (2 s at 200 Hz)
MAX_CONDITION = 1.0e4   # of the column-scaled, weighted regressor
MAX_RELATIVE_CI = 0.10  # 95 % half-width / |value| of m_b, l, I_b
CUTOFF_HZ = 10.0        # the zero-phase low-pass applied to every column [Hz]; 0 = none (6.9: why 10)
BLOCK_S = 1.0           # the jackknife's block [s]
MIN_BLOCKS = 10         # at least this many blocks (shorter ones on a short log)
_ORDER = 2              # Butterworth order (forward and backward: 4 in effect)
_MIN_FILTERED = 30      # periods: a shorter stretch is not filtered (sosfiltfilt's padding)


class IdentificationError(ValueError):
    """The log cannot identify the parameters; ``cause`` is ``too_short``, ``not_excited``, ``unresolved``,
    ``unphysical`` or ``bad_data``, the message one line saying why with the figure."""

    def __init__(self, cause: str, message: str):
        self.cause = cause
        super().__init__(message)


@dataclass(frozen=True)
class Estimate:
    """A value with its standard deviation and 95 % interval ``value +- quantile std`` (``quantile`` 1.96, the
    normal's, or Student's t of the jackknife's degrees of freedom)."""

    value: float
    std: float
    quantile: float = Z95

    @property
    def half_width(self) -> float:
        return self.quantile * self.std

    @property
    def low(self) -> float:
        return self.value - self.half_width

    @property
    def high(self) -> float:
        return self.value + self.half_width

    @property
    def relative(self) -> float:
        """The 95 % half-width as a fraction of |value| (inf at 0)."""
        return self.half_width / abs(self.value) if self.value else math.inf

    def text(self, unit: str = "", digits: int = 5) -> str:
        u = f" {unit}" if unit else ""
        return (f"{self.value:.{digits}g}{u}  (95 % CI {self.low:.{digits}g} .. {self.high:.{digits}g}, "
                f"+-{100 * self.relative:.2g} %)")


@dataclass(frozen=True)
class IdentificationResult:
    """What :func:`identify` found: every value with its interval, and how well the model explains the data."""

    m11: Estimate
    m12: Estimate
    m22: Estimate
    G_b: Estimate          # fitted
    D_w: Estimate
    D_b: Estimate
    m_b: Estimate
    l: Estimate
    I_b: Estimate
    G_b_model: Estimate    # m_b g l = g m12 / r, the check of the fitted G_b
    G_b_check: Estimate    # fitted G_b - g m12 / r (its interval should hold 0)
    residual_rms: Tuple[float, float]   # rows 1 and 2 of eq. (1), unweighted [N m]
    condition_number: float
    samples: int           # periods (equations per row) used
    blocks: int            # the delete-a-block jackknife's blocks (its degrees of freedom: blocks - 1)
    block_s: float         # their length [s] (the last of a stretch may be longer)
    known: PhysicalParams  # m_w, I_w, r, g used (its m_b, I_b, l are not)
    covariance: Optional[np.ndarray] = field(repr=False, compare=False, default=None)   # of THETA, 6 x 6
    duplicates: int = 0    # rows that repeated an earlier row's time and values, counted once (dropped)

    def physical(self) -> PhysicalParams:
        """``known`` with the identified m_b, I_b, l."""
        k = self.known
        return PhysicalParams(m_b=self.m_b.value, m_w=k.m_w, I_b=self.I_b.value, I_w=k.I_w, l=self.l.value, r=k.r,
                              g=k.g)

    def estimates(self) -> Dict[str, Estimate]:
        return {n: getattr(self, n) for n in (*THETA, *DERIVED)}


def _mean2(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a[:-1] + a[1:])


def regression(t, theta_w, theta_b, dtheta_w, dtheta_b, u) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The period-averaged eq. (1) of every period (module doc), unfiltered.

    Returns
    -------
    A1, A2 : ndarray, shape (N - 1, 6)
        The regressors of rows 1 and 2, columns :data:`THETA`.
    U : ndarray, shape (N - 1,)
        u_k of each period: row 1's right side is ``U``, row 2's ``-U``.
    """
    t, w, b, dw, db, u = (np.asarray(a, dtype=float) for a in (t, theta_w, theta_b, dtheta_w, dtheta_b, u))
    n = len(t)
    if any(len(a) != n for a in (w, b, dw, db, u)):
        raise IdentificationError("bad_data", "the columns t, theta_w, theta_b, dtheta_w, dtheta_b, u differ in "
                                              "length")
    h = np.diff(t)
    c, s = np.cos(b), np.sin(b)
    zero = np.zeros(n - 1)
    A1 = np.column_stack([np.diff(dw) / h,                       # m11: th_w''
                          np.diff(c * db) / h,                    # m12: d/dt (cos th_b th_b')
                          zero, zero,
                          _mean2(dw),                             # D_w: th_w'
                          _mean2(dw - db)])                       # D_b: th_w' - th_b'
    A2 = np.column_stack([zero,
                          np.diff(c * dw) / h + _mean2(s * db * dw),   # m12: cos th_b th_w''
                          np.diff(db) / h,                        # m22: th_b''
                          -(_mean2(s) - h * np.diff(c * db) / 12),   # G_b: -sin th_b, end-corrected trapezoid
                          zero,
                          _mean2(db - dw)])                       # D_b: th_b' - th_w'
    return A1, A2, u[:-1].copy()


def _once(*columns) -> Tuple[Tuple[np.ndarray, ...], int]:
    """The columns (t first) with every row that repeats an earlier row's time dropped, and how many were: a period
    is one sample however often a log holds it (a row written twice, a log appended to itself), else the fit
    would count it twice and its interval shrink.  A repeated time whose values differ is refused (``bad_data``)."""
    cols = [np.asarray(a, dtype=float) for a in columns]
    t = cols[0]
    if any(len(a) != len(t) for a in cols):
        raise IdentificationError("bad_data", "the columns t, theta_w, theta_b, dtheta_w, dtheta_b, u differ in "
                                              "length")
    finite = np.flatnonzero(np.isfinite(t))
    _, first, inverse = np.unique(t[finite], return_index=True, return_inverse=True)
    first = finite[first[inverse.ravel()]]               # each row's first row with the same time
    later = finite[first != finite]
    if len(later) == 0:
        return tuple(cols), 0
    table = np.column_stack(cols)
    a, b = table[later], table[first[first != finite]]
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    if not same.all():
        k = int(np.flatnonzero(~same.all(axis=1))[0])
        raise IdentificationError("bad_data", f"rows {int(first[first != finite][k])} and {int(later[k])} have the "
                                              f"same time t = {t[later[k]]:.9g} s and different values: a log "
                                              f"with two records of one period cannot be identified")
    keep = np.ones(len(t), dtype=bool)
    keep[later] = False
    return tuple(a[keep] for a in cols), int(len(later))


def _lowpass(a: np.ndarray, cutoff_hz: float, h: float) -> np.ndarray:
    """The zero-phase low-pass of the module doc along axis 0 (``a`` unchanged when off or too short)."""
    if not cutoff_hz > 0 or len(a) <= _MIN_FILTERED or not cutoff_hz * 2 * h < 1.0:
        return a
    from scipy.signal import butter, sosfiltfilt   # here, not at import: the nodes never identify
    return sosfiltfilt(butter(_ORDER, cutoff_hz * 2 * h, output="sos"), a, axis=0)


def _segments(ok: np.ndarray):
    """(start, stop) of each run of consecutive True."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return list(zip(edges[0::2], edges[1::2]))


def _blocks(bounds, per: int):
    """(start, stop) of consecutive blocks of ``per`` periods within each stretch (a stretch's last block takes its
    remainder; a stretch shorter than ``per`` is one block)."""
    out = []
    for a, z in bounds:
        nb = max(1, (z - a) // per)
        out += [(a + j * per, z if j == nb - 1 else a + (j + 1) * per) for j in range(nb)]
    return out


def _jackknife(Z: np.ndarray, y: np.ndarray, n: int, blocks) -> np.ndarray:
    """The delete-a-block jackknife covariance of the least-squares solution of ``Z theta = y`` whose rows are the
    ``n`` periods' row-1 equations then the same periods' row-2 equations: each block of periods (both rows) left
    out in turn, ``(B - 1) / B sum (theta_(b) - mean)(...)^T``."""
    th = []
    for a, z in blocks:
        keep = np.ones(n, dtype=bool)
        keep[a:z] = False
        keep = np.concatenate([keep, keep])
        th.append(np.linalg.lstsq(Z[keep], y[keep], rcond=None)[0])
    d = np.array(th)
    d -= d.mean(axis=0)
    B = len(blocks)
    return d.T @ d * (B - 1) / B


def identify(t: ArrayLike, theta_w: Sequence[float], theta_b: Sequence[float], dtheta_w: Sequence[float],
             dtheta_b: Sequence[float], u: Sequence[float], known: PhysicalParams, cutoff_hz: float = CUTOFF_HZ,
             min_samples: int = MIN_SAMPLES, max_condition: float = MAX_CONDITION,
             max_relative_ci: float = MAX_RELATIVE_CI, block_s: float = BLOCK_S) -> IdentificationResult:
    """Identify m11, m12, m22, G_b, D_w, D_b, then m_b, l, I_b, from a recorded run (module doc).

    Parameters
    ----------
    t, theta_w, theta_b, dtheta_w, dtheta_b : sequence of float
        The recorded state at each row's time [s, rad, rad/s].
    u : sequence of float
        The torque that acted over [t_k, t_k+1) [N m]: ``u_applied`` (with a motor, the mean of the stage
        torques), not the command.  The last row's is not used.
    known : PhysicalParams
        Its ``m_w``, ``I_w``, ``r``, ``g`` are used (the base parameter file's).
    cutoff_hz : float
        The zero-phase low-pass applied to every regressor and to the torque [Hz] (0: none; at or above the
        Nyquist frequency of the log: none).
    min_samples, max_condition, max_relative_ci
        The refusals' thresholds (:class:`IdentificationError`).
    block_s : float
        The jackknife's block [s] (shorter when the log has fewer than :data:`MIN_BLOCKS` of them).

    Raises
    ------
    IdentificationError
        With its ``cause``: the log is too short, does not excite the parameters, leaves one unresolved, or
        gives a non-physical body.
    """
    cols, duplicates = _once(t, theta_w, theta_b, dtheta_w, dtheta_b, u)
    t = cols[0]
    A1, A2, U = regression(*cols)
    ok = np.isfinite(A1).all(axis=1) & np.isfinite(A2).all(axis=1) & np.isfinite(U)
    with np.errstate(invalid="ignore"):
        ok &= np.diff(np.asarray(t, dtype=float)) > 0
    n = int(ok.sum())
    if n < min_samples:
        raise IdentificationError("too_short", f"too short: {n} usable period(s), at least {min_samples} needed "
                                               f"(a few seconds of excited balancing)")
    bounds = _segments(ok)
    h = float(np.median(np.diff(np.asarray(t, dtype=float))[ok]))
    parts = [(_lowpass(A1[a:z], cutoff_hz, h), _lowpass(A2[a:z], cutoff_hz, h), _lowpass(U[a:z], cutoff_hz, h))
             for a, z in bounds]
    A1 = np.concatenate([p[0] for p in parts])
    A2 = np.concatenate([p[1] for p in parts])
    U = np.concatenate([p[2] for p in parts])
    edges = np.cumsum([0] + [z - a for a, z in bounds])
    bounds = list(zip(edges[:-1], edges[1:]))   # the stretches in the concatenated arrays
    A = np.vstack([A1, A2])
    y = np.concatenate([U, -U])
    norms = np.linalg.norm(A, axis=0)
    dead = [THETA[i] for i in np.flatnonzero(~(norms > 1e-9 * norms.max(initial=0.0)))] if norms.max() > 0 \
        else list(THETA)
    if dead:
        raise IdentificationError("not_excited", f"not excited: the log does not move the regressor of "
                                                 f"{', '.join(dead)} (the robot at rest?); add a chirp or PRBS "
                                                 f"excitation")
    theta, *_ = np.linalg.lstsq(A / norms, y, rcond=None)
    theta = theta / norms
    sig = [float(np.sqrt(np.mean((B @ theta - s * U) ** 2))) for B, s in ((A1, 1.0), (A2, -1.0))]
    floor = 1e-12 * max(1.0, float(np.abs(U).max()))
    wts = np.repeat([1.0 / max(sig[0], floor), 1.0 / max(sig[1], floor)], len(U))
    Aw, yw = A * wts[:, None], y * wts
    wnorms = np.linalg.norm(Aw, axis=0)
    cond = float(np.linalg.cond(Aw / wnorms))
    if not (cond <= max_condition):
        raise IdentificationError("not_excited", f"not excited: the condition number of the regressor is {cond:.3g} "
                                                 f"(> {max_condition:g}); the log does not move the parameters "
                                                 f"apart; add a broadband excitation (chirp or PRBS)")
    theta, *_ = np.linalg.lstsq(Aw / wnorms, yw, rcond=None)
    theta = theta / wnorms
    r1, r2 = A1 @ theta - U, A2 @ theta + U
    per = max(1, min(int(round(block_s / h)), n // MIN_BLOCKS))
    blocks = _blocks(bounds, per)
    cov = _jackknife(Aw / wnorms, yw, n, blocks) / np.outer(wnorms, wnorms)
    from scipy.stats import t as student   # here, not at import: the nodes never identify
    q = float(student.ppf(0.975, len(blocks) - 1))
    return _result(theta, cov, known, (float(np.sqrt(np.mean(r1 ** 2))), float(np.sqrt(np.mean(r2 ** 2)))), cond,
                   n, (len(blocks), per * h, q), max_relative_ci, duplicates)


def _result(theta, cov, known: PhysicalParams, rms, cond, n, jack, max_relative_ci,
            duplicates) -> IdentificationResult:
    m11, m12, m22 = theta[0], theta[1], theta[2]
    r, g = known.r, known.g
    m_b = (m11 - known.I_w) / r ** 2 - known.m_w
    if not m_b > 0:
        raise IdentificationError("unphysical", f"unphysical: m_b = (m11 - I_w)/r^2 - m_w = {m_b:.4g} kg from m11 = "
                                                f"{m11:.4g} kg m^2 (check m_w, I_w, r of the base file, and u_applied)")
    l = m12 / (m_b * r)
    I_b = m22 - m_b * l * l
    for name, v, unit in (("l", l, "m"), ("I_b", I_b, "kg m^2")):
        if not v > 0:
            raise IdentificationError("unphysical", f"unphysical: {name} = {v:.4g} {unit} (m11 = {m11:.4g}, m12 = "
                                                    f"{m12:.4g}, m22 = {m22:.4g}); the model does not fit this log")
    # delta method: the Jacobian of (m_b, l, I_b) with respect to THETA at the estimate
    J = np.zeros((3, len(THETA)))
    J[0, 0] = 1.0 / r ** 2
    J[1, 0], J[1, 1] = -m12 / (m_b ** 2 * r) / r ** 2, 1.0 / (m_b * r)
    J[2, 0], J[2, 1], J[2, 2] = m12 ** 2 / (m_b ** 2 * r ** 2) / r ** 2, -2.0 * m12 / (m_b * r ** 2), 1.0
    dcov = J @ cov @ J.T
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    dstd = np.sqrt(np.maximum(np.diag(dcov), 0.0))
    nb, block_s, q = jack
    est = {name: Estimate(float(theta[i]), float(std[i]), q) for i, name in enumerate(THETA)}
    der = {name: Estimate(float(v), float(dstd[i]), q) for i, (name, v) in enumerate(zip(DERIVED, (m_b, l, I_b)))}
    for name in DERIVED:
        e = der[name]
        if not e.relative <= max_relative_ci:
            raise IdentificationError("unresolved", f"not excited enough: {name} = {e.value:.4g} is unresolved, its "
                                                    f"95 % interval is +-{100 * e.relative:.3g} % (at most "
                                                    f"{100 * max_relative_ci:g} %); excite longer or harder")
    gm = np.zeros(len(THETA))
    gm[1] = g / r
    gc = gm.copy()
    gc[3] = 1.0
    gc[1] = -g / r
    G_b_model = Estimate(float(g * m12 / r), float(math.sqrt(max(gm @ cov @ gm, 0.0))), q)
    G_b_check = Estimate(float(theta[3] - g * m12 / r), float(math.sqrt(max(gc @ cov @ gc, 0.0))), q)
    return IdentificationResult(**est, **der, G_b_model=G_b_model, G_b_check=G_b_check, residual_rms=rms,
                                condition_number=cond, samples=n, blocks=int(nb), block_s=float(block_s), known=known,
                                covariance=cov, duplicates=duplicates)
