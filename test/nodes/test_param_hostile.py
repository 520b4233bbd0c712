"""Hostile parameter requests, events and values never crash or stop a node (mwip_ros.nodes.runtime.rclpy_compat).

rclpy's ParameterService reads each request parameter with ``Parameter.from_parameter_msg`` outside
any try: one SetParameters request with a ParameterValue of type code 99 used to end a node with a
traceback (and stop the recorder and the live view).  Now each such parameter is refused with a
reason that names it, the rest of the request is answered, and the node goes on (every node kind, in this
process: test/nodeharness.py); a bag whose /parameter_events carries such a value re-simulates, the value
skipped and reported (a graph of processes: the re-simulation drives a running controller).
"""
from __future__ import annotations

import math
import socket
import subprocess
import sys

import pytest

from graphproc import PARAMS, Graph
from mwip_ros.nodes.runtime import rclpy_compat as C
from nodeharness import NodeHarness, node_class

MODULE = "mwip_ros.nodes.tools.bag_replay"
TIMEOUT = 60.0


def _pm(name, **value):
    from rcl_interfaces.msg import Parameter, ParameterValue
    return Parameter(name=name, value=ParameterValue(**value))


def _type99(name):
    return _pm(name, type=99, double_value=1.0)


def _double(name, x: float, scalar: bool):
    return _pm(name, type=3, double_value=x) if scalar else _pm(name, type=8, double_array_value=[x] * 4)


def _hostile(name: str, scalar: bool = True) -> list:
    """(label, rcl_interfaces/Parameter, the text its refusal must contain) for ``name``, a declared parameter
    (a double when ``scalar``, else a double array)."""
    shown = C.shown_name
    odd = "odd name/\t\x01\u2603"
    long_name = "n" * 10_000
    return [
        ("type code 99", _type99(name), f"parameter '{name}': type code 99 is not a ROS parameter type"),
        ("type code 255", _pm(name, type=255), f"parameter '{name}': type code 255 is not a ROS parameter type"),
        ("no value", _pm(name, type=0), f"parameter '{name}'"),
        ("a string", _pm(name, type=4, string_value="fast"), f"parameter '{name}'"),
        ("NaN", _double(name, math.nan, scalar), f"parameter '{name}'"),
        ("inf", _double(name, -math.inf, scalar), f"parameter '{name}'"),
        ("array for a scalar" if scalar else "scalar for an array",
         _pm(name, type=8, double_array_value=[1.0, 2.0]) if scalar else _pm(name, type=3, double_value=1.0),
         f"parameter '{name}'"),
        ("a huge array", _pm(name, type=8, double_array_value=[1.0] * 10_000),
         f"parameter '{name}': an array of 10000"),
        ("a huge string array", _pm(name, type=9, string_array_value=["x"] * 5_000), f"parameter '{name}'"),
        ("an empty name", _pm("", type=3, double_value=1.0), "parameter ''"),
        ("odd characters", _pm(odd, type=3, double_value=1.0), f"parameter '{shown(odd)}'"),
        ("a long name", _pm(long_name, type=3, double_value=1.0), f"parameter '{shown(long_name)}'"),
        ("type 99 for use_sim_time", _type99("use_sim_time"), "parameter 'use_sim_time': type code 99"),
    ]


# --- the wrapper alone (no processes) -------------------------------------------------------------

class _FakeNode:
    """What the wrapped callbacks use of a node: its declared names, set_parameters_atomically, a logger."""

    def __init__(self):
        from rcl_interfaces.msg import ParameterDescriptor
        self._parameters = {"k1": None, "boom": None}
        self._descriptors = {"k1": ParameterDescriptor(type=3, dynamic_typing=True)}
        self.calls = []
        self.reported = []
        self.rejects = lambda where, reason: self.reported.append((where, reason))

    def get_fully_qualified_name(self):
        return "/fake"

    def set_parameters_atomically(self, params):
        from rcl_interfaces.msg import SetParametersResult
        from rclpy.exceptions import ParameterNotDeclaredException
        self.calls.append([(p.name, p.value) for p in params])
        for p in params:   # as rclpy's _apply_descriptor does to a dynamically typed parameter
            if p.name in self._descriptors:
                self._descriptors[p.name].type = p.type_.value
        if any(p.name == "boom" for p in params):
            raise RuntimeError("a callback with a bug")
        undeclared = [p.name for p in params if p.name not in self._parameters]
        if undeclared:
            raise ParameterNotDeclaredException(undeclared)
        if any(p.type_.value != 3 for p in params):
            return SetParametersResult(successful=False, reason="expected a floating-point number")
        return SetParametersResult(successful=True)


class _FakeService:
    def __init__(self, node):
        self._node = node

    def _get_node(self):
        return self._node


@pytest.mark.unit
def test_the_wrapped_set_callbacks_refuse_what_they_cannot_read_and_answer_the_rest():
    from rcl_interfaces.srv import SetParameters, SetParametersAtomically
    from rclpy.parameter_service import ParameterService

    C.install()
    C.install()   # idempotent
    assert C.installed()
    node = _FakeNode()
    svc = _FakeService(node)
    request = SetParameters.Request(parameters=[
        _type99("k1"), _pm("k1", type=3, double_value=7.0), _pm("k1", type=4, string_value="x"),
        _pm("boom", type=3, double_value=1.0), _pm("tau5", type=3, double_value=1.0), _pm("k1", type=0)])
    results = ParameterService._set_parameters_callback(svc, request, SetParameters.Response()).results
    assert [r.successful for r in results] == [False, True, False, False, False, False]
    assert results[0].reason == "parameter 'k1': type code 99 is not a ROS parameter type"
    assert results[2].reason == "parameter 'k1': expected a floating-point number"
    assert results[3].reason == "parameter 'boom': RuntimeError: a callback with a bug"
    assert results[4].reason.startswith("parameter 'tau5': ") and "tau5" in results[4].reason[20:]
    assert results[5].reason.startswith("parameter 'k1': no value")
    assert node._descriptors["k1"].type == 3   # the refused string left the declared type
    # the two unreadable ones never reached the node, and were counted as rejected
    assert [c[0][0] for c in node.calls] == ["k1", "k1", "boom", "tau5"]
    assert [w for w, _ in node.reported] == ["/fake/set_parameters"] * 2

    many = SetParameters.Request(parameters=[_type99(f"p{i}") for i in range(C.MAX_PARAMETERS + 5)])
    results = ParameterService._set_parameters_callback(svc, many, SetParameters.Response()).results
    assert len(results) == C.MAX_PARAMETERS + 5 and not any(r.successful for r in results)
    assert results[0].reason == "parameter 'p0': type code 99 is not a ROS parameter type"
    assert results[-1].reason.startswith(f"parameter 'p{C.MAX_PARAMETERS + 4}': not read")

    node.calls.clear()
    atomic = SetParametersAtomically.Request(parameters=[_pm("k1", type=3, double_value=7.0), _type99("k2")])
    atomically = ParameterService._set_parameters_atomically_callback
    result = atomically(svc, atomic, SetParametersAtomically.Response()).result
    assert not result.successful and result.reason.startswith("parameter 'k2': type code 99") and not node.calls
    ok = SetParametersAtomically.Request(parameters=[_pm("k1", type=3, double_value=7.0)])
    assert atomically(svc, ok, SetParametersAtomically.Response()).result.successful


@pytest.mark.unit
def test_a_read_only_service_that_raises_answers_empty():
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter_service import ParameterService

    C.install()

    class Broken(_FakeNode):
        def get_parameter(self, name):
            raise RuntimeError("broken")

    node = Broken()
    response = ParameterService._get_parameters_callback(_FakeService(node), GetParameters.Request(names=["k1"]),
                                                         GetParameters.Response())
    assert list(response.values) == [] and "RuntimeError: broken" in node.reported[0][1]


@pytest.mark.unit
def test_parameter_from_msg_names_each_value_it_cannot_read():
    assert C.parameter_from_msg(_type99("k1")) == (None, "parameter 'k1': type code 99 is not a ROS parameter type")
    assert C.parameter_from_msg(_pm("a\x00b", type=99))[1] == \
        "parameter 'a\\x00b': type code 99 is not a ROS parameter type"
    param, problem = C.parameter_from_msg(_pm("k1", type=3, double_value=2.5))
    assert problem is None and param.name == "k1" and param.value == 2.5
    too_long = _pm("X", type=7, integer_array_value=[1] * 5000)
    assert "longer than any parameter takes" in C.parameter_from_msg(too_long)[1]
    assert C.parameter_from_msg(_pm("x" * 300, type=3))[1].endswith(f"no parameter has a name this long (at most "
                                                                    f"{C.MAX_NAME_CHARS})")
    assert C.parameter_from_msg(_pm("x" * 300, type=3), declared={"x" * 300})[1] is None


@pytest.mark.unit
def test_another_rclpy_version_is_warned_of_once(monkeypatch):
    monkeypatch.setitem(C._state, "warned", False)
    seen = []
    assert C.check_version("7.1.6", warn=seen.append) is None and not seen
    text = C.check_version("8.0.0", warn=seen.append)
    assert C.check_version("8.0.0", warn=seen.append) == text
    assert seen == [text] and "rclpy 8.0.0" in text and "7.1.6" in text
    assert C.rclpy_version() in C.WRITTEN_FOR   # the venv's rclpy is the one this was written for


@pytest.mark.cli
def test_importing_installs_nothing_and_install_is_idempotent():
    code = ("import mwip_ros.nodes.runtime.rclpy_compat as C\n"
            "from rclpy.parameter_service import ParameterService as S\n"
            "before = S._set_parameters_callback\n"
            "assert not C.installed() and not hasattr(before, '_mwip_guarded')\n"
            "C.install(); first = dict(vars(S)); C.install()\n"
            "assert C.installed() and dict(vars(S)) == first and S._set_parameters_callback.__wrapped__ is before\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "[WARN]" not in r.stderr, r.stderr   # the installed rclpy is the one it was written for


@pytest.mark.node
def test_a_real_node_refuses_each_hostile_update_by_name_and_keeps_its_values():
    """The controller in this process (test/nodeharness.py), its parameter services' callbacks called directly."""
    from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters, SetParameters

    with NodeHarness(node_class("dscndo_controller")) as h:
        node = h.node
        cases = _hostile("k1") + _hostile("nominal.m_b")
        request = SetParameters.Request(parameters=[c[1] for c in cases])
        results = h.call("/dscndo_controller/set_parameters", request).results
        assert len(results) == len(cases)
        for (label, _msg, text), result in zip(cases, results):
            assert not result.successful and text in result.reason, (label, result.reason)
        # rclpy retypes a dynamically typed parameter's descriptor before judging the value: put back when refused
        assert node._descriptors["k1"].type == 3 and node._descriptors["nominal.m_b"].type == 3
        assert node.get_parameter("k1").value == 6.0 and node.get_parameter("nominal.m_b").value > 0
        ok = SetParameters.Request(parameters=[_pm("k1", type=3, double_value=7.0)])
        assert h.call("/dscndo_controller/set_parameters", ok).results[0].successful
        assert node.get_parameter("k1").value == 7.0
        names = ["", "odd name/\t\x01", "n" * 2_000, "k1"] * 500
        assert len(h.call("/dscndo_controller/describe_parameters",
                          DescribeParameters.Request(names=["k1"] * 3000)).descriptors) == 3000
        h.call("/dscndo_controller/describe_parameters", DescribeParameters.Request(names=names))
        h.call("/dscndo_controller/get_parameters", GetParameters.Request(names=names))
        h.call("/dscndo_controller/list_parameters", ListParameters.Request(prefixes=names[:8], depth=2 ** 64 - 1))
        got = h.call("/dscndo_controller/get_parameters", GetParameters.Request(names=["k1"]))
        assert [v.double_value for v in got.values] == [7.0]


@pytest.mark.unit
def test_the_recorders_and_live_views_loop_goes_on_after_a_callback_raised(monkeypatch):
    """TopicTap.spin (mcap_recorder, foxglove_server): an exception from a callback is logged, the loop goes on;
    only an executor that raises on every turn for BROKEN_AFTER_S ends the run."""
    from mwip_ros.nodes.tools import tap

    class Log:
        def __init__(self):
            self.errors = []

        def error(self, text):
            self.errors.append(text)

        info = warning = error

    class FakeNode:
        log = Log()

        def get_logger(self):
            return self.log

    class Executor:
        def __init__(self, *outcomes):
            self.outcomes = list(outcomes)

        def spin_once(self, timeout_sec):
            if self.outcomes.pop(0):
                raise ValueError("99 is not a valid Parameter.Type")

    node = FakeNode()
    t = tap.TopicTap(node, [], lambda *a: None)
    failed = []
    ex = Executor(True, False, True)
    for _ in range(3):
        t.spin(ex, lambda: 0, lambda: "", failed.append)
    assert not failed and t.callback_errors == 2
    assert "ValueError: 99 is not a valid Parameter.Type" in node.log.errors[0] and "going on" in node.log.errors[0]
    monkeypatch.setattr(tap, "BROKEN_AFTER_S", 0.0)
    t.spin(Executor(True), lambda: 0, lambda: "", failed.append)
    assert len(failed) == 1 and "raised on every turn" in failed[0]


# --- every node kind, in this process ----------------------------------------------------------------

def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


NODES = {   # label: (node, its fully qualified name, extra ROS arguments, the parameters to attack)
    "plant_sim": ("plant_sim", "/lone/plant_sim", ("-r", "__ns:=/lone"), ("nominal.m_b",)),
    "disturbance_observer": ("disturbance_observer", "/disturbance_observer", (), ("nominal.m_b", "X")),
    "dscndo_controller": ("dscndo_controller", "/dscndo_controller", (), ("k1", "nominal.m_b")),
    "mcap_recorder": ("mcap_recorder", "/mcap_recorder", (), ("chunk_size",)),
    "robot_markers": ("robot_markers", "/robot_markers", (), ("nominal.m_b",)),
    "foxglove_server": ("foxglove_server", "/foxglove_server", (), ("nominal.m_b",)),
}


def _attack(h, target: str, names) -> list:
    """Every hostile request at ``target`` (its parameter services' callbacks, ``h.call``); the problems found
    (empty: each refused, naming the parameter)."""
    from rcl_interfaces.srv import (DescribeParameters, GetParameters, GetParameterTypes, ListParameters,
                                    SetParameters, SetParametersAtomically)
    problems = []
    for name in names:
        cases = _hostile(name, scalar=name != "X")
        results = h.call(f"{target}/set_parameters", SetParameters.Request(parameters=[c[1] for c in cases])).results
        if len(results) != len(cases):
            problems.append(f"{target}: {len(results)} results for {len(cases)} parameters")
        for (label, _msg, text), result in zip(cases, results):
            if result.successful or text not in result.reason:
                problems.append(f"{target} {name} {label}: {result.successful} {result.reason[:200]!r}")
    many = h.call(f"{target}/set_parameters", SetParameters.Request(
        parameters=[_type99(f"{names[0]}_{i}") for i in range(3000)])).results
    if len(many) != 3000 or any(r.successful for r in many) or "type code 99" not in many[0].reason:
        problems.append(f"{target}: 3000 type-99 parameters: {len(many)} results, {many[0].reason if many else ''!r}")
    atomic = h.call(f"{target}/set_parameters_atomically", SetParametersAtomically.Request(
        parameters=[_pm(names[0], type=3, double_value=1.0), _type99(names[0])])).result
    if atomic.successful or f"parameter '{names[0]}': type code 99" not in atomic.reason:
        problems.append(f"{target}: set_parameters_atomically: {atomic.reason!r}")
    odd = ["", "odd name/\t\x01\u2603", "n" * 2_000, "~/x", "..", names[0]] * 200
    h.call(f"{target}/get_parameters", GetParameters.Request(names=odd))
    h.call(f"{target}/describe_parameters", DescribeParameters.Request(names=odd))
    h.call(f"{target}/get_parameter_types", GetParameterTypes.Request(names=odd))
    h.call(f"{target}/list_parameters", ListParameters.Request(prefixes=odd[:12], depth=2 ** 64 - 1))
    return problems


@pytest.mark.node
@pytest.mark.parametrize("label", list(NODES))
def test_every_node_refuses_hostile_parameter_requests_naming_the_parameter_and_goes_on(tmp_path, label):
    """Each node kind in this process, attacked through its own parameter services (the callbacks rclpy's executor
    would run): every hostile parameter refused, naming it; a valid read answered after; nothing raised, nothing
    logged as a broken callback; the recorder still records what comes after the attack."""
    from rcl_interfaces.msg import ParameterType
    from rcl_interfaces.srv import GetParameters

    from mwip_ros.bag import topic_counts
    from mwip_ros.core.plants.model import State
    from mwip_ros.msgs import layouts as L

    node, fqn, args, names = NODES[label]
    bag = tmp_path / "bag"
    extra = {"mcap_recorder": ("-p", f"output:={bag}"), "foxglove_server": ("-p", f"port:={_free_port()}")}
    with NodeHarness(node_class(node), *args, *extra.get(label, ()),
                     params=None if label == "mcap_recorder" else PARAMS) as h:
        problems = _attack(h, fqn, names)
        got = h.call(f"{fqn}/get_parameters", GetParameters.Request(names=["use_sim_time", names[0]])).values
        if [v.type for v in got][:1] != [ParameterType.PARAMETER_BOOL] or len(got) != 2:
            problems.append(f"{fqn}: a valid get after the attack answered {got}")
        if label == "mcap_recorder":   # it still records: what comes now is in the bag it closes
            for k in range(20):
                assert h.feed("joint_states", L.encode_state(k * 5_000_000, State(0.0, 0.01, 0.0, 0.0), 0.0)) == 1
        assert not h.node.done, h.logs()[-3000:]
    logs = h.logs()
    assert not problems, "\n".join(problems)
    assert "is not a valid Parameter.Type" not in logs and "Traceback" not in logs, logs[-3000:]
    assert f"rejected message #1 on {fqn}/set_parameters: parameter '{names[0]}': type code 99" in logs, logs[-3000:]
    assert "recorder error" not in logs and "foxglove_server error" not in logs
    if label == "mcap_recorder":
        assert topic_counts(bag).get("/joint_states") == 20, (topic_counts(bag), logs[-3000:])


# --- re-simulation of a bag whose /parameter_events carries a value of type code 99 ------------------

def _event(node: str, stamp_ns: int, *changed):
    from builtin_interfaces.msg import Time
    from rcl_interfaces.msg import ParameterEvent
    from rclpy.serialization import serialize_message
    ev = ParameterEvent(stamp=Time(sec=stamp_ns // 10 ** 9, nanosec=stamp_ns % 10 ** 9), node=node,
                        changed_parameters=list(changed))
    return serialize_message(ev)


@pytest.mark.graph
def test_resim_skips_a_recorded_value_it_cannot_set_and_completes(tmp_path):
    from mwip_ros.bag import BagWriter
    from mwip_ros.core.plants.model import State
    from mwip_ros.msgs import layouts as L

    bag = tmp_path / "hostile_events"
    with BagWriter(bag) as w:
        w.add_topic("/joint_states", "sensor_msgs/msg/JointState")
        w.add_topic("/parameter_events", "rcl_interfaces/msg/ParameterEvent")
        for k in range(20):
            w.write("/joint_states", L.encode_state(k * 5_000_000, State(0.0, 0.01, 0.0, 0.0), 0.0),
                    10 ** 9 + k * 5_000_000)
            if k == 4:   # a type-99 value beside a good one; later a NaN gain the controller refuses
                w.write("/parameter_events", _event("/dscndo_controller", 22_000_000, _type99("k2"),
                                                    _pm("k1", type=3, double_value=7.0)), 10 ** 9 + k * 5_000_000 + 1)
            if k == 10:
                nan_k1 = _pm("k1", type=3, double_value=math.nan)
                w.write("/parameter_events", _event("/dscndo_controller", 52_000_000, nan_k1),
                        10 ** 9 + k * 5_000_000 + 1)
    with Graph(tmp_path) as g:
        ctl = g.start("dscndo_controller", "-p", "use_sim_time:=true", "-p", "use_observer:=false")
        br = g.start("bag_replay", "-p", f"bag:={bag}", "-p", "mode:=resim", params=None, module=MODULE)
        code = br.wait(120)
        ctl_alive = ctl.poll() is None
    out = br.output()
    assert code == 0 and "RESULT: REPRODUCED" in out and "states fed: 20 of 20" in out, out[-3000:]
    assert ("recorded parameter values skipped (they cannot be set): 1 (/dscndo_controller at t = 0.022 s: "
            "parameter 'k2': type code 99 is not a ROS parameter type)") in out, out[-3000:]
    assert "skipped a recorded parameter value of /dscndo_controller" in out
    assert "recorded parameter changes applied: 1" in out, out[-3000:]
    assert "recorded parameter values refused by the running node: 1 (/dscndo_controller: parameter 'k1'" in out, \
        out[-3000:]
    assert ctl_alive and "k1: 6.0 -> 7.0" in ctl.output(), ctl.output()[-3000:]
    assert "Traceback" not in ctl.output() + out
