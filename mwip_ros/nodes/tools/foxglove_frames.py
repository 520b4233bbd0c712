"""The live view's frame tree: ``robot_state``'s topics turned into Foxglove's own ``foxglove.FrameTransforms``.

Foxglove's 3D panel places a URDF (``/robot_description``, std_msgs/String, which the server forwards as it
forwards every topic) by its frames.  Without tf2_msgs there is no ``/tf`` to forward, so the server publishes
the frames itself on ``/tf`` with the ``foxglove.FrameTransforms`` schema:

- each ``odom`` (nav_msgs/Odometry): odom -> base_link, the message's pose;
- each ``wheel_joint_states`` (sensor_msgs/JointState): base_link -> each joint's child, from the URDF's joints
  and the positions (:func:`mwip_ros.core.mobile_base.urdf.joint_transforms`, as robot_state_publisher computes them),
  the fixed ones (imu_link) included;
- ``robot_description``: only remembered (its joints).

A message that does not decode, or carries a non-finite value, gives no frame and is counted (``rejected``).
"""
from __future__ import annotations

import math
from typing import List, Optional, Tuple

from mwip_ros.core.mobile_base.urdf import Transform, joint_transforms, urdf_joints

__all__ = ["FRAME_TOPICS", "TF_TOPIC", "FrameView", "to_foxglove"]

FRAME_TOPICS = ("odom", "wheel_joint_states", "robot_description")
TF_TOPIC = "/tf"


def _stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


class FrameView:
    """The frames of the last messages of :data:`FRAME_TOPICS` (module docstring)."""

    def __init__(self):
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import JointState
        from std_msgs.msg import String
        self.types = {"odom": Odometry, "wheel_joint_states": JointState, "robot_description": String}
        self.joints = []
        self.rejected = 0

    def feed(self, leaf: str, data: bytes) -> Optional[Tuple[int, List[Transform]]]:
        """(stamp [ns], the transforms) of one message's CDR ``data`` on the topic ``leaf``; None when it gives
        none (the description, a message rejected, joints before the description)."""
        from rclpy.serialization import deserialize_message
        try:
            msg = deserialize_message(data, self.types[leaf])
        except Exception:   # noqa: BLE001 - any bytes rclpy cannot read: rejected, counted
            self.rejected += 1
            return None
        if leaf == "robot_description":
            try:
                self.joints = urdf_joints(msg.data)
            except ValueError:
                self.rejected += 1
            return None
        if leaf == "odom":
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            out = [Transform(msg.header.frame_id or "odom", msg.child_frame_id or "base_link", (p.x, p.y, p.z),
                             (q.x, q.y, q.z, q.w))]
        else:
            if not self.joints or len(msg.position) != len(msg.name):
                return None
            out = joint_transforms(self.joints, dict(zip(msg.name, msg.position)))
        if not all(math.isfinite(v) for t in out for v in (*t.translation, *t.rotation)):
            self.rejected += 1
            return None
        return _stamp_ns(msg.header), out


def to_foxglove(messages, stamp_ns: int, transforms: List[Transform]):
    """The ``foxglove.messages.FrameTransforms`` (``messages``: the SDK's module) of ``transforms`` at ``stamp_ns``."""
    ts = messages.Timestamp(sec=stamp_ns // 1_000_000_000, nsec=stamp_ns % 1_000_000_000)
    return messages.FrameTransforms(transforms=[
        messages.FrameTransform(timestamp=ts, parent_frame_id=t.parent, child_frame_id=t.child,
                                translation=messages.Vector3(x=t.translation[0], y=t.translation[1],
                                                             z=t.translation[2]),
                                rotation=messages.Quaternion(x=t.rotation[0], y=t.rotation[1], z=t.rotation[2],
                                                             w=t.rotation[3]))
        for t in transforms])
