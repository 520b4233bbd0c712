"""The batch over numpy arrays (:mod:`.batch`): the scalar loop's observer, law and true tau_d called with the math
namespace ``numpy`` and parameters whose fields are arrays, the plant's RK4 period compiled
(:class:`.compiled.RK4Periods`); the form of a law without a pure step (a plug-in) and of a recorded run.
"""
from __future__ import annotations

import math
from typing import List, Sequence, Tuple

import numpy as np

from .budget import window_samples
from .. import laws
from ..closed_loop.metrics import window_metrics
from ..closed_loop.sim import ClosedLoop
from ..closed_loop.trajectory import BAD_COMMAND, COLUMNS, DIVERGED, FAILURES, FALL, INTERNAL_COLUMNS, Trajectory
from ..control.observer import DiscreteObserver
from ..control.safety import PLAUSIBLE_TORQUE
from ..plants.model import PhysicalParams, Sinusoid, State, accel, lumped_disturbance
from ..plants.plant import stage_torques
from ..plants.sensing import NOISE_BLOCK, Actuator, Sensors, sensor_rng
from .batch_scenarios import BatchResult, _column, _same, _simulate_each, _stack


class _Streams:
    """Standard normal draws, ``width`` per period, for some scenarios, each from its own generator, drawn
    NOISE_BLOCK periods at a time: the sequence the scalar plant draws (D_w: one per period; the sensors:
    four, ``core.plants.sensing.Normals``).  ``next()`` is (scenarios, width)."""

    def __init__(self, gens, width: int):
        self.gens, self.width = gens, width
        self.block = np.empty((NOISE_BLOCK, len(gens), width))   # a period's draws are one contiguous row
        self.used = NOISE_BLOCK

    def next(self) -> np.ndarray:
        if self.used == NOISE_BLOCK:
            for row, gen in enumerate(self.gens):
                self.block[:, row] = gen.standard_normal((NOISE_BLOCK, self.width))
            self.used = 0
        z = self.block[self.used]
        self.used += 1
        return z


class _Noise:
    """D_w per period for every scenario: each scenario's own generator, in the scalar plant's order."""

    def __init__(self, seeds, mean, variance):
        self.mean, self.sd = mean, np.sqrt(variance)
        self.random = np.flatnonzero(variance != 0.0)
        self.all_random = len(self.random) == len(variance)
        self.streams = _Streams([np.random.default_rng(int(seeds[i])) for i in self.random], 1)

    def draw(self) -> np.ndarray:
        if not len(self.random):
            return self.mean.copy()
        z = self.streams.next()[:, 0]
        if self.all_random:
            return np.maximum(0.0, self.mean + self.sd * z)
        d_w = self.mean.copy()
        d_w[self.random] = np.maximum(0.0, self.mean[self.random] + self.sd[self.random] * z)
        return d_w


class _SensorNormals:
    """The sensors' four normal draws per period for every scenario: each noisy scenario's own stream
    (``core.plants.sensing.sensor_rng``); zeros for the others."""

    def __init__(self, seeds, noisy):
        self.idx = np.flatnonzero(noisy)
        self.streams = _Streams([sensor_rng(int(seeds[i])) for i in self.idx], 4)
        self.z = np.zeros((4, len(seeds)))

    def __call__(self):
        self.z[:, self.idx] = self.streams.next().T
        return tuple(self.z)


def _sensing(pcs, n):
    """The batch's sensors and actuator (None when off); the scenarios share the encoder and the delays."""
    scs = [pc.sensing for pc in pcs]
    counts = _same((sc.encoder_counts_per_rev for sc in scs), "the encoder resolution")
    delay = _same((sc.delay_periods for sc in scs), "the measurement delay")
    act_delay = _same((sc.actuator_delay_periods for sc in scs), "the actuator delay")
    sensors = actuator = None
    if any(sc.measuring for sc in scs):
        noisy = np.array([sc.noisy for sc in scs])
        std = tuple(_column(sc.noise_std[i] for sc in scs) for i in range(4))
        normals = _SensorNormals([pc.seed for pc in pcs], noisy) if noisy.any() else None
        sensors = Sensors(delay, counts, std, normals, np)
    if act_delay:
        actuator = Actuator(act_delay, np.zeros(n))
    return sensors, actuator


class _Trig:
    """numpy as the batch's math namespace, remembering sin and cos of the two newest angle arrays.

    Each period the observer takes sin and cos of the previous state's theta_b (eq. 15), and the law (eq. 28)
    and, inside the metrics window, the true tau_d (eq. 1, eq. 6-7) take them of the current one: three to
    four times the same two arrays.  Those are the costly numpy calls (libm per element), so each is computed
    once.  An array is remembered by identity and kept referenced (its id cannot be reused); the batch never
    changes a state array in place, so a remembered value cannot go stale."""

    def __init__(self):
        self._memo = []   # [(array, sin, cos)], newest last

    def __getattr__(self, name):
        return getattr(np, name)

    def _both(self, a):
        for entry in self._memo:
            if entry[0] is a:
                return entry
        entry = (a, np.sin(a), np.cos(a))
        self._memo = self._memo[-1:] + [entry]
        return entry

    def sin(self, a):
        return self._both(a)[1] if isinstance(a, np.ndarray) else np.sin(a)

    def cos(self, a):
        return self._both(a)[2] if isinstance(a, np.ndarray) else np.cos(a)


def _simulate_numpy(loops: Sequence[ClosedLoop], window: Sequence[float], record: bool = False) -> BatchResult:
    from .compiled import RK4Periods   # numba: imported (and the RK4 period compiled or loaded) on first use
    n = len(loops)
    pcs = [lp.plant for lp in loops]
    h = _same((pc.h for pc in pcs), "the control period")
    substeps = int(_same((pc.substeps for pc in pcs), "the RK4 sub-steps"))
    n_steps = int(round(_same((lp.duration_s for lp in loops), "the duration") / h))
    actual, nominal = _stack([pc.actual for pc in pcs], PhysicalParams), _stack([pc.nominal for pc in pcs],
                                                                                  PhysicalParams)
    f1, f2 = _stack([pc.tau_ext1 for pc in pcs], Sinusoid), _stack([pc.tau_ext2 for pc in pcs], Sinusoid)
    arr = lambda values: np.array(list(values), dtype=float)  # noqa: E731
    D_b, limit, fall = (_column(getattr(pc, f) for pc in pcs) for f in ("D_b", "torque_limit", "fall_angle"))
    noise = _Noise([pc.seed for pc in pcs], arr(pc.D_w_mean for pc in pcs), arr(pc.D_w_variance for pc in pcs))
    use_obs = np.array([lp.use_observer for lp in loops], dtype=bool)
    X = tuple(_column(lp.X[i] for lp in loops) for i in range(4))
    trig = _Trig()
    obs = DiscreteObserver(nominal, X, h, m=trig)
    family = _same((lp.law for lp in loops), "the law")
    plain = laws.variant(family, False) if laws.lookup(family, False) else None
    law = laws.variant(family, True) if use_obs.any() or plain is None else plain
    ctrl = law(_stack([lp.params for lp in loops], law.Params), nominal, h, trig)   # the scalar law, over arrays
    # what the plain law records as u_taud (0: the term is off; NaN: a law without one)
    u_taud_off = 0.0 if plain is None or "u_taud" in plain.internal_names else math.nan

    sensors, actuator = _sensing(pcs, n)
    rk4_periods = RK4Periods(actual, D_b, n)
    x = State._make(arr(pc.initial[i] for pc in pcs) for i in range(4))   # a column per variable
    u_prev = np.zeros(n)
    D_w = noise.draw()
    active = np.ones(n, dtype=bool)
    t_fall = np.full(n, np.nan)
    failure = np.zeros(n, dtype=np.int64)
    first_w, n_window = window_samples(n_steps, h, window)   # the steps k with k h in the window (+-1e-9)
    # a row per sample, a column per scenario: each step writes one contiguous row
    win = {c: np.full((n_window, n), np.nan) for c in ("theta_b", "u", "e1", "e2")}
    rows: List[Tuple[np.ndarray, np.ndarray]] = []   # (record only)
    steps = 0
    with np.errstate(all="ignore"):  # a diverging scenario may overflow: it is frozen, the others go on
        for k in range(n_steps + 1):
            t = k * h
            # a state that is not a number: diverged at t_k, no row (core.closed_loop.loop.Period.run)
            gone = active & ~(np.isfinite(x[0]) & np.isfinite(x[1]) & np.isfinite(x[2]) & np.isfinite(x[3]))
            if gone.any():
                t_fall[gone], failure[gone] = t, DIVERGED
                active &= ~gone
                if not active.any():
                    break
            # the stages of core.closed_loop.loop.STAGES, in its order
            # stage: sensors
            x_m, u_m = sensors.sample(x, u_prev) if sensors else (x, u_prev)   # what the loop sees
            # stage: estimator (the identity: the measurement is a state)
            # stage: observer
            tau_hat = obs.update(x_m, u_m)
            # stage: law
            try:
                u_law, internals = ctrl.step(x_m, (np.where(use_obs, tau_hat[0], 0.0),
                                                   np.where(use_obs, tau_hat[1], 0.0)))
            except Exception:   # noqa: BLE001 - over arrays a law's error can read as numpy's: run it as it runs
                return _simulate_each(loops, window, record)   # alone, which gives the same numbers or its own
            # stage: yaw (none: the planar plant; a spatial plant runs through the scalar loop)
            # stage: drive
            # the driver's bad_command (core.closed_loop.loop.PlantSide.act)
            bad = ~(np.abs(u_law) <= PLAUSIBLE_TORQUE)
            u = np.where(limit > 0.0, np.clip(u_law, -limit, limit), u_law)
            if actuator:
                u = actuator.apply(u)   # the torque that acts over [t_k, t_k+1)
            if bad.any():
                bad &= active
                u = np.where(bad, 0.0, u)   # in fault: zero torque acts
            # stage: plant (row k, its true tau_d and the fall check, then RK4)
            in_window = first_w <= k < first_w + n_window
            if record or in_window:   # the true tau_d is only compared inside the window
                ddq = accel(actual, D_w, D_b, x, u, f1.at(t, np) + 0.0, f2.at(t, np) + 0.0, trig)
                tau_d = lumped_disturbance(nominal, x, ddq, u, trig)
            if record:
                own = [internals.get(c, math.nan) for c in INTERNAL_COLUMNS]
                if "u_taud" in internals:
                    own[INTERNAL_COLUMNS.index("u_taud")] = np.where(use_obs, internals["u_taud"], u_taud_off)
                cols = (t, *x, u, *tau_hat, *tau_d, *own)
                rows.append((active.copy(), np.stack([np.broadcast_to(c, (n,)) for c in cols], axis=1)))
            everyone = bool(active.all())   # the usual case: no scenario has fallen, nothing to mask
            if in_window:
                j = k - first_w
                for c, v in (("theta_b", x[1]), ("u", u), ("e1", tau_hat[0] - tau_d[0]),
                             ("e2", tau_hat[1] - tau_d[1])):
                    win[c][j] = v if everyone else np.where(active, v, np.nan)
            fell = active & ~(np.abs(x[1]) <= fall)
            if fell.any() or bad.any():
                failure[bad & active] = BAD_COMMAND
                failure[fell] = FALL   # the state had fallen before the law spoke (core.closed_loop.loop.Period.run)
                fell |= bad & active
                t_fall[fell] = t
                active &= ~fell
                everyone = False
            if k == n_steps or not active.any():
                break
            steps += n if everyone else int(active.sum())
            tau1, tau2 = stage_torques(f1, f2, (0.0, 0.0), t, h, substeps, np)
            x = State(*rk4_periods(D_w, tau1, tau2, x, u, h, substeps, active))   # fallen ones frozen
            u_prev = u if everyone else np.where(active, u, u_prev)
            D_w = noise.draw()
    fallen = ~np.isnan(t_fall)
    m = window_metrics(win["theta_b"].T, win["u"].T, win["e1"].T, win["e2"].T)
    upright = ~fallen & (n_steps * h >= window[1] - 1e-9)
    return BatchResult(fallen, t_fall, upright, m, steps, _trajectories(rows, loops, h, t_fall, failure) if record
                       else None, failure)


def _trajectories(rows, loops, h, t_fall, failure) -> List[Trajectory]:
    """Each scenario's rows up to the one where it failed (or the end), as the scalar loop returns them (a failed
    one's ``record`` has ``t_fall`` and ``failure``, the :data:`~.trajectory.FAILURES` name)."""
    out = []
    for i, lp in enumerate(loops):
        mine = np.array([r[i] for active, r in rows if active[i]])
        cols = {c: mine[:, j] for j, c in enumerate(COLUMNS)}
        run = Trajectory(lp.name, cols, bool(failure[i]), h)
        if failure[i]:
            run.record.update(t_fall=float(t_fall[i]), failure=FAILURES[failure[i]])
        out.append(run)
    return out
