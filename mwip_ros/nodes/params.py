"""Declare a node's parameters from the schema (:mod:`mwip_ros.params`) and keep them validated.

* every ``--params-file`` on the command line is validated as a whole with the
  same loader the offline tools use (unknown keys, types, ranges -> ParamError);
* every parameter is declared with its description, type and range;
* start-up values (file or ``-p name:=value``) are checked; unknown overrides
  are refused;
* run-time updates of ``dynamic`` parameters are checked and logged; others are
  read-only.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Dict, List, Sequence

import yaml

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.parameter import Parameter

from mwip_ros import params as P

_TYPES = {"double": ParameterType.PARAMETER_DOUBLE, "integer": ParameterType.PARAMETER_INTEGER,
          "bool": ParameterType.PARAMETER_BOOL, "string": ParameterType.PARAMETER_STRING,
          "double_array": ParameterType.PARAMETER_DOUBLE_ARRAY,
          "string_array": ParameterType.PARAMETER_STRING_ARRAY}
_ARRAY_TYPES = {"double_array": Parameter.Type.DOUBLE_ARRAY, "string_array": Parameter.Type.STRING_ARRAY}


def params_files(argv: Sequence[str]) -> List[str]:
    """The ``--params-file`` arguments of a ROS command line."""
    out, args = [], list(argv)
    for i, a in enumerate(args):
        if a == "--params-file" and i + 1 < len(args):
            out.append(args[i + 1])
    return out


def cli_overrides(argv: Sequence[str]) -> List[tuple]:
    """``-p name:=value`` / ``--param name:=value`` rules of a ROS command line, in order, values as YAML."""
    out, args, in_ros = [], list(argv), False
    for i, a in enumerate(args):
        if a == "--ros-args":
            in_ros = True
        elif a == "--":
            in_ros = False
        elif in_ros and a in ("-p", "--param") and i + 1 < len(args) and ":=" in args[i + 1]:
            name, text = args[i + 1].split(":=", 1)
            out.append((name.split(":")[-1], yaml.safe_load(text) if text else ""))
    return out


def _descriptor(spec: P.ParamSpec) -> ParameterDescriptor:
    d = ParameterDescriptor(description=spec.description, type=_TYPES[spec.type],
                            read_only=not spec.dynamic, dynamic_typing=False)
    check = spec.check.__name__ if spec.check else ""
    if spec.type == "double" and check in ("_positive", "_non_negative"):
        d.floating_point_range = [FloatingPointRange(from_value=0.0, to_value=math.inf, step=0.0)]
        d.additional_constraints = "> 0" if check == "_positive" else ">= 0"
    elif spec.type == "integer" and check in ("_at_least_one", "_non_negative", "_priority"):
        lo = 1 if check == "_at_least_one" else 0
        hi = 99 if check == "_priority" else 2 ** 31 - 1
        d.integer_range = [IntegerRange(from_value=lo, to_value=hi, step=1)]
    elif spec.check is not None and check == "check":  # _one_of(...)
        d.additional_constraints = spec.check(object()).split(", got", 1)[0]
    return d


def declare(node, node_name: str, argv: Sequence[str],
            on_change: Callable[[Dict[str, Any]], None] | None = None) -> Dict[str, Any]:
    """Declare every parameter of ``node_name`` on ``node``; return {name: value}.

    Raises ``ParamError`` (naming the key) for a bad file, type, value or unknown override.
    ``on_change(changed)`` is called after an accepted run-time update.
    """
    for f in params_files(argv):
        P.load_param_file(f)  # the whole file, with the file name in the message
    specs = P.specs_for(node_name)
    # rclpy files a -p rule under /**, so a node's own section in the file would win over it;
    # a user expects the command line to win, so re-apply the -p rules last.
    overrides = getattr(node, "_parameter_overrides", None)  # rclpy's {name: Parameter} from file and -p
    if overrides is not None:
        for name, value in cli_overrides(argv):
            try:
                overrides[name] = Parameter(name, value=value)
            except TypeError as exc:
                raise P.ParamError(name, f"unsupported value {value!r} ({exc})", "command line") from None
    values: Dict[str, Any] = {}
    for name, spec in specs.items():
        # an empty list carries no type for rclpy (it would become BYTE_ARRAY): declare by type
        initial = _ARRAY_TYPES[spec.type] if spec.type in _ARRAY_TYPES and not spec.default else spec.default
        try:
            p = node.declare_parameter(name, initial, _descriptor(spec))
        except InvalidParameterTypeException as exc:
            raise P.ParamError(name, f"wrong type: expected {spec.type} ({exc})") from None
        except InvalidParameterValueException as exc:
            raise P.ParamError(name, f"invalid value ({exc})") from None
        values[name] = spec.validate(_py(p.value, spec), name, "start-up value")
    for name in overrides or {}:
        if name in specs or name in P.ROS_OWN or name.startswith(P.ROS_OWN_PREFIXES):
            continue
        raise P.ParamError(name, f"unknown parameter for {node_name}{P.spelling_hint(name, specs)}",
                           "command line")

    def validate(params: List[Parameter]) -> SetParametersResult:
        for prm in params:
            spec = specs.get(prm.name)
            if spec is None:
                continue  # ROS's own (use_sim_time, ...)
            if not spec.dynamic:
                return SetParametersResult(successful=False, reason=f"{prm.name} is read-only (restart to change)")
            try:
                spec.validate(_py(prm.value, spec), prm.name)
            except P.ParamError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def apply(params: List[Parameter]) -> None:
        changed = {p.name: _py(p.value, specs[p.name]) for p in params if p.name in specs}
        if not changed:
            return
        old = {k: values[k] for k in changed}
        values.update(changed)
        node.get_logger().info("parameters changed: " + ", ".join(f"{k}: {old[k]!r} -> {v!r}"
                                                                for k, v in changed.items()))
        if on_change is not None:
            on_change(changed)

    node.add_on_set_parameters_callback(validate)
    node.add_post_set_parameters_callback(apply)
    return values


def _py(v: Any, spec: P.ParamSpec) -> Any:
    """A parameter value as plain Python: arrays (array.array / numpy) as lists, an unset array as []."""
    if v is None and spec.type in _ARRAY_TYPES:
        return []
    if isinstance(v, (str, bool, int, float)) or v is None:
        return v
    return [x for x in v]
