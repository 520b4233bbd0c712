"""The batch simulator's compiled code: the plant's RK4 period (:class:`RK4Periods`) and the whole closed loop
(:func:`kernel_for`), built by numba from the scalar loop's own functions.

The plant's RK4 (eq. 1 evaluated 4 x ``substeps`` times a period) is :func:`.model.accel` and
:func:`.plant.rk4_period` handed to numba as they are, the same code objects (inside the compiled ``rk4_period``,
``accel`` is the compiled ``accel``), the parameters as an :class:`Inertia` tuple (the four terms of eq. 2 it
reads); no second copy of the equations, and a test checks it against the scalar plant bit for bit.
``error_model="numpy"``: a diverging scenario gives inf or NaN, not an exception (the batch freezes it).

The whole loop (:func:`_loop`, one kernel per law, :func:`kernel_for`) runs every period of :func:`.sim.simulate`
the same way: the sensors (noise from draws handed in, the encoder :func:`.sensing.quantize`, the delay queues), the
observer (:func:`.observer.z_start`, ``z_next``, ``tau_hat_of``), the law (its ``pure_step``, :mod:`.laws`) and the
observer term (:func:`.controller.u_taud_of`), :func:`.plant.saturate`, the actuator delay, the true tau_d in the
metrics window (``accel``, :func:`.model.lumped_disturbance`, ``Sinusoid.at``), the fall check and the RK4 period;
the window's sums, minimum and maximum accumulate as it goes. Each of those functions is compiled from its own code
object (:func:`_deep`: the plain functions it calls by a global name are compiled alike); the loop's own code is the
glue between them. The scenarios go :data:`LANES` at a time, period by period: the RK4 period (when the scenarios
share tau_ext) and the observer and the law (``Law.pure_lanes``) run for all the lanes at once, as
:func:`.plant.rk4_period`, :func:`.model.accel`, :func:`.observer.z_next` and the law's ``pure_step`` compiled with
:data:`.simd.lanes` for their numbers and :mod:`.simd` for their math namespace (:func:`_lanes_of`: the same code
objects; libmvec's vector sin, cos and exp, within a few ulp of libm's); the rest runs lane by lane. The normal
draws stay numpy's (each scenario's own generators, in the scalar loop's order), made by the caller
(``core.kernels.batch``) a block of periods at a time.

The optional stages of :mod:`.loop` run there too, scenario by scenario: the raw sensors
(:func:`.raw_sensors.raw_sample` at t_k^-, as ``PlantSim.sample_accel``, their normals handed in like the state-mode
ones, the same delay queue) and the estimator (its ``pure_step``: one kernel per law and estimator,
``kernel_for(law, estimator)``, its state a row of an array), the motor (:func:`.plant.rk4_driven` per scenario, the
torque that acted reported to the observer, the saturated periods counted; the lanes' RK4 is motorless) and the
excitation (a table of each distinct one's periods, added to the law's command before the torque limit).

The stages that are one scenario's period each (the sensors, the law with the motion references, the drive) and
how the scalar loop's functions are compiled: :mod:`.compiled_stages`.

numba compiles on first use and caches the machine code (:mod:`.jitcache`: every cached function stamped with
everything it is made of, callees and frozen constants included, so an edit to any of them is compiled afresh).
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional

import numpy as np

from . import compiled_motion, simd
from ..plants import model, plant
from ..control import observer
from ..control.controller import u_taud_of
from ..control.observer import tau_hat_of, z_next, z_start
from ..plants.model import lumped_disturbance
from ..plants.plant import D_w_of
from .compiled_stages import (_accel, _deep, _lanes_of, _lanes_tag, _no_est, _rk4_driven, _rk4_period, _stage,
                              drive_stage, pure_form, raw_stage, sense_raw, sense_state, track_for)
from .jitcache import jit as _jit
from .jitcache import load_cached

__all__ = ["Inertia", "RK4Periods", "Sin", "kernel_for", "load_cached"]


class Inertia(NamedTuple):
    """The terms of eq. (2) that :func:`.model.accel` reads, for one scenario."""

    m11: float
    m12: float
    m22: float
    G_b: float


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


# --- the whole batch loop, compiled -------------------------------------------------------------------------------

class Sin(NamedTuple):
    """A :class:`~.model.Sinusoid`'s fields, for the compiled ``Sinusoid.at``."""

    amplitude: float
    omega: float
    phase: float


# the names the loop calls that :func:`kernel_for` binds to compiled functions (here: the scalar ones, and the law's
# step, which depends on the law)
accel, rk4_period, rk4_driven, at = model.accel, plant.rk4_period, plant.rk4_driven, model.Sinusoid.at
law_step = None
law_track, motion_row = compiled_motion.law_track, compiled_motion.motion_row   # motion: bound per law
law_track_lanes = compiled_motion.law_track_lanes
load, store = simd.load, simd.store
SIMD = simd.WIDTH > 0
LANES = simd.WIDTH or 8   # scenarios taken together (with SIMD == False: one after another, LANES at a time)


def _no_lanes(p, D_w, D_b, tau1, tau2, x, u, h, n):   # pragma: no cover
    return x   # SIMD is False: never called (and no vector sin or cos to link)


def _held(u, w, K_t, R, V_max, I_max):   # pragma: no cover
    """:func:`.drive.motor_torque` on lanes, never entered (the lanes' RK4 runs motorless loops): the command."""
    return u, 0


def rk4_lanes(p, D_w, D_b, tau1, tau2, x, u, h, n):   # pragma: no cover
    return x


def _no_z_lanes(nominal, c, prev, u_prev, z, step):   # pragma: no cover
    return z   # SIMD is False: never called


z_next_lanes = _no_z_lanes
LAW_LANES = False   # the law's pure_step runs on lanes (Law.pure_lanes): bound per law by kernel_for


def _no_law_lanes(P, p, h, x, s, first):   # pragma: no cover
    return s, s, s   # LAW_LANES is False: never called


def _params3(Pg):   # pragma: no cover
    """The law's three numbers (``P``), a lane each."""
    return load(Pg[0], 0), load(Pg[1], 0), load(Pg[2], 0)


law_lanes, params_lanes = _no_law_lanes, _params3


def _loop(k0, k1, n_steps, h, substeps, first_w, n_window, counts, delay, act_delay, observer_law,
          act, nom, D_b, sins, shared, limit, fall, X, P, use_obs, noisy, std, D_w_mean, D_w_sd, D_w_random,
          Nw, Z, x, u_prev, z, prev, s, qx, qa, active, t_fall, steps, acc, ext, T, tau1, tau2,
          raw, RW, RS, raw_noisy, PE, ES, motor_any, MC, EXT, exi, failure,
          motion, MO, PT, PV, NP, MS, MA):   # pragma: no cover
    """Periods k0 .. k1 - 1 of every active scenario (the arguments by name and meaning: :class:`.kernel_args.LoopArgs`,
    as :mod:`.batch` builds them): the scalar loop of :func:`.sim.simulate` (sensors, observer,
    law, saturation, actuator, true tau_d in the window, fall, RK4), calling its own functions compiled; the
    per-scenario state lives in the arrays between calls.  The scenarios go ``LANES`` at a time, period by period:
    each one's sensors to fall check in turn, then, when they share tau_ext (``shared``: ``sins`` row 0, whose stage
    values are computed once per period into ``T`` (periods, 2, 2 substeps + 1)) and :data:`.simd.WIDTH` is not 0,
    one RK4 period of all of them at once (``rk4_lanes``: :func:`.plant.rk4_period` on :data:`.simd.lanes`), else
    each one's own.

    The optional stages: ``raw`` (the raw sensors, :func:`.raw_sensors.raw_sample` at t_k^-, their normals in ``Z``
    for the scenarios with ``raw_noisy``, delayed in ``qx``, then the estimator's ``pure_step``, ``est_step``;
    ``RW`` a row per scenario: r, d, g, gyro_noise_std, gyro_bias_walk, accel_noise_std, counts of the true plant
    and its sensors; ``RS``: the bias, the previous phi, D_w of the previous period and the previous command;
    ``PE``, ``ES``: the estimator's numbers and state), the motor (``MC`` a row per scenario, K_t, R, V_max, I_max,
    K_t = 0: none; ``motor_any``: some scenario has it, and the RK4 runs per scenario, :func:`.plant.rk4_driven`)
    and the excitation (``EXT[exi[i], k]`` added to the law's command, ``exi[i]`` < 0: none).  ``acc`` columns 8 to
    13: the sums of squares and counts of the estimate's theta_b and theta_b' errors and of the torque that acted
    (window), 14: the periods with the drive saturated (whole run).  ``failure``: why a scenario failed, its
    ``core.closed_loop.trajectory.FAILURES`` code (1 fall, 2 a refused command, 3 diverged), with ``t_fall`` when."""
    n = x.shape[0]
    dt = h / substeps
    if shared and n > 0:
        g1 = Sin(sins[0, 0], sins[0, 1], sins[0, 2])
        g2 = Sin(sins[0, 3], sins[0, 4], sins[0, 5])
        for k in range(k0, k1):
            _stage(T[k - k0, 0], T[k - k0, 1], g1, g2, k * h, dt, substeps)
    together = shared and SIMD and not motor_any   # the lanes' RK4 is motorless
    L = LANES
    xs = np.zeros((4, L))      # the lanes' states, a row per component
    xn = np.zeros((4, L))      # their states one period later
    us = np.zeros(L)
    dws = np.zeros(L)
    pg = np.zeros((4, L))      # the actual plant's eq. (2) terms
    ng = np.zeros((4, L))      # the nominal model's
    cg = np.zeros((4, L))      # the observer's gains
    xmg = np.zeros((4, L))     # what the loop measures of the state
    umg = np.zeros(L)          # and of the previous torque
    zg = np.zeros((2, L))      # the observer's z
    pvg = np.zeros((4, L))     # the previous measured state
    thg = np.zeros((2, L))     # tau_hat
    dbg = np.zeros(L)
    Pg = np.zeros((max(3, P.shape[1]), L))   # the law's numbers
    sg = np.zeros(L)           # its state
    ug = np.zeros(L)           # its torque
    uog = np.zeros(L)          # and with the observer term
    live = np.zeros(L, dtype=np.bool_)
    rg = np.zeros((9, L))      # the lanes' references and hold (core.kernels.compiled_motion.law_track_lanes)
    every = True   # every scenario tracks motion references: the law runs on lanes with them
    for i in range(n):
        every = every and NP[i] >= 0
    lanes_law = LAW_LANES and (every or not motion)
    for i0 in range(0, n, L):
        width = min(L, n - i0)
        any_live = False
        for lane in range(L):
            i = i0 + min(lane, width - 1)   # past the last scenario: a copy of it, never stored
            live[lane] = lane < width and active[i]
            any_live = any_live or live[lane]
            for j in range(4):
                xs[j, lane] = x[i, j]
                pg[j, lane] = act[i, j]
                ng[j, lane] = nom[i, j]
                cg[j, lane] = X[i, j]
                pvg[j, lane] = prev[i, j]
                xmg[j, lane] = x[i, j]
            zg[0, lane], zg[1, lane] = z[i, 0], z[i, 1]
            for j in range(P.shape[1]):
                Pg[j, lane] = P[i, j]
            sg[lane] = s[i]
            dbg[lane] = D_b[i]
            us[lane] = u_prev[i]
            umg[lane] = u_prev[i]
        if not any_live:
            continue
        pv_lanes = Inertia(load(pg[0], 0), load(pg[1], 0), load(pg[2], 0), load(pg[3], 0))
        pn_lanes = Inertia(load(ng[0], 0), load(ng[1], 0), load(ng[2], 0), load(ng[3], 0))
        c_lanes = (load(cg[0], 0), load(cg[1], 0), load(cg[2], 0), load(cg[3], 0))
        db_lanes = load(dbg, 0)
        for k in range(k0, k1):
            t = k * h
            if shared:
                tau1k = T[k - k0, 0]
                tau2k = T[k - k0, 1]
            else:
                tau1k = tau1
                tau2k = tau2
            # the stages of core.closed_loop.loop.STAGES, in its order
            # stage: sensors
            for lane in range(width):   # the sensors (core.plants.sensing.Sensors.sample)
                if not live[lane]:
                    continue
                i = i0 + lane
                if not (math.isfinite(xs[0, lane]) and math.isfinite(xs[1, lane]) and math.isfinite(xs[2, lane])
                        and math.isfinite(xs[3, lane])):   # diverged at t_k (core.closed_loop.loop.Period.run): no row
                    t_fall[i] = t
                    failure[i] = 3   # core.closed_loop.trajectory.DIVERGED
                    active[i] = False
                    live[lane] = False
                    continue
                # core.closed_loop.loop.PlantSide.sense with raw sensors (core.plants.plant.PlantSim.sample_accel)
                if raw:
                    xt = (xs[0, lane], xs[1, lane], xs[2, lane], xs[3, lane])
                    if k == 0:   # D_w of period 0
                        RS[i, 2] = D_w_of(D_w_mean[i], D_w_sd[i], Nw[i, 0]) if D_w_random[i] else D_w_mean[i]
                    if shared:
                        e1, e2 = tau1k[0], tau2k[0]
                    else:
                        e1 = at(Sin(sins[i, 0], sins[i, 1], sins[i, 2]), t) + 0.0
                        e2 = at(Sin(sins[i, 3], sins[i, 4], sins[i, 5]), t) + 0.0
                    if raw_noisy[i]:
                        zk = Z[i, k - k0]
                        zr = (zk[0], zk[1], zk[2], zk[3])
                    else:
                        zr = (0.0, 0.0, 0.0, 0.0)
                    est, umg[lane], _ = sense_raw(Inertia(act[i, 0], act[i, 1], act[i, 2], act[i, 3]), D_b[i], xt,
                                                  u_prev[i], MC[i], e1, e2, zr, RS[i], RW[i], k, h, delay, qx[i],
                                                  PE[i], ES[i])
                    for j in range(4):
                        xmg[j, lane] = est[j]
                elif noisy[i] or counts > 0 or delay > 0:
                    zk = Z[i, k - k0] if noisy[i] else Z[0, 0]   # (Z holds rows of the noisy scenarios only)
                    ms, umg[lane] = sense_state((xs[0, lane], xs[1, lane], xs[2, lane], xs[3, lane]), zk, noisy[i],
                                                std[i], counts, qx[i], k, delay, u_prev[i])
                    for j in range(4):
                        xmg[j, lane] = ms[j]
                else:
                    for j in range(4):
                        xmg[j, lane] = xs[j, lane]
                    umg[lane] = u_prev[i]
            # stage: estimator (raw: run above, each scenario's right after its sample; else the identity)
            # stage: observer
            # the observer (core.control.observer.DiscreteObserver.update): every lane at once, or one after another
            if SIMD:
                xm_lanes = (load(xmg[0], 0), load(xmg[1], 0), load(xmg[2], 0), load(xmg[3], 0))
                if k == 0:
                    zl = z_start(c_lanes, xm_lanes[2], xm_lanes[3])
                else:
                    zl = z_next_lanes(pn_lanes, c_lanes, (load(pvg[0], 0), load(pvg[1], 0), load(pvg[2], 0),
                                                          load(pvg[3], 0)), load(umg, 0),
                                      (load(zg[0], 0), load(zg[1], 0)), h)
                tl = tau_hat_of(c_lanes, zl, xm_lanes[2], xm_lanes[3])
                store(zg[0], 0, zl[0])
                store(zg[1], 0, zl[1])
                store(thg[0], 0, tl[0])
                store(thg[1], 0, tl[1])
                # the law (its pure_step; tracking: core.kernels.compiled_motion), the observer term (ndo)
                if lanes_law:
                    # with the observer term and the hold (core.closed_loop.loop.command, docs/theory.md 6.14)
                    if motion:
                        ul, uol, sl = law_track_lanes(params_lanes(Pg), pn_lanes, h, xm_lanes, sg, xmg, live, width,
                                                      i0, k, MO, PT, PV, NP, MS, rg, ng, thg, tl, observer_law,
                                                      use_obs)
                        store(ug, 0, ul)
                        store(sg, 0, sl)
                        if observer_law:
                            store(uog, 0, uol)
                    else:
                        ul, sl, _ = law_lanes(params_lanes(Pg), pn_lanes, h, xm_lanes, load(sg, 0), k == 0)
                        store(ug, 0, ul)
                        store(sg, 0, sl)
                        if observer_law:
                            store(uog, 0, ul - u_taud_of(pn_lanes, pn_lanes.m12 * simd.cos(xm_lanes[1]), tl))
            else:
                for lane in range(width):
                    if live[lane]:
                        c = (cg[0, lane], cg[1, lane], cg[2, lane], cg[3, lane])
                        if k == 0:
                            zs = z_start(c, xmg[2, lane], xmg[3, lane])
                        else:
                            zs = z_next(Inertia(ng[0, lane], ng[1, lane], ng[2, lane], ng[3, lane]), c,
                                        (pvg[0, lane], pvg[1, lane], pvg[2, lane], pvg[3, lane]), umg[lane],
                                        (zg[0, lane], zg[1, lane]), h)
                        ts = tau_hat_of(c, zs, xmg[2, lane], xmg[3, lane])
                        zg[0, lane], zg[1, lane] = zs
                        thg[0, lane], thg[1, lane] = ts
            any_live = False
            for lane in range(width):
                if not live[lane]:
                    continue
                i = i0 + lane
                pa = Inertia(act[i, 0], act[i, 1], act[i, 2], act[i, 3])
                pn = Inertia(nom[i, 0], nom[i, 1], nom[i, 2], nom[i, 3])
                xt = (xs[0, lane], xs[1, lane], xs[2, lane], xs[3, lane])
                xm = (xmg[0, lane], xmg[1, lane], xmg[2, lane], xmg[3, lane])
                th = (thg[0, lane], thg[1, lane])
                z[i, 0], z[i, 1] = zg[0, lane], zg[1, lane]
                for j in range(4):
                    prev[i, j] = pvg[j, lane] = xm[j]
                # stage: law
                if lanes_law:   # computed above for every lane
                    u = uog[lane] if observer_law and use_obs[i] else ug[lane]
                    s[i] = sg[lane]
                else:
                    if NP[i] >= 0:   # period k's references and the law tracking them, the observer term with them
                        u, s[i] = law_track(P[i], pn, h, xm, s[i], k, MO[i], PT[i], PV[i], NP[i], MS[i], th,
                                            observer_law and use_obs[i])   # (core.kernels.compiled_motion)
                    else:
                        u, s[i], _ = law_step(P[i], pn, h, xm, s[i], k == 0)
                        if observer_law and use_obs[i]:   # core.laws.ndo.WithObserver.step
                            u = u - u_taud_of(pn, pn.m12 * math.cos(xm[1]), th)
                if NP[i] >= 0:
                    motion_row(MA[i], t, xt, MS[i, 2], MO[i])   # row k of core.closed_loop.metrics.motion_metrics
                if exi[i] >= 0:   # the excitation (core.closed_loop.loop.command)
                    u = u + EXT[exi[i], k]
                # stage: yaw (none: the planar plant; a spatial plant runs through the scalar loop)
                # stage: drive
                u, bad = drive_stage(u, limit[i], qa[i], k, act_delay)
                # stage: plant (row k's true tau_d in the window, the fall check, then RK4)
                # D_w of this period from its own draw z, as core.plants.plant.PlantSim._draw_D_w
                D_w = D_w_of(D_w_mean[i], D_w_sd[i], Nw[i, k - k0]) if D_w_random[i] else D_w_mean[i]
                if not shared:
                    f1 = Sin(sins[i, 0], sins[i, 1], sins[i, 2])
                    f2 = Sin(sins[i, 3], sins[i, 4], sins[i, 5])
                    _stage(tau1k, tau2k, f1, f2, t, dt, substeps)
                if first_w <= k < first_w + n_window:   # the true tau_d (core.plants.plant.PlantSim.lumped_disturbance)
                    ddq = accel(pa, D_w, D_b[i], xt, u, tau1k[0], tau2k[0])
                    td = lumped_disturbance(pn, xt, ddq, u)
                    v = xt[1]
                    if math.isfinite(v):
                        acc[i, 0] += v * v
                        acc[i, 1] += 1.0
                        ext[i, 0] = max(ext[i, 0], v)
                        ext[i, 1] = min(ext[i, 1], v)
                        ext[i, 2] = max(ext[i, 2], abs(v))
                    for j, v in enumerate((u, th[0] - td[0], th[1] - td[1])):
                        if math.isfinite(v):
                            acc[i, 2 * j + 2] += v * v
                            acc[i, 2 * j + 3] += 1.0
                    if raw:   # the estimate's errors (core.closed_loop.metrics.compute: theta_b_hat - theta_b, ...)
                        for j, v in enumerate((xm[1] - xt[1], xm[3] - xt[3])):
                            if math.isfinite(v):
                                acc[i, 2 * j + 8] += v * v
                                acc[i, 2 * j + 9] += 1.0
                if not abs(xt[1]) <= fall[i] or bad:   # a fall (theta_b not a number too), or a refused command
                    t_fall[i] = t
                    failure[i] = 1 if not abs(xt[1]) <= fall[i] else 2   # core.closed_loop.trajectory.FALL, BAD_COMMAND
                    active[i] = False
                    live[lane] = False
                    continue
                if k == n_steps:
                    live[lane] = False
                    continue
                steps[i] += 1
                u_prev[i] = u
                us[lane] = u
                dws[lane] = D_w
                RS[i, 2], RS[i, 3] = D_w, u   # what acted over this period: the next raw sample's instant
                any_live = True
                # the motor (core.plants.plant.PlantSim.step): the drive's torque at every RK4 stage
                if MC[i, 0] > 0.0:
                    xs[0, lane], xs[1, lane], xs[2, lane], xs[3, lane], acted, code = rk4_driven(
                        pa, D_w, D_b[i], tau1k, tau2k, xt, u, h, substeps, (MC[i, 0], MC[i, 1], MC[i, 2], MC[i, 3]))
                    u_prev[i] = acted   # what the observer is told next
                    if code > 0:
                        acc[i, 14] += 1.0
                    if first_w <= k < first_w + n_window and math.isfinite(acted):
                        acc[i, 12] += acted * acted
                        acc[i, 13] += 1.0
                elif not together:
                    xs[0, lane], xs[1, lane], xs[2, lane], xs[3, lane] = rk4_period(pa, D_w, D_b[i], tau1k, tau2k,
                                                                                    xt, u, h, substeps)
            if not any_live:
                break
            if together:   # the lanes' RK4 period at once; a lane that fell or ended keeps its state
                xv = rk4_lanes(pv_lanes, load(dws, 0), db_lanes, tau1k, tau2k,
                               (load(xs[0], 0), load(xs[1], 0), load(xs[2], 0), load(xs[3], 0)), load(us, 0), h,
                               substeps)
                for j in range(4):
                    store(xn[j], 0, xv[j])
                for lane in range(width):
                    if live[lane]:
                        for j in range(4):
                            xs[j, lane] = xn[j, lane]
        for lane in range(width):
            i = i0 + lane
            x[i, 0], x[i, 1], x[i, 2], x[i, 3] = xs[0, lane], xs[1, lane], xs[2, lane], xs[3, lane]


_KERNELS: dict = {}


def kernel_for(law: type, estimator: Optional[type] = None):
    """The compiled batch loop of the law class ``law`` (its ``pure_step``, or its base's for an observer
    variant) and, for raw sensors, of the estimator class ``estimator`` (:mod:`.estimators`: its ``pure_step``),
    or None when either has no pure form (the batch then runs over numpy arrays, or the scalar loop)."""
    core = getattr(law, "base", law)
    fn = pure_form(law)
    if fn is None:
        return None
    est = getattr(estimator, "pure_step", None) if estimator is not None else _no_est
    if est is None:
        return None
    if (fn, est) not in _KERNELS:
        step = _deep(fn)
        at = _deep(model.Sinusoid.at)
        lanes = (_lanes_of(plant.rk4_period, rk4_driven=_lanes_of(plant.rk4_driven, accel=_lanes_of(model.accel),
                                                                  motor_torque=_jit(_held, _lanes_tag())))
                 if SIMD else _jit(_no_lanes, _lanes_tag()))
        z_lanes = _lanes_of(observer.z_next) if SIMD else _jit(_no_z_lanes, _lanes_tag())
        by_lanes = SIMD and getattr(core, "pure_lanes", 0) == 3   # a law whose pure_step runs on lanes
        suffix = f"__{fn.__module__}.{fn.__qualname__}".replace(".", "_")
        if est is not _no_est:
            suffix += f"__{est.__module__}.{est.__qualname__}".replace(".", "_")
        own = getattr(core, "pure_track", None)   # the law tracking a motion reference (core.kernels.compiled_motion)
        law_l = _lanes_of(fn) if by_lanes else _jit(_no_law_lanes, _lanes_tag())
        own_l = (_lanes_of(own) if own is not None else
                 _deep(compiled_motion.tracked_step, suffix + "__lanes", law_step=law_l)) if by_lanes else None
        track_l = (_deep(compiled_motion.law_track_lanes, suffix, load=load, store=store, track_lanes=own_l)
                   if by_lanes else _jit(compiled_motion.no_track_lanes, _lanes_tag()))
        _KERNELS[fn, est] = _deep(_loop, suffix, law_step=step,
                             sense_raw=raw_stage(est, suffix), rk4_driven=_rk4_driven,
                             Inertia=Inertia, Sin=Sin, at=at, _stage=_deep(_stage, at=at), accel=_accel,
                             rk4_period=_rk4_period, rk4_lanes=lanes, load=load, store=store,
                             z_next_lanes=z_lanes, LAW_LANES=by_lanes,
                             law_lanes=law_l, law_track_lanes=track_l,
                             params_lanes=_jit(_params3, _lanes_tag()),
                             law_track=track_for(law),
                             motion_row=_deep(compiled_motion.motion_row))
    return _KERNELS[fn, est]
