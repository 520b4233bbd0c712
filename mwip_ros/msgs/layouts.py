"""What each topic of the graph carries, encoded and checked in one place.

    joint_states          sensor_msgs/JointState    name [wheel, body_pitch], position q, velocity q',
                                                    effort [u over the previous period, 0]; stamp t_k
    wheel_torque_cmd      std_msgs/Float64          u [N m]
    disturbance_estimate  geometry_msgs/WrenchStamped  torque.x = tau_hat1, torque.y = tau_hat2
    lumped_disturbance    geometry_msgs/WrenchStamped  the true tau_d, same layout
    controller_internals  sensor_msgs/JointState    name = the law's internal_names (INTERNAL_NAMES for
                                                    dsc, dscndo, lqr, lqr_ndo), values in position
    /clock                rosgraph_msgs/Clock       simulation time

    external_wrench       geometry_msgs/Wrench      torque.x, torque.y added to tau_ext1, tau_ext2

The nodes publish these as bytes and parse the bytes they receive (:mod:`.cdr`), and the
bag readers use the same parsers.  ``parse_*`` raise :class:`~.errors.BadMessage` for
anything that must not be used: bytes that are not the type, joints missing, non-finite
values, and values no robot of this kind can have (:data:`LIMITS`).
"""
from __future__ import annotations

import math
from typing import Dict, Sequence, Tuple

from mwip_ros.core.model import State

from . import cdr
from .errors import BadMessage, CdrError

__all__ = ["JOINT_NAMES", "INTERNAL_NAMES", "LIMITS", "encode_state", "encode_wrench", "encode_internals",
           "encode_command", "encode_clock", "encode_external_wrench", "parse_joint_state", "parse_wrench",
           "parse_command", "parse_clock", "parse_internals", "parse_external_wrench"]

JOINT_NAMES = ("wheel", "body_pitch")
INTERNAL_NAMES = ("S1", "S2", "x4d", "x4_bar", "u_dsc", "u_taud", "u", "x1")

# Plausible values, far beyond anything the robot reaches (in the paper's scenario |theta_b| stays
# below 0.2 rad, the rates below 5 rad/s and the torques below 150 N m; a fall ends a run at
# fall_angle, at most pi/2 in practice) and far inside what the arithmetic survives (a rate of
# 1e160 overflows the law).  A message outside them is rejected like a NaN.
LIMITS = {
    "theta_b": math.pi,        # body pitch [rad]: beyond it the body is upside down
    "theta_w": 1e9,            # wheel angle [rad]: 250,000 km of travel
    "rate": 1e3,               # theta_w', theta_b' [rad/s]
    "torque": 1e6,             # u, tau_hat, tau_d, tau_ext [N m]
}

_STATE = cdr.JointStateEncoder(JOINT_NAMES)
_INTERNALS = cdr.JointStateEncoder(INTERNAL_NAMES)
_WRENCH = cdr.WrenchStampedEncoder()
_ZERO3 = (0.0, 0.0, 0.0)
encode_command = cdr.encode_float64   # std_msgs/Float64 wheel_torque_cmd
encode_clock = cdr.encode_clock       # rosgraph_msgs/Clock


def _finite(values: Sequence[float], what: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise BadMessage(f"non-finite {what}: {list(values)}")


def _within(value: float, limit: str, what: str) -> None:
    if abs(value) > LIMITS[limit]:
        raise BadMessage(f"implausible {what} {value:g} (|{what}| must be <= {LIMITS[limit]:g})")


def _torques(values: Sequence[float], what: str) -> None:
    _finite(values, what)
    for v in values:
        _within(v, "torque", what)


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


_INTERNAL_ENCODERS = {INTERNAL_NAMES: _INTERNALS}


def encode_internals(stamp: int, out, names: Sequence[str] = INTERNAL_NAMES) -> bytes:
    """The controller's internal signals as named values (plot ``controller_internals/position``).

    Parameters
    ----------
    stamp : int
        The state's stamp [ns].
    out : dict or object
        The law's internals (:meth:`mwip_ros.core.laws.Law.step`: a dict) or an object with them as attributes.
    names : sequence of str
        The layout, the law's ``internal_names``; a name ``out`` lacks is published NaN.
    """
    names = tuple(names)
    enc = _INTERNAL_ENCODERS.get(names)
    if enc is None:
        enc = _INTERNAL_ENCODERS[names] = cdr.JointStateEncoder(names)
    get = out.get if isinstance(out, dict) else (lambda n, d: getattr(out, n, d))
    return enc(stamp, [float(get(n, math.nan)) for n in names])


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
    _within(x[1], "theta_b", "theta_b")
    _within(x[0], "theta_w", "theta_w")
    _within(x[2], "rate", "theta_w'")
    _within(x[3], "rate", "theta_b'")
    _within(u_prev, "torque", "effort")
    return stamp, x, u_prev


def parse_wrench(data) -> Tuple[int, float, float]:
    """(stamp_ns, torque.x, torque.y) of a WrenchStamped, or BadMessage."""
    stamp, _frame, _force, torque = _decoded(cdr.decode_wrench_stamped, data, "geometry_msgs/WrenchStamped")
    _torques(torque[:2], "torque")
    return stamp, torque[0], torque[1]


def parse_command(data) -> float:
    """wheel_torque_cmd's value, or BadMessage."""
    u = _decoded(cdr.decode_float64, data, "std_msgs/Float64")
    if not math.isfinite(u):
        raise BadMessage(f"non-finite command {u}")
    _within(u, "torque", "command")
    return u


def encode_external_wrench(t1: float, t2: float) -> bytes:
    """external_wrench: torque.x adds to tau_ext1, torque.y to tau_ext2."""
    return cdr.encode_wrench(_ZERO3, (float(t1), float(t2), 0.0))


def parse_external_wrench(data) -> Tuple[float, float]:
    """(torque.x, torque.y) of an external_wrench message, or BadMessage."""
    _force, torque = _decoded(cdr.decode_wrench, data, "geometry_msgs/Wrench")
    _torques(torque[:2], "torque")
    return torque[0], torque[1]


def parse_clock(data) -> int:
    """/clock's time in ns, or BadMessage."""
    return _decoded(cdr.decode_clock, data, "rosgraph_msgs/Clock")


def parse_internals(data) -> Tuple[int, Dict[str, float]]:
    """(stamp_ns, {name: value}) of a controller_internals message, or BadMessage."""
    stamp, _frame, names, position, _v, _e = _decoded(cdr.decode_joint_state, data, "sensor_msgs/JointState")
    if len(names) != len(position):
        raise BadMessage(f"{len(names)} names for {len(position)} values")
    return stamp, dict(zip(names, position))
