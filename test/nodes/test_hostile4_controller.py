"""The controller node against hostile input, in this process (test/nodeharness.py), issue 46:

* item 1: it reads the plant's ``driver_state``: while no torque acts, cmd_vel is not taken, the references hold at
  the measured state and the yaw integral stays zero; on enable they start from the measured state;
* item 2: its side inputs (``cmd_vel``, ``driver_state``) are read with each state, not served by the executor;
* item 10: a state whose command is not finite leaves the motion references as they were.
"""
import json
import math
from pathlib import Path

import pytest

from mwip_ros.msgs import cdr
from mwip_ros.msgs import layouts as L
from nodeharness import NodeHarness, node_class

pytestmark = pytest.mark.node

CONFIG = Path(__file__).resolve().parents[2] / "config"
H_NS = 5_000_000   # the control period of config/paper.yaml [ns]
REST = (0.0, 0.0, 0.0, 0.0)
MOTION = ("-p", "motion.enabled:=true", "-p", "use_observer:=false")


def _driver(state: str) -> bytes:
    return cdr.encode_string(json.dumps({"state": state, "from": None, "reason": "test"}))


def _controller(*extra):
    return NodeHarness(node_class("dscndo_controller"), *MOTION, *extra)


def _ref(h):
    """The references the last state was answered with (the node's Shaper)."""
    return h.node.motion.ref


def test_disabled_driver_holds_the_references_and_the_yaw_integral_and_enable_starts_from_rest():
    with _controller() as h:
        h.feed("driver_state", _driver("disabled"))
        k = 1
        # 4 s of cmd_vel at 20 Hz (1.0 m/s, 0.5 rad/s) while disabled, the robot at rest (a spatial plant's states:
        # the gyro's yaw rate 0), then 1 s of silence
        for k in range(1, 1001):
            if k <= 800 and k % 10 == 0:
                h.feed("cmd_vel", L.encode_twist(1.0, 0.5))
            h.feed("joint_states", L.encode_state(k * H_NS, REST, 0.0, 0.0))
        got = _ref(h)
        assert got.v == 0.0 and got.dpsi == 0.0 and got.theta_w == 0.0, got
        assert h.node.yaw.integral == 0.0
        assert h.node.motion.accepted == 0 and h.node.ignored == 80
        assert "cmd_vel while the driver is disabled: not taken" in h.logs()
        h.feed("driver_state", _driver("enabled"))
        before = len(h.sent("wheel_torques_cmd"))
        for k in range(1001, 1201):   # 1 s enabled, at rest
            h.feed("joint_states", L.encode_state(k * H_NS, REST, 0.0, 0.0))
        pairs = [L.parse_wheel_torques(d)[1:] for d in h.sent("wheel_torques_cmd")[before:]]
        assert len(pairs) == 200
        assert max(abs(u) for pair in pairs for u in pair) < 1.0, pairs[:5]   # at rest: what rest needs (~0)
        got = _ref(h)
        assert got.v == 0.0 and got.theta_w == 0.0, got
        # enabled, a command is taken again and the reference ramps from rest at max_accel
        h.feed("cmd_vel", L.encode_twist(1.0, 0.0))
        h.feed("joint_states", L.encode_state(1201 * H_NS, REST, 0.0, 0.0))
        assert h.node.motion.accepted == 1
        assert 0.0 < _ref(h).v <= 0.5 * 0.005 + 1e-12   # one period of max_accel from rest


def test_the_references_follow_the_measured_wheel_while_in_fault():
    """A fault (the driver publishes fault) while the wheel turns: the position target stays at the measured wheel
    angle, so enabling again (after a reset) asks for no return to where the references had run to."""
    with _controller() as h:
        h.feed("driver_state", _driver("enabled"))
        for k in range(1, 201):
            if k % 10 == 0:
                h.feed("cmd_vel", L.encode_twist(0.5, 0.0))
            h.feed("joint_states", L.encode_state(k * H_NS, REST, 0.0))
        assert _ref(h).v > 0.0
        h.feed("driver_state", _driver("fault"))
        for k in range(201, 301):
            h.feed("cmd_vel", L.encode_twist(0.5, 0.0))
            x = (0.01 * (k - 200), 0.0, 2.0, 0.0)   # the wheel still turning as the robot coasts
            h.feed("joint_states", L.encode_state(k * H_NS, x, 0.0))
            got = _ref(h)
            assert got.v == 0.0 and got.theta_w == pytest.approx(x[0]), (k, got)


def test_a_driver_state_that_is_not_one_is_rejected_and_changes_nothing():
    with _controller() as h:
        h.feed("driver_state", _driver("disabled"))
        for bad in (cdr.encode_string("{not json"), cdr.encode_string(json.dumps({"state": "armed"})),
                    cdr.encode_string(json.dumps([1, 2])), cdr.encode_string("[" * 5000 + "]" * 5000), b"\x00\x01"):
            h.feed("driver_state", bad)
        h.feed("joint_states", L.encode_state(H_NS, REST, 0.0))
        assert h.node.driver == "disabled"
        assert h.node.rejects.counts.get("driver_state") == 5


def test_the_side_inputs_are_not_served_by_the_executor():
    """cmd_vel and driver_state are read with each state (rclpy_compat.PolledInput), so a flood of them queues
    nothing in front of joint_states: they are not among the subscriptions an executor serves."""
    with _controller() as h:
        served = {s.topic_name for s in h.node.subscriptions}
        polled = {p.topic_name for p in h.node.polled_inputs}
        assert {"/cmd_vel", "/driver_state"} <= polled and not ({"/cmd_vel", "/driver_state"} & served), served
        assert "/joint_states" in served


def test_a_refused_command_leaves_the_motion_references_as_they_were():
    """Item 10: a state for which the law gives no finite command is not a period: the law's state is restored, and
    so are the references (before, the Shaper had advanced: the next state's references skipped a period)."""
    with _controller() as h:
        for k in range(1, 21):
            if k % 10 == 1:
                h.feed("cmd_vel", L.encode_twist(1.0, 0.0))
            h.feed("joint_states", L.encode_state(k * H_NS, REST, 0.0))
        before = h.node.motion.snapshot()
        law = h.node.ctrl
        law.step = lambda x, tau_hat=None: (math.nan, {})   # a law that gives no number for this state
        h.feed("joint_states", L.encode_state(21 * H_NS, REST, 0.0))
        assert "gives no finite command" in h.logs()
        assert h.node.motion.snapshot() == before
        del law.step
        h.feed("joint_states", L.encode_state(22 * H_NS, REST, 0.0))   # the next state takes up the same period
        assert h.node.motion.k == before["k"] + 2



def test_the_yaw_stage_takes_the_drives_wheel_limit_from_plant_sims_section(tmp_path):
    """Item 9: the controller reads plant_sim's drive from the same files (torque_limit, the motor): 0 = the drive's
    own wheel limit, more than it is taken down to it (a warning)."""
    drive = tmp_path / "drive.yaml"
    drive.write_text("plant_sim:\n  ros__parameters:\n    motor: {enabled: true}\n")   # 120 N m: 60 a wheel
    with NodeHarness(node_class("dscndo_controller"), *MOTION, params=[CONFIG / "paper.yaml", drive]) as h:
        assert h.node.yaw.cfg.wheel_limit == pytest.approx(60.0)
    with NodeHarness(node_class("dscndo_controller"), *MOTION, params=[CONFIG / "paper.yaml", CONFIG / "drive.yaml"],
                     as_given=False) as h:
        assert h.node.yaw.cfg.wheel_limit == pytest.approx(150.0)   # config/drive.yaml: torque_limit 300
    with NodeHarness(node_class("dscndo_controller"), *MOTION, "-p", "motion.yaw_wheel_limit:=61.0",
                     params=[CONFIG / "paper.yaml", drive]) as h:   # more than the drive's: the drive's, said
        assert h.node.yaw.cfg.wheel_limit == pytest.approx(60.0)
        assert "more than the drive gives a wheel" in h.logs("WARN")
