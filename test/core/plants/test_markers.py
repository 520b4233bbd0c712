"""The robot's picture: the wheel rolls r theta_w, the body tilts by theta_b about the axle."""
import math

import numpy as np
import pytest

from mathfixtures import NOM
from mwip_ros.core.plants.markers import pitch_quaternion, robot_pose
from mwip_ros.core.plants.model import State

pytestmark = pytest.mark.unit


def _rotate_z_axis(q):
    """Where a rotation (x, y, z, w) sends the unit z axis (the quaternion written out)."""
    x, y, z, w = q
    return np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


@pytest.mark.parametrize("theta_w, theta_b", [(0.0, 0.0), (3.0, 0.2), (-12.5, -0.7), (100.0, 1.0)])
def test_the_wheel_rolls_and_the_body_tilts(theta_w, theta_b):
    p = robot_pose(NOM, State(theta_w, theta_b, 5.0, -1.0))
    r, l = NOM.r, NOM.l
    assert p.wheel_center == pytest.approx((r * theta_w, 0.0, r))        # rolling without slipping
    spoke = np.subtract(p.spoke_end, p.wheel_center)
    assert np.linalg.norm(spoke) == pytest.approx(r) and math.atan2(spoke[0], spoke[2]) == pytest.approx(
        math.atan2(math.sin(theta_w), math.cos(theta_w)))
    body = np.subtract(p.body_center, p.wheel_center)
    assert np.linalg.norm(body) == pytest.approx(l)                      # the CoG is l from the axle
    assert math.atan2(body[0], body[2]) == pytest.approx(theta_b)       # leaning forward for theta_b > 0
    assert np.subtract(p.body_top, p.wheel_center) == pytest.approx(2 * body)
    # the body's orientation turns +z onto the rod's direction
    np.testing.assert_allclose(_rotate_z_axis(pitch_quaternion(theta_b)), body / l, atol=1e-12)
