"""robot_state's /tf message (tf2_msgs/TFMessage where a full ROS install has it), and its one line without it."""
from __future__ import annotations

import math

import pytest
from builtin_interfaces.msg import Time

from mwip_ros import params as P
from mwip_ros.core.mobile_base.urdf import frame_transforms, robot_model
from mwip_ros.nodes.tools import robot_state

pytestmark = pytest.mark.unit


class _TFMessage:   # tf2_msgs/TFMessage's one field, for a machine without tf2_msgs
    def __init__(self, transforms):
        self.transforms = transforms


def test_the_frames_as_transform_stamped():
    m = robot_model(P.defaults_for("robot_state"))
    msg = robot_state.tf_message(_TFMessage, frame_transforms(m, 1.0, -2.0, 0.0, 0.2, 0.4, 0.4), Time(sec=3))
    tf = {t.child_frame_id: t for t in msg.transforms}
    assert set(tf) == {"base_link", "wheel_left_link", "wheel_right_link", "imu_link"}
    base = tf["base_link"]
    assert (base.header.frame_id, base.header.stamp.sec) == ("odom", 3)
    assert (base.transform.translation.x, base.transform.translation.y, base.transform.translation.z) == (1.0, -2.0,
                                                                                                          m.r)
    assert base.transform.rotation.y == pytest.approx(math.sin(0.1)) and base.transform.rotation.w == pytest.approx(
        math.cos(0.1))
    left = tf["wheel_left_link"]
    assert left.header.frame_id == "base_link" and left.transform.translation.y == m.track_width / 2
    assert left.transform.rotation.y == pytest.approx(math.sin(0.2))
    assert tf["imu_link"].transform.translation.z == m.imu_offset


def test_without_tf2_msgs_one_line():
    lines = []

    class Log:
        def info(self, text):
            lines.append(text)
    try:
        import tf2_msgs.msg  # noqa: F401
    except ImportError:
        assert robot_state._tf_message_type(Log()) is None
        assert len(lines) == 1 and "tf2_msgs is not installed" in lines[0] and "\n" not in lines[0]
    else:   # a full ROS install
        assert robot_state._tf_message_type(Log()) is not None and not lines
