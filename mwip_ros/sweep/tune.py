"""Gain tuning: a bounded, seeded global search (scipy's differential evolution) over a sweep's scenarios.

Each candidate is judged on every scenario of the spec at once, through the batch simulator
(and the sweep's runners: this process, worker processes or Dask), by

    J = mean over scenarios of [ theta_b RMS + weight * u RMS ]   (over the metrics window)

where a scenario that falls costs :data:`FALL_PENALTY` instead.  For DSC and DSCNDO,
Theorem 2 (gamma > 0; for plain DSC its controller half a1..a3) is a hard constraint: a
candidate that breaks it is not simulated and costs more than any admissible one.  The
search runs in log space (every tunable is positive and may span decades).  The result is
judged again, beside the base file's gains, on a held-out set: the same spec with another
seed, never seen during the search.
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from mwip_ros import params as P
from mwip_ros.core.kernels import budget
from mwip_ros.core import laws

from . import engine
from .scenarios import expand
from .spec import SpecError, SweepSpec

__all__ = ["Knob", "KNOBS", "check_memory", "knobs_for", "parse_bounds", "Objective", "FALL_PENALTY", "INADMISSIBLE",
           "Tuner", "overlay"]

FALL_PENALTY = 1.0       # per fallen scenario, in the objective's unit (rad): far above any upright RMS
INADMISSIBLE = 10.0      # a candidate that breaks Theorem 2 (plus how far it breaks it): worse than any fall


@dataclass(frozen=True)
class Knob:
    """One tuned number: its name on the command line, where it lives, its default search bounds."""

    name: str
    section: str            # the parameter file section ('dscndo_controller', 'disturbance_observer')
    param: str              # the parameter ('k1', 'X', 'lqr.Q', ...)
    index: Optional[int]    # the entry of an array parameter, else None
    bounds: Tuple[float, float]


KNOBS: Dict[str, List[Knob]] = {
    "k1": [Knob("k1", "dscndo_controller", "k1", None, (0.5, 30.0))],
    "k2": [Knob("k2", "dscndo_controller", "k2", None, (0.5, 30.0))],
    "tau4": [Knob("tau4", "dscndo_controller", "tau4", None, (0.005, 1.0))],
    "X": [Knob("X.c1", "disturbance_observer", "X", 0, (5.0, 2000.0)),      # the diagonal of X (eq. 14);
          Knob("X.c4", "disturbance_observer", "X", 3, (5.0, 2000.0))],     # c2, c3 stay as in the base file
    "lqr.R": [Knob("lqr.R", "dscndo_controller", "lqr.R", None, (1e-4, 1.0))],
    "lqr.Q": [Knob(f"lqr.Q.{s}", "dscndo_controller", "lqr.Q", i, (0.1, 1e4))
              for i, s in enumerate(("theta_b", "dtheta_b", "dtheta_w"))],
    "smc.k": [Knob("smc.k", "dscndo_controller", "smc.k", None, (1.0, 500.0))],
    "smc.boundary_layer": [Knob("smc.boundary_layer", "dscndo_controller", "smc.boundary_layer", None, (0.01, 20.0))],
    # the state estimator (sensors.model: raw), as any other knob
    "complementary.tau": [Knob("complementary.tau", "state_estimator", "complementary.tau", None, (0.05, 10.0))],
    "kalman.bias_walk": [Knob("kalman.bias_walk", "state_estimator", "kalman.bias_walk", None, (1e-5, 0.01))],
    "kalman.accel_noise_std": [Knob("kalman.accel_noise_std", "state_estimator", "kalman.accel_noise_std", None,
                                    (1e-3, 1.0))],
}


def check_memory(spec: SweepSpec, knobs: List[Knob], popsize: int) -> None:
    """Refuse a search whose tables would not fit the memory budget (core.kernels.budget): every generation judges
    ``popsize * len(knobs)`` candidates on every scenario of the spec (and of the held-out set) at once.
    Raises SpecError naming the spec's ``samples`` (or ``vary``) and ``--popsize``."""
    try:
        cap = budget.memory_budget()
    except ValueError as exc:
        raise SpecError(budget.BUDGET_ENV, str(exc)) from None
    n, candidates = spec.n_scenarios, popsize * len(knobs)
    need = budget.tune_table_bytes(n, len(spec.axes), candidates, len(knobs))
    if need > cap:
        key = "samples" if spec.random_axes and spec.samples > 1 else "vary"
        raise SpecError(key, f"{n:,} scenarios x {candidates} candidates per generation (--popsize {popsize} x "
                             f"{len(knobs)} tuned numbers) need about {budget.fmt_bytes(need)}; the memory budget is "
                             f"{budget.fmt_bytes(cap)} (about {int(n * cap // need):,} scenarios fit; "
                             f"{budget.BUDGET_ENV} sets it)", spec.path)


def _law(law: str) -> type:
    """A registered law by name ('dscndo'), or a family's plain law ('dsc', 'lqr')."""
    return laws.get(law) if law in laws.names() else laws.variant(law, False)


def knobs_for(names: Sequence[str], law: str) -> List[Knob]:
    """The knobs called ``names`` for ``law`` (a registered law or a family); a controller knob must be one of
    the law's parameters (core.laws.Law.param_keys), the observer's X is always tunable."""
    cls = _law(law)
    out: List[Knob] = []
    for name in names:
        if name not in KNOBS:
            close = difflib.get_close_matches(name, list(KNOBS), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise SpecError("--tune", f"cannot tune {name!r}{hint}; tunable: {', '.join(KNOBS)}")
        foreign = [k for k in KNOBS[name] if k.section == "dscndo_controller" and k.param not in cls.param_keys]
        if foreign:
            owner = next((laws.get(n) for n in laws.names() if foreign[0].param in laws.get(n).param_keys), None)
            whose = f"{name} is a {owner.title} gain: it belongs to the {owner.family} laws; " if owner else ""
            raise SpecError("--tune", f"{whose}the {cls.family} laws take "
                                      f"{', '.join(cls.param_keys) or 'no controller parameter'}")
        out += [k for k in KNOBS[name] if k not in out]
    return out


def parse_bounds(knobs: List[Knob], given: Sequence[str]) -> List[Tuple[float, float]]:
    """Each knob's bounds: its default, or ``name=lo:hi`` from ``--bounds``; checked against the parameter's
    range (every tunable is > 0).  Raises SpecError naming the knob."""
    bounds = {k.name: k.bounds for k in knobs}
    for item in given:
        name, sep, rng = item.partition("=")
        lo_s, sep2, hi_s = rng.partition(":")
        if not sep or not sep2:
            raise SpecError("--bounds", f"expected name=low:high (e.g. k1=1:20), got {item!r}")
        if name not in bounds:
            raise SpecError("--bounds", f"{name!r} is not tuned here; tuned: {', '.join(bounds)}")
        try:
            lo, hi = float(lo_s), float(hi_s)
        except ValueError:
            raise SpecError("--bounds", f"{item!r}: low and high must be numbers") from None
        bounds[name] = (lo, hi)
    for name, (lo, hi) in bounds.items():
        if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
            raise SpecError("--bounds", f"{name}: the range [{lo:g}, {hi:g}] is empty (need low < high)")
        if not lo > 0:
            raise SpecError("--bounds", f"{name}: must stay > 0 (the parameter's valid range), got low = {lo:g}")
    for k in knobs:
        for end, value in zip(("low", "high"), bounds[k.name]):
            reason = _outside_range(k, value)
            if reason:
                raise SpecError("--bounds", f"{k.name}: {end} = {value:g} is outside the parameter's range: "
                                            f"{k.param} {reason}")
    return [bounds[k.name] for k in knobs]


def _outside_range(knob: Knob, value: float) -> Optional[str]:
    """Why the schema refuses ``value`` for the knob's parameter (an array's entry in its default), or None."""
    spec = P.specs_for(knob.section)[knob.param]
    trial: object = float(value)
    if knob.index is not None:
        trial = [float(x) for x in spec.default]
        trial[knob.index] = float(value)
    try:
        spec.validate(trial)
    except P.ParamError as exc:
        return exc.reason.split(", got ", 1)[0]   # the value is in the caller's text
    return None


def apply(knobs: List[Knob], x: Sequence[float], base: Dict) -> Dict:
    """The merged-values changes that set the knobs to ``x``."""
    out: Dict = {}
    for k, v in zip(knobs, x):
        if k.index is None:
            out[k.param] = float(v)
        else:
            arr = list(out.get(k.param, base[k.param]))
            if k.param == "lqr.Q" and len(arr) == 9:   # a full matrix: tune its diagonal
                arr[4 * k.index] = float(v)
            else:
                arr[k.index] = float(v)
            out[k.param] = arr
    return out


def overlay(knobs: List[Knob], x: Sequence[float], base: Dict) -> Dict[Tuple[str, str], object]:
    """{(section, parameter): value} of a tuned result, for a parameter-file overlay."""
    changed = apply(knobs, x, base)
    where = {k.param: k.section for k in knobs}
    return {(where[p], p): v for p, v in changed.items()}


@dataclass
class Objective:
    """J(candidates) on a spec's scenarios for one law; vectorized over candidates."""

    spec: SweepSpec
    law_name: str
    knobs: List[Knob]
    weight: float
    runner: Callable = engine.run_local   # (chunks) -> iterator of (chunk, result)
    chunk_size: int = engine.DEFAULT_CHUNK
    evaluations: int = 0
    steps: int = 0
    best: Tuple[float, Optional[np.ndarray]] = (math.inf, None)
    scenarios: object = field(default=None)

    def __post_init__(self):
        self.scenarios = expand(self.spec)
        cls = laws.get(self.law_name)
        self.law, self.use_observer = cls.family, cls.observer

    def admissibility(self, x) -> float:
        """< 0 when a candidate breaks the law's stability condition (by that much: for DSC and DSCNDO
        Theorem 2, core.laws.Law.stability_margin), else 0; -INADMISSIBLE when the margin is NaN."""
        cls = laws.get(self.law_name)
        v = dict(self.spec.base_values, **apply(self.knobs, x, self.spec.base_values))
        nominal, h = P.physical(v, "nominal"), P.period(v)
        try:
            params = cls.design(v, nominal, h)
        except ValueError:
            return 0.0   # no law for these values: the simulation says so, as for any candidate
        margin = cls.stability_margin(nominal, params, P.observer_gain(v), observer=cls.observer)
        if math.isnan(margin):   # no verdict from NaN: a condition that cannot be evaluated is not satisfied
            return -INADMISSIBLE
        return min(0.0, margin)

    def _simulate(self, xs) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(upright, theta_b RMS, u RMS), each (candidates, scenarios), of every candidate on every scenario."""
        n = len(self.scenarios)
        overrides = [dict(self.scenarios.overrides(i), **apply(self.knobs, x, self.spec.base_values))
                     for x in xs for i in range(n)]
        up, th, u = np.zeros(len(overrides), dtype=bool), np.full(len(overrides), np.nan), np.full(len(overrides),
                                                                                                  np.nan)
        for chunk, res in self.runner(engine.chunks_of(self.law_name, self.spec.base_values, overrides,
                                                       self.spec.duration_s, self.spec.window,
                                                       engine.chunk_size_for(self.law_name, self.chunk_size))):
            sl = slice(chunk.first, chunk.first + len(chunk))
            up[sl], th[sl], u[sl] = res.upright, res.metrics["theta_b_rms"], res.metrics["u_rms"]
            self.steps += res.steps
        return up.reshape(-1, n), th.reshape(-1, n), u.reshape(-1, n)

    def _cost(self, up, th, u) -> np.ndarray:
        """Per scenario: theta_b RMS + weight * u RMS, or FALL_PENALTY for a fall (or a non-finite metric)."""
        c = th + self.weight * u
        return np.where(up & np.isfinite(c), c, FALL_PENALTY)

    def per_scenario(self, xs: np.ndarray) -> np.ndarray:
        """(candidates, scenarios) costs; rows of inadmissible candidates are not simulated."""
        cost = np.full((len(xs), len(self.scenarios)), np.nan)
        ok = []
        for j, x in enumerate(xs):
            gap = self.admissibility(x)
            if gap < 0:
                cost[j] = INADMISSIBLE - gap
            else:
                ok.append(j)
        if ok:
            cost[ok] = self._cost(*self._simulate([xs[j] for j in ok]))
        self.evaluations += len(xs)
        return cost

    def judge(self, x: Sequence[float]) -> Dict[str, float]:
        """One candidate on every scenario: J, the share upright, the median theta_b RMS and u RMS."""
        x = np.asarray(x, dtype=float)
        up, th, u = (a[0] for a in self._simulate([x]))
        return {"J": float(self._cost(up, th, u).mean()), "upright_share": float(up.mean()),
                "theta_b_rms_median": float(np.median(th[up])) if up.any() else math.nan,
                "u_rms_median": float(np.median(u[up])) if up.any() else math.nan,
                "theorem2_holds": self.admissibility(x) >= 0}

    def __call__(self, xs: np.ndarray) -> np.ndarray:
        """J for each candidate (rows of ``xs``, in parameter units)."""
        j = self.per_scenario(np.atleast_2d(xs)).mean(axis=1)
        i = int(np.argmin(j))
        if j[i] < self.best[0]:
            self.best = (float(j[i]), np.array(xs[i], dtype=float))
        return j


@dataclass
class Tuner:
    """Differential evolution in log space over the knobs' bounds, seeded; ``progress(generation, best_J,
    best_x)`` after each generation.  ``run`` returns (best x, best J, generations); Ctrl-C returns the best
    so far (``interrupted``)."""

    objective: Objective
    bounds: List[Tuple[float, float]]
    seed: int = 0
    maxiter: int = 30
    popsize: int = 8
    progress: Optional[Callable[[int, float, np.ndarray], None]] = None
    interrupted: bool = False

    def run(self) -> Tuple[np.ndarray, float, int]:
        from scipy.optimize import differential_evolution

        logb = [(math.log(lo), math.log(hi)) for lo, hi in self.bounds]
        generation = [0]

        def f(z):   # scipy's vectorized form: z has a column per candidate
            return self.objective(np.exp(np.asarray(z).T))

        def callback(intermediate_result):
            generation[0] += 1
            if self.progress is not None:
                self.progress(generation[0], *self.objective.best)

        try:
            differential_evolution(f, logb, seed=self.seed, maxiter=self.maxiter, popsize=self.popsize, tol=1e-6,
                                   polish=False, vectorized=True, updating="deferred", callback=callback)
        except KeyboardInterrupt:
            self.interrupted = True
        best_j, best_x = self.objective.best
        return best_x, best_j, generation[0]
