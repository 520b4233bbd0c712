"""The planar model of a wheeled robot from its URDF, with every non-wheel joint held (SPEC section 16, "A planar
model from a URDF"; docs/hardware-upkie.md).

Eq. (1)-(2) know a robot by six numbers: the body's mass ``m_b``, its inertia ``I_b`` about the pitch axis through its
centre of mass, the height ``l`` of that centre above the axle, both wheels' mass ``m_w`` and inertia ``I_w`` about the
axle, and the tyre's radius ``r``. A URDF knows it link by link. With the legs (every joint but the wheels') held at
given positions the robot is two rigid sets, and the computation is:

1. forward kinematics from the root link at the held joint positions: each link's pose ``T_i`` in the root frame,
   the frame the robot stands in (x forward, z up, REP-103), each inertial frame ``T_i T_inertial``;
2. the wheel set: every link of the subtree under each wheel joint (tyre, hub, the motor's rotor: whatever the
   URDF hangs below the joint turns with the wheel); the body: every other link;
3. the axle: the wheel joints' axes, both along the root's y (checked, as the joints' origins on one line);
4. ``m_w = sum m_i`` over the wheel set, ``I_w = sum (a^T R_i I_i R_i^T a + m_i rho_i^2)`` with ``a`` the axle's
   direction, ``R_i`` the rotation of link i's inertial frame into the root frame, ``I_i`` its inertia tensor and
   ``rho_i`` the distance of its centre of mass from the axle (the parallel-axis term);
5. ``m_b = sum m_i`` over the body, its centre of mass ``c = sum m_i c_i / m_b``; ``(dx, dz)`` its offset from the
   axle in the root's x-z plane, ``l = sqrt(dx^2 + dz^2)``; ``I_b = sum ((R_i I_i R_i^T)_yy + m_i ((c_i - c)_x^2 +
   (c_i - c)_z^2))``, the pitch axis being y;
6. ``r``: the radius of the largest collision cylinder of each wheel set (the tyre), or the one given; the track
   width between the two tyres' centres.

The inertia tensors are the URDF's unless ``inertias`` replaces them: a simulator may not use the URDF's (PyBullet,
loading a URDF without ``URDF_USE_INERTIA_FROM_FILE`` as Upkie's backend does, recomputes each link's from its
collision shapes; docs/hardware-upkie.md compares both).

A body whose centre of mass is not straight above the axle at the held pose (``dx != 0``) is upright at a root pitch
of ``-com_angle``, ``com_angle = atan2(dx, dz)``: eq. (1)'s theta_b, the lean of the axle-to-centre line, is the
root's pitch plus ``com_angle`` (REP-103: pitch about +y, > 0 leaning forward). Its *body frame* (SPEC section 10:
z_b along the body, towards the centre of mass; x_b forward when upright) is the root frame pitched by
``com_angle``; :attr:`PlanarModel.imu_rotation` maps an IMU link's axes into it (REP-145's ``imu_link``) and
:attr:`PlanarModel.imu_offset` is the IMU's distance from the axle along z_b (``sensors.imu.offset``).

The URDF is read with ``urdf_parser_py`` (ROS's URDF parser); its warnings about tags it does not model
(``<contact>``, a collision's ``<material>``) are dropped. Nothing here imports ROS or a simulator.
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Iterator, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from ..core.plants.model import PhysicalParams

__all__ = ["PlanarModel", "planar_model", "upkie_planar_model", "UPKIE_WHEEL_JOINTS", "UPKIE_IMU_LINK"]

UPKIE_WHEEL_JOINTS = ("left_wheel", "right_wheel")   # Upkie's wheel joints in its URDF and its spine, left first
UPKIE_IMU_LINK = "imu"
_AXIS_TOL = 1e-6   # [rad or m]: the wheel axes along y and on one line, to rounding


@dataclass(frozen=True)
class PlanarModel:
    """The planar model of a robot with its non-wheel joints held, from its URDF (module docstring), SI units.

    Attributes
    ----------
    m_b, I_b, l, m_w, I_w, r : float
        Eq. (2)'s parameters: body mass [kg], body inertia about the pitch axis through its centre of mass [kg m^2],
        the centre's distance from the axle [m], both wheels' mass [kg] and inertia about the axle [kg m^2], the
        tyre's radius [m].
    com_angle : float
        atan2(dx, dz) [rad]: how far ahead of the axle the body's centre of mass is at the held pose, as an angle;
        eq. (1)'s theta_b is the root link's pitch plus it.
    track_width : float
        The distance between the tyres' centres along the axle [m] (the wheel joints' origins when a wheel set has
        no collision cylinder).
    I_b_roll, I_b_yaw : float
        The body's inertia about its body frame's x and z axes through its centre of mass [kg m^2] (a 3D plant's).
    imu_offset : float
        The IMU link's distance from the axle along z_b [m] (nan without an IMU link).
    imu_forward : float
        Its distance from the z_b axis along x_b [m] (the raw-sensor model of SPEC 10 takes it as 0).
    imu_rotation : tuple of 3 tuples of 3 floats
        The rotation of the IMU link's axes into the body frame (a vector v in IMU axes is ``imu_rotation @ v`` in
        the body frame: REP-145's ``imu_link``); the identity without an IMU link.
    wheel_links, body_links : tuple of str
        Which links went where.
    """

    m_b: float
    I_b: float
    l: float
    m_w: float
    I_w: float
    r: float
    com_angle: float
    track_width: float
    I_b_roll: float
    I_b_yaw: float
    imu_offset: float
    imu_forward: float
    imu_rotation: Tuple[Tuple[float, float, float], ...]
    wheel_links: Tuple[str, ...]
    body_links: Tuple[str, ...]

    def physical(self, g: float = 9.81) -> PhysicalParams:
        """The model as :class:`~mwip_ros.core.plants.model.PhysicalParams` (what the laws, the observer, Theorem 2 and
        the tuner take), with gravity ``g`` [m/s^2]."""
        return PhysicalParams(m_b=self.m_b, m_w=self.m_w, I_b=self.I_b, I_w=self.I_w, l=self.l, r=self.r, g=g)

    def body_from_imu(self) -> np.ndarray:
        """:attr:`imu_rotation` as a 3x3 array."""
        return np.array(self.imu_rotation, dtype=float)


def _rpy(rpy: Optional[Sequence[float]]) -> np.ndarray:
    """URDF's fixed-axis roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = (0.0, 0.0, 0.0) if rpy is None else (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def _pose(origin) -> np.ndarray:
    """The 4x4 transform of a URDF ``<origin>`` (identity when absent)."""
    t = np.eye(4)
    if origin is not None:
        t[:3, :3] = _rpy(origin.rpy)
        t[:3, 3] = [0.0, 0.0, 0.0] if origin.xyz is None else origin.xyz
    return t


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation by ``angle`` about the unit ``axis``."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def _joint_motion(joint, q: float) -> np.ndarray:
    """The 4x4 motion of ``joint`` at position ``q`` in its own frame (rotation about, or translation along, its
    axis; a fixed joint: the identity)."""
    t = np.eye(4)
    if joint.type == "fixed" or q == 0.0:
        return t
    axis = np.asarray(joint.axis if joint.axis is not None else (1.0, 0.0, 0.0), dtype=float)
    axis = axis / np.linalg.norm(axis)
    if joint.type in ("revolute", "continuous"):
        t[:3, :3] = _axis_angle(axis, q)
    elif joint.type == "prismatic":
        t[:3, 3] = q * axis
    else:
        raise ValueError(f"joint {joint.name!r} of type {joint.type!r} cannot be held at a position")
    return t


@contextlib.contextmanager
def _quiet_parser() -> Iterator[None]:
    """urdf_parser_py reports tags it does not model (``<contact>``) on stderr; they are not errors here."""
    from ..optional import required
    with required("urdf_parser_py"):   # one line naming the package and its rosdep key when it is missing
        from urdf_parser_py.xml_reflection import core
    old = core.on_error
    core.on_error = lambda message: None
    try:
        yield
    finally:
        core.on_error = old


def _read(urdf: Union[str, Path]):
    """The parsed URDF of a path or of an XML string."""
    from ..optional import required
    with required("urdf_parser_py"):
        from urdf_parser_py.urdf import URDF
    with _quiet_parser():
        text = str(urdf)
        if text.lstrip().startswith("<"):
            return URDF.from_xml_string(text)
        path = Path(urdf)
        if not path.is_file():
            raise ValueError(f"no URDF file at {path}")
        return URDF.from_xml_string(path.read_text())


def _subtree(children: Mapping[str, list], link: str) -> list:
    out, stack = [], [link]
    while stack:
        name = stack.pop()
        out.append(name)
        stack.extend(j.child for j in children.get(name, ()))
    return out


def _tensor(inertia) -> np.ndarray:
    return np.array([[inertia.ixx, inertia.ixy, inertia.ixz],
                     [inertia.ixy, inertia.iyy, inertia.iyz],
                     [inertia.ixz, inertia.iyz, inertia.izz]], dtype=float)


def planar_model(urdf: Union[str, Path], wheel_joints: Sequence[str], held: Optional[Mapping[str, float]] = None,
                 radius: Optional[float] = None, imu_link: Optional[str] = None,
                 inertias: Optional[Mapping[str, np.ndarray]] = None) -> PlanarModel:
    """The planar model of the robot in ``urdf`` with its non-wheel joints held (module docstring, SPEC 16).

    Parameters
    ----------
    urdf : str or Path
        A URDF file's path, or its XML text.
    wheel_joints : sequence of str
        The wheel joints (one per wheel); every link below each is in the wheel set.
    held : mapping of str to float, optional
        Joint positions to hold [rad or m]; every movable joint not named is held at 0. A wheel joint's position
        changes nothing (the wheel set is symmetric about its axle as far as eq. 1 is concerned).
    radius : float, optional
        The tyre's radius [m]; by default the largest collision cylinder's radius in the wheel set.
    imu_link : str, optional
        A link whose pose gives :attr:`PlanarModel.imu_offset` and :attr:`PlanarModel.imu_rotation`.
    inertias : mapping of str to 3x3 array, optional
        Inertia tensors [kg m^2] that replace the URDF's for the links named, each about the link's centre of mass in
        the link's own frame, not its ``<inertial>`` frame: a simulator's own, e.g. PyBullet's, which recomputes
        them from the collision shapes (:func:`mwip_ros.robot.upkie.pybullet_inertias`).

    Returns
    -------
    PlanarModel
        The six parameters and the geometry around them.

    Raises
    ------
    ValueError
        A joint or link that the URDF does not have, wheel axes that are not along the root's y axis or not on one
        line, a wheel set without a cylinder (and no ``radius``), or a body without mass.
    """
    robot = _read(urdf)
    joints = {j.name: j for j in robot.joints}
    links = {lk.name: lk for lk in robot.links}
    held = dict(held or {})
    over = dict(inertias or {})
    for name in list(held) + list(wheel_joints):
        if name not in joints:
            raise ValueError(f"the URDF has no joint {name!r}")
    for name in over:
        if name not in links:
            raise ValueError(f"the URDF has no link {name!r}")
    if not wheel_joints:
        raise ValueError("no wheel joints given")
    children: Dict[str, list] = {}
    for j in robot.joints:
        children.setdefault(j.parent, []).append(j)
    # 1. forward kinematics from the root, at the held positions (wheels at 0)
    root = robot.get_root()
    pose = {root: np.eye(4)}
    stack = [root]
    while stack:
        parent = stack.pop()
        for j in children.get(parent, ()):
            q = 0.0 if j.name in wheel_joints else float(held.get(j.name, 0.0))
            pose[j.child] = pose[parent] @ _pose(j.origin) @ _joint_motion(j, q)
            stack.append(j.child)
    # 2. the wheel set and the body
    wheel = []
    for name in wheel_joints:
        wheel.extend(_subtree(children, joints[name].child))
    body = [name for name in links if name not in wheel]
    # 3. the axle: each wheel joint's axis in the root frame, along y and on one line
    points, axis = [], None
    for name in wheel_joints:
        j = joints[name]
        frame = pose[j.parent] @ _pose(j.origin)
        a = frame[:3, :3] @ np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
        a = a / np.linalg.norm(a)
        if abs(a[0]) > _AXIS_TOL or abs(a[2]) > _AXIS_TOL:
            raise ValueError(f"wheel joint {name!r} turns about {a.round(6).tolist()} in the root frame, not along y")
        points.append(frame[:3, 3])
        axis = np.array([0.0, 1.0, 0.0])
    p0 = points[0]
    for p in points[1:]:
        if abs(p[0] - p0[0]) > _AXIS_TOL or abs(p[2] - p0[2]) > _AXIS_TOL:
            raise ValueError(f"the wheel joints are not on one axle: x, z {p0[[0, 2]].tolist()} and "
                             f"{p[[0, 2]].tolist()}")

    def inertial(name):   # (mass, centre of mass in the root frame, tensor about it in the root frame) or None
        lk = links[name]
        if lk.inertial is None or lk.inertial.mass is None:
            return None
        frame = pose[name] @ _pose(lk.inertial.origin)
        rot = frame[:3, :3]
        if name in over:   # in the link's own frame
            link_rot = pose[name][:3, :3]
            return float(lk.inertial.mass), frame[:3, 3], link_rot @ np.asarray(over[name], float) @ link_rot.T
        tensor = _tensor(lk.inertial.inertia) if lk.inertial.inertia is not None else np.zeros((3, 3))
        return float(lk.inertial.mass), frame[:3, 3], rot @ tensor @ rot.T

    # 4. the wheel set about the axle
    m_w, I_w = 0.0, 0.0
    for name in wheel:
        part = inertial(name)
        if part is None:
            continue
        m, c, tensor = part
        rho = (c - p0) - ((c - p0) @ axis) * axis
        m_w += m
        I_w += float(axis @ tensor @ axis) + m * float(rho @ rho)
    # 5. the body about its centre of mass
    parts = [p for p in (inertial(name) for name in body) if p is not None]
    m_b = sum(m for m, _, _ in parts)
    if m_b <= 0.0:
        raise ValueError("the body (every link but the wheel sets) has no mass")
    com = sum(m * c for m, c, _ in parts) / m_b
    total = np.zeros((3, 3))
    for m, c, tensor in parts:
        d = c - com
        total += tensor + m * (float(d @ d) * np.eye(3) - np.outer(d, d))
    dx, dz = float(com[0] - p0[0]), float(com[2] - p0[2])
    com_angle = math.atan2(dx, dz)
    # the body frame: the root pitched by com_angle about y (z_b through the centre of mass)
    ca, sa = math.cos(com_angle), math.sin(com_angle)
    body_from_root = np.array([[ca, 0.0, -sa], [0.0, 1.0, 0.0], [sa, 0.0, ca]])
    in_body = body_from_root @ total @ body_from_root.T
    # 6. the tyres: each wheel's largest collision cylinder; its radius, and the track between their centres
    centres = []
    for name in wheel_joints:
        tyres = [(float(c.geometry.radius), (pose[lk] @ _pose(c.origin))[:3, 3])
                 for lk in _subtree(children, joints[name].child) for c in (links[lk].collisions or ())
                 if c.geometry is not None and type(c.geometry).__name__ == "Cylinder"]
        if tyres:
            centres.append(max(tyres, key=lambda t: t[0]))
    if radius is None:
        if len(centres) != len(wheel_joints):
            raise ValueError("a wheel set without a collision cylinder: give the tyre's radius")
        radius = max(c[0] for c in centres)
    ys = [c[1][1] for c in centres] if len(centres) == len(wheel_joints) else [p[1] for p in points]
    track = float(max(ys) - min(ys))
    imu_offset, imu_forward, imu_rot = math.nan, math.nan, np.eye(3)
    if imu_link is not None:
        if imu_link not in pose:
            raise ValueError(f"the URDF has no link {imu_link!r}")
        rel = body_from_root @ (pose[imu_link][:3, 3] - p0)
        imu_forward, imu_offset = float(rel[0]), float(rel[2])
        imu_rot = body_from_root @ pose[imu_link][:3, :3]
    return PlanarModel(
        m_b=float(m_b), I_b=float(total[1, 1]), l=math.hypot(dx, dz), m_w=float(m_w), I_w=float(I_w),
        r=float(radius), com_angle=com_angle, track_width=track, I_b_roll=float(in_body[0, 0]),
        I_b_yaw=float(in_body[2, 2]), imu_offset=imu_offset, imu_forward=imu_forward,
        imu_rotation=tuple(tuple(float(v) for v in row) for row in imu_rot),
        wheel_links=tuple(wheel), body_links=tuple(body))


def upkie_planar_model(urdf: Optional[Union[str, Path]] = None) -> PlanarModel:
    """Upkie's planar model in its pendulum posture (hips and knees at 0: legs straight), from ``upkie_description``'s
    URDF (or ``urdf``), wheels ``left_wheel`` and ``right_wheel``, IMU link ``imu``.

    Parameters
    ----------
    urdf : str or Path, optional
        Another Upkie URDF; by default ``upkie_description.URDF_PATH``.

    Returns
    -------
    PlanarModel
        Its planar model (docs/hardware-upkie.md has the numbers).
    """
    if urdf is None:
        try:
            import upkie_description
        except ImportError as exc:
            raise ValueError("Upkie's URDF needs the package upkie_description (pip install "
                             "upkie-description==2.2.0)") from exc
        urdf = upkie_description.URDF_PATH
    return planar_model(urdf, UPKIE_WHEEL_JOINTS, imu_link=UPKIE_IMU_LINK)
