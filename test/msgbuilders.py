"""Message objects for tests that publish with rclpy's typed publishers (the nodes publish bytes)."""
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState

from mwip_ros.msgs.layouts import JOINT_NAMES
from mwip_ros.msgs.stamps import to_time


def joint_state(stamp: int, q, dq, u_prev: float) -> JointState:
    msg = JointState()
    msg.header.stamp = to_time(stamp)
    msg.name = list(JOINT_NAMES)
    msg.position = [float(q[0]), float(q[1])]
    msg.velocity = [float(dq[0]), float(dq[1])]
    msg.effort = [float(u_prev), 0.0]
    return msg


def wrench_stamped(stamp: int, t1: float, t2: float, frame: str = "") -> WrenchStamped:
    msg = WrenchStamped()
    msg.header.stamp = to_time(stamp)
    msg.header.frame_id = frame
    msg.wrench.torque.x = float(t1)
    msg.wrench.torque.y = float(t2)
    return msg
