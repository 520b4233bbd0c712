"""Upkie behind the Backend interface (mwip_ros.robot.upkie, SPEC 16): the action and the observation's signs and axes
as pure functions, the spine's path with a stand-in for Upkie's SpineBackend (the robot is not here), and Upkie's own
PyBullet simulation, headless: signs, axes, determinism, the robot it simulates."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mwip_ros.robot.backend import BackendError, Command
from mwip_ros.robot.upkie import (LEG_JOINTS, UpkieBackend, UpkieConfig, observation_from_spine, pybullet_inertias,
                                  spine_action)

pytestmark = pytest.mark.unit


# --- the action and the observation ----------------------------------------------------------------------------------

def test_action_holds_the_legs_and_commands_the_wheels_in_pure_torque():
    cfg = UpkieConfig(leg_kp_scale=10.0, leg_kd_scale=1.0, leg_maximum_torque=16.0, wheel_maximum_torque=1.7)
    a = spine_action(Command(0.3, 0.5), cfg, left_wheeled=True)["servo"]
    for name in LEG_JOINTS:
        assert a[name] == {"position": 0.0, "velocity": 0.0, "feedforward_torque": 0.0, "kp_scale": 10.0,
                           "kd_scale": 1.0, "maximum_torque": 16.0}
    for name, torque in (("left_wheel", 0.3), ("right_wheel", -0.5)):   # forward: + on the left, - on the right
        w = a[name]
        assert math.isnan(w["position"]) and w["velocity"] == 0.0 and w["kp_scale"] == 0.0 and w["kd_scale"] == 0.0
        assert w["feedforward_torque"] == torque and w["maximum_torque"] == 1.7
    flipped = spine_action(Command(0.3, 0.5), cfg, left_wheeled=False)["servo"]
    assert flipped["left_wheel"]["feedforward_torque"] == -0.3 and flipped["right_wheel"]["feedforward_torque"] == 0.5


def test_stop_is_no_torque_on_any_servo():
    a = spine_action(None, UpkieConfig(), left_wheeled=True)["servo"]
    assert set(a) == set(LEG_JOINTS) | {"left_wheel", "right_wheel"}
    for w in a.values():
        assert w["feedforward_torque"] == 0.0 and w["kp_scale"] == 0.0 and w["kd_scale"] == 0.0
        assert w["maximum_torque"] == 0.0


def _spine_obs(left=(1.0, 2.0, 0.3), right=(-1.0, -2.0, -0.3), fault=0):
    servo = {name: {"position": 0.0, "velocity": 0.0, "torque": 0.0, "fault": 0} for name in LEG_JOINTS}
    servo["left_wheel"] = dict(zip(("position", "velocity", "torque"), left), fault=fault)
    servo["right_wheel"] = dict(zip(("position", "velocity", "torque"), right), fault=0)
    return {"servo": servo, "imu": {"angular_velocity": [0.1, 0.2, 0.3], "raw_linear_acceleration": [1.0, 2.0, 9.0]}}


def test_observation_wheels_in_the_forward_sense_and_imu_rotated():
    # Upkie's IMU link is the body turned by pi about y: x and z flip
    flip_y = np.diag([-1.0, 1.0, -1.0])
    obs = observation_from_spine(_spine_obs(), 1.5, True, flip_y)
    assert (obs.left.position, obs.left.velocity, obs.left.torque) == (1.0, 2.0, 0.3)
    assert (obs.right.position, obs.right.velocity, obs.right.torque) == (1.0, 2.0, 0.3)
    assert obs.phi == 1.0 and obs.phi_rate == 2.0 and obs.torque == pytest.approx(0.6)
    assert obs.imu.angular_velocity == pytest.approx((-0.1, 0.2, -0.3))
    assert obs.imu.linear_acceleration == pytest.approx((-1.0, 2.0, -9.0))
    assert obs.time == 1.5 and obs.fault is None and obs.truth is None
    right_wheeled = observation_from_spine(_spine_obs(), 0.0, False, np.eye(3))
    assert right_wheeled.left.position == -1.0 and right_wheeled.right.position == -1.0


def test_observation_names_a_servo_fault_and_a_missing_servo():
    assert observation_from_spine(_spine_obs(fault=33), 0.0, True, np.eye(3)).fault == \
        "upkie: left_wheel: moteus fault 33"
    obs = _spine_obs()
    del obs["servo"]["right_knee"]
    assert observation_from_spine(obs, 0.0, True, np.eye(3)).fault == "upkie: no reply from servo(s) right_knee"
    del obs["imu"]["raw_linear_acceleration"]
    assert observation_from_spine(obs, 0.0, True, np.eye(3)).imu is None


@pytest.mark.parametrize("key, value", [("dt", 0.0), ("leg_kp_scale", -1.0), ("wheel_maximum_torque", math.nan),
                                        ("initial_pitch", 1.5), ("substeps", -1)])
def test_config_out_of_range_is_named(key, value):
    with pytest.raises(ValueError, match=f"upkie: {key} = "):
        UpkieConfig(**{key: value}).checked()


# --- the spine's path, with a stand-in for upkie's SpineBackend ------------------------------------------------------

class _FakeSpine:
    """What UpkieBackend calls on upkie's SpineBackend: records the actions, answers a fixed observation."""

    def __init__(self):
        self.actions, self.reads, self.closed = [], 0, False

    def get_spine_observation(self):
        self.reads += 1
        return _spine_obs()

    def reset(self, init_state=None):
        return _spine_obs()

    def step(self, action):
        self.actions.append(action)
        return _spine_obs()

    def close(self):
        self.closed = True


def test_spine_path_queries_writes_and_stops_on_close():
    fake = _FakeSpine()
    b = UpkieBackend(fake, "spine", UpkieConfig())
    assert not b.simulated and b.name == "upkie"
    b.reset()
    b.observe()
    b.observe()
    assert fake.reads == 2   # a device is queried at every observe
    b.step(Command(0.1, 0.2))
    assert fake.actions[-1]["servo"]["right_wheel"]["feedforward_torque"] == -0.2
    with pytest.raises(ValueError, match="not finite"):
        b.step(Command(math.nan, 0.0))
    assert len(fake.actions) == 1   # nothing written
    b.close()
    b.close()   # idempotent
    assert fake.closed and fake.actions[-1]["servo"]["left_wheel"]["maximum_torque"] == 0.0   # a stop first
    assert len(fake.actions) == 2
    with pytest.raises(BackendError, match="closed"):
        b.observe()


def test_spine_kind_is_checked():
    with pytest.raises(ValueError, match="one of pybullet, spine"):
        UpkieBackend(_FakeSpine(), "gazebo", UpkieConfig())


# --- Upkie's PyBullet simulation -------------------------------------------------------------------------------------

pybullet = pytest.importorskip("pybullet")
pytest.importorskip("upkie")


@pytest.fixture(scope="module")
def sim():
    b = UpkieBackend.pybullet(UpkieConfig(initial_pitch=0.05))
    yield b
    b.close()


def _steps(b, command, n):
    obs = b.reset()
    x0 = b.axle_position()[0]
    for _ in range(n):
        obs = b.step(command)
    return obs, b.axle_position()[0] - x0


def test_reset_leans_at_the_initial_pitch_at_rest(sim):
    obs = sim.reset()
    assert obs.time == 0.0 and obs.truth[1] == pytest.approx(0.05, abs=2e-4)
    assert abs(obs.truth[3]) < 0.02 and abs(obs.phi) < 1e-4
    assert sim.observe() is obs   # the simulation's current read, not a second difference of the IMU's velocity


def test_forward_torque_rolls_forward_and_pitches_the_body_back(sim):
    free, _ = _steps(sim, Command(0.0, 0.0), 20)
    pushed, dx = _steps(sim, Command(0.3, 0.3), 20)
    assert pushed.time == pytest.approx(0.1)
    assert pushed.left.position > 0.05 and pushed.right.position > 0.05   # both wheels forward: +phi on each
    assert dx > 0.0   # the axle moved forward (REP-103 +x)
    assert pushed.truth[1] < free.truth[1] - 0.005   # the reaction pitches the body back (0.013 rad here)
    assert pushed.left.torque == pytest.approx(0.3) and pushed.torque == pytest.approx(0.6)


def test_gyro_pitch_rate_is_the_bodys_about_plus_y(sim):
    sim.reset()
    gyro, rate = [], []
    for k in range(40):
        obs = sim.step(Command(0.3, 0.3) if k < 20 else Command(-0.3, -0.3))
        gyro.append(obs.imu.angular_velocity[1])
        rate.append(obs.truth[3])
    # imu_link's y is REP-103's left: the pitch rate (the torso's, the true one the centre of mass's lean rate)
    assert np.corrcoef(gyro, rate)[0, 1] > 0.9
    assert min(gyro) < -0.1 and max(gyro) > 0.1


def test_opposite_torques_turn_left_about_z_up(sim):
    obs, _ = _steps(sim, Command(-0.5, 0.5), 20)   # right wheel forward: a left turn (REP-103: yaw > 0)
    assert obs.imu.angular_velocity[2] > 0.1


def test_imu_at_rest_reads_plus_g_along_the_body(sim):
    obs = sim.reset()   # at rest, leaning 0.05 rad forward: the IMU reads gravity alone, tilted with the body
    f = obs.imu.linear_acceleration
    assert f == pytest.approx((-9.81 * math.sin(0.05), 0.0, 9.81 * math.cos(0.05)), abs=0.02)
    assert obs.imu.angular_velocity == pytest.approx((0.0, 0.0, 0.0), abs=0.02)
    assert obs.left.torque == 0.0 and obs.right.torque == 0.0   # nothing acted before t = 0


def test_runs_are_deterministic(sim):
    a, _ = _steps(sim, Command(0.2, 0.1), 30)
    b, _ = _steps(sim, Command(0.2, 0.1), 30)
    assert a == b


def test_one_pybullet_per_process(sim):
    with pytest.raises(BackendError, match="one physics client"):
        UpkieBackend.pybullet()


def test_simulated_robot_is_spec16s_and_pybullets_own_kinetic_energy(sim):
    m = sim.simulated_model()
    assert m.I_b == pytest.approx(0.111, rel=0.01)     # SPEC 16's numbers are PyBullet's robot
    assert m.I_w == pytest.approx(5.2e-4, rel=0.03)
    assert m.m_b == pytest.approx(4.97, abs=0.005) and m.l == pytest.approx(0.281, abs=0.001)
    # independent: PyBullet's own link states give 2 KE = I_w for the wheels turning at 1 rad/s (body still) and
    # 2 KE = m_b l^2 + I_b for the body pitching at 1 rad/s about the axle (the wheels' absolute rate 0)
    rid = sim.inner.robot_id
    inertia = pybullet_inertias(rid)
    index = {pybullet.getJointInfo(rid, i)[1].decode(): i for i in range(pybullet.getNumJoints(rid))}
    links = {pybullet.getJointInfo(rid, i)[12].decode(): i for i in range(pybullet.getNumJoints(rid))}
    pybullet.resetBasePositionAndOrientation(rid, (0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0))
    for name in index:
        pybullet.resetJointState(rid, index[name], 0.0, 0.0)
    axle_z = pybullet.getLinkState(rid, links["left_wheel_tire"], computeForwardKinematics=True)[4][2]
    base_z = pybullet.getBasePositionAndOrientation(rid)[0][2]
    sign = {"left_wheel": 1.0, "right_wheel": -1.0}   # Upkie is left-wheeled: forward is -y on the right joint

    def two_ke(base_v, base_w, wheel_rate):
        pybullet.resetBaseVelocity(rid, base_v, base_w)
        for name, s in sign.items():
            pybullet.resetJointState(rid, index[name], 0.0, s * wheel_rate)
        total = 0.0
        for name, i in [("base", -1)] + sorted(links.items(), key=lambda kv: kv[1]):
            mass = pybullet.getDynamicsInfo(rid, i)[0]
            if i == -1:
                v, w = pybullet.getBaseVelocity(rid)
                q = pybullet.getBasePositionAndOrientation(rid)[1]
            else:
                st = pybullet.getLinkState(rid, i, computeLinkVelocity=True, computeForwardKinematics=True)
                v, w, q = st[6], st[7], st[5]   # the link frame's orientation: the tensor is in the link's frame
            rot = np.array(pybullet.getMatrixFromQuaternion(q)).reshape(3, 3)
            v, w = np.array(v), np.array(w)
            total += mass * v @ v + w @ rot @ inertia[name] @ rot.T @ w
        return total

    assert two_ke((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0) == pytest.approx(m.I_w, rel=1e-6)
    up = base_z - axle_z   # the base above the axle: pitching at 1 rad/s about the axle moves it at `up` m/s along x
    body = two_ke((up, 0.0, 0.0), (0.0, 1.0, 0.0), -1.0)
    assert body == pytest.approx(m.m_b * m.l ** 2 + m.I_b, rel=1e-6)
    sim.reset()
