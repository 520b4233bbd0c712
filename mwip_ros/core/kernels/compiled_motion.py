"""The motion references in the compiled batch loop (:func:`.compiled._loop`, docs/theory.md 6.11): the scalar loop's
:class:`.motion.Shaper` and the laws' tracking, from the same functions.

Per period k of a scenario with motion (:func:`law_track`, which the loop calls at its stage ``law``, as
:func:`.loop.command` hands the references to the law): the profile's target at t_k (:func:`.motion.profile_at`,
clipped to ``max_speed``), v*, theta_w'*, theta_w* from the previous period's (:func:`.motion.speed_start` at k = 0
from the measured wheel angle, then :func:`.motion.speed_step`), and the law's period on them: its ``pure_track``
(DSC's outer loop, :func:`.laws.dsc.dsc_track_step`) or, without one, its ``pure_step`` on the error state
(:func:`.motion.error_state`, :func:`tracked_step`), as ``Law.step`` does with :meth:`.laws.Law.tracked`.  These
are the functions the Shaper and the laws call, compiled from their own code (``compiled._deep``), no copy.

The hold (docs/theory.md 6.14) as :meth:`.motion.Shaper.reference` runs it with the measured state: theta_w* moved
to where the robot comes to rest (:func:`.motion.anchor_step`) and, with the observer term, tau_bar
(:func:`.motion.hold_estimate`) and from the first rest the law regulating about its equilibrium
(:func:`.motion.hold_lean`, and the torque and observer term of :func:`.loop.command`), which :func:`law_track`
applies with the observer term (:func:`.controller.u_taud_of`).

The batch has only the time profile (``motion.profile``; no ``cmd_vel``), so the Shaper's command timeout does not
arise.  The yaw reference psi'* is not formed: the batch runs the planar plant only, which has no yaw stage.

Each row k also adds to the sums of :func:`.metrics.motion_metrics` (:func:`motion_row`: the speed error's sum of
squares, the largest lean, the hold's first and last wheel angles), which :func:`motion_sums_metrics` turns into
the same metrics.
"""
from __future__ import annotations

import math

import numpy as np

from typing import NamedTuple

from . import simd
from ..control.controller import u_taud_of
from ..closed_loop.metrics import HOLD_SETTLE_S, MOTION_METRICS
from ..control.motion import (ANCHOR_BLEND_S, HOLD_NEAR, REST_MOVE, Reference, _clip, anchor_step, error_state,
                              hold_estimate, hold_lean, hold_weight, profile_at, speed_start, speed_step)

__all__ = ["law_track", "law_track_lanes", "no_track_lanes", "motion_reference", "tracked_step", "motion_row",
           "motion_arrays", "motion_sums_metrics", "MOTION_METRICS", "Nominal", "MO_COLUMNS", "MS_COLUMNS"]

# the per-scenario numbers (MO) and state (MS) of the references (motion_arrays): their columns in order
MO_COLUMNS = ("max_speed", "max_accel", "position_gain", "lean_gain", "r", "settle", "hold_settle_s", "hold_gain",
              "rest_move", "blend")
MS_COLUMNS = ("theta_w_ref", "dtheta_w_ref", "v_ref", "s2", "offset", "k_stop", "prev_rate", "tau_bar1",
              "tau_bar2", "lean", "torque", "rested", "pending", "weight", "hold_tau1", "hold_tau2")


class Nominal(NamedTuple):
    """The nominal model's eq. (2) terms that :func:`.model.lumped_disturbance` and :func:`.motion.hold_lean` read."""

    m11: float
    m12: float
    m22: float
    G_b: float


# the names law_track calls that core.kernels.compiled.kernel_for binds per law (here: never called)
law_step = None


def tracked_step(P, p, h, x, s, s2, first, ref):   # pragma: no cover - compiled
    """A law's ``pure_track`` when it has none: its ``pure_step`` (``law_step``) on the state in the reference's
    error coordinates (:func:`.motion.error_state`, as :meth:`.laws.Law.tracked`); ``s2`` unused."""
    u, s_next, internals = law_step(P, p, h, error_state(x, ref), s, first)
    return u, s_next, s2, internals


track_step = track_lanes = tracked_step   # the law's pure_track (and on lanes): bound per law by compiled.kernel_for
load = store = None   # core.kernels.simd's: bound by core.kernels.compiled.kernel_for


def motion_reference(MO, PT, PV, n_points, MS, k, h, x, th, observed, p):   # pragma: no cover - compiled
    """Period k's (theta_w*, theta_w'*, v*) as :meth:`.motion.Shaper.reference` with a profile, the measured state
    ``x`` and (``observed``: a law with the observer term) the estimate ``th`` makes them, into ``MS``
    (:data:`MS_COLUMNS`) from the previous period's, with the hold (docs/theory.md 6.14): theta_w* where the
    robot came to rest, and into ``MS[9]``, ``MS[10]`` the equilibrium's lean and torque, ``MS[14]``, ``MS[15]``
    the weighted tau_bar (0 without it), tau_bar in ``MS[7]``, ``MS[8]``, its weight in ``MS[13]``. ``p`` the
    nominal model; ``MO`` (:data:`MO_COLUMNS`), the profile ``PT[:n_points]``, ``PV[:n_points]``
    (:func:`motion_arrays`). Returns (theta_w*, theta_w'*, v*, whether the equilibrium holds)."""
    vt = _clip(profile_at(PT[:n_points], PV[:n_points], k * h), MO[0])
    if k == 0:
        tw, dtw, v = speed_start(vt, x[0], MO[1], h, MO[4])
        MS[5] = 0.0   # the start is a stop
    else:
        v_was = MS[2]
        tw, dtw, v = speed_step(MS[0], MS[1], MS[2], vt, MO[1], h, MO[4])
        if v == 0.0 and v_was != 0.0:
            MS[5] = k   # a stop: v* reached 0
    MS[0], MS[1], MS[2] = tw, dtw, v
    equilibrium = observed and MO[7] > 0.0
    near = abs(x[1] - MS[9]) <= HOLD_NEAR   # MS[9]: the previous period's lean (0 without the equilibrium)
    if equilibrium and near:   # tau_bar (motion.hold_estimate)
        MS[7], MS[8] = hold_estimate(th[0], th[1], MS[7], MS[8], MO[7])
    still = v == 0.0
    held = still and (k - MS[5]) * h < MO[6] - 1e-9   # the anchor (motion.anchor_step)
    tw, MS[4], MS[12], rest = anchor_step(x[0], x[2], MS[6], tw, MS[4], MS[12], held, MS[11] > 0.0, MO[8], MO[9])
    MS[6] = x[2] if still else math.nan
    MS[11] = 1.0 if still and (MS[11] > 0.0 or rest) else 0.0
    MS[13] = hold_weight(MS[13], MS[11] > 0.0 and equilibrium, near, MO[9])
    on = MS[13] > 0.0
    if on:   # the hold's equilibrium, from the first rest (motion.Shaper._held)
        t1, t2 = MS[13] * MS[7], MS[13] * MS[8]
        MS[9], MS[10], MS[14], MS[15] = hold_lean(p, t2), -t1, t1, t2
    else:
        MS[9], MS[10], MS[14], MS[15] = 0.0, 0.0, 0.0, 0.0
    return tw, dtw, v, on


def law_track(P, p, h, x, s, k, MO, PT, PV, n_points, MS, th, observed):   # pragma: no cover - compiled
    """Period k's references (:func:`motion_reference`) and the law's (u, next state) tracking them for the measured
    state ``x`` (its second state in ``MS[3]``), with the observer term of ``th`` when ``observed``
    (:meth:`.laws.ndo.WithObserver.step`); while the references hold, about the hold's equilibrium as
    :func:`.loop.command` does it (docs/theory.md 6.14)."""
    tw, dtw, v, on = motion_reference(MO, PT, PV, n_points, MS, k, h, x, th, observed, p)
    ref = Reference(tw, dtw, v, 0.0, MO[2], MO[3])
    if on:   # the hold's equilibrium
        xs = (x[0], x[1] - MS[9], x[2], x[3])
        u, s_next, s2, _ = track_step(P, p, h, xs, s, MS[3], k == 0, ref)
        if observed:
            u = u - u_taud_of(p, p.m12 * math.cos(xs[1]), (th[0] - MS[14], th[1] - MS[15]))
        u = u + MS[10]
    else:
        u, s_next, s2, _ = track_step(P, p, h, x, s, MS[3], k == 0, ref)
        if observed:
            u = u - u_taud_of(p, p.m12 * math.cos(x[1]), th)
    MS[3] = s2
    return u, s_next


def law_track_lanes(Pl, pl, h, xl, sg, xmg, live, width, i0, k, MO, PT, PV, NP, MS, R, ng, thg, tl,
                    observed, use_obs):   # pragma: no cover
    """:func:`law_track` for the lanes of scenarios ``i0`` .. ``i0 + width - 1`` (every one with motion): the
    references scenario by scenario (:func:`motion_reference`, the measured states ``xmg``, the estimates
    ``thg`` (the scenarios ``use_obs`` of a law with the observer term, ``observed``), the nominal models
    ``ng``), gathered in ``R`` (theta_w*, theta_w'*, lambda, k_x, the law's second state, the hold's lean,
    torque, tau_bar_1 and tau_bar_2: a row each, a column per lane; 0 where the hold is off), then the law's
    tracking for all lanes at once (``track_lanes``: its ``pure_track``, or ``pure_step`` on the error state, on
    :data:`.simd.lanes`) at theta_b - lean. Returns the lanes' (u, u with the observer term of ``tl`` - tau_bar,
    next state), the hold's torque added to both."""
    for lane in range(width):
        if live[lane]:
            i = i0 + lane
            x = (xmg[0, lane], xmg[1, lane], xmg[2, lane], xmg[3, lane])
            p = Nominal(ng[0, lane], ng[1, lane], ng[2, lane], ng[3, lane])
            R[0, lane], R[1, lane], _, on = motion_reference(MO[i], PT[i], PV[i], NP[i], MS[i], k, h, x,
                                                             (thg[0, lane], thg[1, lane]), observed and use_obs[i], p)
            R[2, lane], R[3, lane], R[4, lane] = MO[i, 2], MO[i, 3], MS[i, 3]
            R[5, lane] = MS[i, 9] if on else 0.0
            R[6, lane] = MS[i, 10] if on else 0.0
            R[7, lane] = MS[i, 14] if on else 0.0
            R[8, lane] = MS[i, 15] if on else 0.0
    ref = Reference(load(R[0], 0), load(R[1], 0), 0.0, 0.0, load(R[2], 0), load(R[3], 0))
    xs = (xl[0], xl[1] - load(R[5], 0), xl[2], xl[3])
    u, s_next, s2, _ = track_lanes(Pl, pl, h, xs, load(sg, 0), load(R[4], 0), k == 0, ref)
    store(R[4], 0, s2)
    for lane in range(width):
        if live[lane]:
            MS[i0 + lane, 3] = R[4, lane]
    torque = load(R[6], 0)
    observed = u - u_taud_of(pl, pl.m12 * simd.cos(xs[1]), (tl[0] - load(R[7], 0), tl[1] - load(R[8], 0)))
    return u + torque, observed + torque, s_next


def no_track_lanes(Pl, pl, h, xl, sg, xmg, live, width, i0, k, MO, PT, PV, NP, MS, R, ng, thg, tl,
                   observed, use_obs):   # pragma: no cover
    """:func:`law_track_lanes` of a kernel whose law does not run on lanes: never called."""
    return xl[0], xl[0], xl[0]


def motion_row(MA, t, x, v_ref, MO):   # pragma: no cover - compiled
    """Row k (time ``t``, true state ``x``, reference speed ``v_ref``) into the sums of
    :func:`.metrics.motion_metrics`: ``MA`` = sum of (r theta_w' - v*)^2 and its count (finite samples), the
    largest finite |theta_b|, the hold's start (the row after the last with v* != 0; NaN while v* != 0), the hold's
    first theta_w and t (from ``settle`` s after its start), its rows, its last theta_w and t."""
    e = MO[4] * x[2] - v_ref
    if math.isfinite(e):
        MA[0] += e * e
        MA[1] += 1.0
    if math.isfinite(x[1]):
        MA[2] = max(MA[2], abs(x[1]))
    if not v_ref == 0.0:   # moving: the hold, if any, starts after this row
        MA[3] = math.nan
        MA[6] = 0.0
        return
    if MA[3] != MA[3]:
        MA[3] = t
    if t >= MA[3] + MO[5] - 1e-9:
        if MA[6] == 0.0:
            MA[4], MA[5] = x[0], t
        MA[6] += 1.0
        MA[7], MA[8] = x[0], t


def motion_arrays(loops, settle: float = HOLD_SETTLE_S):
    """The compiled loop's motion arguments of ``loops`` (each one's ``motion``, a :class:`.motion.MotionConfig`, or
    None): (any has motion, MO, PT, PV, NP, MS, MA): per scenario its numbers (:data:`MO_COLUMNS`: max_speed,
    max_accel, position_gain, lean_gain, r, ``settle``, hold_settle_s, the hold filter's gain 1 - exp(-h /
    hold_filter_s) as :class:`.motion.Shaper` computes it, 0: none, :data:`.motion.REST_MOVE` / r, the anchor's
    blend 1 - exp(-h / :data:`.motion.ANCHOR_BLEND_S`)), its profile's
    times and values (NP points; -1: no motion), the references' state (:data:`MS_COLUMNS`) and the metrics' sums
    (:func:`motion_row`)."""
    n = len(loops)
    cfgs = [lp.motion for lp in loops]
    width = max([1] + [len(c.profile) for c in cfgs if c is not None])
    MO, PT, PV = np.zeros((n, len(MO_COLUMNS))), np.zeros((n, width)), np.zeros((n, width))
    NP = np.full(n, -1, dtype=np.int64)
    for i, (lp, c) in enumerate(zip(loops, cfgs)):
        if c is not None:
            gain = (1.0 - math.exp(-lp.plant.h / c.hold_filter_s)) if c.hold_filter_s > 0.0 else 0.0
            MO[i] = (c.max_speed, c.max_accel, c.position_gain, c.lean_gain, c.r, settle, c.hold_settle_s, gain,
                     REST_MOVE / c.r, 1.0 - math.exp(-lp.plant.h / ANCHOR_BLEND_S))
            NP[i] = len(c.profile)
            for j, (tp, vp) in enumerate(c.profile):
                PT[i, j], PV[i, j] = tp, vp
    MA = np.zeros((n, 9))
    MA[:, 2] = -np.inf
    MA[:, 4:6] = MA[:, 7:9] = np.nan
    MS = np.zeros((n, len(MS_COLUMNS)))
    MS[:, 6] = np.nan   # no previous rate
    return bool((NP >= 0).any()), MO, PT, PV, NP, MS, MA


def motion_sums_metrics(MA: np.ndarray, MO: np.ndarray, NP: np.ndarray) -> dict:
    """:func:`.metrics.motion_metrics`' numbers (:data:`MOTION_METRICS`) from :func:`motion_row`'s sums, NaN for a
    scenario without motion (``NP`` < 0)."""
    on = NP >= 0
    with np.errstate(invalid="ignore", divide="ignore"):
        held = MA[:, 6] > 1
        drift = np.where(held, MO[:, 4] * (MA[:, 7] - MA[:, 4]), np.nan)
        span = MA[:, 8] - MA[:, 5]
        out = {"speed_rms": np.where(MA[:, 1] > 0, np.sqrt(MA[:, 0] / np.where(MA[:, 1] > 0, MA[:, 1], 1.0)), np.nan),
               "hold_drift": drift, "hold_rate": np.where(held & (span > 0), drift / np.where(span > 0, span, 1.0),
                                                          np.nan),
               "max_lean": np.where(np.isfinite(MA[:, 2]), MA[:, 2], np.nan)}
    return {k: np.where(on, v, np.nan) for k, v in out.items()}
