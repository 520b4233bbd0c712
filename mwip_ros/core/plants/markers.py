"""Where the robot's parts are, for a picture of it: a pure function of the nominal model and the state.

World frame: x forward along the ground, z up, y the wheel axle.  The wheel (radius r) rolls
without slipping, so its centre is at (r theta_w, 0, r); a spoke marks its rotation, at
angle theta_w from upright (rolling forward turns its top forward).  The body is a rod from
the axle through its centre of gravity, at distance l from the axle, tilted by theta_b from
upright (theta_b > 0 leans forward).  Both rotations are about the +y axis.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

from .model import PhysicalParams

__all__ = ["RobotPose", "robot_pose", "pitch_quaternion", "pose_quaternion", "pose_angles"]


@dataclass(frozen=True)
class RobotPose:
    wheel_center: Tuple[float, float, float]
    spoke_end: Tuple[float, float, float]     # a point on the rim: shows the wheel's rotation
    body_center: Tuple[float, float, float]   # the centre of gravity, l from the axle
    body_top: Tuple[float, float, float]      # 2 l from the axle: the rod's far end
    wheel_radius: float
    body_length: float                        # 2 l
    theta_w: float
    theta_b: float


def robot_pose(nominal: PhysicalParams, x) -> RobotPose:
    """The parts of the robot in state ``x`` (a State or any (theta_w, theta_b, ...) sequence)."""
    theta_w, theta_b = float(x[0]), float(x[1])
    r, l = nominal.r, nominal.l
    cx, cz = r * theta_w, r                          # rolling without slipping
    sb, cb = math.sin(theta_b), math.cos(theta_b)
    return RobotPose(wheel_center=(cx, 0.0, cz),
                     spoke_end=(cx + r * math.sin(theta_w), 0.0, cz + r * math.cos(theta_w)),
                     body_center=(cx + l * sb, 0.0, cz + l * cb),
                     body_top=(cx + 2 * l * sb, 0.0, cz + 2 * l * cb),
                     wheel_radius=r, body_length=2 * l, theta_w=theta_w, theta_b=theta_b)


def pitch_quaternion(angle: float) -> Tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``angle`` about +y: it turns +z towards +x."""
    return (0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2))


def pose_quaternion(yaw: float, pitch: float, roll: float) -> Tuple[float, float, float, float]:
    """(x, y, z, w) of the body's orientation from its yaw, pitch and roll as :func:`pose_angles` reads them:
    R = Rz(yaw) Rx(roll) Ry(pitch) (REP-103 axes; pitch about the axle, body y, turns +z towards +x)."""
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    w, x, y, z = cy * cr, cy * sr, sy * sr, sy * cr            # qz(yaw) qx(roll)
    return (x * cp - z * sp, w * sp + y * cp, z * cp + x * sp, w * cp - y * sp)   # (.) qy(pitch), as x, y, z, w


def pose_angles(w: float, a: float, b: float, c: float) -> Tuple[float, float, float]:
    """(pitch, yaw, roll) of the body's orientation quaternion w + a i + b j + c k: the pitch is the body z axis's
    angle from the vertical in the plane normal to the axle (body y), over the whole circle; the yaw the heading of
    that plane; the roll the axle's rise (the inverse of :func:`pose_quaternion`)."""
    yx, yy, yz = 2 * (a * b - w * c), 1 - 2 * (a * a + c * c), 2 * (b * c + w * a)    # body y in the world
    zx, zy, zz = 2 * (a * c + w * b), 2 * (b * c - w * a), 1 - 2 * (a * a + b * b)    # body z in the world
    hn = math.hypot(yx, yy) or 1.0
    # z_b . h and z_b . m: h = (y_b x z_world) / |.| = (yy, -yx, 0) / hn, m = h x y_b (the plane's upward axis)
    pitch = math.atan2((zx * yy - zy * yx) / hn, zz * hn - (zx * yx + zy * yy) * yz / hn)
    return pitch, math.atan2(-yx, yy), math.asin(max(-1.0, min(1.0, yz)))
