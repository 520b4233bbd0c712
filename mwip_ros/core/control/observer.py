"""Nonlinear disturbance observer (eq. 8-15) and its discrete form (docs/theory.md, discrete time).

    z'      = L(q) (N_hat(q, q') - [u, 0]^T - p(q') - z),  L = X M_hat^-1,  p = X q'   (eq. 12-13)
    tau_hat = z + X q'

With a constant tau_d the error tau_d - tau_hat obeys e' = -X M_hat^-1 e
(*fix*: eq. 11 of the recovered text reads "tau_tilde' = -L tau_tilde").
Every function takes the whole :class:`~mwip_ros.core.plants.model.State` ``x``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Optional, Tuple, Union, cast

import numpy as np

from ..plants.model import PhysicalParams, Real, coriolis_gravity, mass_matrix

__all__ = ["gain_matrix", "z_dot", "z_dot_explicit", "error_rates", "substeps", "DiscreteObserver"]


def gain_matrix(c) -> np.ndarray:
    """X = [[c1, c2], [c3, c4]] from the flat list (c1, c2, c3, c4) (eq. 14)."""
    c = np.asarray(c, dtype=float)
    if c.shape == (2, 2):
        return c.copy()
    if c.shape != (4,):
        raise ValueError(f"X must have 4 entries (c1, c2, c3, c4), got shape {c.shape}")
    return c.reshape(2, 2)


def z_dot(nominal: PhysicalParams, X: np.ndarray, x, u: float, z) -> np.ndarray:
    """Matrix form of the observer, eq. (12) with eq. (13)."""
    L = X @ np.linalg.inv(mass_matrix(nominal, x))
    return L @ (coriolis_gravity(nominal, x) - np.array([u, 0.0]) - X @ np.asarray(x[2:]) - np.asarray(z))


def z_dot_explicit(nominal: PhysicalParams, X, x, u: float, z, m=math) -> Tuple[float, float]:
    """Eq. (15): the observer written out for the 2x2 case, as floats (what ``DiscreteObserver`` steps).

    ``X`` is the 2x2 gain matrix or the flat (c1, c2, c3, c4); ``m`` the math namespace
    (``numpy`` for arrays of scenarios).
    """
    return z_dot_of(nominal, _flat(X), x, u, z, m)


def z_dot_of(nominal, c, x, u, z, m=math) -> Tuple[float, float]:
    """:func:`z_dot_explicit` with the gains as the flat (c1, c2, c3, c4): a pure function of numbers, which
    ``core.kernels.compiled`` compiles for the batch (``nominal``: anything with ``m11``, ``m12``, ``m22``, ``G_b``)."""
    c1, c2, c3, c4 = c
    p = nominal
    _, th_b, dth_w, dth_b = x
    s, mc = m.sin(th_b), p.m12 * m.cos(th_b)
    A = p.m11 * p.m22 - mc * mc
    D1, D2 = p.m22 + mc, p.m11 + mc
    cent = p.m12 * dth_b * dth_b * s
    w1 = cent + u + c1 * dth_w + c2 * dth_b + z[0]
    w2 = p.G_b * s + cent + c3 * dth_w + c4 * dth_b + z[1]
    return (((c2 * D2 - c1 * D1) * w1 - (c2 * p.m11 - c1 * mc) * w2) / A,   # eq. (15), z1'
            ((c4 * D2 - c3 * D1) * w1 - (c4 * p.m11 - c3 * mc) * w2) / A)   # eq. (15), z2'


def z_start(c, dw, db) -> Tuple[float, float]:
    """z_0 = -X q'_0 (so tau_hat_0 = 0)."""
    c1, c2, c3, c4 = c
    return (-(c1 * dw + c2 * db), -(c3 * dw + c4 * db))


def z_next(nominal, c, prev, u_prev, z, step, m=math) -> Tuple[float, float]:
    """z_k = z_{k-1} + step z'(x_{k-1}, u_{k-1}, z_{k-1}): explicit Euler of eq. (12)."""
    d1, d2 = z_dot_of(nominal, c, prev, u_prev, z, m)
    return (z[0] + step * d1, z[1] + step * d2)


def substeps(elapsed: float, h: float) -> int:
    """How many explicit Euler steps of eq. (12) span ``elapsed`` seconds since the previous state: the fewest of
    length at most the period ``h`` (1 for one period; n for a gap of n periods a realtime observer got).

    The explicit Euler step multiplies the observer's error by I - step X M_hat^-1 (eq. 11 discretised), stable only
    while step < 2 / lambda_max(X M_hat^-1): within one period by design (config/upkie.yaml: 180 1/s against 2 / h =
    400 1/s), but not over a gap integrated in one step of n h (n >= 3 there: the error times -(180 n h - 1), -1.7
    at n = 3, -8 at n = 10, which a run of late samples compounds).  The state and the torque between the two
    samples are not known: each step holds x_{k-1} and u_{k-1} (the torque the driver held over the gap)."""
    n = math.ceil(elapsed / h - 1e-9)
    return n if n > 1 else 1


def tau_hat_of(c, z, dw, db) -> Tuple[float, float]:
    """tau_hat = z + X q'."""
    c1, c2, c3, c4 = c
    return (z[0] + c1 * dw + c2 * db, z[1] + c3 * dw + c4 * db)


def _flat(X) -> Tuple[float, float, float, float]:
    if isinstance(X, tuple) and len(X) == 4:
        return X
    return cast(Tuple[float, float, float, float], tuple(float(v) for v in np.asarray(X, dtype=float).ravel()))


def error_rates(nominal: PhysicalParams, X: np.ndarray, x) -> np.ndarray:
    """Eigenvalues of X M_hat(q)^-1: the decay rates (1/s) of the estimation error."""
    return np.linalg.eigvals(X @ np.linalg.inv(mass_matrix(nominal, x)))


@dataclass
class DiscreteObserver:
    """Explicit-Euler observer (docs/theory.md, discrete time).

    ``update(x_k, u_{k-1})`` is called once per state k and returns tau_hat_k: at k = 0
    it sets z_0 = -X q'_0 (so tau_hat_0 = 0); for k >= 1 it advances
    z_k = z_{k-1} + h z'(x_{k-1}, u_{k-1}, z_{k-1}).  ``h`` is the time since the previous
    state: the control period unless the caller passes another (a realtime node that lost
    states: the whole gap, :func:`substeps`).  ``z`` and the returned
    tau_hat are tuples of two floats.  Assign ``X`` to change the gains.  With ``m = numpy``,
    array parameters and ``X`` as a tuple of four arrays it steps a batch of scenarios.
    """

    nominal: PhysicalParams
    X: Union[np.ndarray, Tuple[Any, ...]]   # (a tuple of four arrays over a batch)
    h: float
    z: Optional[tuple] = None
    m: object = math
    _prev: Optional[tuple] = field(default=None, repr=False)
    _gains: tuple = field(default=(None, None), repr=False)  # (X object, its flat floats)

    def snapshot(self) -> tuple:
        """The observer's state, for :meth:`restore` (a caller that must not keep a bad update)."""
        return self.z, self._prev

    def restore(self, snap: tuple) -> None:
        self.z, self._prev = snap

    def reset(self) -> None:
        """Forget the past: the next update starts again with tau_hat = 0."""
        self.z = self._prev = None

    def update(self, x, u_prev: Real, h: Optional[float] = None) -> Tuple[float, float]:
        if self._gains[0] is not self.X:  # X was (re)assigned, e.g. a parameter update
            self._gains = (self.X, _flat(self.X))
        c = self._gains[1]
        dw, db = x[2], x[3]
        if self.z is None:
            self.z = z_start(c, dw, db)  # tau_hat(0) = 0
        elif h is None:
            self.z = z_next(self.nominal, c, self._prev, u_prev, self.z, self.h, self.m)
        else:   # the time since the previous state: steps of at most h (eq. 12's explicit Euler stays stable)
            n = substeps(h, self.h)
            for _ in range(n):
                self.z = z_next(self.nominal, c, self._prev, u_prev, self.z, h / n, self.m)
        self._prev = x
        return tau_hat_of(c, self.z, dw, db)  # tau_hat = z + X q'
