"""The vector env's compiled plant stage: one RK4 period of each robot at its own period k.

:func:`advance` calls the core's compiled :func:`~mwip_ros.core.plant.rk4_driven` (``core.compiled``: the scalar
plant's own code compiled by numba; with the motor model off it is :func:`~mwip_ros.core.plant.rk4_period`) once per
robot, in one thread (numba's ``prange`` over two threads was 4 to 7
times slower on this shared two-core machine: 5.5 to 9.6 ms against 1.44 ms for 4,096 robots), with tau_ext's stage
values read from a table of the episode's periods (:class:`TauTable`, computed once by the scalar plant's
:func:`~mwip_ros.core.plant.stage_torques`, so robot i at period k integrates exactly the scalar plant's
numbers).  No equation is written here.

With raw sensors, :func:`sense_raw` is the stages ``sensors`` and ``estimator`` of each robot's period k, as the
batch's compiled loop runs them (``core.compiled._loop``, its ``raw`` branch): the accelerations at t_k^-
(:func:`~mwip_ros.core.model.accel` compiled, with what acted over the previous period: its torque, or the motor's
torque at x_k, its D_w), the raw sample (:func:`~mwip_ros.core.raw_sensors.raw_sample` compiled), the measurement
delay queue, and the estimator's :attr:`~mwip_ros.core.estimators.Estimator.pure_step` compiled (a kernel per
estimator class, :func:`raw_kernel`), its state a row of an array per robot.
"""
from __future__ import annotations

import numpy as np

from mwip_ros.core.compiled import Inertia
from mwip_ros.core.compiled import _accel as accel   # the core's compiled model.accel
from mwip_ros.core.compiled import _deep
from mwip_ros.core.compiled import _motor_torque as motor_torque   # the core's compiled drive.motor_torque
from mwip_ros.core.compiled import _rk4_driven as rk4_driven   # the core's compiled plant.rk4_driven
from mwip_ros.core.jitcache import jit
from mwip_ros.core.plant import stage_torques
from mwip_ros.core.raw_sensors import raw_sample

__all__ = ["TauTable", "advance", "raw_kernel"]


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


def est_step(P, h, sample, s, first):   # pragma: no cover
    """The estimator's pure_step (core.estimators), bound per estimator class by :func:`raw_kernel`."""
    return (0.0, 0.0, 0.0, 0.0), (0.0,), (0.0, 0.0, 0.0, False)


def _sense_raw(m11, m12, m22, G_b, D_b, r, g, D_w, T1, T2, k, w, b, dw, db, u_prev, u_drive, K_t, R, V_max, I_max,
               Z, noisy, bias, phi, d, gyro_noise_std, gyro_bias_walk, accel_noise_std, counts, h, delay, q, PE, ES,
               sample, xm, u_m):   # pragma: no cover
    """Stages ``sensors`` and ``estimator`` of period k of every robot (``core.compiled._loop``'s raw branch, robot
    by robot): ``D_w`` the friction that acted over the previous period (period 0's at k = 0), ``u_prev`` the torque
    that acted over it, ``u_drive`` the drive's command of it (the motor's torque at x_k when K_t > 0), ``Z`` (N, 4)
    the period's normals (``noisy``), ``bias``, ``phi`` (in place) the sensors' state, ``q`` (N, delay + 1, 6) the
    delay queue, ``PE`` the estimator's numbers, ``ES`` (N, state size) its states (in place); out: ``sample``
    (N, 5) the delayed raw sample, ``xm`` (4, N) the estimate, ``u_m`` the torque reported with the sample."""
    for i in range(w.size):
        xt = (w[i], b[i], dw[i], db[i])
        ki = k[i]
        ua = u_prev[i]
        if K_t > 0.0 and ki > 0:   # the motor's torque at x_k for the previous command
            ua = motor_torque(u_drive[i], xt[2] - xt[3], K_t, R, V_max, I_max)[0]
        j = ki if T1.shape[0] > 1 else 0
        ddq = accel(Inertia(m11[i], m12[i], m22[i], G_b[i]), D_w[i], D_b[i], xt, ua, T1[j, 0], T2[j, 0])
        zr = (Z[i, 0], Z[i, 1], Z[i, 2], Z[i, 3]) if noisy else (0.0, 0.0, 0.0, 0.0)
        gy, fx, fz, ph, rate, bs = raw_sample(xt, ddq, zr, bias[i], phi[i], ki == 0, h, r[i], d, g[i],
                                              gyro_noise_std, gyro_bias_walk, accel_noise_std, counts)
        bias[i], phi[i] = bs, ph
        slot = ki % (delay + 1)
        q[i, slot, 0], q[i, slot, 1], q[i, slot, 2], q[i, slot, 3], q[i, slot, 4] = gy, fx, fz, ph, rate
        q[i, slot, 5] = u_prev[i]
        rr = (ki - delay) % (delay + 1) if ki >= delay else 0
        for c in range(5):
            sample[i, c] = q[i, rr, c]
        u_m[i] = q[i, rr, 5]
        est, sn, _ = est_step(PE, h, (q[i, rr, 0], q[i, rr, 1], q[i, rr, 2], q[i, rr, 3], q[i, rr, 4]), ES[i],
                              ki == 0)
        for c in range(len(sn)):
            ES[i, c] = sn[c]
        for c in range(4):
            xm[c, i] = est[c]


_RAW: dict = {}


def raw_kernel(estimator: type):
    """:func:`_sense_raw` compiled with the estimator class ``estimator``'s ``pure_step`` (one kernel per class)."""
    if estimator not in _RAW:
        step = estimator.pure_step
        suffix = f"__{step.__module__}.{step.__qualname__}".replace(".", "_")
        _RAW[estimator] = _deep(_sense_raw, suffix, est_step=_deep(step), raw_sample=_deep(raw_sample), accel=accel,
                                motor_torque=motor_torque, Inertia=Inertia)
    return _RAW[estimator]
