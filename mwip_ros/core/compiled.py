"""The plant's RK4 period for many scenarios at once: :func:`.plant.rk4_period` compiled by numba.

The batch simulator spends most of its time integrating the plant (eq. 1 is evaluated 4 x
``substeps`` times per period).  Over numpy arrays every one of the ~700 operations of a period is
a separate pass over the scenarios, so this one part runs instead as compiled code, one scenario
after another, with the scalar plant's own functions:

* :func:`.model.accel` and :func:`.plant.rk4_period` are handed to numba as they are: the same
  code objects, with the math namespace ``m`` left at its default ``math``.  The only change is
  that, inside the compiled ``rk4_period``, the name ``accel`` refers to the compiled ``accel``.
  There is no second copy of the equations, and a test checks the result against the scalar plant
  bit for bit.
* The physical parameters reach ``accel`` as an :class:`Inertia` tuple: the four terms of eq. (2)
  it reads (``m11``, ``m12``, ``m22``, ``G_b``), under the names of
  :class:`~.model.PhysicalParams`' properties.
* ``error_model="numpy"``: a diverging scenario gives inf or NaN as numpy would, instead of an
  exception (the batch freezes it at its fall).

numba compiles on first use (about a second) and caches the machine code where numba would
(``NUMBA_CACHE_DIR`` if set, else ``__pycache__`` next to the sources, else numba's user-wide cache
directory), so later processes (sweep workers) only load it.  numba would renew a cached function
only when its own file changes, but the compiled RK4 period contains ``accel`` from ``model.py``:
here every cached function is stamped with the contents of all three files (``model.py``,
``plant.py``, this one), so an edit to any equation is compiled afresh.
"""
from __future__ import annotations

import hashlib
import types
from pathlib import Path
from typing import NamedTuple

import numba
import numpy as np
from numba.core.caching import (CompileResultCacheImpl, FunctionCache, InTreeCacheLocator, UserProvidedCacheLocator,
                                UserWideCacheLocator)

from . import model, plant

__all__ = ["Inertia", "RK4Periods", "SOURCES"]

SOURCES = (Path(model.__file__), Path(plant.__file__), Path(__file__))   # what the compiled code is made of
_STAMP = hashlib.sha256(b"".join(p.read_bytes() for p in SOURCES)).hexdigest()


class _Stamped:
    def get_source_stamp(self):
        return _STAMP   # numba's own stamp covers the function's file only


class _UserProvided(_Stamped, UserProvidedCacheLocator):
    pass


class _InTree(_Stamped, InTreeCacheLocator):
    pass


class _UserWide(_Stamped, UserWideCacheLocator):
    pass


class _CacheImpl(CompileResultCacheImpl):
    _locator_classes = [_UserProvided, _InTree, _UserWide]   # numba's order: NUMBA_CACHE_DIR first


class _Cache(FunctionCache):
    _impl_class = _CacheImpl


def _jit(fn):
    """numba's nopython compilation of ``fn``, cached under the stamp of :data:`SOURCES`."""
    compiled = numba.njit(error_model="numpy")(fn)
    try:
        compiled._cache = _Cache(compiled.py_func)   # what ``cache=True`` sets, with the stamp above
    except RuntimeError:   # no writable cache directory: compile in every process
        pass
    return compiled


class Inertia(NamedTuple):
    """The terms of eq. (2) that :func:`.model.accel` reads, for one scenario."""

    m11: float
    m12: float
    m22: float
    G_b: float


def _compiled(fn, **calls):
    """``fn``'s own code compiled by numba, with the global names in ``calls`` bound to compiled functions."""
    same = types.FunctionType(fn.__code__, {**fn.__globals__, **calls}, fn.__name__, fn.__defaults__)
    same.__qualname__ = fn.__qualname__
    return _jit(same)


_accel = _compiled(model.accel)
_rk4_period = _compiled(plant.rk4_period, accel=_accel)


@_jit
def _advance(m11, m12, m22, G_b, D_b, D_w, tau1, tau2, w, b, dw, db, u, h, substeps, active):   # pragma: no cover
    for i in range(w.size):
        if active[i]:
            j1 = i if tau1.shape[1] > 1 else 0   # a column per scenario, or one shared by all
            j2 = i if tau2.shape[1] > 1 else 0
            w[i], b[i], dw[i], db[i] = _rk4_period(Inertia(m11[i], m12[i], m22[i], G_b[i]), D_w[i], D_b[i],
                                                   tau1[:, j1], tau2[:, j2], (w[i], b[i], dw[i], db[i]), u[i], h,
                                                   substeps)


def _full(v, n: int) -> np.ndarray:
    """A float (shared by the scenarios) or an array of the scenarios' values, as a new array of n."""
    return np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=float), (n,)))


def _table(values, n: int) -> np.ndarray:
    """Stage values (floats, or arrays of the scenarios' values) as a (stages, n) array, a column per scenario;
    (stages, 1) when every value is a float (shared by all scenarios)."""
    if not any(np.ndim(v) for v in values):
        return np.array(values, dtype=float).reshape(len(values), 1)
    out = np.empty((len(values), n))
    for j, v in enumerate(values):
        out[j] = v
    return out


class RK4Periods:
    """:func:`.plant.rk4_period` for many scenarios, compiled; the plant's parameters are set once.

    The fields of ``p`` and ``D_b`` are floats shared by all scenarios or arrays of one value per scenario
    (as are ``D_w``, ``u`` and the stage torques of :meth:`__call__`).  Every argument reaches the compiled
    loop as a contiguous float array, so it is compiled for one signature only."""

    def __init__(self, p: model.PhysicalParams, D_b, n: int):
        self.n = n
        self.params = tuple(_full(getattr(p, f), n) for f in Inertia._fields) + (_full(D_b, n),)

    def __call__(self, D_w, tau1, tau2, x, u, h: float, substeps: int, active: np.ndarray) -> tuple:
        """The state one period later (four new arrays) of every scenario whose ``active`` is true; the others
        keep theirs.  ``tau1``, ``tau2``: tau_ext per stage time (:func:`.plant.stage_torques`)."""
        n = self.n
        out = tuple(np.array(v, dtype=float) for v in x)
        _advance(*self.params, _full(D_w, n), _table(tau1, n), _table(tau2, n), *out, _full(u, n),
                 float(h), int(substeps), np.ascontiguousarray(active, dtype=bool))
        return out
