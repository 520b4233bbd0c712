"""robot_state with the lockstep graph and the realistic raw sensors: odom follows the true wheel within the
drift measured offline (test/core/test_odometry.py: at most 1.3 mm over the paper's 10 s, 0.67 mm at the end),
robot_description is latched for a late subscriber and parses, the wheel joint states carry phi, and a bad state
is rejected, never integrated."""
from __future__ import annotations

import math

import pytest
from nav_msgs.msg import Odometry
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from graphproc import PARAMS, Graph, run_lockstep
from injector import Injector
from mwip_ros.runs import load_run

pytestmark = pytest.mark.graph

RAW = (PARAMS, PARAMS.parent / "sensors_raw_realistic.yaml")
LATE = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                  durability=DurabilityPolicy.TRANSIENT_LOCAL)


def test_odom_matches_the_true_pose_and_the_description_is_latched(tmp_path):
    urdf_parser = pytest.importorskip("urdf_parser_py.urdf")
    with Graph(tmp_path) as g:
        node = g.start("robot_state", params=RAW)
        assert node.wait_for_output("robot state ready", 30), node.output()

        def until_integrated(plant, timeout):
            """The plant's exit, once robot_state has the run's last state: its input is the state estimator's
            joint_states, whose writer keeps the run only while the estimator runs (run_lockstep stops it when the
            plant is done); under load robot_state's reader can match it after the plant has ended."""
            code = plant.wait(timeout)
            if code != 0:   # the caller's assertion names the plant's failure, not a wait for states never sent
                return code
            with Injector(g.domain_id, name="run_reader") as inj:
                seen = []
                inj.node.create_subscription(Odometry, "odom", seen.append, LATE)
                assert inj.wait(lambda: seen and seen[-1].header.stamp.sec == 3, 60), (len(seen), node.output())
            return code

        code, csv_path, logs = run_lockstep(tmp_path, True, "-p", "duration_s:=3.0", params=RAW, law="dsc",
                                            domain_id=g.domain_id, wait=until_integrated)
        assert code == 0, logs["plant_sim"].output()
        with Injector(g.domain_id, name="late_reader") as inj:   # joins after the run: what is latched or kept
            odom, desc, wheels = [], [], []
            inj.node.create_subscription(Odometry, "odom", odom.append, LATE)
            inj.node.create_subscription(String, "robot_description", desc.append, LATE)
            inj.node.create_subscription(JointState, "wheel_joint_states", wheels.append, LATE)
            # the run's last state (3 s) reaches the late reader too: the publisher keeps the run's history
            assert inj.wait(lambda: odom and odom[-1].header.stamp.sec == 3 and desc and wheels, 60), (
                len(odom), len(desc), len(wheels))
        assert node.stop() == 0
    out = node.output()
    assert "rectangle rule" in out   # raw sensors (plant_sim's sensors.model in the same files): the period's rates
    assert "tf2_msgs is not installed" in out or "/tf" not in out   # one line when tf2_msgs is missing
    assert out.count("tf2_msgs is not installed") <= 1
    run = load_run(csv_path)
    assert len(run) == 601
    last = odom[-1]
    assert (last.header.frame_id, last.child_frame_id) == ("odom", "base_link")
    t = last.header.stamp.sec + last.header.stamp.nanosec * 1e-9
    k = int(round(t / 0.005))
    assert k == 600   # the last state of the 3 s run
    true_x = 0.254 * (run.columns["theta_w"][k] - run.columns["theta_w"][0])
    assert abs(true_x) > 0.3                                         # it rolled: the comparison means something
    assert abs(last.pose.pose.position.x - true_x) < 1.3e-3          # the drift measured offline: at most 1.3 mm
    assert last.pose.pose.position.y == 0.0 and last.pose.pose.position.z == 0.254
    # the orientation: no yaw, pitched by theta_b (the estimate, within 0.02 rad of the truth)
    q = last.pose.pose.orientation
    assert q.x == 0.0 and q.z == 0.0
    assert abs(2 * math.atan2(q.y, q.w) - run.columns["theta_b"][k]) < 0.02
    assert last.pose.covariance[0] > 0.0 and last.twist.covariance[0] > 0.0   # 4096 counts, gyro noise 0.004
    robot = urdf_parser.URDF.from_xml_string(desc[0].data)
    assert robot.link_map["base_link"].inertial.mass == 310.6       # config/paper.yaml's plant_sim section
    js = wheels[-1]
    assert list(js.name) == ["wheel_left_joint", "wheel_right_joint"]
    assert js.position[0] == js.position[1]


def test_a_bad_state_is_rejected_and_a_reset_restarts_the_odometry(tmp_path):
    from mwip_ros.core.model import State
    from mwip_ros.msgs import layouts as L
    with Graph(tmp_path) as g:
        node = g.start("robot_state")
        with Injector(g.domain_id) as inj:
            js = inj.publisher("joint_states", JointState)
            got = []
            sub = inj.node.create_subscription(Odometry, "odom", got.append, LATE)
            assert inj.wait(lambda: js.get_subscription_count() >= 1 and sub.get_publisher_count() >= 1, 30)
            js.publish(L.encode_state(0, State(0.0, 0.0, 4.0, 0.0), 0.0))
            js.publish(b"\x00\x01\x00\x00garbage")
            for k in range(1, 101):   # 0.5 s at 4 rad/s, a period apart (a stamp a window ahead is a stray: rejected)
                js.publish(L.encode_state(k * 5_000_000, State(0.02 * k, 0.0, 4.0, 0.0), 0.0))
            x_end = 0.254 * 4.0 * 0.5
            # the last odom (its reader keeps the newest 10) at the end of the 0.5 s
            assert inj.wait(lambda: got and got[-1].pose.pose.position.x == pytest.approx(x_end, abs=1e-12), 30), \
                node.output()
            for k in range(3):   # stamps back at the start, three that agree (issue 46 item 4): a reset
                js.publish(L.encode_state(k * 5_000_000, State(0.0, 0.0, 0.0, 0.0), 0.0))
            assert inj.wait(lambda: got[-1].pose.pose.position.x == 0.0, 30), node.output()
        assert node.stop() == 0
    out = node.output()
    assert "rejected message #1 on joint_states" in out and "restarts at the origin" in out
    assert "trapezoid rule" in out   # the plant's state (the default): instantaneous rates
