"""Many scenarios at once: the closed loop of :mod:`.sim` over numpy arrays, one entry per scenario.

Every equation is the scalar loop's own (``model.accel``, ``plant.rk4_period``,
``DiscreteObserver``, the law's ``step`` (:mod:`.laws`), ``model.lumped_disturbance``), so the batch and the
scalar loop cannot drift apart; a test checks each batch trajectory against :func:`.sim.simulate`.
Two forms of the one loop:

* compiled (the default for a law with a pure form, ``Law.pure_step``: dsc, dscndo, lqr, lqr_ndo): the
  whole period, sensors to RK4, runs as one numba kernel built from those same functions
  (:func:`.compiled.kernel_for`), scenario by scenario; the normal draws are numpy's, made here a
  block at a time and handed in; the metrics come from the window's running sums
  (:func:`window_sums_metrics`, the arithmetic of :func:`.metrics.window_metrics`).
  ``MWIP_BATCH_COMPILED=0`` (or ``compiled=False``) turns it off.  The raw sensors with their estimator, the
  motor and the excitation run there too (the scenarios sharing whether they measure raw and the estimator's
  method); with ``record``, or a law without a pure form, those loops run the scalar loop per scenario
  (:func:`_simulate_each`).
* over numpy arrays (a law without a pure form, a plug-in; ``record=True``): the observer, the law and
  the true tau_d are called with the math namespace ``numpy`` and parameters whose fields are arrays;
  the plant's RK4 period runs as the same ``plant.rk4_period`` compiled by numba (:mod:`.compiled`).
  A law whose step raises over arrays (its own error, or numpy's for a law written for one scenario,
  ``if x[1] > a``) runs scenario by scenario instead (:func:`_simulate_each`): the same numbers, or the
  law's own error as a :class:`~.laws.LawError` naming the scenario.

* Each scenario has its own parameters and its own seeded D_w stream (the scalar plant's
  generator, drawn in the same order).
* A scenario that fails is marked with the time it failed and why (:data:`FAILURES`, as the scalar loop,
  :class:`.loop.Period`): it falls (|theta_b| > its fall angle, or theta_b not a number), the law's command is
  refused (not a finite number, or beyond :data:`.safety.PLAUSIBLE_TORQUE`: the driver's ``bad_command``, zero
  torque acts in that row), or its state diverges (a component not a finite number after a period: no row).
  Its row at that instant is the last it records, and from then on its state is frozen, so a
  fallen or diverging scenario never poisons the others, and is never upright.
* The metrics over the window come from :func:`.metrics.window_metrics`, the function the
  single-run metrics use.

The scenarios of one batch must share the control period, the RK4 sub-steps, the duration and
the law's family (a sweep groups them so); with and without the observer term may mix (the
law's observer variant runs, with tau_hat = 0 for the scenarios without it).
"""
from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, fields, is_dataclass
from typing import Dict, List, Optional, Sequence, Tuple, Type

import numpy as np

from .budget import window_samples
from ..estimators import Estimator
from .. import laws
from ..closed_loop.metrics import compute as metrics_compute
from ..closed_loop.metrics import MOTION_METRICS, motion_metrics, window_metrics
from ..plants.model import PhysicalParams, Sinusoid, State, accel, lumped_disturbance
from ..control.observer import DiscreteObserver
from ..closed_loop.trajectory import BAD_COMMAND, DIVERGED, FAILURES, FALL
from ..plants.plant import stage_torques
from ..control.safety import PLAUSIBLE_TORQUE
from ..plants.sensing import NOISE_BLOCK, Actuator, Sensors, sensor_rng
from ..closed_loop.sim import ClosedLoop
from ..closed_loop.trajectory import COLUMNS, INTERNAL_COLUMNS, Trajectory

__all__ = ["BatchResult", "simulate_batch", "compiled_form", "COMPILED_ENV", "compiled_default", "FAILURES", "FALL",
           "BAD_COMMAND", "DIVERGED"]

COMPILED_ENV = "MWIP_BATCH_COMPILED"   # "0": the numpy loop even for a law with a compiled form


BLOCKS = 1   # noise blocks (core.plants.sensing.NOISE_BLOCK periods) drawn and run per call of the compiled loop


def compiled_default() -> bool:
    """Whether :func:`simulate_batch` runs the compiled loop by default (``$MWIP_BATCH_COMPILED``, default on)."""
    return os.environ.get(COMPILED_ENV, "1").strip() not in ("0", "false", "no", "off", "")


@functools.lru_cache(maxsize=None)
def numba_missing() -> Optional[str]:
    """None when numba (optional, :mod:`mwip_ros.optional`) is installed, else the line naming it: without it
    :func:`simulate_batch` runs the scalar loop scenario by scenario (:func:`_simulate_each`), slower, the same
    numbers."""
    from mwip_ros.optional import missing
    return missing("numba")



@dataclass
class BatchResult:
    """Per scenario: fell or not, when, and the metrics over the window (arrays of length N)."""

    fallen: np.ndarray          # bool
    t_fall: np.ndarray          # [s], NaN when upright
    upright: np.ndarray         # bool: never fell and ran past the window
    metrics: Dict[str, np.ndarray]
    steps: int                  # scenario-steps integrated (fallen scenarios stop counting)
    trajectories: Optional[List[Trajectory]] = None
    failure: Optional[np.ndarray] = None   # int: why each failed, an index of FAILURES (0: it did not)

    def __post_init__(self):
        if self.failure is None:
            self.failure = np.where(self.fallen, FALL, 0).astype(np.int64)


def _column(values):
    """The scenarios' values of one quantity: one float when they all share it, else an array.

    A shared value stays a scalar, so whatever depends only on shared values (tau_ext with one
    amplitude and frequency, the nominal model's inertia terms) is computed once per step, not
    once per scenario; elementwise it is the same arithmetic, so the results do not change."""
    a = np.asarray(list(values), dtype=float)
    return float(a[0]) if len(a) and (a == a[0]).all() else a


def _stack(items, cls):
    """One ``cls`` (a dataclass or a NamedTuple) whose field f holds the scenarios' values of f (:func:`_column`)."""
    names = [f.name for f in fields(cls)] if is_dataclass(cls) else list(cls._fields)
    return cls(**{f: _column(getattr(i, f) for i in items) for f in names})


def _same(values, what: str):
    values = set(values)
    if len(values) != 1:
        raise ValueError(f"the scenarios of one batch must share {what}; got {sorted(values)}")
    return values.pop()


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


def simulate_batch(loops: Sequence[ClosedLoop], window: Sequence[float], record: bool = False,
                   compiled: Optional[bool] = None) -> BatchResult:
    """Run every scenario of ``loops`` for its ``duration_s``; ``record`` keeps each one's trajectory.

    ``compiled`` (default :func:`compiled_default`): without ``record``, a law with a pure form
    (``Law.pure_step``) runs as one compiled loop (:func:`_simulate_compiled`); else, and for every other law,
    the loop runs over numpy arrays with the plant's RK4 compiled.  Without numba (:func:`numba_missing`), the
    scalar loop scenario by scenario.  The raw sensors and their estimator, the motor
    and the excitation (:func:`_beyond_arrays`) run compiled too when the scenarios share whether they have raw
    sensors and the estimator's method (:func:`_raw_stage`); else, with ``record`` or a law without a pure form,
    the scalar loop scenario by scenario (:func:`_simulate_each`).  The array and compiled forms have no driver
    state machine (docs/theory.md 6.8): they always run enabled, so scenarios with ``require_enable: true`` (a
    driver nobody enables: its bridge open, no torque) run the scalar loop, which has it; so do scenarios with
    another plant backend (``mujoco``: a simulation that diverges is the scenario's ``diverged`` failure).  Motion
    references (``motion``, theory 6.11) run compiled (:mod:`.compiled_motion`), else the scalar loop."""
    if _scalar_only(loops):   # both array forms need numba, a driver and eq. (1)
        return _simulate_each(loops, window, record)
    beyond = any(_beyond_arrays(lp) for lp in loops)
    form = compiled_form(loops, record, compiled)
    if form is not None:
        kernel, law, stage = form
        return _simulate_compiled(loops, window, law, kernel, *stage)   # raw, the estimator
    if beyond:
        return _simulate_each(loops, window, record)
    return _simulate_numpy(loops, window, record)


def _scalar_only(loops: Sequence[ClosedLoop]) -> bool:
    """Whether only the scalar loop runs ``loops``: no numba, a driver nobody enables, another plant backend."""
    return bool(numba_missing()) or any(lp.plant.require_enable or lp.plant.backend != "rk4" for lp in loops)


def compiled_form(loops: Sequence[ClosedLoop], record: bool = False, compiled: Optional[bool] = None):
    """(the compiled loop, the law class, (raw, the estimator class)) that :func:`simulate_batch` runs ``loops``
    with, or None when it runs another form (see there).  Getting it compiles nothing: numba compiles (or loads
    from its cache) at the first call."""
    if compiled is None:
        compiled = compiled_default()
    if not compiled or record or _scalar_only(loops):
        return None
    from .compiled import kernel_for
    family = _same((lp.law for lp in loops), "the law")
    use_obs = [lp.use_observer for lp in loops]
    law = laws.lookup(family, any(use_obs)) or laws.lookup(family, not any(use_obs))
    stage = _raw_stage(loops) if any(_beyond_arrays(lp) for lp in loops) else (False, None)
    if law is None or (any(use_obs) and not law.observer) or stage is None:
        return None
    kernel = kernel_for(law, stage[1])
    return None if kernel is None else (kernel, law, stage)


def _raw_stage(loops: Sequence[ClosedLoop]):
    """(raw sensors or not, the estimator class or None) when the scenarios share both (the compiled loop is
    specialised per estimator); None when they do not, or the estimator has no pure step."""
    from .. import estimators
    raws = {lp.plant.raw is not None for lp in loops}
    if len(raws) != 1:
        return None
    if not raws.pop():
        return False, None
    methods = {lp.estimator.method if lp.estimator is not None else None for lp in loops}
    method = methods.pop() if len(methods) == 1 else None
    if method is None:
        return None
    cls = estimators.get(method)
    return (True, cls) if getattr(cls, "pure_step", None) is not None else None


def _beyond_arrays(loop: ClosedLoop) -> bool:
    """Stages the numpy form does not run: the raw sensors and their estimator, the motor, the excitation, motion."""
    pc = loop.plant
    return pc.raw is not None or pc.motor.enabled or loop.excitation is not None or loop.motion is not None


def _simulate_each(loops: Sequence[ClosedLoop], window: Sequence[float], record: bool = False) -> BatchResult:
    """The scalar loop (:func:`.sim.simulate`) scenario by scenario, its metrics as the batch gives them: the
    form for the stages the array forms do not run (:func:`_beyond_arrays`), the same numbers by construction."""
    from ..closed_loop.sim import simulate
    runs = []
    for i, lp in enumerate(loops):
        try:
            runs.append(simulate(lp, diverged_fails=True))   # a diverged scenario is a failure, not an error
        except laws.LawError as exc:   # the law's own error, with the scenario (its index in ``loops``)
            raise exc.in_scenario(i) from exc
    named = [metrics_compute(r.columns, window, lp.plant.fall_angle, r.record.get("t_fall"))
             for r, lp in zip(runs, loops)]
    fallen = np.array([r.fallen for r in runs], dtype=bool)
    t_fall = np.array([m.t_fall if m.t_fall is not None else np.nan for m in named])
    n_steps = [int(round(lp.duration_s / lp.plant.h)) for lp in loops]
    upright = ~fallen & np.array([n * lp.plant.h >= window[1] - 1e-9 for n, lp in zip(n_steps, loops)])
    keys = ("theta_b_p2p", "theta_b_rms", "theta_b_max_abs", "u_rms", "tau_err1_rms", "tau_err2_rms",
            "theta_b_est_err_rms", "dtheta_b_est_err_rms", "u_applied_rms", "saturated_s")
    out = {k: np.array([getattr(m, k) for m in named], dtype=float) for k in keys}
    out = {k: v for k, v in out.items() if k in keys[:6] or np.isfinite(v).any()}
    # core.closed_loop.metrics.motion_metrics (NaN: a scenario without motion)
    if any(lp.motion is not None for lp in loops):
        mm = [motion_metrics(r.columns, lp.motion.r, lp.plant.fall_angle) if lp.motion else {}
              for r, lp in zip(runs, loops)]
        out.update({k: np.array([m.get(k, np.nan) for m in mm], dtype=float) for k in MOTION_METRICS})
    steps = sum(len(r) - 1 for r in runs)
    failure = np.array([FAILURES.index(r.record.get("failure", "fall")) if r.fallen else 0 for r in runs],
                       dtype=np.int64)
    return BatchResult(fallen, t_fall, upright, out, steps, runs if record else None, failure)


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


def _simulate_compiled(loops: Sequence[ClosedLoop], window: Sequence[float], law: Type[laws.Law], kernel,
                       raw: bool = False, estimator: Optional[Type[Estimator]] = None) -> BatchResult:
    """The whole loop compiled (``core.kernels.compiled._loop``), NOISE_BLOCK periods per call, the normal draws made
    here by each scenario's own generators in the scalar loop's order and handed in as blocks.  ``raw``: the
    plants measure raw (every one), ``estimator`` the class of their state estimator; the motor and the
    excitation are per scenario."""
    from .compiled import Inertia, load_cached
    from .compiled_motion import motion_arrays, motion_sums_metrics
    from ..identification.excitation import Excitation
    from .kernel_args import LoopArgs
    from ..plants.raw_sensors import raw_rng
    n = len(loops)
    pcs = [lp.plant for lp in loops]
    h = float(_same((pc.h for pc in pcs), "the control period"))
    substeps = int(_same((pc.substeps for pc in pcs), "the RK4 sub-steps"))
    n_steps = int(round(_same((lp.duration_s for lp in loops), "the duration") / h))
    scs = [pc.sensing for pc in pcs]
    counts = int(_same((sc.encoder_counts_per_rev for sc in scs), "the encoder resolution"))
    delay = int(_same((sc.delay_periods for sc in scs), "the measurement delay"))
    act_delay = int(_same((sc.actuator_delay_periods for sc in scs), "the actuator delay"))
    core: Type[laws.Law] = getattr(law, "base", law)
    raws = [pc.raw for pc in pcs if pc.raw is not None]   # every plant's with ``raw``
    arr = lambda rows: np.ascontiguousarray(np.array(rows, dtype=float).reshape(n, -1))  # noqa: E731
    terms = {}   # PhysicalParams -> its eq. (2) terms (the property's own function: no cached_property lock)

    def inertia(p):
        if p not in terms:
            terms[p] = [getattr(type(p), f).func(p) for f in Inertia._fields]
        return terms[p]
    act = arr([inertia(pc.actual) for pc in pcs])
    nom = arr([inertia(pc.nominal) for pc in pcs])
    D_b = arr([pc.D_b for pc in pcs])[:, 0].copy()
    sins = arr([[f.amplitude, f.omega, f.phase, g.amplitude, g.omega, g.phase]
                for f, g in ((pc.tau_ext1, pc.tau_ext2) for pc in pcs)])
    shared = bool(n) and bool((sins == sins[0]).all())
    T = np.zeros((NOISE_BLOCK * BLOCKS if shared else 1, 2, 2 * substeps + 1))
    limit = arr([pc.torque_limit for pc in pcs])[:, 0].copy()
    fall = arr([pc.fall_angle for pc in pcs])[:, 0].copy()
    X = arr([[float(v) for v in np.asarray(lp.X, dtype=float).ravel()] for lp in loops])
    P = arr([[float(v) for v in core.pure_params(lp.params)] for lp in loops]) if n else np.zeros((0, 0))
    use_obs = np.array([lp.use_observer for lp in loops], dtype=bool)
    noisy = np.array([sc.noisy and not raw for sc in scs], dtype=bool)   # raw: no state-mode sensors
    std = arr([list(sc.noise_std) for sc in scs])
    mean = np.array([pc.D_w_mean for pc in pcs], dtype=float)
    var = np.array([pc.D_w_variance for pc in pcs], dtype=float)
    random = np.flatnonzero(var != 0.0)
    dw_gens = [np.random.default_rng(int(pcs[i].seed)) for i in random]
    raw_noisy = np.array([rc.noisy for rc in raws] if raw else [False] * n, dtype=bool)
    # the four normals of a period: the state-mode sensors' (core.plants.sensing.Normals) or the raw sensors' (raw_rng)
    z_idx = np.flatnonzero(raw_noisy if raw else noisy)
    z_gens = [(raw_rng if raw else sensor_rng)(int(pcs[i].seed)) for i in z_idx]
    block = NOISE_BLOCK * BLOCKS   # periods per call: a generator's one draw of several blocks is the same sequence
    # the normal draws, a row per scenario (the compiled loop runs one scenario after another), filled in place
    Nw = np.zeros((n, block)) if len(random) else np.zeros((1, 1))
    Z = np.zeros((n, block, 4)) if len(z_idx) else np.zeros((1, 1, 4))
    rnd = var != 0.0
    sd = np.sqrt(var)
    x = arr([[float(v) for v in pc.initial] for pc in pcs])
    u_prev = np.zeros(n)
    z = np.zeros((n, 2))
    prev = np.zeros((n, 4))
    s = np.zeros(n)
    qx = np.zeros((n, delay + 1, 6))
    qa = np.zeros((n, act_delay + 1))
    active = np.ones(n, dtype=bool)
    t_fall = np.full(n, np.nan)
    failure = np.zeros(n, dtype=np.int64)
    steps = np.zeros(n, dtype=np.int64)
    acc = np.zeros((n, 15))   # sum of squares and count of theta_b, u, e1, e2, the estimate's errors, u applied
    # (finite samples); the periods saturated
    ext = np.empty((n, 3))   # max, min, max |.| of theta_b
    ext[:, 0], ext[:, 1], ext[:, 2] = -np.inf, np.inf, -np.inf
    tau1, tau2 = np.zeros(2 * substeps + 1), np.zeros(2 * substeps + 1)
    first_w, n_window = window_samples(n_steps, h, window)
    motion, MO, PT, PV, NP, MS, MA = motion_arrays(loops)   # the references (docs/theory.md 6.11), their metrics
    # the raw sensors (r, d, g, gyro_noise_std, gyro_bias_walk, accel_noise_std, counts) and their state (bias,
    # phi, D_w and the command of the previous period); the estimator's numbers and state
    RW = arr([[pc.actual.r, rc.offset, pc.actual.g, rc.gyro_noise_std, rc.gyro_bias_walk, rc.accel_noise_std,
               rc.encoder_counts_per_rev] for pc, rc in zip(pcs, raws)]) if raw else np.zeros((1, 7))
    RS = np.zeros((n, 4))
    if raw:
        RS[:, 0] = [rc.gyro_bias for rc in raws]
        made = {}

        def numbers(lp):
            key = (lp.estimator, lp.plant.nominal.r, lp.plant.nominal.g)
            if key not in made:
                made[key] = [float(v) for v in lp.estimator.make(h, key[1], key[2]).P]
            return made[key]
        PE = arr([numbers(lp) for lp in loops])
        assert estimator is not None   # raw: _raw_stage gave the scenarios' estimator class
        ES = np.zeros((n, estimator.state_size))
    else:
        PE, ES = np.zeros((1, 1)), np.zeros((1, 1))
    MC = arr([pc.motor_constants for pc in pcs])
    motor = MC[:, 0] > 0.0
    # the excitations: a row per distinct one, every period of the run
    # (core.identification.excitation.Excitation.series)
    series: Dict = {}
    exi = np.array([-1 if lp.excitation is None else series.setdefault(lp.excitation, len(series)) for lp in loops],
                   dtype=np.int64)
    EXT = np.zeros((max(1, len(series)), n_steps + 1))
    for cfg, row in series.items():
        EXT[row] = Excitation(cfg, h).series(n_steps + 1)
    with np.errstate(all="ignore"):
        for k0 in range(0, n_steps + 1, block):
            if not active.any():
                break
            k1 = min(k0 + block, n_steps + 1)   # the last block draws only what it runs: the same sequence
            for row, gen in enumerate(dw_gens):   # core.plants.plant.PlantSim._draw_D_w, a block at a time
                gen.standard_normal(out=Nw[random[row], :k1 - k0])
            for row, gen in enumerate(z_gens):    # core.plants.sensing.Normals
                gen.standard_normal(out=Z[z_idx[row], :k1 - k0])
            args = LoopArgs(   # the compiled loop's arguments by name (core.kernels.kernel_args), passed positionally
                k0=k0, k1=k1, n_steps=n_steps, h=h, substeps=substeps, first_w=first_w, n_window=n_window,
                counts=counts, delay=delay, act_delay=act_delay, observer_law=bool(law.observer),
                act=act, nom=nom, D_b=D_b, sins=sins, shared=shared, limit=limit, fall=fall, X=X, P=P, use_obs=use_obs,
                noisy=noisy, std=std, D_w_mean=mean, D_w_sd=sd, D_w_random=rnd, Nw=Nw, Z=Z,
                x=x, u_prev=u_prev, z=z, prev=prev, s=s, qx=qx, qa=qa, active=active,
                t_fall=t_fall, steps=steps, acc=acc, ext=ext, T=T, tau1=tau1, tau2=tau2,
                raw=raw, RW=RW, RS=RS, raw_noisy=raw_noisy, PE=PE, ES=ES,
                motor_any=bool(motor.any()), MC=MC, EXT=EXT, exi=exi, failure=failure,
                motion=motion, MO=MO, PT=PT, PV=PV, NP=NP, MS=MS, MA=MA)
            if k0 == 0:
                load_cached(kernel, tuple(args))
            kernel(*args)
        m = window_sums_metrics(acc, ext)
        if raw:
            m.update(_stage_metrics(acc, steps, h, motor, raw=True, motor_on=False))
        if motor.any():
            m.update(_stage_metrics(acc, steps, h, motor, raw=False, motor_on=True))
        if motion:
            m.update(motion_sums_metrics(MA, MO, NP))
    fallen = ~np.isnan(t_fall)
    upright = ~fallen & (n_steps * h >= window[1] - 1e-9)
    return BatchResult(fallen, t_fall, upright, m, int(steps.sum()), None, failure)


def window_sums_metrics(acc: np.ndarray, ext: np.ndarray) -> dict:
    """:func:`.metrics.window_metrics` from running sums: ``acc`` (N, 8) the sum of squares and the count of the
    finite samples of theta_b, u, e1, e2; ``ext`` (N, 3) the max, min and max |.| of the finite theta_b."""
    def rms(j):
        return np.where(acc[:, j + 1] > 0, np.sqrt(acc[:, j] / np.where(acc[:, j + 1] > 0, acc[:, j + 1], 1.0)),
                        np.nan)
    any_ = acc[:, 1] > 0
    return {"theta_b_p2p": np.where(any_, ext[:, 0] - ext[:, 1], np.nan), "theta_b_rms": rms(0),
            "theta_b_max_abs": np.where(any_, ext[:, 2], np.nan), "u_rms": rms(2), "tau_err1_rms": rms(4),
            "tau_err2_rms": rms(6)}


def _stage_metrics(acc: np.ndarray, steps: np.ndarray, h: float, motor: np.ndarray, raw: bool, motor_on: bool) -> dict:
    """The optional stages' metrics of :func:`.metrics.compute` from the compiled loop's sums (``acc`` columns 8 to
    14): the estimate's errors (raw sensors), the torque that acted and the time saturated (the scenarios with the
    motor; NaN for the others)."""
    def rms(j):
        ok = acc[:, j + 1] > 0
        return np.where(ok, np.sqrt(acc[:, j] / np.where(ok, acc[:, j + 1], 1.0)), np.nan)
    out = {}
    if raw:
        out["theta_b_est_err_rms"], out["dtheta_b_est_err_rms"] = rms(8), rms(10)
    if motor_on:
        out["u_applied_rms"] = np.where(motor, rms(12), np.nan)
        # whole run: the periods integrated with the drive saturated, times h (NaN for a run of one row)
        out["saturated_s"] = np.where(motor & (steps > 0), acc[:, 14] * h, np.nan)
    return out


def _trajectories(rows, loops, h, t_fall, failure) -> List[Trajectory]:
    """Each scenario's rows up to the one where it failed (or the end), as the scalar loop returns them (a failed
    one's ``record`` has ``t_fall`` and ``failure``, the :data:`FAILURES` name)."""
    out = []
    for i, lp in enumerate(loops):
        mine = np.array([r[i] for active, r in rows if active[i]])
        cols = {c: mine[:, j] for j, c in enumerate(COLUMNS)}
        run = Trajectory(lp.name, cols, bool(failure[i]), h)
        if failure[i]:
            run.record.update(t_fall=float(t_fall[i]), failure=FAILURES[failure[i]])
        out.append(run)
    return out
