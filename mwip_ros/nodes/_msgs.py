"""Message layouts of SPEC section 7, their validation, and the graph's QoS.

The nodes exchange serialized messages (``raw=True`` subscriptions, ``publish(bytes)``)
encoded and decoded by :mod:`mwip_ros.cdr`: the wire format and the topic types are the
usual ones, without rclpy's per-message object conversion (BENCHMARKS.md).  The
``joint_state`` / ``wrench_stamped`` builders make message objects, for publishers that
use them (tests, tools).
"""
from __future__ import annotations

import math
from typing import Dict, Sequence, Tuple

from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from mwip_ros import cdr

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


# --- serialized messages (what the nodes publish and take) ------------------------------------------

_STATE = cdr.JointStateEncoder(JOINT_NAMES)
_INTERNALS = cdr.JointStateEncoder(INTERNAL_NAMES)
_WRENCH = cdr.WrenchStampedEncoder()
_ZERO3 = (0.0, 0.0, 0.0)
encode_command = cdr.encode_float64   # std_msgs/Float64 wheel_torque_cmd
encode_clock = cdr.encode_clock       # rosgraph_msgs/Clock


def encode_state(stamp: int, q, dq, u_prev: float) -> bytes:
    """joint_states: positions q, velocities dq, effort [u_{k-1}, 0] (SPEC section 7)."""
    return _STATE(stamp, (float(q[0]), float(q[1])), (float(dq[0]), float(dq[1])), (float(u_prev), 0.0))


def encode_wrench(stamp: int, t1: float, t2: float) -> bytes:
    """disturbance_estimate / lumped_disturbance: torque.x = component 1, torque.y = component 2."""
    return _WRENCH(stamp, _ZERO3, (float(t1), float(t2), 0.0))


def encode_internals(stamp: int, out) -> bytes:
    """The controller's internal signals as named values (plot ``controller_internals/position``)."""
    return _INTERNALS(stamp, [float(getattr(out, n)) for n in INTERNAL_NAMES])


def parse_joint_state(data: bytes) -> Tuple[int, Tuple[float, float], Tuple[float, float], float]:
    """(stamp_ns, q, dq, u_prev) or BadMessage. Joints are looked up by name."""
    try:
        stamp, _frame, names, position, velocity, effort = cdr.decode_joint_state(data)
    except cdr.CdrError as exc:
        raise BadMessage(f"not a sensor_msgs/JointState: {exc}") from None
    if len(names) != 2 or len(set(names)) != 2 or set(names) != set(JOINT_NAMES):
        raise BadMessage(f"joint names {names}, expected {list(JOINT_NAMES)}")
    if len(position) != 2 or len(velocity) != 2 or len(effort) not in (1, 2):
        raise BadMessage(f"array lengths position={len(position)} velocity={len(velocity)} "
                         f"effort={len(effort)}, expected 2, 2, 1 or 2")
    iw, ib = (0, 1) if names[0] == "wheel" else (1, 0)
    q = (position[iw], position[ib])
    dq = (velocity[iw], velocity[ib])
    if iw >= len(effort):
        raise BadMessage(f"effort {list(effort)} has no entry for 'wheel' (name index {iw})")
    u_prev = effort[iw]
    _finite((*q, *dq, u_prev), "joint state")
    return stamp, q, dq, u_prev


def parse_wrench(data: bytes) -> Tuple[int, float, float]:
    """(stamp_ns, torque.x, torque.y) of a WrenchStamped or BadMessage."""
    try:
        stamp, _frame, _force, torque = cdr.decode_wrench_stamped(data)
    except cdr.CdrError as exc:
        raise BadMessage(f"not a geometry_msgs/WrenchStamped: {exc}") from None
    _finite(torque[:2], "torque")
    return stamp, torque[0], torque[1]


def parse_command(data: bytes) -> float:
    """wheel_torque_cmd's value or BadMessage."""
    try:
        u = cdr.decode_float64(data)
    except cdr.CdrError as exc:
        raise BadMessage(f"not a std_msgs/Float64: {exc}") from None
    if not math.isfinite(u):
        raise BadMessage(f"non-finite command {u}")
    return u


# --- message objects (for publishers that use them: tests, tools) ------------------------------------

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
