"""Message layouts of SPEC section 7, their validation, and the graph's QoS."""
from __future__ import annotations

import math
from typing import Dict, Sequence, Tuple

from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

JOINT_NAMES = ("wheel", "body_pitch")
INTERNAL_NAMES = ("S1", "S2", "x4d", "x4_bar", "u_dsc", "u_taud", "u", "x1")

# Reliable and deep enough that nothing is dropped in lockstep, also for a recorder.
GRAPH_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)


class BadMessage(ValueError):
    """A message that must not be integrated; the text says why."""


def to_time(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_ns(t: Time) -> int:
    return t.sec * 1_000_000_000 + t.nanosec


def _finite(values: Sequence[float], what: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise BadMessage(f"non-finite {what}: {list(values)}")


def joint_state(stamp: int, q, dq, u_prev: float) -> JointState:
    msg = JointState()
    msg.header.stamp = to_time(stamp)
    msg.name = list(JOINT_NAMES)
    msg.position = [float(q[0]), float(q[1])]
    msg.velocity = [float(dq[0]), float(dq[1])]
    msg.effort = [float(u_prev), 0.0]
    return msg


def parse_joint_state(msg: JointState) -> Tuple[int, Tuple[float, float], Tuple[float, float], float]:
    """(stamp_ns, q, dq, u_prev) or BadMessage. Joints are looked up by name."""
    names = list(msg.name)
    if sorted(names) != sorted(JOINT_NAMES):
        raise BadMessage(f"joint names {names}, expected {list(JOINT_NAMES)}")
    if len(msg.position) != 2 or len(msg.velocity) != 2 or len(msg.effort) not in (1, 2):
        raise BadMessage(f"array lengths position={len(msg.position)} velocity={len(msg.velocity)} "
                         f"effort={len(msg.effort)}, expected 2, 2, 1 or 2")
    iw, ib = names.index("wheel"), names.index("body_pitch")
    q = (float(msg.position[iw]), float(msg.position[ib]))
    dq = (float(msg.velocity[iw]), float(msg.velocity[ib]))
    u_prev = float(msg.effort[iw])
    _finite((*q, *dq, u_prev), "joint state")
    return stamp_ns(msg.header.stamp), q, dq, u_prev


def wrench_stamped(stamp: int, t1: float, t2: float, frame: str = "") -> WrenchStamped:
    msg = WrenchStamped()
    msg.header.stamp = to_time(stamp)
    msg.header.frame_id = frame
    msg.wrench.torque.x = float(t1)
    msg.wrench.torque.y = float(t2)
    return msg


def parse_wrench_stamped(msg: WrenchStamped) -> Tuple[int, float, float]:
    t1, t2 = float(msg.wrench.torque.x), float(msg.wrench.torque.y)
    _finite((t1, t2), "torque")
    return stamp_ns(msg.header.stamp), t1, t2


def internals(stamp: int, out) -> JointState:
    """The controller's internal signals as named values (plot ``controller_internals/position``)."""
    msg = JointState()
    msg.header.stamp = to_time(stamp)
    msg.name = list(INTERNAL_NAMES)
    msg.position = [float(getattr(out, n)) for n in INTERNAL_NAMES]
    return msg


def lockstep_missing(node, state_pub, need_subs: int) -> list:
    """What a lockstep driver (plant_sim, bag_replay resim) is waiting for, in words naming the nodes."""
    what = []
    if node.count_publishers("wheel_torque_cmd") == 0:
        what.append("dscndo_controller (nothing publishes wheel_torque_cmd)")
    if node.count_publishers("disturbance_estimate") == 0:
        what.append("disturbance_observer (nothing publishes disturbance_estimate; the controller waits for "
                    "it when use_observer is true)")
    matched = state_pub.get_subscription_count()
    if matched < need_subs:
        what.append(f"{need_subs} subscribers on joint_states (matched: {matched})")
    return what


class Rejects:
    """Counts rejected messages per topic and logs them (first few, then every 100th)."""

    def __init__(self, logger):
        self.logger = logger
        self.counts: Dict[str, int] = {}

    def __call__(self, topic: str, reason: str) -> None:
        n = self.counts.get(topic, 0) + 1
        self.counts[topic] = n
        if n <= 5 or n % 100 == 0:
            self.logger.warning(f"rejected message #{n} on {topic}: {reason}")

    def summary(self) -> str:
        return ", ".join(f"{k}: {v}" for k, v in sorted(self.counts.items())) or "none"
