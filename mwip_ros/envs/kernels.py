"""The vector env's compiled plant stage: one RK4 period of each robot at its own period k.

:func:`advance` calls the core's compiled :func:`~mwip_ros.core.plant.rk4_driven` (``core.compiled``: the scalar
plant's own code compiled by numba; with the motor model off it is :func:`~mwip_ros.core.plant.rk4_period`) once per
robot, in one thread (numba's ``prange`` over two threads was 4 to 7
times slower on this shared two-core machine: 5.5 to 9.6 ms against 1.44 ms for 4,096 robots), with tau_ext's stage
values read from a table of the episode's periods (:class:`TauTable`, computed once by the scalar plant's
:func:`~mwip_ros.core.plant.stage_torques`, so robot i at period k integrates exactly the scalar plant's
numbers).  No equation is written here.
"""
from __future__ import annotations

import numpy as np

from mwip_ros.core.compiled import Inertia
from mwip_ros.core.compiled import _rk4_driven as rk4_driven   # the core's compiled plant.rk4_driven
from mwip_ros.core.jitcache import jit
from mwip_ros.core.plant import stage_torques

__all__ = ["TauTable", "advance"]


class TauTable:
    """tau_ext1 and tau_ext2 at the RK4 stage times of periods 0, 1, ... (a row per period, as
    :func:`~mwip_ros.core.plant.stage_torques` gives them to the scalar plant), grown as the robots get further (to
    the furthest robot's period, doubling): ``T1``, ``T2``; one row of zeros when both are zero."""

    def __init__(self, pc):
        self.pc = pc
        width = 2 * pc.substeps + 1
        self.zero = pc.tau_ext1.amplitude == 0.0 and pc.tau_ext2.amplitude == 0.0
        self.T1, self.T2 = np.zeros((1, width)), np.zeros((1, width))
        self.rows = 0 if not self.zero else 1
        if not self.zero:
            self.cover(256)

    def cover(self, k_max: int) -> None:
        """Rows up to period ``k_max`` (included)."""
        if self.zero or k_max < self.rows:
            return
        pc, old = self.pc, self.rows
        size = max(k_max + 1, 2 * old)
        T1, T2 = np.empty((size, self.T1.shape[1])), np.empty((size, self.T2.shape[1]))
        T1[:old], T2[:old] = self.T1[:old], self.T2[:old]
        for k in range(old, size):
            T1[k], T2[k] = stage_torques(pc.tau_ext1, pc.tau_ext2, (0.0, 0.0), k * pc.h, pc.h, pc.substeps)
        self.T1, self.T2, self.rows = T1, T2, size


def _advance(m11, m12, m22, G_b, D_b, D_w, T1, T2, k, w, b, dw, db, u, h, substeps, run, K_t, R, V_max, I_max,
             acted):   # pragma: no cover
    """One period of the robots of ``run`` (their state arrays ``w``, ``b``, ``dw``, ``db`` in place), the torque
    that acted over it into ``acted``; each robot's true eq. (2) terms ``m11`` .. ``G_b`` and ``D_b``; (K_t, R,
    V_max, I_max) the motor, K_t = 0: none (core.plant.NO_MOTOR; as fast as rk4_period here: 2.3 to 3.2 ms for 4,096
    robots, both, on the loaded machine)."""
    motor = (K_t, R, V_max, I_max)
    for i in range(w.size):
        if run[i]:
            j = k[i] if T1.shape[0] > 1 else 0
            p = Inertia(m11[i], m12[i], m22[i], G_b[i])
            w[i], b[i], dw[i], db[i], acted[i], _ = rk4_driven(p, D_w[i], D_b[i], T1[j], T2[j],
                                                               (w[i], b[i], dw[i], db[i]), u[i], h, substeps, motor)


advance = jit(_advance, "envs")   # numba's cache, stamped with everything it is made of (core.jitcache)
