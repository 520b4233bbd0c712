"""external_wrench's force.y and torque.z (msgs.layouts, core.plants.mujoco_plant): a lateral push at the body's centre
of gravity and a yaw torque act on the MuJoCo body, signs per REP-103 (y left, z up); the planar rk4 plant ignores
them."""
import math

import pytest

from mwip_ros import params as P
from mwip_ros.core.plants.plant import make_plant
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.errors import BadMessage
from mwip_ros.params.paths import default_params_file

pytestmark = pytest.mark.unit

PAPER = P.merged_values(P.load_param_file(default_params_file()))
QUIET = {"initial.theta_b": 0.0, "actual.D_w_variance": 0.0, "tau_ext1.amplitude": 0.0, "tau_ext2.amplitude": 0.0}


def _pushed(backend, wrench, periods=20, after=40):
    p = make_plant(P.plant_config(dict(PAPER, backend=backend, **QUIET)))
    for _ in range(periods):
        p.step(0.0, wrench)
    for _ in range(after):
        p.step(0.0, (0.0, 0.0, 0.0, 0.0))
    return p


def test_the_message_carries_force_y_and_torque_z_and_refuses_an_absurd_one():
    assert L.parse_external_wrench(L.encode_external_wrench(1.0, 2.0, 3.0, 4.0)) == (1.0, 2.0, 3.0, 4.0)
    assert L.parse_external_wrench(L.encode_external_wrench(1.0, 2.0)) == (1.0, 2.0, 0.0, 0.0)
    for fy, tz in ((1e9, 0.0), (math.nan, 0.0), (0.0, 1e9), (0.0, math.inf)):
        with pytest.raises(BadMessage):
            L.parse_external_wrench(L.encode_external_wrench(0.0, 0.0, fy, tz))


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_lateral_push_moves_the_body_to_its_side_and_rolls_it_that_way(sign):
    pytest.importorskip("mujoco")
    p = _pushed("mujoco", (0.0, 0.0, sign * 3000.0, 0.0))   # 3000 N for 0.1 s at the centre of gravity, 0.57 m up
    # REP-103: +y is left; the top going left is a negative roll (about +x, forward)
    assert sign * p.pose.y > 1e-3 and sign * p.pose.roll < -5e-3
    small = _pushed("mujoco", (0.0, 0.0, sign * 300.0, 0.0))   # far below tipping (about 1460 N) and sliding
    assert abs(small.pose.roll) < 1e-4 and abs(small.pose.y) < 1e-4
    assert p.data.xfrc_applied.tolist()[1] == [0.0] * 6   # the zero wrench that followed cleared it


def test_a_yaw_torque_turns_the_robot_counterclockwise_and_rk4_ignores_both():
    pytest.importorskip("mujoco")
    p = _pushed("mujoco", (0.0, 0.0, 0.0, 100.0))
    assert p.pose.yaw > 1e-4 and p.pose.wheel_left < 0.0 < p.pose.wheel_right   # left wheel back, right ahead
    a, b = _pushed("rk4", (5.0, 1.0)), _pushed("rk4", (5.0, 1.0, 3000.0, 100.0))
    assert tuple(a.x) == tuple(b.x)
