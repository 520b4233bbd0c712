"""N robots stepped one period at a time over numpy arrays, each at its own period k: the vector env's stepper.

The batch simulator (:mod:`mwip_ros.core.batch`, :mod:`mwip_ros.core.compiled`) runs whole episodes with one period
k shared by every scenario; a vector env steps its robots one period per call, takes the command from outside, and
restarts a robot whose episode ended while the others go on (so the robots' periods differ).  This module is that
stepper, numpy-vectorised over the robots; it writes no equation: each stage calls the core's own pure functions
over arrays (the functions the compiled loop compiles), in :data:`mwip_ros.core.loop.STAGES`' order:

* ``sensors``: :func:`~mwip_ros.core.sensing.measure` (noise from each robot's own stream,
  :func:`~mwip_ros.core.sensing.sensor_rng`, the encoder), the measurement delay (the queue of
  :class:`~mwip_ros.core.sensing.Sensors`, a ring per robot); with raw sensors (``sensors.model: raw``) the raw
  sample (:func:`~mwip_ros.core.raw_sensors.raw_sample`, noise from each robot's
  :func:`~mwip_ros.core.raw_sensors.raw_rng` stream) and its delay queue, compiled (:func:`.kernels.raw_kernel`);
* ``estimator``: the identity, or with raw sensors the estimator's ``pure_step`` (:mod:`mwip_ros.core.estimators`,
  its state a row per robot; a restarted robot's next step is a first step), in the same kernel;
* ``observer``: :func:`~mwip_ros.core.observer.z_start`, :func:`~mwip_ros.core.observer.z_next`,
  :func:`~mwip_ros.core.observer.tau_hat_of`;
* ``law``: the base law's ``pure_step`` (:mod:`mwip_ros.core.laws`) and the observer term
  :func:`~mwip_ros.core.controller.u_taud_of` (a law without one, ``mpc``: a QP per robot, the law's own object per
  robot, its ``step`` one robot after another; a restart is its ``reset``, a cold start), the excitation
  (:mod:`mwip_ros.core.excitation`), plus the action;
* ``drive``: the driver's ``bad_command`` (:data:`~mwip_ros.core.safety.PLAUSIBLE_TORQUE`), the torque limit, the
  actuator delay (the queue of :class:`~mwip_ros.core.sensing.Actuator`);
* ``plant``: D_w (:func:`~mwip_ros.core.plant.D_w_of`'s arithmetic, each robot's own stream), tau_ext at each robot's
  own t_k (:func:`~mwip_ros.core.plant.stage_torques`, a table of the episode's periods), one RK4 period with the
  motor when the files have it (:func:`~mwip_ros.core.plant.rk4_driven` compiled: :mod:`.kernels`), the fall check.

With ``require_enable: true`` the driver starts disabled and nobody enables it (as in ``mwip_sim``): its bridge is
open in every period, no torque acts and the motor carries no current (:func:`~mwip_ros.core.plant.gated_drive`);
a command that is not plausible still faults it.  Another plant backend and the motion references are refused,
naming the key (``plant_sim.backend``, ``motion.enabled``; the scalar env, :class:`~mwip_ros.envs.scalar.MwipEnv`,
runs both).
A restarted robot keeps its noise streams (its next draws), so no generator is built again.
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from mwip_ros.core import estimators
from mwip_ros.core.compiled import pure_form
from mwip_ros.core.controller import u_taud_of
from mwip_ros.core.excitation import Excitation
from mwip_ros.core.observer import tau_hat_of, z_next, z_start
from mwip_ros.core.plant import NO_MOTOR
from mwip_ros.core.raw_sensors import raw_rng
from mwip_ros.core.safety import PLAUSIBLE_TORQUE
from mwip_ros.core.sensing import NOISE_BLOCK, measure, sensor_rng
from mwip_ros.core.trajectory import BAD_COMMAND, DIVERGED, FALL

from .common import EnvSetup
from .kernels import TauTable, advance, raw_kernel
from .robots import TERMS

__all__ = ["Lanes", "refusal"]


def refusal(s: EnvSetup) -> Optional[str]:
    """Why the vector env cannot run the setup ``s`` (one line naming the key), or None."""
    loop = s.loop
    pc = loop.plant
    if pc.backend != "rk4":
        return f"plant_sim.backend: the vector env runs the rk4 plant only, got {pc.backend!r} (MwipEnv runs it)"
    if loop.motion is not None:
        return "motion.enabled: the vector env tracks no motion references (MwipEnv runs them); set it false"
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

    def peek(self, mask: np.ndarray) -> np.ndarray:
        """(N, width): the next draws of the robots in ``mask``, left to be drawn (the others: unused)."""
        for i in np.flatnonzero(mask & (self.used == NOISE_BLOCK)):
            self.block[i] = self.gens[i].standard_normal((NOISE_BLOCK, self.width))
            self.used[i] = 0
        return self.block[self.rows, np.minimum(self.used, NOISE_BLOCK - 1)]

    def draw(self, mask: np.ndarray) -> np.ndarray:
        """(N, width): the next draws of the robots in ``mask`` (the others: whatever is at their place, unused)."""
        z = self.peek(mask)
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
        # the driver's bridge: require_enable and nobody to enable it, open in every period (core.safety)
        self.enabled = not pc.require_enable
        self.motor = tuple(float(c) for c in pc.motor_constants) if self.enabled else NO_MOTOR
        self.c = tuple(float(v) for v in np.asarray(loop.X, dtype=float).ravel())   # c1..c4 (eq. 14)
        self.law = self.laws = None
        if s.base_law is not None:
            cls = loop.law_class
            self.law = pure_form(cls)
            if self.law is not None:
                self.P = getattr(cls, "base", cls).pure_params(loop.params)
                self.observer_term = bool(cls.observer)
            else:   # no pure step (mpc: a QP per robot): the law's own object per robot, stepped one by one
                self.laws = [cls(loop.params, pc.nominal, pc.h) for _ in range(n)]
        sc = pc.sensing
        self.delay, self.act_delay, self.counts = sc.delay_periods, sc.actuator_delay_periods, sc.encoder_counts_per_rev
        self.raw = pc.raw
        self.noisy = sc.noisy and pc.raw is None   # raw: no state-mode sensors
        self.rows = np.arange(n)
        # each robot's true eq. (2) terms, D_b, r and g: columns of (7, n) (envs.robots: set per robot from a sweep)
        self.robot = np.array([[float(getattr(pc.actual, f))] * n for f in TERMS] + [[float(pc.D_b)] * n]
                              + [[float(pc.actual.r)] * n, [float(pc.actual.g)] * n])
        self.tau = TauTable(pc)
        self.sd_w = float(np.sqrt(pc.D_w_variance))
        # the excitation of each period (core.loop.command adds it to the law's command), a table of the episode
        self.ext = (Excitation(loop.excitation, pc.h).series(s.n_steps + 1) if loop.excitation is not None else None)
        self.dw = _Streams(n, 1, np.random.default_rng) if pc.D_w_variance != 0.0 else None
        self.zs = _Streams(n, 4, sensor_rng) if self.noisy else None
        if pc.raw is not None:   # the raw sensors' state and queue, the estimator's numbers and states
            est = loop.estimator
            self.kernel = raw_kernel(estimators.get(est.method))
            self.PE = np.array([float(v) for v in est.make(pc.h, pc.nominal.r, pc.nominal.g).P])
            self.ES = np.zeros((n, estimators.get(est.method).state_size))
            self.zs = _Streams(n, 4, raw_rng) if pc.raw.noisy else None
            self.bias, self.phi = np.full(n, float(pc.raw.gyro_bias)), np.zeros(n)
            self.qr = np.zeros((n, self.delay + 1, 6))
            self.sample = np.zeros((n, 5))
            self.D_w = np.full(n, float(pc.D_w_mean))   # what acted over the previous period (the raw sample's)
            self.u_drive = np.zeros(n)
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
        if self.raw is not None:
            self.bias[idx] = float(self.raw.gyro_bias)
        if self.laws is not None:   # a cold start (the scalar env builds the law again)
            for i in idx:
                self.laws[i].reset()

    def observe(self) -> tuple:
        """Stages ``sensors``, ``observer`` and ``law`` (the base law's command, kept in :attr:`u_base`) of every
        robot's period k: the state each one's law sees (four arrays)."""
        n, k = self.n, self.k
        # stage: sensors
        x, u_m = self.x, self.u_prev
        if self.raw is not None:   # the raw sample, its delay and the estimator: kernels._sense_raw
            xm, u_m = self._sense_raw()
        elif self.noisy or self.counts or self.delay:
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
        # stage: estimator (the identity when the measurement is a state; raw: run above, in the sensors' kernel)
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
        elif self.laws is not None:   # core.loop.command: the law's step with the state and tau_hat it sees
            xs, ts = [np.asarray(v, dtype=float).tolist() for v in xm], [v.tolist() for v in th]
            u = np.array([float(lw.step((xs[0][i], xs[1][i], xs[2][i], xs[3][i]), (ts[0][i], ts[1][i]))[0])
                          for i, lw in enumerate(self.laws)])
        else:
            u = np.zeros(n)   # no base law: the action is the whole command
        if self.ext is not None:   # core.loop.command: the law's command plus the excitation of period k
            u = u + self.ext[np.minimum(k, len(self.ext) - 1)]
        self.u_base = u
        self.first = np.zeros(n, dtype=bool)
        return xm

    def _D_w(self, z) -> np.ndarray:
        """Each robot's D_w from its draws ``z`` (:func:`~mwip_ros.core.plant.D_w_of` over arrays)."""
        return np.maximum(0.0, self.pc.D_w_mean + self.sd_w * z)

    def _sense_raw(self) -> tuple:
        """The raw sample of every robot's period k, delayed, and its estimate: (the estimate, four arrays; the
        torque reported with the sample); :attr:`sample` the delayed samples."""
        n, raw = self.n, self.raw
        first = self.k == 0
        if first.any() and self.dw is not None:   # D_w of period 0 (the draw the plant stage takes next)
            self.D_w = np.where(first, self._D_w(self.dw.peek(first)[:, 0]), self.D_w)
        Z = self.zs.draw(np.ones(n, dtype=bool)) if self.zs is not None else np.zeros((1, 4))
        self.tau.cover(int(self.k.max()))
        xm, u_m = np.empty((4, n)), np.empty(n)
        with np.errstate(all="ignore"):
            self.kernel(*self.robot, self.D_w, self.tau.T1, self.tau.T2, self.k, *self.x, self.u_prev, self.u_drive,
                        *self.motor, Z, self.zs is not None, self.bias, self.phi,
                        float(raw.offset), float(raw.gyro_noise_std), float(raw.gyro_bias_walk),
                        float(raw.accel_noise_std), int(raw.encoder_counts_per_rev), self.h, self.delay, self.qr,
                        self.PE, self.ES, self.sample, xm, u_m)
        return tuple(xm), u_m

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
        if not self.enabled:   # core.safety.DriverStateMachine.torque_gate: disabled, zero torque acts
            u = np.zeros(self.n)
        # stage: plant (D_w of the period, tau_ext at each robot's own t_k, RK4)
        run = go & ~bad
        if self.dw is not None:   # core.plant.D_w_of over arrays
            D_w = self._D_w(self.dw.draw(go)[:, 0])
        else:
            D_w = np.full(self.n, float(pc.D_w_mean))
        x = tuple(v.copy() for v in self.x)
        u = np.ascontiguousarray(u, dtype=float)
        acted = u.copy()   # the motor's torque over the period (without a motor: the command)
        with np.errstate(all="ignore"):
            self.tau.cover(int(k.max()))
            args = (*self.robot[:5], D_w, self.tau.T1, self.tau.T2, k, *x, u, self.h, self.substeps, run)
            advance(*args, *self.motor, acted)
            self.x = x
            finite = np.isfinite(x[0]) & np.isfinite(x[1]) & np.isfinite(x[2]) & np.isfinite(x[3])
            fell = run & ~(np.abs(x[1]) <= pc.fall_angle)
        self.u_prev = np.where(go, acted, self.u_prev)   # what the sensors report next (core.plant.PlantSim.u_prev)
        if self.raw is not None:   # what acted over this period: the next raw sample's instant
            self.D_w = np.where(go, D_w, self.D_w)
            self.u_drive = np.where(go, u, self.u_drive)
        self.k = k + go
        code = np.where(bad, BAD_COMMAND, np.where(fell, np.where(finite, FALL, DIVERGED), 0))
        return u, code
