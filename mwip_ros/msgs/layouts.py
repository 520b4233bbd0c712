"""What each topic of the graph carries, encoded and checked in one place.

    joint_states          sensor_msgs/JointState    name [wheel, body_pitch], position q, velocity q',
                                                    effort [u over the previous period, 0]; stamp t_k
    wheel_torque_cmd      std_msgs/Float64          u [N m]
    disturbance_estimate  geometry_msgs/WrenchStamped  torque.x = tau_hat1, torque.y = tau_hat2
    lumped_disturbance    geometry_msgs/WrenchStamped  the true tau_d, same layout
    controller_internals  sensor_msgs/JointState    name = INTERNAL_NAMES, values in position
    /clock                rosgraph_msgs/Clock       simulation time

The nodes publish these as bytes and parse the bytes they receive (:mod:`.cdr`), and the
bag readers use the same parsers.  ``parse_*`` raise :class:`~.errors.BadMessage` for
anything that must not be used: bytes that are not the type, joints missing, non-finite
values.
"""
from __future__ import annotations

import math
from typing import Dict, Sequence, Tuple

from mwip_ros.core.model import State

from . import cdr
from .errors import BadMessage, CdrError

__all__ = ["JOINT_NAMES", "INTERNAL_NAMES", "encode_state", "encode_wrench", "encode_internals",
           "encode_command", "encode_clock", "parse_joint_state", "parse_wrench", "parse_command",
           "parse_clock", "parse_internals"]

JOINT_NAMES = ("wheel", "body_pitch")
INTERNAL_NAMES = ("S1", "S2", "x4d", "x4_bar", "u_dsc", "u_taud", "u", "x1")

_STATE = cdr.JointStateEncoder(JOINT_NAMES)
_INTERNALS = cdr.JointStateEncoder(INTERNAL_NAMES)
_WRENCH = cdr.WrenchStampedEncoder()
_ZERO3 = (0.0, 0.0, 0.0)
encode_command = cdr.encode_float64   # std_msgs/Float64 wheel_torque_cmd
encode_clock = cdr.encode_clock       # rosgraph_msgs/Clock


def _finite(values: Sequence[float], what: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise BadMessage(f"non-finite {what}: {list(values)}")


def _decoded(decode, data, type_name: str):
    try:
        return decode(data)
    except CdrError as exc:
        raise BadMessage(f"not a {type_name}: {exc}") from None


# --- encoding ----------------------------------------------------------------------------------------

def encode_state(stamp: int, x, u_prev: float) -> bytes:
    """joint_states: positions q, velocities q', effort [u_{k-1}, 0]."""
    return _STATE(stamp, (float(x[0]), float(x[1])), (float(x[2]), float(x[3])), (float(u_prev), 0.0))


def encode_wrench(stamp: int, t1: float, t2: float) -> bytes:
    """disturbance_estimate / lumped_disturbance: torque.x = component 1, torque.y = component 2."""
    return _WRENCH(stamp, _ZERO3, (float(t1), float(t2), 0.0))


def encode_internals(stamp: int, out) -> bytes:
    """The controller's internal signals as named values (plot ``controller_internals/position``)."""
    return _INTERNALS(stamp, [float(getattr(out, n)) for n in INTERNAL_NAMES])


# --- parsing -----------------------------------------------------------------------------------------

def parse_joint_state(data) -> Tuple[int, State, float]:
    """(stamp_ns, state, u_prev) of a joint_states message, or BadMessage. Joints are looked up by name."""
    stamp, _frame, names, position, velocity, effort = _decoded(cdr.decode_joint_state, data,
                                                                "sensor_msgs/JointState")
    if len(names) != 2 or len(set(names)) != 2 or set(names) != set(JOINT_NAMES):
        raise BadMessage(f"joint names {names}, expected {list(JOINT_NAMES)}")
    if len(position) != 2 or len(velocity) != 2 or len(effort) not in (1, 2):
        raise BadMessage(f"array lengths position={len(position)} velocity={len(velocity)} "
                         f"effort={len(effort)}, expected 2, 2, 1 or 2")
    iw, ib = (0, 1) if names[0] == "wheel" else (1, 0)
    if iw >= len(effort):
        raise BadMessage(f"effort {list(effort)} has no entry for 'wheel' (name index {iw})")
    x = State(position[iw], position[ib], velocity[iw], velocity[ib])
    u_prev = effort[iw]
    _finite((*x, u_prev), "joint state")
    return stamp, x, u_prev


def parse_wrench(data) -> Tuple[int, float, float]:
    """(stamp_ns, torque.x, torque.y) of a WrenchStamped, or BadMessage."""
    stamp, _frame, _force, torque = _decoded(cdr.decode_wrench_stamped, data, "geometry_msgs/WrenchStamped")
    _finite(torque[:2], "torque")
    return stamp, torque[0], torque[1]


def parse_command(data) -> float:
    """wheel_torque_cmd's value, or BadMessage."""
    u = _decoded(cdr.decode_float64, data, "std_msgs/Float64")
    if not math.isfinite(u):
        raise BadMessage(f"non-finite command {u}")
    return u


def parse_clock(data) -> int:
    """/clock's time in ns, or BadMessage."""
    return _decoded(cdr.decode_clock, data, "rosgraph_msgs/Clock")


def parse_internals(data) -> Tuple[int, Dict[str, float]]:
    """(stamp_ns, {name: value}) of a controller_internals message, or BadMessage."""
    stamp, _frame, names, position, _v, _e = _decoded(cdr.decode_joint_state, data, "sensor_msgs/JointState")
    if len(names) != len(position):
        raise BadMessage(f"{len(names)} names for {len(position)} values")
    return stamp, dict(zip(names, position))
