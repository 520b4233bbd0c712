"""Parameter files: read and validate a ROS 2 parameter file as a whole; one node's values from it."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Mapping, Optional

import difflib
import yaml

from .errors import ParamError
from mwip_ros.core.closed_loop.loop import loop_nodes
from mwip_ros.yamlio import RosYamlLoader, YamlRefused, load_yaml
from .schema import (NODE_SPECS, QOS_OVERRIDES, QOS_OVERRIDES_REFUSED, ROS_OWN, SHARED, SHARED_SPECS, check_derived,
                     defaults_for, spelling_hint, specs_for)


TYPO_CUTOFF = 0.8   # a foreign section name this close to one of ours is refused as a misspelling

__all__ = ["ParamFile", "RosYamlLoader", "load_param_file", "load_param_files", "load_yaml", "merged_values",
           "node_key", "parse_param_dict", "robot_values"]


def _flatten(d: Mapping, prefix: str, key_path: str, source: str) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for k, v in d.items():
        if not isinstance(k, str):
            raise ParamError(f"{key_path}{k}", "parameter names must be strings", source)
        name = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(_flatten(v, name + ".", key_path, source))
        else:
            out[name] = v
    return out


def node_key(section: str) -> str:
    """'plant_sim', '/plant_sim', '/robot1/plant_sim', '/**/plant_sim' -> 'plant_sim'; '/**' -> '/**'."""
    s = section.strip()
    if s in ("/**", "**"):
        return SHARED
    return s.rstrip("/").rsplit("/", 1)[-1]


@dataclass
class ParamFile:
    """A validated parameter file: section -> {dotted name: value}.

    ``others`` holds, unchecked, the sections of nodes that are not mwip_ros's (a shared file may
    configure a whole system): a node renamed with ``__node:=`` reads its own among them, checked
    then (:meth:`section_for`)."""

    path: str
    sections: Dict[str, Dict[str, Any]] = field(default_factory=dict)
    others: Dict[str, Dict[str, Any]] = field(default_factory=dict)

    def section_for(self, node: str, name: str) -> Dict[str, Any]:
        """The section of the ``node`` (its kind, e.g. 'dscndo_controller') running under ``name``, checked
        against ``node``'s parameters: an unknown key in it is refused, naming it."""
        if name in self.sections:
            return self.sections[name]
        if name in self.others:
            return {k: _check_entry(node, k, v, self.path, shown=name) for k, v in self.others[name].items()}
        return {}

    def for_node(self, node: str, overrides: Optional[Mapping[str, Any]] = None) -> Dict[str, Any]:
        """Defaults, then the shared section, then the node's section, then ``overrides`` (checked)."""
        values = defaults_for(node)
        for sec in (SHARED, node):
            for k, v in self.sections.get(sec, {}).items():
                if k in values:
                    values[k] = v
        specs = specs_for(node)
        for k, v in (overrides or {}).items():
            if k not in specs:
                raise ParamError(k, f"unknown parameter for {node}", "override")
            values[k] = specs[k].validate(v, k, "override")
        check_derived(values, self.path)
        return values


def _check_entry(section: str, name: str, value: Any, source: str, shown: Optional[str] = None) -> Any:
    key = name if section == SHARED else f"{shown or section}.{name}"
    if name in ROS_OWN:
        return ROS_OWN[name].validate(value, key, source)
    if name.startswith(QOS_OVERRIDES):
        raise ParamError(key, QOS_OVERRIDES_REFUSED, source)
    if section == SHARED:
        shared = {s.name: s for s in SHARED_SPECS}
        if name in shared:
            return shared[name].validate(value, key, source)
        owners = [n for n, specs in NODE_SPECS.items() if any(s.name == name for s in specs)]
        hint = f" (it belongs under {owners[0]}:)" if owners else (spelling_hint(name, shared) or spelling_hint(
            name, {s.name: n for n, specs in NODE_SPECS.items() for s in specs}))
        raise ParamError(key, f"unknown parameter in the shared /** section{hint}", source)
    specs = specs_for(section)
    if name not in specs:
        owners = [n for n, sp in NODE_SPECS.items() if n != section and any(s.name == name for s in sp)]
        hint = f" (it belongs under {owners[0]}:)" if owners else spelling_hint(name, specs)
        raise ParamError(key, f"unknown parameter for {section}{hint}", source)
    return specs[name].validate(value, key, source)


def parse_param_dict(doc: Any, source: str = "<params>") -> ParamFile:
    """Validate a loaded ROS 2 parameter document (the whole file)."""
    if not isinstance(doc, Mapping) or not doc:
        raise ParamError("<file>", "expected a mapping of node names to {ros__parameters: ...}", source)
    pf = ParamFile(path=source)
    for section_raw, body in doc.items():
        section = node_key(str(section_raw))
        foreign = section != SHARED and section not in NODE_SPECS
        if foreign:
            close = difflib.get_close_matches(section, list(NODE_SPECS), n=1, cutoff=TYPO_CUTOFF)
            if close:   # one letter off one of ours: a typo, not another node
                raise ParamError(str(section_raw), f"unknown node name (did you mean '{close[0]}'?); mwip_ros's "
                                                   f"nodes: /**, {', '.join(NODE_SPECS)}", source)
        if not isinstance(body, Mapping) or set(body) != {"ros__parameters"}:
            odd = [str(k) for k in body if k != "ros__parameters"] if isinstance(body, Mapping) else []
            hint = f": got '{odd[0]}'{spelling_hint(odd[0], ['ros__parameters'])}" if odd else ""
            raise ParamError(f"{section_raw}", f"each node section must contain exactly 'ros__parameters:'{hint}",
                             source)
        params = body["ros__parameters"] or {}
        if not isinstance(params, Mapping):
            raise ParamError(f"{section_raw}.ros__parameters", "must be a mapping", source)
        flat = _flatten(params, "", "", source)
        if foreign:   # another node's section (or one of ours renamed with __node:=): checked by whoever reads it
            pf.others.setdefault(section, {}).update(flat)
            continue
        checked = {name: _check_entry(section, name, v, source) for name, v in flat.items()}
        pf.sections.setdefault(section, {}).update(checked)
    return pf


def load_param_file(path, option: str = "--params-file") -> ParamFile:
    """Read and validate a ROS 2 parameter file; raises ParamError naming the key or the file.

    ``option`` is how the user gave the file (a node's ``--params-file``, ``mwip_sim --params``): a file that
    is missing, a directory or unreadable is reported under that name."""
    p = Path(path)
    if p.is_dir():
        raise ParamError(option, f"{p} is a directory, not a parameter file")
    if not p.exists():
        raise ParamError(option, f"no such file: {p}")
    if not p.is_file():   # a FIFO, a device: never read (mwip_ros.yamlio)
        raise ParamError(option, f"{p}: not a regular file (a FIFO or a device), not read")
    try:
        doc = load_yaml(p, "parameter file")   # bounded: size, no aliases, nodes, depth (mwip_ros.yamlio)
    except YamlRefused as exc:
        where = exc.problem_mark
        line = f" (line {where.line + 1})" if where is not None else ""
        raise ParamError("<file>", f"refused: {exc.problem}{line}", str(p)) from None
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        line = f" at line {where.line + 1}, column {where.column + 1}" if where is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ParamError("<file>", f"not valid YAML{line}: {problem}", str(p)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ParamError(option, f"cannot read {p}: {exc}") from None
    return parse_param_dict(doc, str(p))


def load_param_files(paths, option: str = "--params-file") -> ParamFile:
    """Several parameter files, each checked, merged in order as ROS merges repeated ``--params-file``: a key
    in a later file wins (a base file, then an overlay such as ``config/sensing_realistic.yaml``).  ``option``
    as for :func:`load_param_file`."""
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    merged = ParamFile(path=" + ".join(str(p) for p in paths))
    for p in paths:
        pf = load_param_file(p, option)
        for section, values in pf.sections.items():
            merged.sections.setdefault(section, {}).update(values)
        for section, values in pf.others.items():
            merged.others.setdefault(section, {}).update(values)
    return merged


# the closed loop's nodes (core.closed_loop.loop.STAGES), the plant's values last (they win where sections share a key)
NODES_OF_THE_LOOP = tuple(reversed(loop_nodes(estimator=True)))


def merged_values(pf: ParamFile, overrides: Optional[Mapping] = None) -> Dict[str, Any]:
    """One dict with the plant's, observer's and controller's values from one parameter file
    (what the offline tools simulate)."""
    v: Dict[str, Any] = {}
    for node in NODES_OF_THE_LOOP:
        v.update(pf.for_node(node))
    v.update(overrides or {})
    check_derived(v, pf.path)
    return v


def robot_values(param_files, control_rate_hz: float) -> dict:
    """The robot a simulated backend runs: the ``plant_sim`` section of ``param_files`` (merged in order, over the
    schema's defaults, checked as plant_sim checks it), at the driver's ``control_rate_hz``.

    Parameters
    ----------
    param_files : list of path
        The node's ``--params-file`` files, in command-line order ([]: the defaults: the paper's robot).
    control_rate_hz : float
        The driver's rate (the period a simulated backend integrates).

    Returns
    -------
    dict
        plant_sim's values.
    """
    pf = load_param_files(param_files) if param_files else ParamFile(path="<defaults>")
    return pf.for_node("plant_sim", {"control_rate_hz": float(control_rate_hz)})
