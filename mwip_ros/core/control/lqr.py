"""The textbook baseline: a discrete LQR on the nominal model's linearization (docs/theory.md, baselines).

* State ``x = [theta_b, theta_b', theta_w']`` (the wheel angle is not regulated, as in DSC).
* Linearization of the nominal model (eq. 4 without friction) at theta_b = 0, q' = 0:
  ``M0 [theta_w''; theta_b''] = [u; -u + G_b theta_b]``, ``M0 = [[m11, m12], [m12, m22]]``,
  ``W = M0^-1``: ``A = [[0, 1, 0], [W22 G_b, 0, 0], [W12 G_b, 0, 0]]``, ``B = [0, W21 - W22, W11 - W12]^T``.
* Zero-order hold at the control period h (``scipy.linalg.expm`` of the block matrix), the discrete
  algebraic Riccati equation (``scipy.linalg.solve_discrete_are``) with ``Q``, ``R``;
  ``K = (R + B_d^T P B_d)^-1 B_d^T P A_d``.
* Law ``lqr``: ``u_k = -K x_k``; ``lqr_ndo``: ``u_k = -K x_k - u_taud,k`` with u_taud of eq. (20),
  the same observer term as DSCNDO.  The command computed from state k is applied over
  [t_k, t_{k+1}), as for DSC.

The laws every caller steps are :class:`mwip_ros.core.laws.lqr.LqrLaw` (``lqr_law``, with its own
internals, no NaN) and its observer variant (:mod:`mwip_ros.core.laws.ndo`); ``LqrController``
stays for the tests.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Sequence, Tuple

import numpy as np

from .controller import ControlOutput, u_taud_of
from ..plants.model import PhysicalParams

__all__ = ["NO_DESIGN", "LqrDesignError", "linearization", "weights", "lqr_gain", "lqr_law", "lqr_u", "LqrController"]


class LqrDesignError(ValueError):
    """Q, R or the model give no LQR gain; ``key`` names the parameter to change."""

    def __init__(self, key: str, message: str):
        self.key, self.reason = key, message
        super().__init__(f"{key}: {message}")


def linearization(nominal: PhysicalParams) -> Tuple[np.ndarray, np.ndarray]:
    """(A, B) of the nominal model at the upright equilibrium, state [theta_b, theta_b', theta_w']."""
    p = nominal
    W = np.linalg.inv(np.array([[p.m11, p.m12], [p.m12, p.m22]]))
    A = np.array([[0.0, 1.0, 0.0], [W[1, 1] * p.G_b, 0.0, 0.0], [W[0, 1] * p.G_b, 0.0, 0.0]])
    B = np.array([[0.0], [W[1, 0] - W[1, 1]], [W[0, 0] - W[0, 1]]])
    return A, B


def weights(Q: Sequence[float], R: float) -> Tuple[np.ndarray, np.ndarray]:
    """Q (3 entries: the diagonal; 9: the matrix, row by row) and R as matrices, checked: Q symmetric positive
    semidefinite, R > 0.  Raises :class:`LqrDesignError` naming ``lqr.Q`` or ``lqr.R``."""
    q = np.asarray(Q, dtype=float)
    if q.shape == (3,):
        Qm = np.diag(q)
    elif q.shape == (9,):
        Qm = q.reshape(3, 3)
    else:
        raise LqrDesignError("lqr.Q", f"give the diagonal (3 entries) or the 3x3 matrix (9), got {len(q)} entries")
    if not np.all(np.isfinite(Qm)):
        raise LqrDesignError("lqr.Q", f"must be finite, got {list(q)}")
    if not np.allclose(Qm, Qm.T, rtol=0, atol=1e-12 * max(1.0, np.abs(Qm).max())):
        raise LqrDesignError("lqr.Q", f"must be symmetric, got {Qm.tolist()}")
    low = float(np.linalg.eigvalsh(Qm).min())
    if low < -1e-12 * max(1.0, np.abs(Qm).max()):
        raise LqrDesignError("lqr.Q", f"must be positive semidefinite; its smallest eigenvalue is {low:g}")
    if not (isinstance(R, (int, float)) and math.isfinite(R) and R > 0):
        raise LqrDesignError("lqr.R", f"must be > 0 (positive definite), got {R!r}")
    return Qm, np.array([[float(R)]])


def _zoh(A: np.ndarray, B: np.ndarray, h: float, expm) -> Tuple[np.ndarray, np.ndarray]:
    n, m = A.shape[0], B.shape[1]
    block = np.vstack((np.hstack((A, B)), np.zeros((m, n + m))))
    ms = expm(h * block)[:n, :]
    return ms[:, :n], ms[:, n:]


def lqr_gain(nominal: PhysicalParams, h: float, Q: Sequence[float], R: float) -> Tuple[float, float, float]:
    """K = (R + B_d^T P B_d)^-1 B_d^T P A_d, the discrete LQR gain at period ``h`` (zero-order hold).

    Remembered for the last designs asked for: a sweep asks for the same one for thousands of scenarios."""
    return _gain(nominal, float(h), tuple(float(q) for q in Q), R)


# The refusal's words on every path: which of the two a degenerate weight takes (the Riccati solver failing, or a gain
# that leaves a mode on the unit circle) depends on the CPU's LAPACK path; what the user reads first does not.
NO_DESIGN = "no stabilizing design for the nominal model with these weights"


@functools.lru_cache(maxsize=256)
def _gain(nominal: PhysicalParams, h: float, Q: Tuple[float, ...], R: float) -> Tuple[float, float, float]:
    from scipy.linalg import expm, solve_discrete_are   # not scipy.signal: it would add ~45 MiB to every node

    Qm, Rm = weights(Q, R)
    A, B = linearization(nominal)
    # zero-order hold: expm of [[A, B], [0, 0]] h holds [[A_d, B_d], [0, I]] (what scipy.signal.cont2discrete's
    # "zoh" computes, written out)
    Ad, Bd = _zoh(A, B, h, expm)
    try:
        P = solve_discrete_are(Ad, Bd, Qm, Rm)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise LqrDesignError("lqr.Q", f"{NO_DESIGN}: the Riccati equation has no stabilizing solution ({exc}); the "
                                      f"pair (A, B) or (A, Q) may not be stabilizable/detectable") from None
    K = np.linalg.solve(Rm + Bd.T @ P @ Bd, Bd.T @ P @ Ad)[0]
    closed = np.abs(np.linalg.eigvals(Ad - Bd @ K[None, :])).max()
    if not np.all(np.isfinite(K)) or not closed < 1.0:
        raise LqrDesignError("lqr.Q", f"{NO_DESIGN}: the gain leaves the linearized model unstable (spectral "
                                      f"radius {closed:g} of A_d - B_d K)")
    return float(K[0]), float(K[1]), float(K[2])


def lqr_law(nominal: PhysicalParams, K, x, tau_hat=None, m=math) -> ControlOutput:
    """u = -K [theta_b, theta_b', theta_w'] (- u_taud of eq. 20 with ``tau_hat``); ``m`` the math namespace.

    The fields DSC has and LQR does not (S2, x1, x4_bar, x4d) are NaN; S1 = theta_b as in eq. (22)."""
    theta_b = x[1]
    u_lqr = lqr_u(K, x)
    u_taud = 0.0 if tau_hat is None else u_taud_of(nominal, nominal.m12 * m.cos(theta_b), tau_hat)
    nan = math.nan
    return ControlOutput(u=u_lqr - u_taud, u_dsc=u_lqr, u_taud=u_taud, S1=theta_b, S2=nan, x1=nan, x4_bar=nan,
                         x4d=nan)


def lqr_u(K, x):
    """-K [theta_b, theta_b', theta_w'] (a pure function of numbers: ``core.kernels.compiled`` compiles it)."""
    _, theta_b, dtheta_w, dtheta_b = x
    return -(K[0] * theta_b + K[1] * dtheta_b + K[2] * dtheta_w)


@dataclass
class LqrController:
    """LQR (``use_observer=False``) or LQR+NDO, with the step interface of ``DscController``."""

    nominal: PhysicalParams
    K: Tuple[float, float, float]
    use_observer: bool = True
    m: object = math

    def step(self, x, tau_hat=None) -> ControlOutput:
        return lqr_law(self.nominal, self.K, x, tau_hat if self.use_observer else None, self.m)
