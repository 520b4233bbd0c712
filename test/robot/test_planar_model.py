"""The planar model from a URDF (SPEC 16, mwip_ros.robot.planar_model): a small robot computed by hand, Upkie's URDF
against SPEC 16's numbers, and the robot PyBullet simulates against PyBullet's own kinetic energy."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mwip_ros.robot.planar_model import planar_model, upkie_planar_model

pytestmark = pytest.mark.unit

# A body (base, with its inertial turned by pi/2 about x), an arm on a hip joint, two wheels whose joints turn about
# +y through opposite local axes, a 20 g valve off the left wheel's axle, and an IMU link turned by pi about x.
SMALL = """<?xml version="1.0"?>
<robot name="small">
  <link name="base">
    <inertial><origin xyz="0.02 0 0.4" rpy="1.5707963267948966 0 0"/><mass value="3.0"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.2" iyz="0" izz="0.05"/></inertial>
  </link>
  <joint name="hip" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 1 0"/><limit effort="1" lower="-3" upper="3" velocity="1"/></joint>
  <link name="arm">
    <inertial><origin xyz="0 0 0.2"/><mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/></inertial>
  </link>
  <joint name="left_wheel" type="continuous"><parent link="base"/><child link="left_tyre"/>
    <origin xyz="0 0.2 0" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/></joint>
  <link name="left_tyre">
    <inertial><origin xyz="0 0 0.01"/><mass value="0.5"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.002"/></inertial>
    <collision><geometry><cylinder radius="0.1" length="0.03"/></geometry></collision>
  </link>
  <joint name="valve_fix" type="fixed"><parent link="left_tyre"/><child link="left_valve"/>
    <origin xyz="0.05 0 0"/></joint>
  <link name="left_valve">
    <inertial><mass value="0.02"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>
  </link>
  <joint name="right_wheel" type="continuous"><parent link="base"/><child link="right_tyre"/>
    <origin xyz="0 -0.2 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 -1"/></joint>
  <link name="right_tyre">
    <inertial><origin xyz="0 0 0.01"/><mass value="0.5"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.002"/></inertial>
    <collision><geometry><cylinder radius="0.1" length="0.03"/></geometry></collision>
  </link>
  <joint name="imu_fix" type="fixed"><parent link="base"/><child link="imu"/>
    <origin xyz="0.01 0 0.3" rpy="3.141592653589793 0 0"/></joint>
  <link name="imu"/>
</robot>
"""
WHEELS = ("left_wheel", "right_wheel")


def _small(**kw):
    return planar_model(SMALL, WHEELS, imu_link="imu", **kw)


def test_small_robot_by_hand_with_the_arm_held_forward():
    m = _small(held={"hip": math.pi / 2})
    # the hip turned by +pi/2 about y takes the arm's z axis to +x: its centre at (0.2, 0, 0.5)
    com_x, com_z = (3.0 * 0.02 + 1.0 * 0.2) / 4.0, (3.0 * 0.4 + 1.0 * 0.5) / 4.0
    assert m.m_b == pytest.approx(4.0, rel=1e-12)
    assert m.l == pytest.approx(math.hypot(com_x, com_z), rel=1e-12)
    assert m.com_angle == pytest.approx(math.atan2(com_x, com_z), rel=1e-12)
    # the base's inertial turned by pi/2 about x: its local z (0.05) lies along y; the arm's yy (0.02) stays
    i_b = (0.05 + 3.0 * ((0.02 - com_x) ** 2 + (0.4 - com_z) ** 2)
           + 0.02 + 1.0 * ((0.2 - com_x) ** 2 + (0.5 - com_z) ** 2))
    assert m.I_b == pytest.approx(i_b, rel=1e-12)
    # wheel sets: both tyres about their own axle (izz 0.002 each) and the valve's 20 g at 5 cm
    assert m.m_w == pytest.approx(1.02, rel=1e-12)
    assert m.I_w == pytest.approx(0.002 + 0.002 + 0.02 * 0.05 ** 2, rel=1e-12)
    assert set(m.wheel_links) == {"left_tyre", "left_valve", "right_tyre"}
    assert set(m.body_links) == {"base", "arm", "imu"}
    assert m.r == 0.1 and m.track_width == pytest.approx(0.4, abs=1e-12)


def test_small_robot_roll_yaw_and_imu_in_the_body_frame():
    m = _small(held={"hip": math.pi / 2})
    com = np.array([(3.0 * 0.02 + 1.0 * 0.2) / 4.0, 0.0, (3.0 * 0.4 + 1.0 * 0.5) / 4.0])
    a = math.atan2(com[0], com[2])
    # the body's tensor in the root frame: the base's (0.1, 0.05, 0.2 after its turn about x), the arm's (0.03, 0.02,
    # 0.01 after the hip's pi/2 about y), each plus m (|d|^2 I - d d^T) about the centre of mass
    total = np.diag([0.1, 0.05, 0.2]) + np.diag([0.03, 0.02, 0.01])
    for mass, c in ((3.0, np.array([0.02, 0.0, 0.4])), (1.0, np.array([0.2, 0.0, 0.5]))):
        d = c - com
        total = total + mass * (d @ d * np.eye(3) - np.outer(d, d))
    x_b, z_b = np.array([math.cos(a), 0.0, -math.sin(a)]), np.array([math.sin(a), 0.0, math.cos(a)])
    assert m.I_b_roll == pytest.approx(x_b @ total @ x_b, rel=1e-12)
    assert m.I_b_yaw == pytest.approx(z_b @ total @ z_b, rel=1e-12)
    p = np.array([0.01, 0.0, 0.3])
    assert m.imu_offset == pytest.approx(p @ z_b, rel=1e-12)
    assert m.imu_forward == pytest.approx(p @ x_b, rel=1e-12)
    # the IMU link is the root turned by pi about x: its z is the root's -z, its x the root's x; in body coordinates
    # (their components along x_b, y, z_b):
    down, ahead = np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0])
    assert m.body_from_imu() @ [0.0, 0.0, 1.0] == pytest.approx([x_b @ down, 0.0, z_b @ down], abs=1e-12)
    assert m.body_from_imu() @ [1.0, 0.0, 0.0] == pytest.approx([x_b @ ahead, 0.0, z_b @ ahead], abs=1e-12)
    assert m.body_from_imu() @ [0.0, 1.0, 0.0] == pytest.approx([0.0, -1.0, 0.0], abs=1e-12)


def test_held_position_moves_the_body_and_the_wheels_do_not_matter():
    straight = _small()   # the arm straight up: its centre at (0, 0, 0.7)
    assert straight.l == pytest.approx(math.hypot(0.06 / 4.0, (1.2 + 0.7) / 4.0), rel=1e-12)
    turned = _small(held={"hip": math.pi / 2, "left_wheel": 1.0})
    assert turned.I_w == pytest.approx(_small(held={"hip": math.pi / 2}).I_w, rel=1e-12)


def test_inertias_given_replace_the_urdf_ones():
    # the left tyre's tensor in its own frame, its axle (local z) now 0.005
    m = _small(held={"hip": math.pi / 2}, inertias={"left_tyre": np.diag([0.001, 0.001, 0.005])})
    assert m.I_w == pytest.approx(0.005 + 0.002 + 0.02 * 0.05 ** 2, rel=1e-12)


def test_physical_params_feed_the_model():
    p = _small(held={"hip": math.pi / 2}).physical(g=9.81)
    assert p.m11 == pytest.approx((4.0 + 1.02) * 0.1 ** 2 + 0.00405, rel=1e-12)
    assert p.G_b == pytest.approx(4.0 * 9.81 * p.l, rel=1e-12)


@pytest.mark.parametrize("change, words", [
    (lambda s: s.replace('<axis xyz="0 0 -1"/>', '<axis xyz="1 0 0"/>'), "not along y"),
    (lambda s: s.replace('origin xyz="0 -0.2 0"', 'origin xyz="0.1 -0.2 0"'), "not on one axle"),
    (lambda s: s.replace('<collision><geometry><cylinder radius="0.1" length="0.03"/></geometry></collision>', ''),
     "give the tyre's radius"),
])
def test_bad_robots_are_refused_with_a_reason(change, words):
    with pytest.raises(ValueError, match=words):
        planar_model(change(SMALL), WHEELS)


def test_unknown_names_are_refused():
    with pytest.raises(ValueError, match="no joint 'knee'"):
        planar_model(SMALL, WHEELS, held={"knee": 0.1})
    with pytest.raises(ValueError, match="no link 'lidar'"):
        planar_model(SMALL, WHEELS, imu_link="lidar")
    with pytest.raises(ValueError, match="no URDF file"):
        planar_model("/nonexistent/robot.urdf", WHEELS)


# --- Upkie ------------------------------------------------------------------------------------------------------------

upkie_description = pytest.importorskip("upkie_description")


def test_upkie_from_its_urdf_against_spec16():
    m = upkie_planar_model()
    assert m.m_b == pytest.approx(4.97, abs=0.005)
    assert m.l == pytest.approx(0.281, abs=0.001)
    # SPEC's 0.365 kg leaves out the wheels' two 1 g virtual links each (contact, centre): 0.369 with them
    assert m.m_w == pytest.approx(0.365, rel=0.015)
    assert m.r == 0.05
    # the URDF's inertial tags: I_b 2.2 % under SPEC's 0.111; I_w per side the three links' izz (rotor, hub, tyre)
    # and the 1 g contact link 0.047 m off the axle (SPEC's 5.2e-4 is PyBullet's robot: test_upkie_backend.py)
    assert m.I_b == pytest.approx(0.111, rel=0.03)
    assert m.I_w == pytest.approx(2 * (2.89e-05 + 3.45267e-05 + 1.089375e-04 + 0.001 * 0.047 ** 2), rel=1e-9)
    # the body's centre is 6.4 mm behind the axle: upright at a base pitch of +0.0229 rad
    assert m.com_angle == pytest.approx(math.atan2(-0.00644, 0.281), abs=2e-4)
    # the IMU on the base, 0.507 - 0.1 m above the axle; its z axis points down the body
    assert m.imu_offset == pytest.approx(0.407, abs=0.001)
    assert (m.body_from_imu() @ [0.0, 0.0, 1.0])[2] == pytest.approx(-1.0, abs=1e-3)


def test_upkie_wheel_radius_is_upkies_own():
    model = pytest.importorskip("upkie.model")
    up = model.Model()
    assert upkie_planar_model().r == up.wheel_radius
    assert upkie_planar_model().track_width == pytest.approx(up.wheel_base, abs=1e-9)
