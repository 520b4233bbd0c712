"""The robot's URDF, generated from the parameter file (docs/theory.md 6.12), for ``robot_description``.

Frames follow REP-103 (x forward, y left, z up) and the 3D model of docs/theory.md 6.10:

- ``base_link``: the body, origin on the axle's centre, z along the body (it pitches with theta_b).  Its mass
  ``actual.m_b`` sits at (0, 0, ``actual.l``) with the inertia (``actual.I_b_roll``, ``actual.I_b``,
  ``actual.I_b_yaw``) about its centre of gravity;
- ``wheel_left_link`` / ``wheel_right_link``: at y = +-``actual.track_width`` / 2, each with half of
  ``actual.m_w`` and of ``actual.I_w`` about the axle (a quarter about the other two axes, as a thin disc), a
  cylinder of radius ``actual.r``; their joints ``wheel_left_joint`` / ``wheel_right_joint`` are
  ``continuous`` about +y, the angle being the encoder's phi = theta_w - theta_b (the wheel relative to the
  body: theta > 0 rolls forward);
- ``imu_link``: fixed at (0, 0, ``sensors.imu.offset``) on the body, the IMU's frame (REP-145).

:func:`robot_model` reads the values of a parameter dict; :func:`urdf` writes the XML (the ``robot_state``
node publishes it latched on ``robot_description``; the live view shows it in its 3D panel).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, List, Mapping, NamedTuple, Tuple
from xml.sax.saxutils import quoteattr

__all__ = ["ROBOT_NAME", "ODOM_FRAME", "Transform", "frame_transforms", "Joint", "urdf_joints", "joint_transforms",
           "BASE_LINK", "IMU_LINK", "WHEEL_LINKS", "WHEEL_JOINTS", "RobotModel", "robot_model", "urdf"]

ROBOT_NAME = "mwip"
ODOM_FRAME = "odom"
BASE_LINK = "base_link"
IMU_LINK = "imu_link"
WHEEL_LINKS = ("wheel_left_link", "wheel_right_link")
WHEEL_JOINTS = ("wheel_left_joint", "wheel_right_joint")
# the parameters the model is made of (each a plant_sim parameter of the schema)
KEYS = ("actual.m_b", "actual.m_w", "actual.I_b", "actual.I_w", "actual.l", "actual.r", "actual.I_b_roll",
        "actual.I_b_yaw", "actual.track_width", "sensors.imu.offset")


class Transform(NamedTuple):
    """One frame's pose in its parent: translation (x, y, z) [m], rotation (x, y, z, w)."""

    parent: str
    child: str
    translation: Tuple[float, float, float]
    rotation: Tuple[float, float, float, float]


@dataclass(frozen=True)
class RobotModel:
    """The numbers of the URDF (SI units), each from the parameter named beside it."""

    m_b: float           # actual.m_b [kg]
    m_w: float           # actual.m_w [kg], both wheels
    I_b: float           # actual.I_b [kg m^2], pitch (about y)
    I_w: float           # actual.I_w [kg m^2], both wheels about the axle
    l: float             # actual.l [m], axle to the centre of gravity
    r: float             # actual.r [m], wheel radius
    I_b_roll: float      # actual.I_b_roll [kg m^2]
    I_b_yaw: float       # actual.I_b_yaw [kg m^2]
    track_width: float   # actual.track_width [m]
    imu_offset: float    # sensors.imu.offset [m]

    @property
    def wheel_width(self) -> float:
        """A wheel's drawn width [m]: the MuJoCo model's (:func:`~mwip_ros.core.plants.mujoco_plant.wheel_width`, r /
        5)."""
        from ..plants.mujoco_plant import wheel_width
        return wheel_width(self.r)


def robot_model(values: Mapping[str, Any]) -> RobotModel:
    """The :class:`RobotModel` of a parameter dict (a ``plant_sim`` or ``robot_state`` node's values); a missing
    key raises KeyError naming it."""
    return RobotModel(*(float(values[k]) for k in KEYS))


def _f(x: float) -> str:
    return repr(float(x))


def _inertial(mass: float, xyz, ixx: float, iyy: float, izz: float) -> str:
    return (f'<inertial><origin xyz="{" ".join(_f(a) for a in xyz)}" rpy="0 0 0"/><mass value="{_f(mass)}"/>'
            f'<inertia ixx="{_f(ixx)}" ixy="0" ixz="0" iyy="{_f(iyy)}" iyz="0" izz="{_f(izz)}"/></inertial>')


def urdf(m: RobotModel, name: str = ROBOT_NAME) -> str:
    """The URDF (XML text) of the robot ``m`` (module docstring)."""
    body_len = 2.0 * m.l   # the body drawn as a box from the axle to twice the centre of gravity's height
    body_w = max(m.track_width - 2.0 * m.wheel_width, m.track_width / 2.0)
    parts = [
        '<?xml version="1.0"?>',
        f'<robot name={quoteattr(name)}>',
        '<material name="body"><color rgba="0.1 0.4 0.8 0.9"/></material>',
        '<material name="wheel"><color rgba="0.2 0.2 0.2 1"/></material>',
        '<material name="imu"><color rgba="1 0.6 0 1"/></material>',
        f'<link name="{BASE_LINK}">',
        _inertial(m.m_b, (0.0, 0.0, m.l), m.I_b_roll, m.I_b, m.I_b_yaw),
        f'<visual><origin xyz="0 0 {_f(m.l)}" rpy="0 0 0"/><geometry><box size="{_f(0.12)} {_f(body_w)} '
        f'{_f(body_len)}"/></geometry><material name="body"/></visual>',
        '</link>',
    ]
    for link, joint, sign in zip(WHEEL_LINKS, WHEEL_JOINTS, (1.0, -1.0)):
        parts += [
            f'<link name="{link}">',
            _inertial(m.m_w / 2.0, (0.0, 0.0, 0.0), m.I_w / 4.0, m.I_w / 2.0, m.I_w / 4.0),
            # a URDF cylinder's axis is its z: turned by -pi/2 about x onto y
            f'<visual><origin xyz="0 0 0" rpy="-1.5707963267948966 0 0"/><geometry><cylinder radius="{_f(m.r)}" '
            f'length="{_f(m.wheel_width)}"/></geometry><material name="wheel"/></visual>',
            f'<visual><origin xyz="{_f(m.r / 2.0)} {_f(sign * m.wheel_width * 0.6)} 0" rpy="0 0 0"/><geometry>'
            f'<box size="{_f(m.r)} {_f(m.wheel_width / 5.0)} {_f(m.r / 10.0)}"/></geometry>'
            '<material name="imu"/></visual>',   # a spoke: shows the wheel turn
            f'<collision><origin xyz="0 0 0" rpy="-1.5707963267948966 0 0"/><geometry><cylinder radius="{_f(m.r)}" '
            f'length="{_f(m.wheel_width)}"/></geometry></collision>',
            '</link>',
            f'<joint name="{joint}" type="continuous"><parent link="{BASE_LINK}"/><child link="{link}"/>'
            f'<origin xyz="0 {_f(sign * m.track_width / 2.0)} 0" rpy="0 0 0"/><axis xyz="0 1 0"/></joint>',
        ]
    parts += [
        f'<link name="{IMU_LINK}"><visual><geometry><box size="0.04 0.04 0.02"/></geometry><material name="imu"/>'
        '</visual></link>',
        f'<joint name="imu_joint" type="fixed"><parent link="{BASE_LINK}"/><child link="{IMU_LINK}"/>'
        f'<origin xyz="0 0 {_f(m.imu_offset)}" rpy="0 0 0"/></joint>',
        '</robot>',
    ]
    return "\n".join(parts) + "\n"


def _yaw_pitch(yaw: float, pitch: float):
    """(x, y, z, w) of a yaw about z then a pitch about the new y: q_z(yaw) q_y(pitch)."""
    sz, cz, sy, cy = math.sin(yaw / 2), math.cos(yaw / 2), math.sin(pitch / 2), math.cos(pitch / 2)
    return (-sz * sy, cz * sy, cy * sz, cz * cy)


def frame_transforms(m: RobotModel, x: float, y: float, yaw: float, theta_b: float, phi_left: float,
                     phi_right: float) -> List[Transform]:
    """The frame tree odom -> base_link -> wheels / imu_link of the pose (x, y, yaw) in ``odom``, the body's pitch
    ``theta_b`` and the wheels' joint angles phi (relative to the body): base_link on the axle's centre, r above
    the ground, turned by yaw then pitched; each wheel at y = +-track_width / 2 turned by its phi about y."""
    return [Transform(ODOM_FRAME, BASE_LINK, (x, y, m.r), _yaw_pitch(yaw, theta_b)),
            *joint_transforms(model_joints(m), {WHEEL_JOINTS[0]: phi_left, WHEEL_JOINTS[1]: phi_right})]


@functools.lru_cache(maxsize=8)
def model_joints(m: RobotModel) -> Tuple["Joint", ...]:
    """The joints of :func:`urdf` of ``m`` (parsed once per model)."""
    return tuple(urdf_joints(urdf(m)))


class Joint(NamedTuple):
    """One joint of a URDF: its origin in the parent (xyz [m], rpy [rad]) and, when it moves, its axis."""

    name: str
    type: str
    parent: str
    child: str
    xyz: Tuple[float, float, float]
    rpy: Tuple[float, float, float]
    axis: Tuple[float, float, float]


MAX_URDF_CHARS = 1 << 20   # a URDF read (a robot_description from any publisher): this robot's is about 3 kB


def _floats(text, default, joint, what: str):
    """Three finite numbers of an attribute (``xyz``, ``rpy``), ``default`` without it; ValueError naming the joint."""
    if not text:
        return default
    try:
        out = tuple(float(a) for a in text.split())
    except ValueError:
        out = ()
    if len(out) != 3 or not all(math.isfinite(a) for a in out):
        raise ValueError(f"joint {joint.get('name')!r}: {what}={text[:60]!r} is not three finite numbers")
    return out


def urdf_joints(text: str) -> List[Joint]:
    """The joints of the URDF ``text`` (any robot's, not only :func:`urdf`'s).  Raises ValueError for text that
    is no URDF: not XML, longer than :data:`MAX_URDF_CHARS`, a joint without parent or child, an origin or axis
    that is not three finite numbers."""
    import xml.etree.ElementTree as ET
    if len(text) > MAX_URDF_CHARS:
        raise ValueError(f"{len(text):,} characters, larger than a URDF is read ({MAX_URDF_CHARS:,})")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ValueError(f"not XML: {exc}") from None
    if root.tag != "robot":
        raise ValueError(f"not a URDF: the root element is <{root.tag}>, not <robot>")
    out = []
    for j in root.findall("joint"):
        origin, axis = j.find("origin"), j.find("axis")
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None:
            raise ValueError(f"joint {j.get('name')!r} has no parent or child")
        out.append(Joint(j.get("name", ""), j.get("type", "fixed"), parent.get("link", ""), child.get("link", ""),
                         _floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0), j, "xyz"),
                         _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0), j, "rpy"),
                         _floats(axis.get("xyz") if axis is not None else None, (1.0, 0.0, 0.0), j, "axis xyz")))
    return out


def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def _rpy(r: float, p: float, y: float):
    """(x, y, z, w) of URDF's rpy: roll about x, then pitch about y, then yaw about z, all about fixed axes."""
    def about(axis, a):
        s = math.sin(a / 2.0)
        return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(a / 2.0))
    return _qmul(about((0, 0, 1), y), _qmul(about((0, 1, 0), p), about((1, 0, 0), r)))


def joint_transforms(joints, positions: Mapping[str, float]) -> List[Transform]:
    """Each joint's child frame in its parent, as robot_state_publisher computes it: the origin, then a turn by the
    joint's position about its axis (continuous and revolute joints; ``positions`` by joint name, missing = 0).
    Prismatic and other moving joints are left out; fixed joints are included."""
    out = []
    for j in joints:
        q = _rpy(*j.rpy)
        if j.type in ("continuous", "revolute"):
            n = math.sqrt(sum(a * a for a in j.axis)) or 1.0
            a, s = float(positions.get(j.name, 0.0)), math.sin(float(positions.get(j.name, 0.0)) / 2.0)
            q = _qmul(q, (j.axis[0] / n * s, j.axis[1] / n * s, j.axis[2] / n * s, math.cos(a / 2.0)))
        elif j.type != "fixed":
            continue
        out.append(Transform(j.parent, j.child, tuple(j.xyz), q))
    return out
