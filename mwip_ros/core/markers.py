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

__all__ = ["RobotPose", "robot_pose", "pitch_quaternion"]


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
