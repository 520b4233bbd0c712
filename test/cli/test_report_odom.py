"""mwip_report with robot_state's odom in the bag: its drift from the true pose (docs/theory.md 6.12)."""
from __future__ import annotations

import math

import pytest

from bagcheck import graph_topics, write_bag, write_graph_bag
from mwip_ros.cli import report
from mwip_ros.msgs import cdr
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.errors import BadMessage
from mwip_ros.runs import read_bag_run

pytestmark = pytest.mark.unit


def test_the_odometry_codec_reads_what_rclpy_writes():
    from nav_msgs.msg import Odometry
    from rclpy.serialization import serialize_message
    m = Odometry()
    m.header.stamp.sec, m.header.stamp.nanosec = 3, 7
    m.header.frame_id, m.child_frame_id = "odom", "base_link"
    m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z = 1.5, -0.25, 0.254
    m.pose.pose.orientation.y, m.pose.pose.orientation.w = 0.6, 0.8
    data = serialize_message(m)
    assert cdr.decode_odometry(data) == (3_000_000_007, "odom", "base_link", (1.5, -0.25, 0.254, 0.0, 0.6, 0.0, 0.8))
    assert L.parse_odometry(data) == (3_000_000_007, 1.5, -0.25, 0.254)
    m.child_frame_id = "world"
    with pytest.raises(BadMessage, match="expected 'odom' -> 'base_link'"):
        L.parse_odometry(serialize_message(m))
    m.child_frame_id, m.pose.pose.position.x = "base_link", math.nan
    with pytest.raises(BadMessage, match="non-finite"):
        L.parse_odometry(serialize_message(m))
    with pytest.raises(BadMessage):
        L.parse_odometry(data[:20])


def test_the_report_states_the_drift(tmp_path):
    # bagcheck's graph bag without a spatial plant's true_pose: message i of every topic at stamp i s; the state's
    # theta_w = 0.1 i (a state for odd i only: bagcheck gives the even ones no effort, which a state needs), the odom's
    # x = 0.1 i, z (= r) 0.254, y 0: from stamp 1 to 5 the truth moved 0.254 * 0.4 = 0.1016 m, the odom 0.4 m
    bag = tmp_path / "b"
    write_bag(bag, {t: ty for t, ty in graph_topics().items() if t != "/true_pose"}, n=7)
    run = read_bag_run(bag)
    odo = run.record["odometry"]
    assert odo["t_s"] == pytest.approx(4.0)
    assert odo["odom_x_m"] == pytest.approx(0.4) and odo["true_x_m"] == pytest.approx(0.1016)
    assert odo["drift_m"] == pytest.approx(0.2984)
    out = report.write_report([run], tmp_path / "rep", gif_fps=None)
    note = out["notes"][run.label][-1]
    assert note == "odom drifts 0.2984 m from the true pose over 4.000 s (x 0.4 m against 0.1016 m)"
    assert note in (tmp_path / "rep" / "metrics.md").read_text()


def test_with_a_true_pose_the_drift_is_from_it(tmp_path):
    """A spatial plant's bag (backend mujoco): the truth is true_pose's (x, y), here x = 0.1 i, y = -0.05 i at every
    stamp: from stamp 0 to 6 it moved (0.6, -0.3) m, the odom (0.6, 0) m: 0.3 m apart (r theta_w, which ignores slip
    and turns, would say 0.254 * 0.4 m over the states' stamps 1 to 5)."""
    bag = tmp_path / "b"
    write_graph_bag(bag, n=7)
    odo = read_bag_run(bag).record["odometry"]
    assert odo["t_s"] == pytest.approx(6.0)
    assert odo["true_x_m"] == pytest.approx(0.6) and odo["true_y_m"] == pytest.approx(-0.3)
    assert odo["drift_m"] == pytest.approx(0.3)
