"""``mwip_identify --retune``: a law's gains tuned on the identified model by ``mwip_tune``'s machinery.

The identified body (m_b, I_b, l) becomes both the controller's nominal model (``nominal.*``, under ``/**``) and the
simulated robot (``plant_sim``'s ``actual.*``) of a sweep spec written to a temporary directory: the base file(s)'
scenario (the paper's: its initial tilt, its external torques, its duration and the metrics window of
``mwip_sim``), :data:`SAMPLES` draws with the robot's m_b, I_b and l each scaled within +-:data:`SPREAD` (the gains
must not depend on the identification being exact).  :class:`mwip_ros.sweep.tune.Objective` and
:class:`~mwip_ros.sweep.tune.Tuner` search the law's gains (:func:`knob_names`) on it: ``J`` = mean theta_b RMS
+ 1e-4 u RMS, a fall costs 1, and for DSC and DSCNDO a candidate that breaks Theorem 2 on the identified nominal
model (gamma <= 0) is never simulated.  The result is judged beside the base file's gains on a held-out set (the
same spec, another seed) as ``mwip_tune`` judges it.  Nothing here simulates or searches by itself.
"""
from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

__all__ = ["SAMPLES", "SPREAD", "WEIGHT", "knob_names", "tunable_laws", "Retuned", "retune"]

SAMPLES = 8        # scenarios of the search (and of the held-out set)
SPREAD = 0.05      # each of m_b, I_b, l of the simulated robot within +-5 % of the identified value
WEIGHT = 1e-4      # of u RMS [N m] against theta_b RMS [rad], mwip_tune's default


def knob_names(law: str) -> List[str]:
    """What ``--retune`` tunes for ``law``: every controller knob of ``mwip_tune`` that is one of the law's parameters,
    and the observer's X (c1, c4) when the law has the observer term."""
    from mwip_ros.core import laws
    from mwip_ros.sweep.tune import KNOBS
    cls = laws.get(law)
    names = [n for n, ks in KNOBS.items()
             if all(k.section == "dscndo_controller" and k.param in cls.param_keys for k in ks)]
    return names + (["X"] if cls.observer else [])


def tunable_laws() -> List[str]:
    """The registered laws with at least one tunable gain."""
    from mwip_ros.core import laws
    return [n for n in laws.names() if knob_names(n)]


@dataclass
class Retuned:
    """The tuned gains and how they were judged."""

    law: str
    knobs: list                 # mwip_ros.sweep.tune.Knob
    base_x: np.ndarray          # the base file's gains
    x: np.ndarray               # the tuned gains
    j: float                    # the search set's J of the tuned gains
    before: Optional[dict]      # the held-out set's judgement of the base file's gains (Objective.judge)
    after: Optional[dict]       # ... of the tuned gains
    generations: int
    candidates: int
    margin: float               # the law's stability margin at the tuned gains on the identified model (Theorem 2's
                                # gamma for DSC/DSCNDO; inf for a law without a condition; NaN: not evaluated)
    placed: Dict                # {(section, parameter): value} of the tuned gains
    held_scenarios: int = 0     # the held-out set's scenarios
    holdout_seed: int = 0       # its spec seed

    @property
    def names(self) -> List[str]:
        return [k.name for k in self.knobs]


def _write_yaml(path: Path, doc) -> None:
    import yaml
    path.write_text(yaml.safe_dump(doc, sort_keys=False))


def retune(base: Sequence[Path], physical, law: str, maxiter: int, popsize: int, seed: int = 0,
           samples: int = SAMPLES, spread: float = SPREAD, weight: float = WEIGHT, log=None,
           bounds: Sequence[str] = ()) -> Retuned:
    """Tune ``law``'s gains (:func:`knob_names`) for the robot ``physical`` (its m_b, I_b, l) on the base files'
    scenario (module doc), within ``bounds`` (``name=lo:hi`` items, as ``mwip_tune --bounds``; the rest at their
    defaults).  Raises ``mwip_ros.sweep.spec.SpecError`` or ``mwip_ros.params.ParamError`` for a base that cannot make
    the spec, or for bounds that name no tuned knob or leave its range."""
    from mwip_ros import params as P
    from mwip_ros.cli.tune import _base_values
    from mwip_ros.core import laws
    from mwip_ros.core.closed_loop.metrics import fit_window, WINDOW
    from mwip_ros.sweep import engine
    from mwip_ros.sweep.spec import SpecError, load_spec
    from mwip_ros.sweep.tune import Objective, Tuner, check_memory, knobs_for, overlay, parse_bounds

    cls = laws.get(law)
    knobs = knobs_for(knob_names(law), law)
    bounds = parse_bounds(knobs, list(bounds))
    with tempfile.TemporaryDirectory(prefix="mwip_retune_") as tmp:
        tmp = Path(tmp)
        body = {k: float(getattr(physical, k)) for k in ("m_b", "I_b", "l")}
        _write_yaml(tmp / "model.yaml", {"/**": {"ros__parameters": {"nominal": dict(body)}},
                                         "plant_sim": {"ros__parameters": {"actual": dict(body)}}})
        values = P.merged_values(P.load_param_files([*base, tmp / "model.yaml"]))
        duration = float(values["duration_s"]) or 10.0
        window, _ = fit_window(WINDOW, duration)
        spec_doc = {"base": [str(Path(b).resolve()) for b in base] + [str(tmp / "model.yaml")],
                    "controllers": [law], "duration_s": duration, "metrics_window_s": [float(w) for w in window],
                    "seed": int(seed), "samples": int(samples),
                    "vary": {f"plant_sim.actual.{k}": {"scale": [1.0 - spread, 1.0 + spread]}
                             for k in ("m_b", "I_b", "l")}}
        _write_yaml(tmp / "spec.yaml", spec_doc)
        spec = load_spec(tmp / "spec.yaml")
        held_doc = dict(spec_doc, seed=int(seed) + 1)
        _write_yaml(tmp / "held.yaml", held_doc)
        holdout = load_spec(tmp / "held.yaml")
        for sp in (spec, holdout):   # as mwip_tune: the tables checked against the memory budget before any is built
            try:
                check_memory(sp, knobs, popsize)
            except SpecError as exc:
                raise SpecError("--popsize", exc.reason) from None
        search = Objective(spec, law, knobs, weight, engine.run_local)
        held = Objective(holdout, law, knobs, weight, engine.run_local)
        base_x = _base_values(knobs, spec.base_values)

        def progress(gen, best_j, best_x):
            if log is not None:
                log(f"generation {gen}/{maxiter}: J = {best_j:.6g} at "
                    + ", ".join(f"{k.name} = {v:.4g}" for k, v in zip(knobs, best_x)))

        tuner = Tuner(search, bounds, seed=seed, maxiter=maxiter, popsize=popsize, progress=progress)
        x, j, generations = tuner.run()
        if x is None:
            raise KeyboardInterrupt
        before, after = held.judge(base_x), held.judge(x)
        v = dict(spec.base_values)
        from mwip_ros.sweep.tune import apply
        v.update(apply(knobs, x, spec.base_values))
        nominal = P.physical(v, "nominal")
        try:
            margin = float(cls.stability_margin(nominal, cls.design(v, nominal, P.period(v)), P.observer_gain(v),
                                                observer=cls.observer))
        except ValueError:
            margin = math.nan
        placed = overlay(knobs, x, spec.base_values)
    return Retuned(law, knobs, base_x, np.asarray(x, dtype=float), float(j), before, after, generations,
                   search.evaluations, margin, placed, len(held.scenarios), holdout.seed)
