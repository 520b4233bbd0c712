"""The live view's frames (nodes/tools/foxglove_frames.py): robot_state's odom and wheel joints as
foxglove.FrameTransforms, the messages the server would send, built and encoded offline."""
from __future__ import annotations

import math
import struct

import pytest
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from mwip_ros import params as P
from mwip_ros.core.mobile_base.urdf import frame_transforms, joint_transforms, robot_model, urdf, urdf_joints
from mwip_ros.nodes.tools.foxglove_frames import FrameView, to_foxglove

pytestmark = pytest.mark.unit

MODEL = robot_model(P.defaults_for("robot_state"))   # track 0.5 m, r 0.254 m (true r of the schema), IMU 0.3 m


def _odom(x, y, qy, qw, stamp=(2, 5)):
    m = Odometry()
    m.header.stamp.sec, m.header.stamp.nanosec = stamp
    m.header.frame_id, m.child_frame_id = "odom", "base_link"
    m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z = x, y, 0.254
    m.pose.pose.orientation.y, m.pose.pose.orientation.w = qy, qw
    return serialize_message(m)


def _wheels(phi, stamp=(2, 5)):
    m = JointState()
    m.header.stamp.sec, m.header.stamp.nanosec = stamp
    m.name, m.position = ["wheel_left_joint", "wheel_right_joint"], [phi, phi]
    return serialize_message(m)


def test_joints_of_the_urdf_turn_about_y_like_the_nodes_tf():
    joints = urdf_joints(urdf(MODEL))
    tf = {t.child: t for t in joint_transforms(joints, {"wheel_left_joint": 0.3, "wheel_right_joint": -0.2})}
    assert tf["wheel_left_link"].translation == (0.0, 0.25, 0.0)
    assert tf["wheel_left_link"].rotation == pytest.approx((0.0, math.sin(0.15), 0.0, math.cos(0.15)), abs=1e-15)
    assert tf["wheel_right_link"].rotation == pytest.approx((0.0, math.sin(-0.1), 0.0, math.cos(-0.1)), abs=1e-15)
    assert tf["imu_link"].translation == (0.0, 0.0, 0.3) and tf["imu_link"].rotation == (0.0, 0.0, 0.0, 1.0)
    # the same tree as robot_state's /tf (core.mobile_base.urdf.frame_transforms), frame for frame
    node = {t.child: t for t in frame_transforms(MODEL, 1.0, 2.0, 0.0, 0.1, 0.3, -0.2)}
    for child, t in tf.items():
        assert node[child].parent == t.parent and node[child].translation == pytest.approx(t.translation)
        assert node[child].rotation == pytest.approx(t.rotation, abs=1e-15)
    base = node["base_link"]
    assert (base.parent, base.translation) == ("odom", (1.0, 2.0, MODEL.r))
    assert base.rotation == pytest.approx((0.0, math.sin(0.05), 0.0, math.cos(0.05)), abs=1e-15)


def test_yaw_then_pitch():
    # yaw pi/2 then pitch 0.2: base_link's x axis points to world y, tilted down by 0.2 (REP-103, pitch about y)
    (base, *_rest) = frame_transforms(MODEL, 0.0, 0.0, math.pi / 2, 0.2, 0.0, 0.0)
    x, y, z, w = base.rotation
    # the rotated x axis: first column of the rotation matrix
    col = (1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y))
    assert col == pytest.approx((0.0, math.cos(0.2), -math.sin(0.2)), abs=1e-12)


def test_the_view_makes_frames_from_odom_and_the_wheels_once_it_has_the_description():
    v = FrameView()
    assert v.feed("wheel_joint_states", _wheels(0.3)) is None          # no description yet: no wheel frames
    assert v.feed("robot_description", serialize_message(String(data=urdf(MODEL)))) is None
    stamp, frames = v.feed("odom", _odom(1.5, -0.5, math.sin(0.05), math.cos(0.05)))
    assert stamp == 2_000_000_005
    assert [(f.parent, f.child, f.translation) for f in frames] == [("odom", "base_link", (1.5, -0.5, 0.254))]
    stamp, frames = v.feed("wheel_joint_states", _wheels(0.3))
    assert {f.child for f in frames} == {"wheel_left_link", "wheel_right_link", "imu_link"}
    assert v.rejected == 0
    assert v.feed("odom", b"\x00\x01\x00\x00garbage") is None
    assert v.feed("odom", _odom(math.nan, 0.0, 0.0, 1.0)) is None
    assert v.feed("robot_description", serialize_message(String(data="<html/>"))) is None
    assert v.rejected == 3
    assert v.joints   # a bad description leaves the last good one


def test_the_foxglove_message_carries_the_frames():
    foxglove = pytest.importorskip("foxglove")
    from foxglove import messages
    joints = urdf_joints(urdf(MODEL))
    msg = to_foxglove(messages, 2_000_000_005, joint_transforms(joints, {"wheel_left_joint": 0.3}))
    data = msg.encode()
    assert isinstance(msg, messages.FrameTransforms) and foxglove is not None
    for text in (b"base_link", b"wheel_left_link", b"wheel_right_link", b"imu_link"):
        assert text in data
    for value in (0.25, -0.25, 0.3, math.sin(0.15), math.cos(0.15)):   # doubles, protobuf's fixed64 little-endian
        assert struct.pack("<d", value) in data

