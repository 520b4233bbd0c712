"""A sweep spec (YAML): the base parameter file, the laws, the length, the window, and what varies.

.. code-block:: yaml

    base: ../paper.yaml                 # relative to this spec (or a list: a base, then overlays);
                                        # default: the package's config/paper.yaml
    controllers: [dsc, dscndo]
    duration_s: 10.0
    metrics_window_s: [5.0, 10.0]
    seed: 1
    samples: 200                        # draws per grid point of the random axes
    vary:
      plant_sim.actual.m_b: {scale: [0.7, 1.3]}      # uniform factor on the base value
      plant_sim.tau_ext1.amplitude: {grid: [0, 15, 30, 45]}
      plant_sim.initial.theta_b: {linspace: [-0.6, 0.6, 25]}
      dscndo_controller.k1: {uniform: [2.0, 10.0]}
      nominal.m_b: {values: [210.6]}                  # keys of the shared /** section have no prefix

Grid axes (``grid``, ``values``, ``linspace``) form a Cartesian product; random axes
(``uniform``, ``scale``, ``normal: [mean, sd]``) are drawn ``samples`` times per grid point.
:func:`load_spec` checks everything a sweep could trip on later (unknown keys, with a "did you
mean"; a key under the wrong section; a parameter the offline loop does not use; an empty grid;
an impossible distribution; values outside a parameter's range) and raises :class:`SpecError`
naming the key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

import yaml

from mwip_ros import params as P
from mwip_ros.core.kernels import budget
from mwip_ros.core import laws
from mwip_ros.params.errors import bounded
from mwip_ros.params.file import NODES_OF_THE_LOOP
from mwip_ros.yamlio import YamlRefused, load_yaml, shown

__all__ = ["SpecError", "Axis", "SweepSpec", "load_spec", "parse_spec", "GRID_KINDS", "RANDOM_KINDS", "SWEEP_BACKENDS"]

GRID_KINDS = ("grid", "values", "linspace")
RANDOM_KINDS = ("uniform", "scale", "normal")
TOP_KEYS = ("base", "controllers", "duration_s", "metrics_window_s", "seed", "samples", "vary")
MAX_SCENARIOS = 50_000_000
# The plant backends the sweep engine runs (mwip_sweep, mwip_tune): rk4 batched, mujoco through the scalar loop
# scenario by scenario (core.kernels.batch.simulate_batch).
SWEEP_BACKENDS = ("rk4", "mujoco")

# Parameters of the loop's nodes that do not change the offline closed loop (or that the spec sets itself).
NOT_SIMULATED = {
    "mode": "the offline loop is always lockstep", "duration_s": "set the spec's duration_s",
    "use_observer": "list the laws under controllers:", "law": "list the laws under controllers:",
    "csv": "an output file", "summary_json": "an output file",
    "lockstep_timeout_s": "wall-clock time of the ROS graph", "expected_subscribers": "the ROS graph's set-up",
    "stale_command_periods": "realtime runs only", "realtime_priority": "process scheduling",
    "watchdog_s": "realtime runs only", "exit_on_fall": "the offline loop ends at a fall",
    "require_enable": "the offline loop has nobody to enable the driver",
}


class SpecError(ValueError):
    """A sweep spec that cannot run; ``key`` names the offending entry (``vary.<key>`` for an axis)."""

    def __init__(self, key: str, message: str, source: Optional[str] = None):
        key, message = bounded(key, 200), bounded(message)   # a value's repr never makes a message of megabytes
        self.key, self.reason, self.source = key, message, source
        super().__init__(f"{source + ': ' if source else ''}{key}: {message}")


@dataclass(frozen=True)
class Axis:
    """One varied parameter: its spec key, the merged-values name, its ROS type and its distribution."""

    key: str          # as written in the spec: 'plant_sim.actual.m_b', 'nominal.m_b'
    section: str      # '/**' or a node name: where --write-params puts it
    name: str         # the parameter's name in that section (and in merged values): 'actual.m_b'
    type: str         # 'double' | 'integer' | 'double_array'
    kind: str         # grid | values | linspace | uniform | scale | normal
    args: tuple       # the grid's values, or the distribution's numbers
    base: Any = None  # the base file's value (for scale)

    @property
    def random(self) -> bool:
        return self.kind in RANDOM_KINDS

    @property
    def count(self) -> int:
        """How many values a grid axis takes (without listing them: a linspace count is checked first)."""
        return self.args[2] if self.kind == "linspace" else len(self.args)

    def grid_values(self) -> list:
        if self.kind == "linspace":
            a, b, n = self.args
            return [a + (b - a) * i / (n - 1) for i in range(n)] if n > 1 else [a]
        return list(self.args)


@dataclass
class SweepSpec:
    path: str
    base_path: List[Path]             # the base file and any overlays, merged in order
    base_values: Dict[str, Any]       # merged values of the base file (plant, observer, controller)
    base_sections: Dict[str, Dict[str, Any]]
    controllers: Tuple[str, ...]
    duration_s: float
    window: Tuple[float, float]
    seed: int
    samples: int
    axes: List[Axis] = field(default_factory=list)

    @property
    def grid_axes(self) -> List[Axis]:
        return [a for a in self.axes if not a.random]

    @property
    def random_axes(self) -> List[Axis]:
        return [a for a in self.axes if a.random]

    @property
    def n_scenarios(self) -> int:
        n = 1
        for a in self.grid_axes:
            n *= a.count
        return n * (self.samples if self.random_axes else 1)


def load_spec(path, base_override: Optional[Path] = None, backends=("rk4",)) -> SweepSpec:
    """Read and check a sweep spec file; raises :class:`SpecError` (or ``ParamError`` for the base file).
    ``backends``: the plant backends the caller runs (``mwip_sweep``, ``mwip_tune``: rk4 and mujoco, the scalar loop
    runs a mujoco scenario; the environments: rk4); a base file, or a ``vary: plant_sim.backend`` value, with
    another one is refused naming the key."""
    p = Path(path)
    if not p.is_file():
        raise SpecError("<spec>", f"no such file: {p}" if not p.exists() else f"{p} is a directory" if p.is_dir()
                        else f"{p}: not a regular file (a FIFO or a device), not read")
    try:
        doc = load_yaml(p, "sweep spec")   # bounded: size, no aliases, nodes, depth (mwip_ros.yamlio)
    except YamlRefused as exc:
        mark = exc.problem_mark
        raise SpecError("<spec>", f"refused: {exc.problem}" + (f" (line {mark.line + 1})" if mark else ""),
                        str(p)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError("<spec>", f"cannot read {p}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise SpecError("<spec>", f"not valid YAML{where}: {getattr(exc, 'problem', None) or exc}", str(p)) from None
    return parse_spec(doc, str(p), p.parent, base_override, backends)


_did_you_mean = P.spelling_hint   # the one "did you mean" of a key, a law or a word (params.schema)


def _number(v, key: str, source: str, what: str = "a number") -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SpecError(key, f"expected {what}, got {shown(v)}", source)
    return float(v)


def parse_spec(doc: Any, source: str = "<spec>", here: Path = Path("."),
               base_override: Optional[Path] = None, backends=("rk4",)) -> SweepSpec:
    """Check a loaded spec document; ``here`` is the directory ``base`` is relative to; ``backends`` as
    :func:`load_spec`'s."""
    if not isinstance(doc, dict):
        raise SpecError("<spec>", "expected a mapping with base, controllers, duration_s, ..., vary", source)
    for k in doc:
        if k not in TOP_KEYS:
            raise SpecError(str(k), f"unknown key{_did_you_mean(str(k), TOP_KEYS)}; known: {', '.join(TOP_KEYS)}",
                            source)
    if base_override is not None:
        base_path = [Path(base_override)]
    elif doc.get("base") is not None:
        base = doc["base"] if isinstance(doc["base"], list) else [doc["base"]]
        if not base or not all(isinstance(b, str) and b for b in base):
            raise SpecError("base", f"expected a parameter file's path (or a list: a base and overlays), got "
                                    f"{shown(doc['base'])}", source)
        base_path = [(here / b).resolve() for b in base]
    else:
        from mwip_ros.params.paths import default_params_file
        base_path = [default_params_file()]
    pf = P.load_param_files(base_path, option="base")   # ParamError names the file and the key
    base_values = P.merged_values(pf)
    if base_values.get("backend", "rk4") not in backends:
        raise SpecError("base", f"plant_sim.backend: {base_values['backend']}: {_runs_only(backends)}", source)

    ctrls = doc.get("controllers", ["dsc", "dscndo"])   # the paper's comparison unless the spec says more
    known = laws.names()   # the registry (core.laws)
    if isinstance(ctrls, str):
        ctrls = [ctrls]
    if not isinstance(ctrls, list) or not ctrls:
        raise SpecError("controllers", f"expected a non-empty list of {', '.join(known)}", source)
    for c in ctrls:
        if c not in known:
            raise SpecError("controllers", f"unknown law {shown(c)}{_did_you_mean(str(c), known)}; known: "
                                           f"{', '.join(known)}", source)
    if len(set(ctrls)) != len(ctrls):
        raise SpecError("controllers", f"a law is listed twice: {ctrls}", source)
    for c in ctrls:   # a law whose optional package is missing (mpc: daqp), before any chunk runs
        missing = laws.unavailable(laws.get(c))
        if missing:
            raise SpecError("controllers", missing, source)

    duration = _number(doc.get("duration_s", base_values["duration_s"]), "duration_s", source, "seconds > 0")
    if not 0 < duration <= 1e5:
        raise SpecError("duration_s", f"must be > 0 and at most 1e5 s, got {shown(duration)}", source)
    win = doc.get("metrics_window_s", [0.5 * duration, duration])
    if not isinstance(win, list) or len(win) != 2:
        raise SpecError("metrics_window_s", f"expected [t0, t1], got {shown(win)}", source)
    t0, t1 = (_number(w, "metrics_window_s", source, "seconds") for w in win)
    if not 0 <= t0 < t1 <= duration + 1e-9:
        raise SpecError("metrics_window_s", f"needs 0 <= t0 < t1 <= duration_s ({duration:g}), got {shown(win)}",
                        source)
    seed = doc.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SpecError("seed", f"expected an integer >= 0, got {shown(seed)}", source)
    samples = doc.get("samples", 1)
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
        raise SpecError("samples", f"expected an integer >= 1, got {shown(samples)}", source)

    vary = doc.get("vary") or {}
    if not isinstance(vary, dict):
        raise SpecError("vary", "expected a mapping of parameter keys to distributions", source)
    axes = [_axis(str(k), d, base_values, source) for k, d in vary.items()]
    for a in axes:
        if a.name == "backend":
            _check_backends(a, base_values, backends, source)
    spec = SweepSpec(source, base_path, base_values, pf.sections, tuple(ctrls), duration, (t0, t1), seed,
                     samples, axes)
    if spec.n_scenarios > MAX_SCENARIOS:
        raise SpecError("vary", f"{spec.n_scenarios:,} scenarios; at most {MAX_SCENARIOS:,} per sweep", source)
    check_memory(spec)
    return spec


def _runs_only(backends) -> str:
    return (f"this tool runs the {' and '.join(backends)} backend only; mwip_sim, plant_sim, mwip_sweep and "
            f"mwip_tune run mujoco")


def _check_backends(axis: Axis, base_values: Dict[str, Any], backends, source: str) -> None:
    """An axis over ``plant_sim.backend``: every value one the caller runs, and the base file valid as each
    backend reads it (the 3D model's checks of ``backend: mujoco`` apply only when a scenario takes it)."""
    for b in axis.grid_values():
        if b not in backends:
            raise SpecError(f"vary.{axis.key}", f"{b}: {_runs_only(backends)}", source)
        if b != base_values.get("backend", "rk4"):
            try:
                P.check_derived(dict(base_values, backend=b), source)
            except P.ParamError as exc:
                raise SpecError(f"vary.{axis.key}", f"{b}: the base file's {exc.key}: {exc.reason}",
                                source) from None


def _budget(source: str) -> int:
    try:
        return budget.memory_budget()
    except ValueError as exc:
        raise SpecError(budget.BUDGET_ENV, str(exc), source) from None


def check_memory(spec: SweepSpec) -> None:
    """Refuse a spec whose runs would not fit the memory budget (core.kernels.budget), before anything is built:
    the sweep's table of scenarios and result rows, and one scenario in a simulation batch (its metrics
    window and delay queues, at the worst values the axes can take).  Raises SpecError naming the key."""
    cap = _budget(spec.path)
    n, laws = spec.n_scenarios, len(spec.controllers)
    table = budget.sweep_table_bytes(n, len(spec.axes), laws)
    if table > cap:
        key = "samples" if spec.random_axes and spec.samples > 1 else "vary"
        fit = int(n * cap // table)
        raise SpecError(key, f"{n:,} scenarios x {laws} law(s) need about {budget.fmt_bytes(table)} for the "
                             f"scenario table and the result rows; the memory budget is {budget.fmt_bytes(cap)} "
                             f"(about {fit:,} scenarios fit; {budget.BUDGET_ENV} sets it)", spec.path)
    rate = _worst(spec, "control_rate_hz")
    delay, act = int(_worst(spec, "sensors.delay_periods")), int(_worst(spec, "actuator.delay_periods"))
    h = 1.0 / rate
    n_steps = int(round(spec.duration_s / h))
    n_window = budget.window_samples(n_steps, h, spec.window)[1]
    per = budget.scenario_batch_bytes(n_window, n_steps, delay, act) + budget.batch_fixed_bytes(n_steps, delay, act)
    one = budget.batch_budget(cap)
    if per > one:
        parts = {"metrics_window_s": budget.BATCH_WINDOW_SAMPLE * n_window,
                 "sensors.delay_periods": budget.BATCH_DELAY_PERIOD * min(delay, n_steps),
                 "actuator.delay_periods": budget.BATCH_ACTUATOR_PERIOD * min(act, n_steps)}
        key = max(parts, key=parts.get)
        if key == "metrics_window_s":
            key = "metrics_window_s" if spec.window != (0.5 * spec.duration_s, spec.duration_s) else "duration_s"
            what = (f"its metrics window [{spec.window[0]:g}, {spec.window[1]:g}] s at {rate:g} Hz is {n_window:,} "
                    f"samples")
        else:
            what = f"{key} = {max(delay, act):,} queues {min(max(delay, act), n_steps):,} periods"
        raise SpecError(key, f"one scenario of {spec.duration_s:g} s needs about {budget.fmt_bytes(per)}: {what}; a "
                             f"simulation batch may hold {budget.fmt_bytes(one)} (a quarter of the memory budget "
                             f"{budget.fmt_bytes(cap)}, {budget.BUDGET_ENV} sets it)", spec.path)


def _worst(spec: SweepSpec, name: str) -> float:
    """The largest value the merged parameter ``name`` takes in any scenario of ``spec`` (the end of a range;
    a normal's mean + 8 sd, capped at the parameter's own maximum)."""
    worst = spec.base_values[name]
    for a in spec.axes:
        if a.name != name:
            continue
        if a.kind == "linspace":
            v = max(a.args[0], a.args[1])
        elif a.kind in ("grid", "values"):
            v = max(a.args)
        elif a.kind == "uniform":
            v = a.args[1]
        elif a.kind == "scale":
            v = a.base * a.args[1]
        else:
            ps = {s.name: s for s in P.SHARED_SPECS}.get(name) or P.specs_for("plant_sim").get(name)
            hi = getattr(getattr(ps, "check", None), "bounds", (None, math.inf))[1]
            v = min(a.args[0] + 8 * a.args[1], hi)
        worst = max(worst, v)
    return worst


def _resolve(key: str, source: str) -> Tuple[str, str, P.ParamSpec]:
    """'plant_sim.actual.m_b' -> ('plant_sim', 'actual.m_b', spec); 'nominal.m_b' -> ('/**', ...)."""
    shared = {s.name: s for s in P.SHARED_SPECS}
    def owners(name: str) -> List[str]:
        return [n for n in NODES_OF_THE_LOOP if any(s.name == name for s in P.NODE_SPECS[n])]

    head, _, rest = key.partition(".")
    if head in P.NODE_SPECS:
        if head not in NODES_OF_THE_LOOP:
            raise SpecError(f"vary.{key}", f"{head} is not part of the simulated loop (its parameters are "
                                           f"{', '.join(NODES_OF_THE_LOOP)}'s)", source)
        if rest in shared:
            raise SpecError(f"vary.{key}", f"{rest} is shared by every node (the /** section): write it without "
                                           f"a prefix, as '{rest}'", source)
        mine = {s.name: s for s in P.NODE_SPECS[head]}
        if rest in mine:
            return head, rest, mine[rest]
        others = owners(rest)
        if others:
            raise SpecError(f"vary.{key}", f"{rest} is not a parameter of {head}; it belongs under {others[0]} "
                                           f"(write '{others[0]}.{rest}')", source)
        raise SpecError(f"vary.{key}", f"unknown parameter for {head}{_did_you_mean(rest, mine)}", source)
    if key in shared:
        return P.SHARED, key, shared[key]
    others = owners(key)
    if others:
        raise SpecError(f"vary.{key}", f"{key} belongs under {others[0]}: write '{others[0]}.{key}'", source)
    every = list(shared) + [f"{n}.{s.name}" for n in NODES_OF_THE_LOOP for s in P.NODE_SPECS[n]]
    raise SpecError(f"vary.{key}", f"unknown parameter{_did_you_mean(key, every)}; write 'node.key' (e.g. "
                                   f"plant_sim.actual.m_b) or a key of the shared section (e.g. nominal.m_b)",
                    source)


def _axis(key: str, dist: Any, base_values: Dict[str, Any], source: str) -> Axis:
    section, name, ps = _resolve(key, source)
    where = f"vary.{key}"
    if name in NOT_SIMULATED:
        raise SpecError(where, f"does not change the offline closed loop ({NOT_SIMULATED[name]})", source)
    if ps.type not in ("double", "integer", "double_array", "string", "bool"):
        raise SpecError(where, f"a {ps.type} parameter cannot be varied", source)
    kinds = GRID_KINDS + RANDOM_KINDS
    if not isinstance(dist, dict) or len(dist) != 1:
        raise SpecError(where, f"expected one distribution, e.g. {{grid: [...]}}; one of {', '.join(kinds)}", source)
    (kind, args), = dist.items()
    if kind not in kinds:
        raise SpecError(where, f"unknown distribution {shown(kind)}{_did_you_mean(str(kind), kinds)}; one of "
                               f"{', '.join(kinds)}", source)
    base = base_values[name]
    if ps.type != "double" and kind in RANDOM_KINDS + ("linspace",):
        raise SpecError(where, f"{kind} draws real numbers; {name} is a {ps.type}: use grid or values", source)

    def check(v, what=""):
        """The value as the parameter holds it, checked against its range."""
        if ps.type == "double":
            v = _number(v, where, source)
        elif ps.type == "integer":
            if isinstance(v, bool) or not isinstance(v, int):
                raise SpecError(where, f"expected integers, got {shown(v)}", source)
        elif ps.type in ("string", "bool"):   # a choice: sensors.model, method, motor.enabled, ...
            if ps.type == "bool" and not isinstance(v, bool):
                raise SpecError(where, f"expected true or false, got {shown(v)}", source)
        else:
            if not isinstance(v, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
                raise SpecError(where, f"expected lists of numbers such as {base}, got {shown(v)}", source)
            v = [float(x) for x in v]
        try:
            return ps.validate(v, name)
        except P.ParamError as exc:
            raise SpecError(where, f"{what}{exc.reason}", source) from None

    if kind in ("grid", "values"):
        if not isinstance(args, list) or not args:
            raise SpecError(where, f"{kind} needs a non-empty list of values, got {shown(args)}", source)
        return Axis(key, section, name, ps.type, kind, tuple(check(v) for v in args), base)
    if not isinstance(args, list) or len(args) != (3 if kind == "linspace" else 2):
        shape = {"linspace": "[start, stop, count]", "uniform": "[low, high]", "scale": "[low, high] (factors)",
                 "normal": "[mean, standard deviation]"}[kind]
        raise SpecError(where, f"{kind} needs {shape}, got {shown(args)}", source)
    if kind == "linspace":
        a, b = check(args[0], "start "), check(args[1], "stop ")
        n = args[2]
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise SpecError(where, f"linspace count must be an integer >= 1, got {shown(n)}", source)
        if n == 1 and a != b:
            raise SpecError(where, "linspace with one point needs start == stop", source)
        return Axis(key, section, name, ps.type, kind, (a, b, n), base)
    lo, hi = (_number(v, where, source) for v in args)
    if kind == "normal":
        check(lo, "mean ")
        if not hi > 0:
            raise SpecError(where, f"normal needs a standard deviation > 0, got {shown(hi)}", source)
        return Axis(key, section, name, ps.type, kind, (lo, hi), base)
    if not lo < hi:
        raise SpecError(where, f"{kind} needs low < high, got [{shown(lo)}, {shown(hi)}] (use values: for one value)",
                        source)
    if kind == "scale":
        if not lo > 0:
            raise SpecError(where, f"scale factors must be > 0, got {shown(lo)}", source)
        check(base * lo, f"scale {lo:g} of the base value {shown(base)} ")
        check(base * hi, f"scale {hi:g} of the base value {shown(base)} ")
    else:
        check(lo, "low end ")
        check(hi, "high end ")
    return Axis(key, section, name, ps.type, kind, (lo, hi), base)
