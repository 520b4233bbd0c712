"""N robots stepped one period at a time over numpy arrays, each at its own period k: the vector env's stepper.

The batch simulator (:mod:`mwip_ros.core.batch`, :mod:`mwip_ros.core.compiled`) runs whole episodes with one period
k shared by every scenario; a vector env steps its robots one period per call, takes the command from outside, and
restarts a robot whose episode ended while the others go on (so the robots' periods differ).  This module is that
stepper, numpy-vectorised over the robots; it writes no equation: each stage calls the core's own pure functions
over arrays (the functions the compiled loop compiles), in :data:`mwip_ros.core.loop.STAGES`' order:

* ``sensors``: :func:`~mwip_ros.core.sensing.measure` (noise from each robot's own stream,
  :func:`~mwip_ros.core.sensing.sensor_rng`, the encoder), the measurement delay (the queue of
  :class:`~mwip_ros.core.sensing.Sensors`, a ring per robot);
* ``observer``: :func:`~mwip_ros.core.observer.z_start`, :func:`~mwip_ros.core.observer.z_next`,
  :func:`~mwip_ros.core.observer.tau_hat_of`;
* ``law``: the base law's ``pure_step`` (:mod:`mwip_ros.core.laws`) and the observer term
  :func:`~mwip_ros.core.controller.u_taud_of`, the excitation (:mod:`mwip_ros.core.excitation`), plus the action;
* ``drive``: the driver's ``bad_command`` (:data:`~mwip_ros.core.safety.PLAUSIBLE_TORQUE`), the torque limit, the
  actuator delay (the queue of :class:`~mwip_ros.core.sensing.Actuator`);
* ``plant``: D_w (:func:`~mwip_ros.core.plant.D_w_of`'s arithmetic, each robot's own stream), tau_ext at each robot's
  own t_k (:func:`~mwip_ros.core.plant.stage_torques`, a table of the episode's periods), one RK4 period with the
  motor when the files have it (:func:`~mwip_ros.core.plant.rk4_driven` compiled: :mod:`.kernels`), the fall check.

The raw sensors with their estimator and the driver's enable are not here (the scalar
env, :class:`~mwip_ros.envs.scalar.MwipEnv`, has every stage): the vector env refuses such files, naming the key.
A restarted robot keeps its noise streams (its next draws), so no generator is built again.
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from mwip_ros.core.compiled import pure_form
from mwip_ros.core.controller import u_taud_of
from mwip_ros.core.excitation import Excitation
from mwip_ros.core.observer import tau_hat_of, z_next, z_start
from mwip_ros.core.safety import PLAUSIBLE_TORQUE
from mwip_ros.core.sensing import NOISE_BLOCK, measure, sensor_rng
from mwip_ros.core.trajectory import BAD_COMMAND, DIVERGED, FALL

from .common import EnvSetup
from .kernels import TauTable, advance
from .robots import TERMS

__all__ = ["Lanes", "refusal"]


def refusal(s: EnvSetup) -> Optional[str]:
    """Why the vector env cannot run the setup ``s`` (one line naming the key), or None."""
    loop = s.loop
    pc = loop.plant
    if pc.backend != "rk4":
        return f"plant_sim.backend: the vector env runs the rk4 plant only, got {pc.backend!r} (MwipEnv runs it)"
    if pc.raw is not None:
        return "sensors.model: the vector env measures the state only, not raw (MwipEnv runs raw sensors)"
    if pc.require_enable:
        return "require_enable: the vector env's driver is always enabled (MwipEnv runs the driver's state machine)"
    if s.base_law is not None and pure_form(loop.law_class) is None:
        return f"base_law: {s.base_law} has no pure step (Law.pure_step) to run over arrays (MwipEnv runs it)"
    return None


class _Streams:
    """Each robot's standard normal draws, ``width`` per period, from its own generator, a block at a time; a robot
    draws only in the periods it runs, so each has its own place in its block."""

    def __init__(self, n: int, width: int, make):
        self.make, self.width = make, width
        self.gens = [None] * n
        self.block = np.zeros((n, NOISE_BLOCK, width))
        self.used = np.full(n, NOISE_BLOCK)
        self.rows = np.arange(n)

    def seed(self, idx, seeds) -> None:
        for i, sd in zip(idx, seeds):
            self.gens[i] = self.make(int(sd))
        self.used[idx] = NOISE_BLOCK

    def draw(self, mask: np.ndarray) -> np.ndarray:
        """(N, width): the next draws of the robots in ``mask`` (the others: whatever is at their place, unused)."""
        for i in np.flatnonzero(mask & (self.used == NOISE_BLOCK)):
            self.block[i] = self.gens[i].standard_normal((NOISE_BLOCK, self.width))
            self.used[i] = 0
        z = self.block[self.rows, np.minimum(self.used, NOISE_BLOCK - 1)]
        self.used += mask
        return z


class Lanes:
    """The state of N robots of the setup ``s`` between periods, and their stages (see the module)."""

    def __init__(self, s: EnvSetup, n: int):
        why = refusal(s)
        if why:
            raise ValueError(why)
        loop = s.loop
        pc = self.pc = loop.plant
        self.n, self.h, self.substeps, self.setup = n, pc.h, pc.substeps, s
        self.c = tuple(float(v) for v in np.asarray(loop.X, dtype=float).ravel())   # c1..c4 (eq. 14)
        self.law = None
        if s.base_law is not None:
            cls = loop.law_class
            self.law = pure_form(cls)
            self.P = getattr(cls, "base", cls).pure_params(loop.params)
            self.observer_term = bool(cls.observer)
        sc = pc.sensing
        self.delay, self.act_delay, self.counts = sc.delay_periods, sc.actuator_delay_periods, sc.encoder_counts_per_rev
        self.noisy = sc.noisy
        self.rows = np.arange(n)
        # each robot's true eq. (2) terms and D_b, columns of (5, n) (envs.robots: set per robot from a sweep spec)
        self.robot = np.array([[float(getattr(pc.actual, f))] * n for f in TERMS] + [[float(pc.D_b)] * n])
        self.tau = TauTable(pc)
        self.sd_w = float(np.sqrt(pc.D_w_variance))
        # the excitation of each period (core.loop.command adds it to the law's command), a table of the episode
        self.ext = (Excitation(loop.excitation, pc.h).series(s.n_steps + 1) if loop.excitation is not None else None)
        self.dw = _Streams(n, 1, np.random.default_rng) if pc.D_w_variance != 0.0 else None
        self.zs = _Streams(n, 4, sensor_rng) if self.noisy else None
        self.x = tuple(np.full(n, float(v)) for v in pc.initial)
        self.k = np.zeros(n, dtype=np.int64)
        self.u_prev = np.zeros(n)
        self.z = (np.zeros(n), np.zeros(n))
        self.prev = tuple(np.zeros(n) for _ in range(4))
        self.s = np.zeros(n)
        self.first = np.ones(n, dtype=bool)
        self.qx = np.zeros((self.delay + 1, 5, n))
        self.qa = np.zeros((self.act_delay + 1, n))
        self.u_base = np.zeros(n)
        self.tau_hat = (np.zeros(n), np.zeros(n))

    def restart(self, mask: np.ndarray, seeds: Optional[Sequence[int]] = None) -> None:
        """Start the robots of ``mask`` again at t = 0 in the initial state (``seeds``: new noise streams for them,
        one each; None: they keep their streams)."""
        idx = np.flatnonzero(mask)
        if seeds is not None:
            for streams in (self.dw, self.zs):
                if streams is not None:
                    streams.seed(idx, seeds)
        for j, v in enumerate(self.pc.initial):
            self.x[j][idx] = float(v)
        self.k[idx] = 0
        self.u_prev[idx] = 0.0
        self.s[idx] = 0.0
        self.first[idx] = True
        self.qa[:, idx] = 0.0

    def observe(self) -> tuple:
        """Stages ``sensors``, ``observer`` and ``law`` (the base law's command, kept in :attr:`u_base`) of every
        robot's period k: the state each one's law sees (four arrays)."""
        n, k = self.n, self.k
        # stage: sensors
        x, u_m = self.x, self.u_prev
        if self.noisy or self.counts or self.delay:
            std = self.pc.sensing.noise_std
            z = self.zs.draw(np.ones(n, dtype=bool)).T if self.noisy else None
            xm = measure(x, z, std, self.counts, np)
            if self.delay:
                d1 = self.delay + 1
                slot = k % d1
                for j in range(4):
                    self.qx[slot, j, self.rows] = xm[j]
                self.qx[slot, 4, self.rows] = u_m
                r = np.where(k >= self.delay, (k - self.delay) % d1, 0)
                xm = tuple(self.qx[r, j, self.rows] for j in range(4))
                u_m = self.qx[r, 4, self.rows]
        else:
            xm = x
        # stage: estimator (the identity: the measurement is a state)
        # stage: observer (core.observer.DiscreteObserver.update)
        p, c, first = self.pc.nominal, self.c, self.first
        z = z_next(p, c, self.prev, u_m, self.z, self.h, np)
        if first.any():
            z0 = z_start(c, xm[2], xm[3])
            z = (np.where(first, z0[0], z[0]), np.where(first, z0[1], z[1]))
        self.z, self.prev = z, xm
        self.tau_hat = th = tau_hat_of(c, z, xm[2], xm[3])
        # stage: law (the base law; the action is added in advance)
        if self.law is not None:
            u, s_next, _ = self.law(self.P, p, self.h, xm, self.s, False, np)
            if first.any():
                u0, s0, _ = self.law(self.P, p, self.h, xm, self.s, True, np)
                u, s_next = np.where(first, u0, u), np.where(first, s0, s_next)
            if self.observer_term:   # core.laws.ndo.WithObserver.step
                u = u - u_taud_of(p, p.m12 * np.cos(xm[1]), th)
            self.s = s_next
        else:
            u = np.zeros(n)   # no base law: the action is the whole command
        if self.ext is not None:   # core.loop.command: the law's command plus the excitation of period k
            u = u + self.ext[np.minimum(k, len(self.ext) - 1)]
        self.u_base = u
        self.first = np.zeros(n, dtype=bool)
        return xm

    def advance(self, u_cmd: np.ndarray, go: np.ndarray):
        """Stages ``drive`` and ``plant`` of period k for the robots of ``go`` with the commands ``u_cmd``: (the
        drive's torque (after the limit and the delay), each robot's failure code: 0, or FALL, BAD_COMMAND, DIVERGED
        of :mod:`mwip_ros.core.trajectory`)."""
        pc, k = self.pc, self.k
        # stage: yaw (none: the vector env runs the planar plant)
        # stage: drive
        bad = go & ~(np.abs(u_cmd) <= PLAUSIBLE_TORQUE)   # the driver's bad_command (core.loop.PlantSide.act)
        u = np.clip(u_cmd, -pc.torque_limit, pc.torque_limit) if pc.torque_limit > 0.0 else u_cmd
        if self.act_delay:   # core.sensing.Actuator.apply
            a1 = self.act_delay + 1
            slot = k % a1
            self.qa[slot, self.rows] = np.where(go, u, self.qa[slot, self.rows])
            u = np.where(k >= self.act_delay, self.qa[(k - self.act_delay) % a1, self.rows], 0.0)
        u = np.where(bad, 0.0, u)
        # stage: plant (D_w of the period, tau_ext at each robot's own t_k, RK4)
        run = go & ~bad
        if self.dw is not None:   # core.plant.D_w_of over arrays
            D_w = np.maximum(0.0, pc.D_w_mean + self.sd_w * self.dw.draw(go)[:, 0])
        else:
            D_w = np.full(self.n, float(pc.D_w_mean))
        x = tuple(v.copy() for v in self.x)
        u = np.ascontiguousarray(u, dtype=float)
        acted = u.copy()   # the motor's torque over the period (without a motor: the command)
        with np.errstate(all="ignore"):
            self.tau.cover(int(k.max()))
            args = (*self.robot, D_w, self.tau.T1, self.tau.T2, k, *x, u, self.h, self.substeps, run)
            advance(*args, *(float(c) for c in pc.motor_constants), acted)
            self.x = x
            finite = np.isfinite(x[0]) & np.isfinite(x[1]) & np.isfinite(x[2]) & np.isfinite(x[3])
            fell = run & ~(np.abs(x[1]) <= pc.fall_angle)
        self.u_prev = np.where(go, acted, self.u_prev)   # what the sensors report next (core.plant.PlantSim.u_prev)
        self.k = k + go
        code = np.where(bad, BAD_COMMAND, np.where(fell, np.where(finite, FALL, DIVERGED), 0))
        return u, code
