"""The vector env's compiled plant stage: one RK4 period of each robot at its own period k.

:func:`advance` calls the core's compiled :func:`~mwip_ros.core.plants.plant.rk4_driven` (``core.kernels.compiled``: the
scalar plant's own code compiled by numba; with the motor model off it is
:func:`~mwip_ros.core.plants.plant.rk4_period`) once per robot, in one thread (BENCHMARKS.md, "The Gymnasium
environments": why not ``prange``), with tau_ext's stage values read from a table of the episode's periods
(:class:`TauTable`, computed once by the scalar plant's
:func:`~mwip_ros.core.plants.plant.stage_torques`, so robot i at period k integrates exactly the scalar plant's
numbers).  No equation is written here.

The stages ``sensors`` (a plant that measures the state), ``law`` with the motion references and ``drive`` are the
compiled loop's own stage functions (:func:`~mwip_ros.core.kernels.compiled_stages.sense_state`,
:func:`~mwip_ros.core.kernels.compiled_motion.law_track` bound per law by
:func:`~mwip_ros.core.kernels.compiled_stages.track_for`,
:func:`~mwip_ros.core.kernels.compiled_stages.drive_stage`), called robot by robot at each robot's own period k:
:func:`sense`,
:func:`track_kernel`, :func:`drive`.

With raw sensors (docs/theory.md 6.4), :func:`raw_kernel` is the stages ``sensors`` and ``estimator`` of each
robot's period k: the compiled loop's own :func:`~mwip_ros.core.kernels.compiled_stages.sense_raw` (the accelerations at
t_k^- of eq. 1, the raw sample, its delay queue, the estimator's ``pure_step``; a kernel per estimator class), its state
a row of an array per robot.
"""
from __future__ import annotations

import numpy as np

from mwip_ros.core.kernels.compiled import Inertia
from mwip_ros.core.kernels.compiled_stages import _deep, drive_stage, raw_stage, sense_state, track_for
from mwip_ros.core.kernels.compiled_stages import _rk4_driven as rk4_driven   # the core's compiled plant.rk4_driven
from mwip_ros.core.kernels.jitcache import jit
from mwip_ros.core.plants.plant import stage_torques

__all__ = ["TauTable", "advance", "sense", "drive", "track_kernel", "raw_kernel"]


class TauTable:
    """tau_ext1 and tau_ext2 at the RK4 stage times of periods 0, 1, ... (a row per period, as
    :func:`~mwip_ros.core.plants.plant.stage_torques` gives them to the scalar plant), grown as the robots get further
    (to the furthest robot's period, doubling): ``T1``, ``T2``; one row of zeros when both are zero."""

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
    V_max, I_max) the motor, K_t = 0: none (core.plants.plant.NO_MOTOR)."""
    motor = (K_t, R, V_max, I_max)
    for i in range(w.size):
        if run[i]:
            j = k[i] if T1.shape[0] > 1 else 0
            p = Inertia(m11[i], m12[i], m22[i], G_b[i])
            w[i], b[i], dw[i], db[i], acted[i], _ = rk4_driven(p, D_w[i], D_b[i], T1[j], T2[j],
                                                               (w[i], b[i], dw[i], db[i]), u[i], h, substeps, motor)


advance = jit(_advance, "envs")   # numba's cache, stamped with everything it is made of (core.kernels.jitcache)


def _sense(k, w, b, dw, db, u_prev, Z, noisy, std, counts, delay, q, xm, u_m):   # pragma: no cover
    """Stage ``sensors`` of every robot's period k, a plant that measures the state: the compiled loop's own
    :func:`~mwip_ros.core.kernels.compiled_stages.sense_state` robot by robot (``Z`` (N, 4) the period's normals when
    ``noisy``, ``q`` (N, delay + 1, 5) the delay queues, in place); out: ``xm`` (4, N) the measured states, ``u_m`` the
    torques reported with them."""
    for i in range(w.size):
        ms, u_m[i] = sense_state((w[i], b[i], dw[i], db[i]), Z[i] if noisy else Z[0], noisy, std, counts, q[i], k[i],
                                 delay, u_prev[i])
        for c in range(4):
            xm[c, i] = ms[c]


sense = _deep(_sense)   # sense_state compiled with it (core.kernels.compiled_stages._deep)


def _drive(u_cmd, go, limit, qa, k, act_delay, enabled, u, bad):   # pragma: no cover
    """Stage ``drive`` of the robots of ``go``: the compiled loop's own
    :func:`~mwip_ros.core.kernels.compiled_stages.drive_stage` robot by robot (``qa`` (N, act_delay + 1) the actuator
    queues, in place), then the driver's gate (not ``enabled``: the bridge is open, zero torque acts,
    :meth:`~mwip_ros.core.control.safety.DriverStateMachine.torque_gate`); out: ``u`` the torque that acts, ``bad`` the
    refused commands (``bad_command``)."""
    for i in range(u_cmd.size):
        if go[i]:
            u[i], bad[i] = drive_stage(u_cmd[i], limit, qa[i], k[i], act_delay)
            if not enabled:
                u[i] = 0.0
        else:
            u[i], bad[i] = 0.0, False


drive = _deep(_drive)   # drive_stage compiled with it


def _track(P, m11, m12, m22, G_b, h, w, b, dw, db, s, k, MO, PT, PV, n_points, MS, th1, th2, observed,
           u):   # pragma: no cover
    """Stage ``law`` with the motion references of every robot's period k: the compiled loop's own
    :func:`~mwip_ros.core.kernels.compiled_motion.law_track` (bound per law,
    :func:`~mwip_ros.core.kernels.compiled_stages.track_for`) robot by robot, for the measured state (``w`` .. ``db``)
    and tau_hat (``th1``, ``th2``), the law's state ``s`` and each robot's references' state ``MS`` (N,
    :data:`~mwip_ros.core.kernels.compiled_motion.MS_COLUMNS`) in place; ``P`` the law's numbers, (``m11`` .. ``G_b``)
    the nominal model, ``MO``, ``PT``, ``PV``, ``n_points`` the profile
    (:func:`~mwip_ros.core.kernels.compiled_motion.motion_arrays`); out: ``u`` the law's command."""
    p = Inertia(m11, m12, m22, G_b)
    for i in range(w.size):
        u[i], s[i] = law_track(P, p, h, (w[i], b[i], dw[i], db[i]), s[i], k[i], MO, PT, PV, n_points, MS[i],
                               (th1[i], th2[i]), observed)


def law_track(P, p, h, x, s, k, MO, PT, PV, n_points, MS, th, observed):   # pragma: no cover
    """The law's compiled :func:`~mwip_ros.core.kernels.compiled_motion.law_track`, bound per law by
    :func:`track_kernel`."""
    return 0.0, s


_TRACK: dict = {}


def track_kernel(law: type):
    """:func:`_track` compiled with the law class ``law``'s tracking stage (one kernel per law), or None: the law has
    no pure form (the vector env then calls :func:`mwip_ros.core.closed_loop.loop.command` per robot)."""
    if law not in _TRACK:
        stage = track_for(law)
        suffix = f"__{law.__module__}.{law.__qualname__}".replace(".", "_")
        _TRACK[law] = None if stage is None else _deep(_track, suffix, law_track=stage, Inertia=Inertia)
    return _TRACK[law]


def _sense_raw(m11, m12, m22, G_b, D_b, r, g, T1, T2, k, w, b, dw, db, u_prev, MC, Z, noisy, RS, RW, h, delay, q,
               PE, ES, sample, xm, u_m):   # pragma: no cover
    """Stages ``sensors`` and ``estimator`` of period k of every robot: the compiled loop's own
    :func:`~mwip_ros.core.kernels.compiled_stages.sense_raw` (bound per estimator class, :func:`raw_kernel`) robot by
    robot, each robot's true robot (``m11`` .. ``D_b``, ``r``, ``g``: its columns of the env's robots) and tau_ext at
    its own t_k (``T1``, ``T2``); ``u_prev`` the torque that acted over the previous period, ``MC`` the motor, ``Z`` (N,
    4) the period's normals (``noisy``), ``RS`` (N, 4) each robot's sensors' state (bias, phi, D_w and the drive's
    command of the previous period; in place), ``RW`` the raw sensors' numbers (its r and g set per robot), ``q`` (N,
    delay + 1, 6) the delay queues, ``PE`` the estimator's numbers, ``ES`` (N, state size) its states (in place);
    out: ``sample`` (N, 5) the delayed raw sample, ``xm`` (4, N) the estimate, ``u_m`` the torque reported with the
    sample."""
    rw = RW.copy()
    for i in range(w.size):
        j = k[i] if T1.shape[0] > 1 else 0
        zr = (Z[i, 0], Z[i, 1], Z[i, 2], Z[i, 3]) if noisy else (0.0, 0.0, 0.0, 0.0)
        rw[0], rw[2] = r[i], g[i]
        est, u_m[i], rr = sense_raw(Inertia(m11[i], m12[i], m22[i], G_b[i]), D_b[i], (w[i], b[i], dw[i], db[i]),
                                    u_prev[i], MC, T1[j, 0], T2[j, 0], zr, RS[i], rw, k[i], h, delay, q[i], PE, ES[i])
        for c in range(5):
            sample[i, c] = q[i, rr, c]
        for c in range(4):
            xm[c, i] = est[c]


def sense_raw(pa, D_b, xt, u_prev, MC, e1, e2, zr, RS, RW, k, h, delay, q, PE, ES):   # pragma: no cover
    """:func:`mwip_ros.core.kernels.compiled_stages.sense_raw`, bound per estimator class by :func:`raw_kernel`."""
    return (0.0, 0.0, 0.0, 0.0), 0.0, 0


_RAW: dict = {}


def raw_kernel(estimator: type):
    """:func:`_sense_raw` compiled with the estimator class ``estimator``'s ``pure_step`` (one kernel per class)."""
    if estimator not in _RAW:
        step = estimator.pure_step
        suffix = f"__{step.__module__}.{step.__qualname__}".replace(".", "_")
        _RAW[estimator] = _deep(_sense_raw, suffix, sense_raw=raw_stage(step, suffix + "__envs"), Inertia=Inertia)
    return _RAW[estimator]
