"""robot_state with the lockstep loop and the realistic raw sensors: odom follows the true wheel within the
drift measured offline (test/core/mobile_base/test_odometry.py: at most 1.3 mm over the paper's 10 s, 0.67 mm at the
end), robot_description is latched for a late subscriber and parses, the wheel joint states carry phi, and a bad state
is rejected, never integrated. In this process: the loop's nodes and robot_state wired by their topics
(test/nodeharness.py's Loop), a late reader a peer in robot_state's own participant (robot_state across processes:
test_yaw_graph.py, test_foxglove_frames_graph.py)."""
from __future__ import annotations

import math

import pytest
from nav_msgs.msg import Odometry
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from graphproc import PARAMS
from mwip_ros.runs import load_run
from nodeharness import Loop, NodeHarness, node_class

pytestmark = pytest.mark.node

RAW = (PARAMS, PARAMS.parent / "sensors_raw_realistic.yaml")
LATE = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                  durability=DurabilityPolicy.TRANSIENT_LOCAL)


def test_odom_matches_the_true_pose_and_the_description_is_latched(tmp_path):
    urdf_parser = pytest.importorskip("urdf_parser_py.urdf")
    csv_path = tmp_path / "graph.csv"
    with NodeHarness(node_class("robot_state"), params=RAW) as rs:
        with Loop("-p", "duration_s:=3.0", "-p", f"csv:={csv_path}", params=RAW) as loop:
            loop.wire.harnesses.append(rs)   # robot_state hears what the loop publishes (the estimator's states)
            loop.start()
            assert loop.run(), loop.plant.logs()[-3000:]
            assert loop.plant.node.exit_code == 0, loop.plant.logs()[-3000:]
        # a reader that joins after the run: what is latched or kept
        odom = rs.listen("odom", Odometry, qos=LATE, name="late_reader")
        desc = rs.listen("robot_description", String, qos=LATE, name="late_reader")
        wheels = rs.listen("wheel_joint_states", JointState, qos=LATE, name="late_reader")
        # the run's last state (3 s) reaches the late reader too: the publisher keeps the run's history
        assert rs.spin(lambda: odom and odom[-1].header.stamp.sec == 3 and desc and wheels, 10), (
            len(odom), len(desc), len(wheels))
    out = rs.logs()
    assert "rectangle rule" in out   # raw sensors (plant_sim's sensors.model in the same files): the period's rates
    assert "tf2_msgs is not installed" in out or rs.sent("/tf")   # one line when tf2_msgs is missing
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


def test_a_bad_state_is_rejected_and_a_reset_restarts_the_odometry():
    from mwip_ros.core.plants.model import State
    from mwip_ros.msgs import layouts as L
    with NodeHarness(node_class("robot_state")) as rs:
        rs.feed("joint_states", L.encode_state(0, State(0.0, 0.0, 4.0, 0.0), 0.0))
        rs.feed("joint_states", b"\x00\x01\x00\x00garbage")
        for k in range(1, 101):   # 0.5 s at 4 rad/s, a period apart (a stamp a window ahead is a stray: rejected)
            rs.feed("joint_states", L.encode_state(k * 5_000_000, State(0.02 * k, 0.0, 4.0, 0.0), 0.0))
        got = rs.messages("odom", Odometry)
        assert got[-1].pose.pose.position.x == pytest.approx(0.254 * 4.0 * 0.5, abs=1e-12)
        for k in range(3):   # stamps back at the start, three that agree (issue 46 item 4): a reset
            rs.feed("joint_states", L.encode_state(k * 5_000_000, State(0.0, 0.0, 0.0, 0.0), 0.0))
        got = rs.messages("odom", Odometry)
    assert len(got) > 101 and got[-1].pose.pose.position.x == 0.0   # the odometry restarted at the origin
    out = rs.logs()
    assert "rejected message #1 on joint_states" in out and "restarts at the origin" in out
    assert "trapezoid rule" in out   # the plant's state (the default): instantaneous rates
