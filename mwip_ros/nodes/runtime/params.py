"""Declare a node's parameters from the schema (:mod:`mwip_ros.params`) and keep them validated.

* every ``--params-file`` and ``-p`` rule on the command line is validated before rcl
  sees it (:func:`check_command_line`, called by ``run_node``), with the same loader the
  offline tools use (unknown keys, types, ranges, YAML syntax -> ParamError, exit 2); an
  argument outside ``--ros-args`` (which rcl would ignore) is refused, except ``-h`` /
  ``--help``, which :func:`wants_help` sees and :func:`parameter_help` answers from the schema;
* every parameter is declared with its description, type and range; the values follow
  ROS 2's rule (rclcpp's and rclpy's): what is given for the node by its own name (its
  section of a file, ``-p NODE:name:=value``) wins over what is given for every node
  (``/**`` sections, ``-p name:=value``), and among rules of one kind the later on the
  command line wins.  Beyond rcl, the node also reads its own plain-name section under a
  namespace (rcl matches sections by fully qualified name and would skip it).  A ``-p``
  rule that a section overrides is logged as a warning naming both;
* start-up values are checked, with the derived quantities (the inertia terms); unknown
  overrides are refused;
* run-time updates of ``dynamic`` parameters are checked as strictly as start-up values
  and logged; others are read-only; a refusal names the key.
"""
from __future__ import annotations

import textwrap
from typing import Any, Callable, Dict, Iterator, List, Sequence, Tuple

import yaml

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.parameter import Parameter

from mwip_ros import params as P
from mwip_ros.nodes.runtime import rclpy_compat

_TYPES = {"double": ParameterType.PARAMETER_DOUBLE, "integer": ParameterType.PARAMETER_INTEGER,
          "bool": ParameterType.PARAMETER_BOOL, "string": ParameterType.PARAMETER_STRING,
          "double_array": ParameterType.PARAMETER_DOUBLE_ARRAY,
          "string_array": ParameterType.PARAMETER_STRING_ARRAY}
_ARRAY_TYPES = {"double_array": Parameter.Type.DOUBLE_ARRAY, "string_array": Parameter.Type.STRING_ARRAY}


def plant_file_values(argv: Sequence[str], keys: Sequence[str]) -> Dict[str, Any]:
    """``keys`` of the plant_sim sections of the command line's parameter files, the later file winning: what a node
    other than the plant must know of it (robot_state the robot's geometry, the state estimator its backend)."""
    out = {}
    for kind, arg in ros_arguments(argv):
        if kind == "--params-file":
            section = P.load_param_file(arg).sections.get("plant_sim", {})
            out.update({k: v for k, v in section.items() if k in keys})
    return out


def ros_arguments(argv: Sequence[str]) -> Iterator[Tuple[str, str]]:
    """``("--params-file", path)`` and ``("-p", rule)`` of a ROS command line, in command-line order: the
    arguments between ``--ros-args`` and ``--`` (or the end), where rcl reads them."""
    args, in_ros = list(argv), False
    for i, a in enumerate(args):
        if a == "--ros-args":
            in_ros = True
        elif a == "--":
            in_ros = False
        elif in_ros and i + 1 < len(args):
            if a == "--params-file":
                yield a, args[i + 1]
            elif a in ("-p", "--param"):
                yield "-p", args[i + 1]


def parse_rule(rule: str) -> tuple:
    """``(name, value, node)`` of one ``-p [NODE:]name:=value`` rule (node :data:`~mwip_ros.params.SHARED`
    without one), the value read as ROS reads it (``1e-1`` is a double).  Raises ParamError naming the rule
    for a value that is not YAML."""
    if ":=" not in rule:
        raise P.ParamError(rule, f"-p {rule!r} is not a 'name:=value' rule", "command line")
    name, text = rule.split(":=", 1)
    target, _, name = name.rpartition(":")   # "plant_sim:mode" is for the node plant_sim only
    if not text.strip():
        raise P.ParamError(name, f"-p {rule!r} gives no value", "command line")
    try:
        value = P.load_yaml(text)
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise P.ParamError(name, f"-p {rule!r}: the value is not YAML ({problem})", "command line") from None
    return name, value, target or P.SHARED


HELP_FLAGS = ("-h", "--help")


class UnknownArgument(P.ParamError):
    """An argument outside ``--ros-args``: rcl would ignore it, so the node refuses it (one line, exit 2)."""

    def __init__(self, arg: str, text: str):
        super().__init__(arg, text, "command line")
        self.args = (text,)   # str(): the text alone (no "parameter '...'": it is not one)


def user_arguments(argv: Sequence[str]) -> List[str]:
    """The arguments after the program name that are outside every ``--ros-args ... [--]`` block: rcl leaves
    them to the program (rcl's own rule: ``--ros-args`` opens a block, ``--`` closes it)."""
    out, in_ros = [], False
    for a in list(argv)[1:]:
        if a == "--ros-args":
            in_ros = True
        elif in_ros:
            in_ros = a != "--"
        else:
            out.append(a)
    return out


def wants_help(argv: Sequence[str]) -> bool:
    """``-h`` or ``--help`` outside ``--ros-args`` (``plant_sim --help``, ``ros2 run mwip_ros plant_sim --help``)."""
    return any(a in HELP_FLAGS for a in user_arguments(argv))


def usage_line(name: str) -> str:
    return f"{name} [--ros-args --params-file FILE -p {name}:NAME:=VALUE ...]"


def check_command_line(argv: Sequence[str], name: str = "node") -> None:
    """Every parameter file and ``-p`` rule of ``argv``, checked before rcl parses them (its parser stops the
    process with a traceback): raises ParamError naming the file or the key; an argument outside
    ``--ros-args`` (rcl would ignore it: a node takes none), UnknownArgument naming it."""
    extra = user_arguments(argv)
    if extra:
        raise UnknownArgument(extra[0], f"unknown argument {extra[0]!r} (a node takes ROS arguments only, after "
                                        f"--ros-args; {name} --help lists its parameters)")
    for kind, arg in ros_arguments(argv):
        if kind == "--params-file":
            P.load_param_file(arg)
        else:
            parse_rule(arg)


def _show(v: Any) -> str:
    """A value as it is written in a parameter file or a ``-p`` rule."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_show(x) for x in v) + "]"
    return repr(v)


def range_text(spec: P.ParamSpec) -> str:
    """The values ``spec`` accepts, in words from its range, choices or rule ('' when any value of its type will
    do)."""
    if spec.choices is not None:
        return f"one of {', '.join(map(repr, spec.choices))}"
    lo, hi = spec.lo, spec.hi
    if spec.type == "integer" and (lo is not None or hi is not None):
        if spec.words:
            return spec.words
        if lo is not None and hi is not None:
            return f"{lo}..{hi}"
        return f">= {lo}" if lo is not None else f"<= {hi}"
    if spec.type == "double" and lo is not None and hi is not None:
        if spec.floor is not None:
            return f"[{spec.floor:g}, {hi:g}]"
        return f"{'(' if spec.lo_open else '['}{lo:g}, {hi:g}]"
    return spec.words


def _spec_lines(spec: P.ParamSpec) -> List[str]:
    facts = [spec.type, f"default {_show(spec.default)}"]
    allowed = range_text(spec)
    if allowed:
        facts.append(allowed)
    if spec.dynamic:
        facts.append("changeable at run time")
    return [f"  {spec.name}  ({', '.join(facts)})",
            textwrap.fill(spec.description, width=100, initial_indent=" " * 6, subsequent_indent=" " * 6)]


def parameter_help(node_name: str) -> List[str]:
    """The parameters of ``node_name`` from the schema (type, default, range, description), as help lines;
    [] for a node the schema does not know."""
    if node_name not in P.NODE_SPECS:
        return []
    own = P.NODE_SPECS[node_name]
    lines = textwrap.wrap(f"parameters of every node (the /** section of a --params-file, or -p NAME:=VALUE; "
                          f"the node's own section and -p {node_name}:NAME:=VALUE win over them):", width=100)
    for spec in (*P.SHARED_SPECS, P.ROS_OWN["use_sim_time"]):
        lines += _spec_lines(spec)
    if own:
        lines += ["", f"parameters of {node_name} (its {node_name}: section, or -p {node_name}:NAME:=VALUE):"]
        for spec in own:
            lines += _spec_lines(spec)
    return lines


def _matches(target: str, node) -> bool:
    """Whether a ``-p TARGET:name:=value`` rule is for ``node`` (its name, or its fully qualified name)."""
    fqn = f"{node.get_namespace().rstrip('/')}/{node.get_name()}"
    return target in (node.get_name(), fqn, fqn.lstrip("/"))


def start_values(node, node_name: str, argv: Sequence[str]) -> tuple:
    """The start-up values the command line gives ``node`` (ROS 2's rule: its own name's values over the
    wildcard's; the later over the earlier within each), and the ``-p`` rules an own-name value overrode:
    ``({name: value}, [(name, rule value, value that won)])``."""
    specs = P.specs_for(node_name)
    own_name = node.get_name()
    wildcard: Dict[str, Any] = {}
    own: Dict[str, Any] = {}
    cli_wild: Dict[str, Any] = {}
    for kind, arg in ros_arguments(argv):    # files and -p rules in command-line order
        if kind == "--params-file":
            pf = P.load_param_file(arg)
            wildcard.update({k: v for k, v in pf.sections.get(P.SHARED, {}).items() if k in specs})
            for sec in dict.fromkeys((node_name, own_name)):
                section = pf.sections.get(sec, {}) if sec == node_name else pf.section_for(node_name, sec)
                own.update({k: v for k, v in section.items() if k in specs})
        else:
            name, value, target = parse_rule(arg)
            if target == P.SHARED:
                wildcard[name] = cli_wild[name] = value
            elif _matches(target, node):
                own[name] = value
    shadowed = [(k, v, own[k]) for k, v in cli_wild.items() if k in own and own[k] != v]
    return {**wildcard, **own}, shadowed


def _descriptor(spec: P.ParamSpec) -> ParameterDescriptor:
    """The ROS descriptor of ``spec``, from its data: type, description, read-only, the range (an open end of
    an integer's at the int32 limit), and the words of a lower bound at 0 or of the choices."""
    # dynamic_typing for the run-time parameters: rclpy would refuse a wrong type before our check runs,
    # with a reason that does not name the key; our check (ParamSpec.validate) refuses it, naming the key.
    d = ParameterDescriptor(description=spec.description, type=_TYPES[spec.type],
                            read_only=not spec.dynamic, dynamic_typing=spec.dynamic)
    lo, hi = spec.lo, spec.hi
    if spec.type == "double" and lo is not None and hi is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
        d.additional_constraints = f"must be {'>' if spec.lo_open else '>='} {lo:g}" if lo == 0.0 else ""
    elif spec.type == "integer" and (lo is not None or hi is not None):
        d.integer_range = [IntegerRange(from_value=int(-P.schema.INT32_MAX - 1 if lo is None else lo),
                                        to_value=int(P.schema.INT32_MAX if hi is None else hi), step=1)]
    elif spec.choices is not None:
        d.additional_constraints = f"must be one of {', '.join(map(repr, spec.choices))}"
    return d


def declare(node, node_name: str, argv: Sequence[str],
            on_change: Callable[[Dict[str, Any]], None] | None = None,
            check: Callable[[Dict[str, Any]], None] | None = None) -> Dict[str, Any]:
    """Declare every parameter of ``node_name`` on ``node``; return {name: value}.

    Raises ``ParamError`` (naming the key) for a bad file, type, value or unknown override.
    ``on_change(changed)`` is called after an accepted run-time update.  ``check(values)``, the node's own check
    of the values together (e.g. that the law chosen can run here), raises ParamError: at start-up as the other
    checks do, at run time the update is refused with its text.
    """
    specs = P.specs_for(node_name)
    # rcl skips a plain-name section under a namespace: apply the values as start_values reads them (ROS 2's
    # precedence, with that section too), over rclpy's own reading.
    overrides = rclpy_compat.parameter_overrides(node)  # rclpy's {name: Parameter} from file and -p
    given, shadowed = start_values(node, node_name, argv)
    for name, value in given.items():
        try:
            overrides[name] = Parameter(name, value=value)
        except TypeError as exc:
            raise P.ParamError(name, f"unsupported value {value!r} ({exc})", "command line") from None
    for name, rule, value in shadowed:
        node.get_logger().warning(
            f"-p {name}:={rule!r} is overridden by {name}: {value!r} in this node's own section (ROS 2: a "
            f"node's own section wins over /** and over -p without a node name); write "
            f"-p {node.get_name()}:{name}:=... to override it")
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
    P.check_derived(values, "start-up value")
    if check is not None:
        check(values)
    for name in overrides:
        if name.startswith(P.schema.QOS_OVERRIDES):
            raise P.ParamError(name, P.schema.QOS_OVERRIDES_REFUSED, "command line")
        if name in specs or name in P.ROS_OWN:
            continue
        raise P.ParamError(name, f"unknown parameter for {node_name}{P.spelling_hint(name, specs)}",
                           "command line")

    def validate(params: List[Parameter]) -> SetParametersResult:
        new = dict(values)
        for prm in params:
            spec = specs.get(prm.name)
            if spec is None:
                if prm.name in P.ROS_OWN:
                    continue  # ROS's own (use_sim_time, ...)
                return SetParametersResult(successful=False, reason=f"parameter '{prm.name}': unknown parameter "
                                           f"for {node_name}{P.spelling_hint(prm.name, specs)}")
            if not spec.dynamic:
                return SetParametersResult(successful=False, reason=f"{prm.name} is read-only (restart to change)")
            try:
                new[prm.name] = spec.validate(_py(prm.value, spec), prm.name)
            except P.ParamError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        try:
            P.check_derived(new)
            if check is not None:
                check(new)
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

    rclpy_compat.name_undeclared_parameters(node, lambda name: P.spelling_hint(name, specs))
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
