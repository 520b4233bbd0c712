"""N robots stepped one period at a time, each at its own period k: the vector env's stepper.

The batch simulator (:mod:`mwip_ros.core.kernels.batch`, :mod:`mwip_ros.core.kernels.compiled`) runs whole episodes with
one period k shared by every scenario; a vector env steps its robots one period per call, takes the command from
outside, and restarts a robot whose episode ended while the others go on (so the robots' periods differ).  This module
is that stepper; it writes no stage of its own: each stage of :data:`mwip_ros.core.closed_loop.loop.STAGES`
(docs/theory.md, section 4) calls the compiled loop's own stage function robot by robot (:mod:`.kernels`) or the core's
pure functions over arrays, in that order:

* ``sensors``: a plant that measures the state, :func:`mwip_ros.core.kernels.compiled_stages.sense_state` (noise from
  each robot's own stream, :func:`~mwip_ros.core.plants.sensing.sensor_rng`, the encoder, the measurement delay queue);
  with raw sensors (``sensors.model: raw``, docs/theory.md 6.4) the raw sample
  (:func:`~mwip_ros.core.plants.raw_sensors.raw_sample`, noise from each robot's
  :func:`~mwip_ros.core.plants.raw_sensors.raw_rng` stream) and its delay queue (:func:`.kernels.raw_kernel`);
* ``estimator``: the identity, or with raw sensors the estimator's ``pure_step`` (:mod:`mwip_ros.core.estimators`,
  its state a row per robot; a restarted robot's next step is a first step), in the same kernel;
* ``observer``: eq. (12)-(14), :func:`~mwip_ros.core.control.observer.z_start`,
  :func:`~mwip_ros.core.control.observer.z_next`, :func:`~mwip_ros.core.control.observer.tau_hat_of` over arrays;
* ``law``: the base law's ``pure_step`` (:mod:`mwip_ros.core.laws`) and the observer term
  :func:`~mwip_ros.core.control.controller.u_taud_of`; with the motion references (``motion.enabled``, docs/theory.md
  6.11 and the hold, 6.14) the compiled loop's own stage, :func:`mwip_ros.core.kernels.compiled_motion.law_track`
  (:func:`mwip_ros.core.kernels.compiled_stages.track_for`), each robot with its references' state; a law without a pure
  step (``mpc``: a QP per robot) is the law's own object per robot through
  :func:`mwip_ros.core.closed_loop.loop.command` (with motion, a :class:`~mwip_ros.core.control.motion.Shaper` per
  robot; a restart is its ``reset``, a cold start); then the excitation
  (:mod:`mwip_ros.core.identification.excitation`).  **The action enters here, once**: the env adds the residual torque
  to this command (:meth:`Lanes.advance` takes the sum), where
  :func:`mwip_ros.core.closed_loop.loop.command` adds the excitation, before the drive;
* ``yaw``: none (the planar plant; the MuJoCo plant's yaw stage runs in :class:`~mwip_ros.envs.scalar.MwipEnv`);
* ``drive``: :func:`mwip_ros.core.kernels.compiled_stages.drive_stage` (the driver's ``bad_command``, the torque limit,
  the actuator delay queue), then the driver's gate (``require_enable``: the bridge open, zero torque);
* ``plant``: D_w (:func:`~mwip_ros.core.plants.plant.D_w_of`'s arithmetic, each robot's own stream), tau_ext at each
  robot's own t_k (:func:`~mwip_ros.core.plants.plant.stage_torques`, a table of the episode's periods), one RK4 period
  of eq. (1) with the motor when the files have it (:func:`~mwip_ros.core.plants.plant.rk4_driven` compiled:
  :mod:`.kernels`), the fall check.

With ``require_enable: true`` the driver starts disabled and nobody enables it (as in ``mwip_sim``): its bridge is
open in every period, no torque acts and the motor carries no current (:func:`~mwip_ros.core.plants.plant.gated_drive`);
a command that is not plausible still faults it.  Another plant backend, and the motion references with
``require_enable`` (the compiled stage does not idle the references), are refused naming the key
(:class:`~mwip_ros.envs.scalar.MwipEnv` runs both).  A restarted robot keeps its noise streams (its next draws), so
no generator is built again.
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from mwip_ros.core import estimators
from mwip_ros.core.kernels.compiled_stages import pure_form
from mwip_ros.core.kernels.compiled_motion import motion_arrays
from mwip_ros.core.closed_loop.loop import command
from mwip_ros.core.plants.model import State
from mwip_ros.core.control.motion import Shaper
from mwip_ros.core.control.controller import u_taud_of
from mwip_ros.core.identification.excitation import Excitation
from mwip_ros.core.control.observer import tau_hat_of, z_next, z_start
from mwip_ros.core.plants.plant import NO_MOTOR
from mwip_ros.core.plants.raw_sensors import raw_rng
from mwip_ros.core.plants.sensing import NOISE_BLOCK, sensor_rng
from mwip_ros.core.closed_loop.trajectory import BAD_COMMAND, DIVERGED, FALL

from .common import EnvSetup
from .kernels import TauTable, advance, drive, raw_kernel, sense, track_kernel
from .robots import TERMS

__all__ = ["Lanes", "refusal"]


def refusal(s: EnvSetup) -> Optional[str]:
    """Why the vector env cannot run the setup ``s`` (one line naming the key), or None."""
    loop = s.loop
    pc = loop.plant
    if pc.backend != "rk4":
        return f"plant_sim.backend: the vector env runs the rk4 plant only, got {pc.backend!r} (MwipEnv runs it)"
    if loop.motion is not None and pc.require_enable:
        return ("require_enable: the vector env tracks the motion references with the driver enabled only (the "
                "compiled loop's stage does not idle them; MwipEnv runs it)")
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
        # the driver's bridge: require_enable and nobody to enable it, open in every period (core.control.safety)
        self.enabled = not pc.require_enable
        self.motor = tuple(float(c) for c in pc.motor_constants) if self.enabled else NO_MOTOR
        self.c = tuple(float(v) for v in np.asarray(loop.X, dtype=float).ravel())   # c1..c4 (eq. 14)
        self.law = self.laws = self.track = self.shapers = None
        # the motion references (docs/theory.md 6.11): the compiled loop's numbers and each robot's references' state
        self.motion = loop.motion is not None and s.base_law is not None   # no base law: nothing tracks them
        if self.motion:
            self.MO, self.PT, self.PV, self.NP, self.MS0, _ = (a[0] for a in motion_arrays([loop])[1:])
            self.MS = np.tile(self.MS0, (n, 1))
        if s.base_law is not None:
            cls = loop.law_class
            self.law = pure_form(cls)
            if self.law is not None:
                self.P = getattr(cls, "base", cls).pure_params(loop.params)
                self.observer_term = bool(cls.observer)
                # the compiled loop's law stage with the references (core.kernels.compiled_stages.track_for)
                if self.motion:
                    self.track = track_kernel(cls)
                    self.PA = np.array([float(v) for v in self.P])
                    self.nom = tuple(float(getattr(pc.nominal, f)) for f in TERMS)
            else:   # no pure step (mpc: a QP per robot): the law's own object per robot, stepped one by one
                self.laws = [cls(loop.params, pc.nominal, pc.h) for _ in range(n)]
                if self.motion:   # the scalar loop's references, a Shaper per robot (core.closed_loop.loop.command)
                    self.shapers = [Shaper(loop.motion, pc.h, pc.nominal) for _ in range(n)]
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
        # the excitation of each period (core.closed_loop.loop.command adds it to the law's command), a table of the
        # episode
        self.ext = (Excitation(loop.excitation, pc.h).series(s.n_steps + 1) if loop.excitation is not None else None)
        self.dw = _Streams(n, 1, np.random.default_rng) if pc.D_w_variance != 0.0 else None
        self.zs = _Streams(n, 4, sensor_rng) if self.noisy else None
        if pc.raw is not None:   # the raw sensors' state and queue, the estimator's numbers and states
            est = loop.estimator
            self.kernel = raw_kernel(estimators.get(est.method))
            self.PE = np.array([float(v) for v in est.make(pc.h, pc.nominal.r, pc.nominal.g).P])
            self.ES = np.zeros((n, estimators.get(est.method).state_size))
            self.zs = _Streams(n, 4, raw_rng) if pc.raw.noisy else None
            # each robot's sensors' state (core.kernels.compiled_stages.sense_raw): the gyro's bias, the previous phi,
            # and what acted over the previous period (D_w, the drive's command): the raw sample's instant
            self.RS = np.zeros((n, 4))
            self.RS[:, 0], self.RS[:, 2] = float(pc.raw.gyro_bias), float(pc.D_w_mean)
            rc = pc.raw   # r, d, g, gyro_noise_std, gyro_bias_walk, accel_noise_std, counts (r, g: each robot's)
            self.RW = np.array([float(pc.actual.r), float(rc.offset), float(pc.actual.g), float(rc.gyro_noise_std),
                                float(rc.gyro_bias_walk), float(rc.accel_noise_std), float(rc.encoder_counts_per_rev)])
            self.MC = np.array(self.motor, dtype=float)
            self.qr = np.zeros((n, self.delay + 1, 6))
            self.sample = np.zeros((n, 5))
        self.x = tuple(np.full(n, float(v)) for v in pc.initial)
        self.k = np.zeros(n, dtype=np.int64)
        self.u_prev = np.zeros(n)
        self.z = (np.zeros(n), np.zeros(n))
        self.prev = tuple(np.zeros(n) for _ in range(4))
        self.s = np.zeros(n)
        self.first = np.ones(n, dtype=bool)
        self.qx = np.zeros((n, self.delay + 1, 5))
        self.qa = np.zeros((n, self.act_delay + 1))
        self.std = np.array([float(v) for v in sc.noise_std])
        self.limit = float(pc.torque_limit)
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
        self.qa[idx] = 0.0
        if self.motion:
            self.MS[idx] = self.MS0
        if self.shapers is not None:
            for i in idx:
                self.shapers[i] = Shaper(self.setup.loop.motion, self.h, self.pc.nominal)
        if self.raw is not None:
            self.RS[idx, 0] = float(self.raw.gyro_bias)
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
        elif self.noisy or self.counts or self.delay:   # core.kernels.compiled_stages.sense_state, robot by robot
            Z = self.zs.draw(np.ones(n, dtype=bool)) if self.noisy else np.zeros((1, 4))
            xm_, u_m = np.empty((4, n)), np.empty(n)
            sense(k, *x, self.u_prev, Z, self.noisy, self.std, self.counts, self.delay, self.qx, xm_, u_m)
            xm = tuple(xm_)
        else:
            xm = x
        # stage: estimator (the identity when the measurement is a state; raw: run above, in the sensors' kernel)
        # stage: observer (core.control.observer.DiscreteObserver.update)
        p, c, first = self.pc.nominal, self.c, self.first
        z = z_next(p, c, self.prev, u_m, self.z, self.h, np)
        if first.any():
            z0 = z_start(c, xm[2], xm[3])
            z = (np.where(first, z0[0], z[0]), np.where(first, z0[1], z[1]))
        self.z, self.prev = z, xm
        self.tau_hat = th = tau_hat_of(c, z, xm[2], xm[3])
        # stage: law (the base law; the action is added in advance)
        # with the motion references: the compiled loop's stage (core.kernels.compiled_motion)
        if self.track is not None:
            u, xc = np.empty(n), [np.ascontiguousarray(v, dtype=float) for v in xm]
            self.track(self.PA, *self.nom, self.h, *xc, self.s, k, self.MO, self.PT, self.PV, int(self.NP), self.MS,
                       np.ascontiguousarray(th[0]), np.ascontiguousarray(th[1]), self.observer_term, u)
        elif self.law is not None:
            u, s_next, _ = self.law(self.P, p, self.h, xm, self.s, False, np)
            if first.any():
                u0, s0, _ = self.law(self.P, p, self.h, xm, self.s, True, np)
                u, s_next = np.where(first, u0, u), np.where(first, s0, s_next)
            if self.observer_term:   # core.laws.ndo.WithObserver.step
                u = u - u_taud_of(p, p.m12 * np.cos(xm[1]), th)
            self.s = s_next
        elif self.laws is not None:   # core.closed_loop.loop.command: the law's step with the state and tau_hat it sees
            xs, ts = [np.asarray(v, dtype=float).tolist() for v in xm], [v.tolist() for v in th]
            shapers = self.shapers if self.shapers is not None else [None] * n
            u = np.array([float(command(lw, State(xs[0][i], xs[1][i], xs[2][i], xs[3][i]), (ts[0][i], ts[1][i]),
                                        None, int(k[i]), shapers[i])[0]) for i, lw in enumerate(self.laws)])
        else:
            u = np.zeros(n)   # no base law: the action is the whole command
        if self.ext is not None:   # core.closed_loop.loop.command: the law's command plus the excitation of period k
            u = u + self.ext[np.minimum(k, len(self.ext) - 1)]
        self.u_base = u
        self.first = np.zeros(n, dtype=bool)
        return xm

    def _D_w(self, z) -> np.ndarray:
        """Each robot's D_w from its draws ``z`` (:func:`~mwip_ros.core.plants.plant.D_w_of` over arrays)."""
        return np.maximum(0.0, self.pc.D_w_mean + self.sd_w * z)

    def _sense_raw(self) -> tuple:
        """The raw sample of every robot's period k, delayed, and its estimate: (the estimate, four arrays; the
        torque reported with the sample); :attr:`sample` the delayed samples."""
        n = self.n
        first = self.k == 0
        if first.any() and self.dw is not None:   # D_w of period 0 (the draw the plant stage takes next)
            self.RS[:, 2] = np.where(first, self._D_w(self.dw.peek(first)[:, 0]), self.RS[:, 2])
        Z = self.zs.draw(np.ones(n, dtype=bool)) if self.zs is not None else np.zeros((1, 4))
        self.tau.cover(int(self.k.max()))
        xm, u_m = np.empty((4, n)), np.empty(n)
        with np.errstate(all="ignore"):
            self.kernel(*self.robot, self.tau.T1, self.tau.T2, self.k, *self.x, self.u_prev, self.MC, Z,
                        self.zs is not None, self.RS, self.RW, self.h, self.delay, self.qr, self.PE, self.ES,
                        self.sample, xm, u_m)
        return tuple(xm), u_m

    def advance(self, u_cmd: np.ndarray, go: np.ndarray):
        """Stages ``drive`` and ``plant`` of period k for the robots of ``go`` with the commands ``u_cmd``: (the
        drive's torque (after the limit and the delay), each robot's failure code: 0, or FALL, BAD_COMMAND, DIVERGED
        of :mod:`mwip_ros.core.closed_loop.trajectory`)."""
        pc, k = self.pc, self.k
        # stage: yaw (none: the vector env runs the planar plant)
        # stage: drive (core.kernels.compiled_stages.drive_stage robot by robot, then the driver's gate)
        u, bad = np.empty(self.n), np.empty(self.n, dtype=bool)
        drive(np.ascontiguousarray(u_cmd, dtype=float), go, self.limit, self.qa, k, self.act_delay, self.enabled,
              u, bad)
        # stage: plant (D_w of the period, tau_ext at each robot's own t_k, RK4)
        run = go & ~bad
        if self.dw is not None:   # core.plants.plant.D_w_of over arrays
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
        # what the sensors report next (core.plants.plant.PlantSim.u_prev)
        self.u_prev = np.where(go, acted, self.u_prev)
        if self.raw is not None:   # what acted over this period: the next raw sample's instant
            self.RS[:, 2] = np.where(go, D_w, self.RS[:, 2])
            self.RS[:, 3] = np.where(go, u, self.RS[:, 3])
        self.k = k + go
        code = np.where(bad, BAD_COMMAND, np.where(fell, np.where(finite, FALL, DIVERGED), 0))
        return u, code
