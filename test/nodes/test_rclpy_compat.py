"""Each use of an rclpy internal (mwip_ros.nodes.runtime.rclpy_compat) against the rclpy installed: the private
attribute exists with the shape it was written for, rclpy still behaves as the patch assumes, and the
patched behaviour is what the nodes rely on.  A test here that fails after an rclpy upgrade names the
function to revisit.  (The parameter-service callbacks: test_param_hostile.py.)"""
from __future__ import annotations

import inspect
import subprocess
import sys

import pytest

from mwip_ros.nodes.runtime import rclpy_compat as C


class _PlainNode:
    """A plain rclpy node (no use_sim_time) for the harness: made in its private context, no discovery."""

    def __new__(cls, context=None, argv=()):
        from rclpy.node import Node
        return Node("compat_test", context=context)


@pytest.fixture
def node():
    """A real rclpy node (no use_sim_time, two -p rules) in a private context (test/nodeharness.py), destroyed
    afterwards."""
    from nodeharness import NodeHarness
    with NodeHarness(_PlainNode, "-p", "k1:=7.5", "-p", "other:=1", params=None, as_given=True,
                     name="compat_test") as h:
        yield h.node


@pytest.mark.unit
def test_the_rclpy_is_the_one_written_for():
    assert C.rclpy_version() in C.WRITTEN_FOR


@pytest.mark.node
def test_parameter_overrides_are_rclpys_start_up_values_and_what_declare_takes(node):
    from rclpy.parameter import Parameter

    overrides = C.parameter_overrides(node)
    assert overrides is node._parameter_overrides and isinstance(overrides, dict)
    assert set(overrides) == {"k1", "other"} and all(isinstance(p, Parameter) for p in overrides.values())
    assert overrides["k1"].value == 7.5 and overrides["k1"].name == "k1"
    assert node.declare_parameter("k1", 6.0).value == 7.5            # declare takes the override
    overrides["k2"] = Parameter("k2", value=3.0)                       # what params.declare puts in it
    assert node.declare_parameter("k2", 1.0).value == 3.0
    with pytest.raises(C.RclpyChanged, match="_parameter_overrides"):
        C.parameter_overrides(object())


@pytest.mark.node
def test_undeclared_names_are_named_where_rclpy_names_none(node):
    from rclpy.exceptions import ParameterNotDeclaredException
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    assert list(inspect.signature(Node._check_undeclared_parameters).parameters) == ["self", "parameter_list"]
    assert isinstance(node._parameters, dict)
    node.declare_parameter("k1", 6.0)
    with pytest.raises(ParameterNotDeclaredException) as rclpys:     # rclpy's own check: names nothing
        node.set_parameters([Parameter("k3", value=1.0)])
    assert "k3" not in str(rclpys.value)   # when rclpy names it itself, the patch can go

    C.name_undeclared_parameters(node, lambda name: " (did you mean 'k1'?)" if name == "k3" else "")
    with pytest.raises(ParameterNotDeclaredException) as ours:
        node.set_parameters([Parameter("k3", value=1.0)])
    assert "k3 (did you mean 'k1'?)" in str(ours.value)
    with pytest.raises(ParameterNotDeclaredException, match="k4"):
        node.set_parameters_atomically([Parameter("k1", value=2.0), Parameter("k4", value=1.0)])
    assert node.get_parameter("k1").value == 7.5                      # nothing of a refused request was set
    assert node.set_parameters([Parameter("k1", value=2.0)])[0].successful   # a declared one goes through
    assert node.get_parameter("k1").value == 2.0
    with pytest.raises(C.RclpyChanged, match="_check_undeclared_parameters"):
        C.name_undeclared_parameters(object())


@pytest.mark.node
def test_a_clock_without_sim_time_reads_what_the_node_sets(node):
    from rclpy.clock import ROSClock
    from rclpy.time import Time

    assert list(inspect.signature(ROSClock._set_ros_time_is_active).parameters) == ["self", "enabled"]
    clock = node.get_clock()
    assert isinstance(clock, ROSClock)
    clock.set_ros_time_override(Time(nanoseconds=5))
    assert not clock.ros_time_is_active and clock.now().nanoseconds != 5   # an override alone does nothing
    C.use_ros_time_override(clock)
    assert clock.ros_time_is_active and clock.now().nanoseconds == 5
    clock.set_ros_time_override(Time(nanoseconds=1_000_000_123))
    assert clock.now().nanoseconds == 1_000_000_123
    with pytest.raises(C.RclpyChanged, match="_set_ros_time_is_active"):
        C.use_ros_time_override(object())


def _clock_msg(ns):
    from rosgraph_msgs.msg import Clock as ClockMsg

    msg = ClockMsg()
    sec, nanosec = divmod(ns, 1_000_000_000)
    # the message's sec is an int32: a negative time is a negative sec with nanosec in [0, 1e9)
    msg.clock.sec, msg.clock.nanosec = sec, nanosec
    return msg


@pytest.mark.node
def test_the_clock_guard_rejects_what_rclpys_time_source_raises_on(node):
    from rclpy.clock import ClockType, ROSClock
    from rclpy.time_source import TimeSource

    C.guard_clock()
    C.guard_clock()   # idempotent
    assert C.clock_guarded()
    guarded = TimeSource.clock_callback
    original = guarded.__wrapped__
    assert not getattr(original, "_mwip_guarded", False)
    assert list(inspect.signature(original).parameters) == ["self", "msg"]
    assert callable(TimeSource._get_node)

    bare = TimeSource()
    with pytest.raises(ValueError):        # rclpy's own callback on a negative /clock: raised in the executor
        original(bare, _clock_msg(-1))

    seen = []
    node.rejects = lambda topic, reason: seen.append((topic, reason))
    source = TimeSource(node=node)
    clock = ROSClock()
    assert clock.clock_type == ClockType.ROS_TIME
    source.attach_clock(clock)
    source.ros_time_is_active = True
    guarded(source, _clock_msg(2_000_000_000))
    assert clock.now().nanoseconds == 2_000_000_000
    guarded(source, _clock_msg(-1))                      # negative: rejected, counted, the clock keeps its time
    guarded(source, _clock_msg(1_000_000_000))           # backwards
    guarded(source, _clock_msg(5_000_000_000))           # more than a second ahead
    assert clock.now().nanoseconds == 2_000_000_000
    assert [t for t, _ in seen] == ["/clock"] * 3 and "negative" in seen[0][1], seen
    guarded(source, _clock_msg(2_000_000_000))           # a resend: dropped, not rejected
    guarded(source, _clock_msg(2_500_000_000))
    assert clock.now().nanoseconds == 2_500_000_000 and len(seen) == 3


@pytest.mark.cli
def test_importing_patches_nothing_and_install_patches_the_clock_too():
    code = ("import importlib\n"
            "from rclpy.node import Node\n"
            "from rclpy.time_source import TimeSource\n"
            "check, callback = Node._check_undeclared_parameters, TimeSource.clock_callback\n"
            "for m in ('runtime.rclpy_compat', 'runtime.entry', 'runtime.process', 'runtime.params',\n"
            "          'runtime.guards', 'loop.plant_sim', 'loop.disturbance_observer', 'loop.dscndo_controller',\n"
            "          'tools.mcap_recorder', 'tools.bag_replay', 'tools.robot_markers', 'tools.foxglove_server'):\n"
            "    importlib.import_module('mwip_ros.nodes.' + m)\n"
            "import mwip_ros.nodes.runtime.rclpy_compat as C\n"
            "assert not C.installed() and not C.clock_guarded()\n"
            "assert Node._check_undeclared_parameters is check and TimeSource.clock_callback is callback\n"
            "C.install()\n"
            "assert C.installed() and C.clock_guarded() and TimeSource.clock_callback.__wrapped__ is callback\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
