"""What each topic of the graph carries, encoded and checked in one place.

    joint_states          sensor_msgs/JointState    name [wheel, body_pitch], position q, velocity q',
                                                    effort [u over the previous period, 0]; stamp t_k
    wheel_torque_cmd      std_msgs/Float64          u [N m]
    disturbance_estimate  geometry_msgs/WrenchStamped  torque.x = tau_hat1, torque.y = tau_hat2
    lumped_disturbance    geometry_msgs/WrenchStamped  the true tau_d, same layout
    controller_internals  sensor_msgs/JointState    name = the law's internal_names (INTERNAL_NAMES for
                                                    dsc, dscndo, lqr, lqr_ndo), values in position
    /clock                rosgraph_msgs/Clock       simulation time

    external_wrench       geometry_msgs/Wrench      torque.x, torque.y added to tau_ext1, tau_ext2; force.y, torque.z
                                                    a lateral push and a yaw torque on a 3D plant's body (mujoco)
    true_pose             geometry_msgs/PoseStamped a spatial plant's (backend mujoco) true 3D pose: frame_id
                                                    odom (REP-105), position the axle's centre, orientation
                                                    from yaw, pitch, roll (core.plants.markers.pose_quaternion); stamp
                                                    t_k
    true_wheel_states     sensor_msgs/JointState    a spatial plant's wheels: name [wheel_left_joint,
                                                    wheel_right_joint] (the URDF's), position each wheel's
                                                    absolute angle [rad], velocity its rate; stamp t_k

    raw sensors (plant_sim with sensors.model: raw, docs/theory.md 6.4; the state_estimator reads them):
    imu/data_raw          sensor_msgs/Imu           frame_id imu_link; no orientation (all 0,
                                                    orientation_covariance[0] = -1, REP-145);
                                                    angular_velocity (0, gyro, 0), linear_acceleration
                                                    (accel_x, 0, accel_z); covariances diagonal
                                                    (gyro_noise_std^2, accel_noise_std^2); stamp t_k
    wheel_encoder         sensor_msgs/JointState    frame_id "" (a joint's state: no frame, as
                                                    joint_state_publisher sends it); name [wheel],
                                                    position [phi = theta_w - theta_b],
                                                    velocity [phi rate], effort [torque that acted
                                                    over the previous period]; stamp t_k

The nodes publish these as bytes and parse the bytes they receive (:mod:`.cdr`), and the
bag readers use the same parsers.  ``parse_*`` raise :class:`~.errors.BadMessage` for
anything that must not be used: bytes that are not the type, joints missing, non-finite
values, and values no robot of this kind can have (:data:`LIMITS`; the raw sensors' :data:`RAW_LIMITS`).
"""
from __future__ import annotations

import json
import math
from typing import Dict, Optional, Sequence, Tuple

from mwip_ros.core.control.controller import INTERNALS
from mwip_ros.core.plants.markers import pose_angles, pose_quaternion
from mwip_ros.core.plants.model import State
from mwip_ros.core.control.motion import ABSURD_SPEED, ABSURD_YAW_RATE
from mwip_ros.core.control.safety import PLAUSIBLE_STATE, PLAUSIBLE_TORQUE, STATES
from mwip_ros.core.mobile_base.urdf import WHEEL_JOINTS

from . import cdr
from .errors import BadMessage, CdrError

__all__ = ["JOINT_NAMES", "INTERNAL_NAMES", "LIMITS", "RAW_LIMITS", "IMU_FRAME", "ENCODER_FRAME", "ENCODER_JOINT",
           "encode_state", "encode_wrench", "encode_internals",
           "encode_command", "encode_clock", "encode_external_wrench", "parse_joint_state", "parse_wrench",
           "parse_command", "parse_clock", "parse_internals", "parse_external_wrench", "encode_imu", "parse_imu",
           "encode_encoder", "parse_encoder", "parse_odometry", "check_state", "RAW_FILTERS", "CMD_VEL_FILTER",
           "STATE_FILTER", "ESTIMATE_FILTER",
           "encode_twist", "parse_twist", "POSE_FRAME", "encode_pose", "parse_pose", "parse_bool", "YAW_JOINT",
           "parse_yaw_rate",
           "WHEEL_TORQUE_JOINTS", "encode_wheel_torques", "parse_wheel_torques", "encode_wheel_states",
           "parse_wheel_states", "parse_driver_state", "MAX_DRIVER_STATE_BYTES"]

JOINT_NAMES = ("wheel", "body_pitch")
YAW_JOINT = "yaw"   # joint_states' third joint from a spatial plant: velocity = the gyro's yaw rate (theory 6.13)
WHEEL_TORQUE_JOINTS = WHEEL_JOINTS   # wheel_torques_cmd's names: the URDF's wheel joints (core.mobile_base.urdf)
INTERNAL_NAMES = INTERNALS   # controller_internals' names (core.control.controller)

# Plausible values, far beyond anything the robot reaches (in the paper's scenario |theta_b| stays
# below 0.2 rad, the rates below 5 rad/s and the torques below 150 N m; a fall ends a run at
# fall_angle, at most pi/2 in practice) and far inside what the arithmetic survives (a rate of
# 1e160 overflows the law).  A message outside them is rejected like a NaN.
LIMITS = {
    **PLAUSIBLE_STATE,         # theta_b [rad], theta_w [rad], rate: theta_w', theta_b' [rad/s] (core.control.safety)
    "torque": PLAUSIBLE_TORQUE,   # u, tau_hat, tau_d, tau_ext [N m] (core.control.safety: the driver's own limit)
}

# The raw sensors' plausible readings (theory.md 6.4), far beyond a balancing robot (the paper's run: |gyro| < 5 rad/s,
# |accel| < 30 m/s^2) and far inside what the estimators' arithmetic survives.  A reading beyond them is rejected
# like a NaN.  (A missing orientation, orientation_covariance[0] = -1, is what the plant sends, and an IMU that
# does give one is not an error: the estimators never read it.)
RAW_LIMITS = {
    "gyro": 1e3,               # |angular_velocity| per axis [rad/s]
    "accel": 1e3,              # |linear_acceleration| per axis [m/s^2]: about 100 g
    "phi": LIMITS["theta_w"],  # |encoder angle| [rad]
    "rate": LIMITS["rate"],    # |encoder rate| [rad/s]
    "torque": LIMITS["torque"],   # |reported torque| [N m]
}
IMU_FRAME = "imu_link"         # REP-145: the IMU's own frame (the body frame at the IMU, core.plants.raw_sensors)
ENCODER_JOINT = "wheel"        # the encoder's joint: the wheel relative to the body
ENCODER_FRAME = ""             # the encoder's JointState frame_id: none (a joint angle is no pose in a frame)
POSE_FRAME = "odom"            # true_pose's frame: the world fixed where the run starts (REP-105)



def _inside(field: str, limit: float) -> str:
    """A DDS-SQL condition that holds iff -limit <= field <= limit: strict comparisons with the next double (Fast
    DDS evaluates ``a >= b`` as ``not a < b``, which a NaN passes; a NaN fails every strict comparison)."""
    bound = repr(math.nextafter(limit, math.inf))
    return f"{field} > -{bound} AND {field} < {bound}"


# The raw topics' DDS content filters (the state estimator's realtime subscriptions, nodes.runtime.content_filter):
# what parse_imu / parse_encoder would reject for its frame, names or values, written from the same constants, so
# that the middleware drops it before it enters the reader's queue.  A sample that cannot be deserialized fails
# the filter too.  The parsers stay the judge of what passes (stamps, the array lengths beyond the first value).
RAW_FILTERS = {
    "imu/data_raw": " AND ".join([f"header.frame_id = '{IMU_FRAME}'"]
                                 + [_inside(f"{v}.{a}", RAW_LIMITS[k])
                                    for v, k in (("angular_velocity", "gyro"), ("linear_acceleration", "accel"))
                                    for a in "xyz"]),
    "wheel_encoder": " AND ".join([f"header.frame_id = '{ENCODER_FRAME}'", f"name[0] = '{ENCODER_JOINT}'"]
                                  + [_inside(f"{f}[0]", RAW_LIMITS[k])
                                     for f, k in (("position", "phi"), ("velocity", "rate"), ("effort", "torque"))]),
}

# cmd_vel's DDS content filter (the controller's cmd_vel reader, nodes.runtime.content_filter; issue 46 item 2): what
# core.control.motion.Shaper.command rejects for its numbers (linear.x or angular.z not finite, or beyond ABSURD_SPEED /
# ABSURD_YAW_RATE), and bytes that cannot be deserialized, dropped by the middleware before the reader's depth-1
# history: a flood of them can neither displace a valid command nor cost the controller's Python a look.  The other
# four fields are read by no one (parse_twist), so they are not judged here either.
CMD_VEL_FILTER = f"{_inside('linear.x', ABSURD_SPEED)} AND {_inside('angular.z', ABSURD_YAW_RATE)}"

# The control inputs' DDS content filters (the observer's and the controller's realtime joint_states and
# disturbance_estimate readers, nodes.runtime.state_input; issue 46 item 2): what parse_joint_state and parse_wrench
# reject for their numbers, whatever the joints' order (both positions within theta_w's limit, the looser; both rates
# within the rate's), and bytes that cannot be deserialized.  Stamps are not judged here: a bound that moves with the
# stream needs the filter's parameters changed as it runs, and Fast DDS 2.14's writers crashed (a segmentation fault in
# the plant's publish) when a reader changed them under a flood; the StampGuard judges (and counts) stamps.
STATE_FILTER = " AND ".join(_inside(f"{f}[{i}]", LIMITS[k]) for f, k in (("position", "theta_w"), ("velocity", "rate"))
                            for i in (0, 1))
ESTIMATE_FILTER = " AND ".join(_inside(f"wrench.torque.{a}", LIMITS["torque"]) for a in "xy")

_STATE = cdr.JointStateEncoder(JOINT_NAMES)
_STATE_YAW = cdr.JointStateEncoder(JOINT_NAMES + (YAW_JOINT,))
_WHEEL_TORQUES = cdr.JointStateEncoder(WHEEL_TORQUE_JOINTS)
_IMU = cdr.ImuEncoder(IMU_FRAME)
_ENCODER = cdr.JointStateEncoder((ENCODER_JOINT,), ENCODER_FRAME)
_NO_ORIENTATION = (0.0, 0.0, 0.0, 0.0)
_NO_ORIENTATION_COV = (-1.0,) + (0.0,) * 8
_INTERNALS = cdr.JointStateEncoder(INTERNAL_NAMES)
_WRENCH = cdr.WrenchStampedEncoder()
_POSE = cdr.PoseStampedEncoder(POSE_FRAME)
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

def encode_state(stamp: int, x, u_prev: float, yaw_rate: Optional[float] = None) -> bytes:
    """joint_states: positions q, velocities q', effort [u_{k-1}, 0]; with ``yaw_rate`` (a spatial plant, theory
    6.13) a third joint :data:`YAW_JOINT` whose position is 0 and velocity the gyro's yaw rate."""
    if yaw_rate is None:
        return _STATE(stamp, (float(x[0]), float(x[1])), (float(x[2]), float(x[3])), (float(u_prev), 0.0))
    return _STATE_YAW(stamp, (float(x[0]), float(x[1]), 0.0), (float(x[2]), float(x[3]), float(yaw_rate)),
                      (float(u_prev), 0.0))


def encode_wheel_torques(stamp: int, u_left: float, u_right: float) -> bytes:
    """wheel_torques_cmd (sensor_msgs/JointState): name :data:`WHEEL_TORQUE_JOINTS`, no position or velocity, effort
    [u_L, u_R] [N m], stamped with the state it answers (theory 6.13)."""
    return _WHEEL_TORQUES(stamp, (), (), (float(u_left), float(u_right)))


def parse_wheel_torques(data) -> Tuple[int, float, float]:
    """(stamp_ns, u_L, u_R) of a wheel_torques_cmd, or BadMessage: the names :data:`WHEEL_TORQUE_JOINTS` in that order,
    two efforts, each finite and plausible."""
    stamp, _frame, names, _position, _velocity, effort = _decoded(cdr.decode_joint_state, data,
                                                                  "sensor_msgs/JointState")
    if tuple(names) != WHEEL_TORQUE_JOINTS:
        raise BadMessage(f"joint names {names}, expected {list(WHEEL_TORQUE_JOINTS)}")
    if len(effort) != 2:
        raise BadMessage(f"effort has {len(effort)} entries, expected 2 (u_L, u_R)")
    _finite(effort, "wheel torques")
    for v in effort:
        _within(v, "torque", "wheel torque")
    return stamp, float(effort[0]), float(effort[1])


def encode_wheel_states(stamp: int, angles: Sequence[float], rates: Sequence[float] = ()) -> bytes:
    """true_wheel_states (sensor_msgs/JointState): name :data:`WHEEL_TORQUE_JOINTS` (the URDF's wheel joints), position
    each wheel's absolute angle [rad] (:class:`~mwip_ros.core.plants.plant.Pose`'s wheel_left, wheel_right), velocity
    their rates [rad/s] (empty when the plant has none), stamp t_k."""
    return _WHEEL_TORQUES(stamp, tuple(float(a) for a in angles), tuple(float(r) for r in rates))


def parse_wheel_states(data) -> Tuple[int, Tuple[float, float], Optional[Tuple[float, float]]]:
    """(stamp_ns, (left, right) angles, (left, right) rates or None) of a true_wheel_states, or BadMessage: the names
    :data:`WHEEL_TORQUE_JOINTS` in that order, two positions and none or two velocities, each finite and plausible
    (:data:`LIMITS` theta_w, rate)."""
    stamp, _frame, names, position, velocity, _effort = _decoded(cdr.decode_joint_state, data,
                                                                  "sensor_msgs/JointState")
    if tuple(names) != WHEEL_TORQUE_JOINTS:
        raise BadMessage(f"joint names {names}, expected {list(WHEEL_TORQUE_JOINTS)}")
    if len(position) != 2 or len(velocity) not in (0, 2):
        raise BadMessage(f"{len(position)} positions and {len(velocity)} velocities, expected 2 and 2 (or none)")
    _finite((*position, *velocity), "wheel states")
    for v in position:
        _within(v, "theta_w", "wheel angle")
    for v in velocity:
        _within(v, "rate", "wheel rate")
    rates = (float(velocity[0]), float(velocity[1])) if len(velocity) else None
    return stamp, (float(position[0]), float(position[1])), rates


def encode_wrench(stamp: int, t1: float, t2: float) -> bytes:
    """disturbance_estimate / lumped_disturbance: torque.x = component 1, torque.y = component 2."""
    return _WRENCH(stamp, _ZERO3, (float(t1), float(t2), 0.0))


def encode_pose(stamp: int, pose) -> bytes:
    """true_pose: a :class:`~mwip_ros.core.plants.plant.Pose` as a PoseStamped in :data:`POSE_FRAME`."""
    return _POSE(stamp, (float(pose.x), float(pose.y), float(pose.z)),
                 pose_quaternion(pose.yaw, pose.pitch, pose.roll))


def _diagonal(variance: float) -> Tuple[float, ...]:
    v = float(variance)
    return (v, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v)


def encode_imu(stamp: int, gyro: float, accel_x: float, accel_z: float, gyro_variance: float = 0.0,
               accel_variance: float = 0.0, gyro_z: float = 0.0) -> bytes:
    """imu/data_raw: no orientation (orientation_covariance[0] = -1), angular_velocity (0, gyro, gyro_z: a spatial
    plant's yaw gyro, docs/theory.md 6.13), linear_acceleration (accel_x, 0, accel_z), each covariance ``variance``
    times the identity (0 = unknown)."""
    return _IMU(stamp, _NO_ORIENTATION, _NO_ORIENTATION_COV, (0.0, float(gyro), float(gyro_z)),
                _diagonal(gyro_variance), (float(accel_x), 0.0, float(accel_z)), _diagonal(accel_variance))


def encode_encoder(stamp: int, phi: float, rate: float, torque: float) -> bytes:
    """wheel_encoder: name [wheel], position [phi], velocity [phi rate], effort [the torque that acted]."""
    return _ENCODER(stamp, (float(phi),), (float(rate),), (float(torque),))


_INTERNAL_ENCODERS: Dict[Tuple[str, ...], cdr.JointStateEncoder] = {INTERNAL_NAMES: _INTERNALS}


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
    if len(names) == 3 and names[2] == YAW_JOINT:   # a spatial plant's yaw joint (theory 6.13): read by parse_yaw_rate
        names = names[:2]
        if len(position) != 3 or len(velocity) != 3:
            raise BadMessage(f"array lengths position={len(position)} velocity={len(velocity)}, expected 3, 3 with "
                             f"the joint {YAW_JOINT!r}")
        position, velocity = position[:2], velocity[:2]
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
    check_state(x, u_prev)
    return stamp, x, u_prev


def parse_yaw_rate(data) -> Optional[float]:
    """The gyro's yaw rate of a joint_states message from a spatial plant (its third joint :data:`YAW_JOINT`), None
    without one; BadMessage when it is not finite or implausible (call after :func:`parse_joint_state`)."""
    _stamp, _frame, names, _position, velocity, _effort = _decoded(cdr.decode_joint_state, data,
                                                                   "sensor_msgs/JointState")
    if len(names) != 3 or names[2] != YAW_JOINT or len(velocity) != 3:
        return None
    w = velocity[2]
    _finite((w,), "yaw rate")
    _within(w, "rate", "yaw rate")
    return float(w)


def check_state(x, u_prev: float = 0.0) -> None:
    """BadMessage unless the state ``x`` and the torque ``u_prev`` are finite and plausible (:data:`LIMITS`): what
    :func:`parse_joint_state` accepts (a node checks what it would publish with it)."""
    _finite((*x, u_prev), "joint state")
    _within(x[1], "theta_b", "theta_b")
    _within(x[0], "theta_w", "theta_w")
    _within(x[2], "rate", "theta_w'")
    _within(x[3], "rate", "theta_b'")
    _within(u_prev, "torque", "effort")


def _raw_within(values: Sequence[float], limit: str, what: str) -> None:
    for v in values:
        if abs(v) > RAW_LIMITS[limit]:
            raise BadMessage(f"implausible {what} {v:g} (|{what}| must be <= {RAW_LIMITS[limit]:g})")


def parse_imu(data, yaw: bool = False) -> Tuple[float, ...]:
    """(stamp_ns, gyro = angular_velocity.y, accel_x, accel_z), with ``yaw`` then angular_velocity.z (a spatial
    plant's yaw gyro, docs/theory.md 6.13), of an imu/data_raw message, or BadMessage (every
    axis of angular_velocity and linear_acceleration must be finite and plausible, the frame :data:`IMU_FRAME`;
    the orientation and the covariances are not read)."""
    stamp, frame, _q, _qc, w, _wc, a, _ac = _decoded(cdr.decode_imu, data, "sensor_msgs/Imu")
    if frame != IMU_FRAME:
        raise BadMessage(f"frame_id {frame[:64]!r}, expected {IMU_FRAME!r} (the IMU's own frame, REP-145)")
    _finite((*w, *a), "IMU reading")
    _raw_within(w, "gyro", "angular_velocity")
    _raw_within(a, "accel", "linear_acceleration")
    return (stamp, w[1], a[0], a[2], w[2]) if yaw else (stamp, w[1], a[0], a[2])


def parse_encoder(data) -> Tuple[int, float, float, float]:
    """(stamp_ns, phi, phi rate, torque) of a wheel_encoder message, or BadMessage (name [wheel], one value in
    each of position, velocity and effort, finite and plausible; the frame :data:`ENCODER_FRAME`)."""
    stamp, frame, names, position, velocity, effort = _decoded(cdr.decode_joint_state, data,
                                                               "sensor_msgs/JointState")
    if frame != ENCODER_FRAME:
        raise BadMessage(f"frame_id {frame[:64]!r}, expected {ENCODER_FRAME!r} (the encoder's JointState has none)")
    if list(names) != [ENCODER_JOINT]:
        raise BadMessage(f"joint names {list(names)}, expected [{ENCODER_JOINT!r}]")
    if len(position) != 1 or len(velocity) != 1 or len(effort) != 1:
        raise BadMessage(f"array lengths position={len(position)} velocity={len(velocity)} effort={len(effort)}, "
                         f"expected 1, 1, 1")
    phi, rate, torque = position[0], velocity[0], effort[0]
    _finite((phi, rate, torque), "encoder reading")
    _raw_within((phi,), "phi", "encoder angle")
    _raw_within((rate,), "rate", "encoder rate")
    _raw_within((torque,), "torque", "effort")
    return stamp, phi, rate, torque


def parse_odometry(data) -> Tuple[int, float, float, float]:
    """(stamp_ns, x, y, z) of robot_state's odom (frame odom, child base_link), or BadMessage (finite, plausible)."""
    stamp, frame, child, pose = _decoded(cdr.decode_odometry, data, "nav_msgs/Odometry")
    if (frame, child) != ("odom", "base_link"):
        raise BadMessage(f"frames {frame[:64]!r} -> {child[:64]!r}, expected 'odom' -> 'base_link'")
    _finite(pose, "odometry pose")
    _within(max(abs(v) for v in pose[:3]), "theta_w", "odometry position")
    return stamp, pose[0], pose[1], pose[2]


def parse_wrench(data) -> Tuple[int, float, float]:
    """(stamp_ns, torque.x, torque.y) of a WrenchStamped, or BadMessage."""
    stamp, _frame, _force, torque = _decoded(cdr.decode_wrench_stamped, data, "geometry_msgs/WrenchStamped")
    _torques(torque[:2], "torque")
    return stamp, torque[0], torque[1]


def parse_pose(data) -> Tuple[int, Tuple[float, ...]]:
    """(stamp_ns, (x, y, z, yaw, pitch, roll)) of a true_pose message, or BadMessage (frame :data:`POSE_FRAME`,
    every value finite, the quaternion of unit norm to 1e-6)."""
    stamp, frame, p, q = _decoded(cdr.decode_pose_stamped, data, "geometry_msgs/PoseStamped")
    if frame != POSE_FRAME:
        raise BadMessage(f"frame_id {frame[:64]!r}, expected {POSE_FRAME!r}")
    _finite((*p, *q), "pose")
    if abs(sum(v * v for v in q) - 1.0) > 1e-6:
        raise BadMessage(f"orientation {list(q)} is not a unit quaternion")
    pitch, yaw, roll = pose_angles(q[3], q[0], q[1], q[2])
    return stamp, (p[0], p[1], p[2], yaw, pitch, roll)


def parse_bool(data) -> bool:
    """emergency_stop's value: std_msgs/Bool from its CDR bytes (encapsulation CDR_LE or CDR_BE, then one byte 0 or
    1), or BadMessage."""
    b = bytes(data[:5])
    if len(b) < 5 or b[0] != 0 or b[1] not in (0, 1):
        raise BadMessage(f"not a std_msgs/Bool: {len(data)} bytes, encapsulation {b[:2].hex() or 'missing'}")
    if b[4] > 1:
        raise BadMessage(f"not a std_msgs/Bool: data byte {b[4]} is neither 0 nor 1")
    return b[4] == 1


MAX_DRIVER_STATE_BYTES = 4096   # a driver_state record is a few hundred bytes; a longer one is not read


def parse_driver_state(data) -> str:
    """The driver's state (``disabled``, ``enabled`` or ``fault``, :data:`mwip_ros.core.control.safety.STATES`) of one
    ``driver_state`` message (std_msgs/String, the JSON record ``plant_sim`` publishes at each transition), or
    BadMessage: not a String, longer than :data:`MAX_DRIVER_STATE_BYTES`, not JSON, no known ``state``."""
    if len(data) > MAX_DRIVER_STATE_BYTES:
        raise BadMessage(f"not a driver_state record: {len(data)} bytes, more than {MAX_DRIVER_STATE_BYTES}")
    text = _decoded(cdr.decode_string, data, "std_msgs/String")
    try:
        state = json.loads(text).get("state")
    except (ValueError, AttributeError, RecursionError):
        raise BadMessage("not a driver_state record: not a JSON object") from None
    if state not in STATES:
        raise BadMessage(f"not a driver_state record: state {str(state)[:40]!r} is not one of {', '.join(STATES)}")
    return state


def parse_command(data) -> float:
    """wheel_torque_cmd's value, or BadMessage."""
    u = _decoded(cdr.decode_float64, data, "std_msgs/Float64")
    if not math.isfinite(u):
        raise BadMessage(f"non-finite command {u}")
    _within(u, "torque", "command")
    return u


def encode_external_wrench(t1: float, t2: float, fy: float = 0.0, tz: float = 0.0) -> bytes:
    """external_wrench: torque.x adds to tau_ext1, torque.y to tau_ext2; force.y (``fy``, a lateral push) and torque.z
    (``tz``, a yaw torque) act on a spatial plant's body (backend mujoco), the planar one ignores them."""
    return cdr.encode_wrench((0.0, float(fy), 0.0), (float(t1), float(t2), float(tz)))


def parse_external_wrench(data) -> Tuple[float, float, float, float]:
    """(torque.x, torque.y, force.y, torque.z) of an external_wrench message, or BadMessage (force.y is held to
    the torques' bound, in N)."""
    force, torque = _decoded(cdr.decode_wrench, data, "geometry_msgs/Wrench")
    _torques((torque[0], torque[1], torque[2]), "torque")
    _finite(force[1:2], "force")
    _within(force[1], "torque", "force.y")
    return torque[0], torque[1], force[1], torque[2]


def encode_twist(vx: float, wz: float) -> bytes:
    """cmd_vel (geometry_msgs/Twist, REP-103 base frame): linear.x = ``vx`` [m/s], angular.z = ``wz`` [rad/s]."""
    return cdr.encode_wrench((float(vx), 0.0, 0.0), (0.0, 0.0, float(wz)))   # the same layout: two Vector3


def parse_twist(data) -> Tuple[float, float]:
    """(linear.x, angular.z) of a cmd_vel Twist, or BadMessage when it is not one; the numbers are judged by
    :meth:`mwip_ros.core.control.motion.Shaper.command` (not finite or absurd: rejected and counted)."""
    linear, angular = _decoded(cdr.decode_wrench, data, "geometry_msgs/Twist")   # Twist's layout is Wrench's
    return linear[0], angular[2]


def parse_clock(data) -> int:
    """/clock's time in ns, or BadMessage."""
    return _decoded(cdr.decode_clock, data, "rosgraph_msgs/Clock")


def parse_internals(data) -> Tuple[int, Dict[str, float]]:
    """(stamp_ns, {name: value}) of a controller_internals message, or BadMessage."""
    stamp, _frame, names, position, _v, _e = _decoded(cdr.decode_joint_state, data, "sensor_msgs/JointState")
    if len(names) != len(position):
        raise BadMessage(f"{len(names)} names for {len(position)} values")
    return stamp, dict(zip(names, position))
