"""The scenarios of a sweep: every grid point times ``samples`` random draws, each with its D_w seed.

Scenario ``i`` is grid point ``i // samples`` (the grid axes in the spec's order, the last
varying fastest) and draw ``i % samples`` of the random axes.  All random numbers come from
one generator seeded with the spec's ``seed``, drawn before any simulation starts, so a sweep
gives the same scenarios however its chunks are spread over workers.  Unless the spec varies
``plant_sim.seed``, scenario ``i``'s D_w noise seed is derived from the spec's seed and ``i``
(:func:`noise_seed`); both controllers of a scenario see the same noise.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List

import numpy as np
import yaml

from mwip_ros import params as P
from mwip_ros.params.file import NODES_OF_THE_LOOP

from .spec import Axis, SpecError, SweepSpec

__all__ = ["Scenarios", "expand", "noise_seed", "parameter_file", "parameter_overlay"]


def noise_seed(spec_seed: int, i: int) -> int:
    """The D_w seed of scenario ``i``: independent streams for every scenario, reproducible from the spec."""
    return int(np.random.SeedSequence([spec_seed, i]).generate_state(1, np.uint32)[0])


@dataclass
class Scenarios:
    """``values[key][i]``: the value axis ``key`` takes in scenario ``i`` (the scaled value for ``scale``)."""

    axes: List[Axis]
    values: Dict[str, list]
    seeds: List[int]

    def __len__(self) -> int:
        return len(self.seeds)

    def overrides(self, i: int) -> Dict[str, Any]:
        """Scenario ``i``'s changes to the base file's merged values (seed included)."""
        out = {a.name: self.values[a.key][i] for a in self.axes}
        out.setdefault("seed", self.seeds[i])
        return out


def expand(spec: SweepSpec) -> Scenarios:
    """Every scenario of ``spec``, checked: a normal draw outside its parameter's range raises
    :class:`SpecError` naming the scenario, before anything runs (grid values and the ends of the other
    distributions were checked with the spec)."""
    grid = spec.grid_axes
    rand = spec.random_axes
    samples = spec.samples if rand else 1
    points = list(itertools.product(*(a.grid_values() for a in grid))) or [()]
    n = len(points) * samples
    values: Dict[str, list] = {a.key: [] for a in spec.axes}
    for point in points:
        for a, v in zip(grid, point):
            values[a.key].extend([v] * samples)
    rng = np.random.default_rng(spec.seed)
    for a in rand:   # one block per axis, in the spec's order: adding a grid point does not reshuffle others
        lo, hi = a.args
        if a.kind == "normal":
            draws = rng.normal(lo, hi, n)
        else:
            draws = rng.uniform(lo, hi, n)
            if a.kind == "scale":
                draws = draws * a.base
        values[a.key] = [float(v) for v in draws]
    seed_axis = next((a for a in spec.axes if a.section == "plant_sim" and a.name == "seed"), None)
    seeds = list(values[seed_axis.key]) if seed_axis else [noise_seed(spec.seed, i) for i in range(n)]
    sc = Scenarios(spec.axes, values, seeds)
    _check(spec, sc)
    return sc


def _check(spec: SweepSpec, sc: Scenarios) -> None:
    specs = {}
    for node in NODES_OF_THE_LOOP:
        specs.update(P.specs_for(node))
    for a in spec.random_axes:
        if a.kind == "normal":   # the only draws that can leave the parameter's range
            for i, v in enumerate(sc.values[a.key]):
                try:
                    specs[a.name].validate(v, a.name)
                except P.ParamError as exc:
                    raise SpecError(f"vary.{a.key}", f"scenario {i} draws {v!r}, which {exc.reason}; narrow the "
                                                     f"normal distribution", spec.path) from None


def parameter_file(base_sections: Dict[str, Dict[str, Any]], placed: Dict[tuple, Any], path: Path,
                   header: str = "") -> None:
    """Write a complete ROS 2 parameter file: every parameter of the shared section and of the loop's nodes,
    from the base file's sections (defaults where it is silent) with ``placed[(section, name)]`` on top."""
    pf = P.ParamFile(path="<sweep>", sections={k: dict(v) for k, v in base_sections.items()})
    for (section, name), value in placed.items():
        pf.sections.setdefault(section, {})[name] = value
    shared_names = [s.name for s in P.SHARED_SPECS]
    sections = {P.SHARED: {k: v for k, v in pf.for_node(NODES_OF_THE_LOOP[0]).items() if k in shared_names}}
    for node in ("plant_sim", "disturbance_observer", "dscndo_controller"):
        sections[node] = {k: v for k, v in pf.for_node(node).items() if k not in shared_names}
    _write(sections, path, header)


def parameter_overlay(placed: Dict[tuple, Any], path: Path, header: str = "") -> None:
    """Write only ``placed[(section, name)]`` as a ROS 2 parameter file: an overlay to pass after a base file
    (``mwip_sim --params base.yaml overlay.yaml``, or a second ``--params-file``)."""
    sections: Dict[str, Dict[str, Any]] = {}
    for (section, name), value in placed.items():
        sections.setdefault(section, {})[name] = value
    _write(sections, path, header)


def _write(sections: Dict[str, Dict[str, Any]], path: Path, header: str) -> None:
    """{section: {dotted name: value}} as a ROS 2 parameter file, checked by reading it back.  An empty array (the
    default of ``motion.profile``, ``ground.bumps``, ...) is left out: ROS reads ``[]`` as a byte array, not as an
    empty double array, and the node would refuse the file; left out, the parameter takes its default, empty."""
    doc = {sec: {"ros__parameters": _nest({k: v for k, v in values.items() if not (isinstance(v, (list, tuple))
                                                                              and len(v) == 0)})}
           for sec, values in sections.items()}
    path.write_text(header + yaml.dump(doc, Dumper=_Dumper, sort_keys=False, default_flow_style=False, width=120))
    P.load_param_file(path)   # what was written reads back as a valid file


class _Dumper(yaml.SafeDumper):
    """Block mappings, one parameter per line; arrays in flow style ([100.0, 0.0, 0.0, 100.0]), as people write them."""


_Dumper.add_representer(list, lambda d, v: d.represent_sequence("tag:yaml.org,2002:seq", v, flow_style=True))


def _nest(flat: Dict[str, Any]) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for k, v in flat.items():
        d = out
        *parents, leaf = k.split(".")
        for p in parents:
            d = d.setdefault(p, {})
        d[leaf] = float(v) if isinstance(v, np.floating) else v
    return out
