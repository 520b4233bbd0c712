"""The URDF made from the parameter file (docs/theory.md 6.12), read back with urdf_parser_py (ROS's URDF parser)."""
from __future__ import annotations

import pytest

from mwip_ros import params as P
from mwip_ros.params.paths import default_params_file
from mwip_ros.core.mobile_base.urdf import BASE_LINK, IMU_LINK, WHEEL_JOINTS, WHEEL_LINKS, robot_model, urdf

urdf_parser = pytest.importorskip("urdf_parser_py.urdf")

pytestmark = pytest.mark.unit


def _parse(values):
    return urdf_parser.URDF.from_xml_string(urdf(robot_model(values)))


def test_links_joints_and_axes_are_rep103():
    robot = _parse(P.defaults_for("robot_state"))
    assert sorted(link.name for link in robot.links) == sorted([BASE_LINK, *WHEEL_LINKS, IMU_LINK])
    assert robot.get_root() == BASE_LINK
    joints = {j.name: j for j in robot.joints}
    assert set(joints) == {*WHEEL_JOINTS, "imu_joint"}
    for name, link, y in zip(WHEEL_JOINTS, WHEEL_LINKS, (0.25, -0.25)):   # left is +y (REP-103), track 0.5 m
        j = joints[name]
        assert (j.type, j.parent, j.child) == ("continuous", BASE_LINK, link)
        assert list(j.axis) == [0.0, 1.0, 0.0]
        assert list(j.origin.xyz) == [0.0, y, 0.0]
    imu = joints["imu_joint"]
    assert (imu.type, imu.parent, imu.child, list(imu.origin.xyz)) == ("fixed", BASE_LINK, IMU_LINK, [0.0, 0.0, 0.3])


def test_masses_and_inertias_are_the_parameter_files():
    # config/paper.yaml's true robot (Table II): m_b 310.6, I_b 65, l 0.317, m_w 29, I_w 0.6, r 0.254
    pf = P.load_param_file(default_params_file())
    v = dict(P.defaults_for("robot_state"))
    v.update({k: val for k, val in pf.for_node("plant_sim").items() if k in v})
    robot = _parse(v)
    body = robot.link_map[BASE_LINK].inertial
    assert body.mass == 310.6
    assert list(body.origin.xyz) == [0.0, 0.0, 0.317]
    assert (body.inertia.ixx, body.inertia.iyy, body.inertia.izz) == (65.0, 65.0, 20.0)   # roll, pitch, yaw
    for link in WHEEL_LINKS:
        w = robot.link_map[link]
        assert w.inertial.mass == 14.5                       # half of m_w = 29
        assert w.inertial.inertia.iyy == 0.3                 # half of I_w = 0.6, about the axle
        assert w.inertial.inertia.ixx == 0.15
        assert w.visual.geometry.radius == 0.254


def test_every_number_comes_from_the_parameters():
    base = dict(P.defaults_for("robot_state"))
    changed = {"actual.m_b": 123.0, "actual.m_w": 8.0, "actual.I_b": 7.0, "actual.I_w": 0.2, "actual.l": 0.5,
               "actual.r": 0.1, "actual.I_b_roll": 9.0, "actual.I_b_yaw": 3.0, "actual.track_width": 0.8,
               "sensors.imu.offset": 0.45}
    robot = _parse({**base, **changed})
    body = robot.link_map[BASE_LINK].inertial
    assert (body.mass, body.origin.xyz[2]) == (123.0, 0.5)
    assert (body.inertia.ixx, body.inertia.iyy, body.inertia.izz) == (9.0, 7.0, 3.0)
    left = robot.link_map[WHEEL_LINKS[0]]
    assert (left.inertial.mass, left.inertial.inertia.iyy, left.visual.geometry.radius) == (4.0, 0.1, 0.1)
    joints = {j.name: j for j in robot.joints}
    assert joints[WHEEL_JOINTS[0]].origin.xyz[1] == 0.4 and joints[WHEEL_JOINTS[1]].origin.xyz[1] == -0.4
    assert joints["imu_joint"].origin.xyz[2] == 0.45
    with pytest.raises(KeyError, match="actual.track_width"):
        robot_model({k: v for k, v in base.items() if k != "actual.track_width"})
