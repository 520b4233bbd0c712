"""The closed loop on a robot's backend (mwip_ros.robot.closed_loop): over a backend that is the project's own rk4 plant
and raw sensors it is the offline simulator, row for row; on Upkie's PyBullet it balances, deterministically; its
failures end the run with a reason."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.plants.plant import make_plant
from mwip_ros.core.plants.raw_sensors import RawSensors
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.params.paths import default_params_file
from mwip_ros.robot.backend import Backend, Imu, Observation, Wheel
from mwip_ros.robot.closed_loop import Push, raw_sample, run, summary

pytestmark = pytest.mark.unit

CONFIG = default_params_file().parent
UPKIE = [CONFIG / "paper.yaml", CONFIG / "upkie.yaml"]


class PlantBackend(Backend):
    """The project's plant (eq. 1, RK4) and raw sensors (SPEC 10) as a robot: each wheel reads phi, its rate and half
    the torque that acted; the IMU the gyro about y and the specific force in x and z."""

    name = "rk4"
    simulated = True

    def __init__(self, cfg, fault_at=None):
        self.cfg, self.fault_at = cfg, fault_at
        self.commands = []

    def _read(self) -> Observation:
        p = self.plant
        s = self.sensors.sample(p.x, p.sample_accel())
        wheel = Wheel(s.encoder, s.encoder_rate, 0.5 * p.u_prev)
        fault = "rk4: left_wheel: over-temperature" if self.fault_at is not None and p.k >= self.fault_at else None
        return Observation(p.t, wheel, wheel, Imu((0.0, s.gyro, 0.0), (s.accel_x, 0.0, s.accel_z)), fault,
                           tuple(p.x))

    def observe(self):
        return self.last

    def reset(self):
        self.plant = make_plant(self.cfg)
        self.sensors = RawSensors.for_plant(self.cfg.raw, self.cfg.seed, self.cfg.h, self.cfg.actual.r,
                                            self.cfg.actual.g)
        self.last = self._read()
        return self.last

    def step(self, command):
        self.commands.append(command)
        self.plant.step(command.left + command.right)
        self.last = self._read()
        return self.last

    def close(self):
        pass


def _paper_raw(**over):
    values = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "sensors_raw_realistic.yaml"]))
    values.update(over)
    return P.typed.closed_loop(values, controller="dscndo")


def test_raw_sample_of_a_read():
    obs = Observation(0.0, Wheel(0.2, 1.0, 0.1), Wheel(0.4, 3.0, 0.3), Imu((9.0, 0.5, 8.0), (1.5, 7.0, 9.5)))
    assert tuple(raw_sample(obs)) == (0.5, 1.5, 9.5, pytest.approx(0.3), 2.0)
    with pytest.raises(ValueError, match="no IMU"):
        raw_sample(replace(obs, imu=None))


def test_over_the_projects_plant_it_is_the_offline_simulator_row_for_row():
    # the paper's robot with realistic raw sensors through the Kalman filter, a torque limit that binds early
    loop = _paper_raw(torque_limit=150.0)
    loop = replace(loop, duration_s=2.0)
    offline = simulate(loop)
    backend = PlantBackend(loop.plant)
    robot = run(backend, loop, 2.0)
    assert len(robot) == len(offline) == 401
    for col in ("t", "theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_hat1", "tau_hat2", "gyro", "accel_x",
                "accel_z", "encoder", "encoder_rate", "theta_b_hat", "dtheta_w_hat", "u_dsc", "x4d"):
        np.testing.assert_allclose(robot[col], offline[col], rtol=1e-12, atol=1e-12, err_msg=col)
    np.testing.assert_allclose(robot["u_applied"][:-1], offline["u_applied"][:-1], rtol=1e-12, atol=1e-12)
    # u split over the wheels: u/2 each, summing back to u exactly
    assert all(c.left == c.right and c.left + c.right == u for c, u in zip(backend.commands, robot["u"]))
    assert not robot.fallen and robot.record == {}


def test_measure_truth_feeds_the_state():
    loop = replace(_paper_raw(), duration_s=0.5)
    traj = run(PlantBackend(loop.plant), loop, 0.5, measure="truth")
    assert np.array_equal(traj["theta_b_hat"], traj["theta_b"])   # the estimate column holds what the law saw
    with pytest.raises(ValueError, match="one of raw, truth"):
        run(PlantBackend(loop.plant), loop, 0.5, measure="imu")


def test_a_device_fault_ends_the_run_with_its_reason():
    loop = _paper_raw()
    traj = run(PlantBackend(loop.plant, fault_at=10), loop, 1.0)
    assert traj.fallen and traj.record["failure"] == "device_fault"
    assert traj.record["t_fall"] == pytest.approx(0.05)
    assert "over-temperature" in traj.record["fall_text"]
    assert len(traj) == 10


def test_a_fall_ends_the_run_and_the_summary_gives_no_numbers():
    loop = _paper_raw(torque_limit=1.0)   # far too weak for 340 kg: it falls
    traj = run(PlantBackend(loop.plant), loop, 10.0)
    assert traj.fallen and traj.record["failure"] == "fall"
    s = summary(traj, (5.0, 10.0))
    assert not s["upright"] and not s["covers_window"]
    assert math.isnan(s["theta_b_rms"]) and s["failure"].startswith("FELL at t = ")


class NoTruthBackend(PlantBackend):
    """The plant as a robot has it: its reads carry no truth (a device's)."""

    name = "device"
    simulated = False

    def _read(self) -> Observation:
        return replace(super()._read(), truth=None)


def test_a_robot_without_truth_is_judged_on_its_estimate_and_says_so():
    loop = _paper_raw()
    traj = run(NoTruthBackend(loop.plant), loop, 2.0)
    assert not traj.fallen and np.all(np.isnan(traj["theta_b"]))   # no truth: NaN, never a number
    s = summary(traj, (1.0, 2.0))
    assert s["judged_on"] == "estimate" and s["upright"] and s["covers_window"]
    est = traj["theta_b_hat"][(traj.t >= 1.0 - 1e-9)]
    assert s["theta_b_rms"] == pytest.approx(float(np.sqrt(np.mean(est ** 2))), rel=1e-12)
    assert 0.0 < s["theta_b_rms"] < 0.05 and s["theta_b_max_abs"] > 0.0
    assert math.isnan(s["theta_b_est_err_rms"])   # no truth to compare the estimate with
    assert math.isnan(s["max_drift"]) and math.isnan(s["final_drift"])   # no pose


def test_a_robots_bag_its_estimate_on_joint_states_is_summarised_as_the_estimate(tmp_path):
    """A bag of the wheel_driver on a device (imu/data_raw, wheel_encoder, the estimator's joint_states, no
    true_joint_states, no pose): its summary is the estimate's, said so; what the bag lacks is NaN (it was a
    KeyError on theta_b_hat)."""
    from mwip_ros.bag import BagWriter, qos_profiles_yaml
    from mwip_ros.msgs import layouts as L
    from mwip_ros.runs import read_bag_run
    from bagcheck import ENDPOINT_QOS

    h_ns, n = 5_000_000, 401
    theta = [0.02 * math.cos(0.5 * k * 0.005) for k in range(n)]
    topics = {"/imu/data_raw": "sensor_msgs/msg/Imu", "/wheel_encoder": "sensor_msgs/msg/JointState",
              "/joint_states": "sensor_msgs/msg/JointState"}
    with BagWriter(tmp_path / "robot") as bag:
        for topic, type_name in topics.items():
            bag.add_topic(topic, type_name, qos_profiles_yaml([ENDPOINT_QOS]), "")
        for k in range(n):
            stamp = 1_000_000_000 + k * h_ns
            bag.write("/imu/data_raw", L.encode_imu(stamp, 0.0, 0.0, 9.81), stamp)
            bag.write("/wheel_encoder", L.encode_encoder(stamp, 0.0, 0.0, 0.1), stamp)
            bag.write("/joint_states", L.encode_state(stamp, (0.0, theta[k], 0.0, 0.0), 0.1), stamp + 1000)
    traj = read_bag_run(tmp_path / "robot")
    assert traj.record["states_from"] == "estimate"
    s = summary(traj, (1.0, 2.0))
    assert s["judged_on"] == "estimate" and s["upright"] and s["covers_window"]
    assert s["theta_b_rms"] == pytest.approx(float(np.sqrt(np.mean(np.square(theta[200:])))), rel=1e-9)
    assert s["theta_b_max_abs"] == pytest.approx(max(abs(v) for v in theta[200:]), rel=1e-9)
    assert math.isnan(s["theta_b_est_err_rms"]) and math.isnan(s["max_drift"])
    assert s["t_end"] == pytest.approx(2.0, abs=1e-9)
    short = summary(traj, (1.0, 2.5))   # a window the bag does not cover: NaN, no verdict
    assert not short["covers_window"] and math.isnan(short["theta_b_rms"])
    from mwip_ros.cli.report import run_notes
    from mwip_ros.core.closed_loop import metrics
    notes = run_notes(traj, metrics.compute(traj.columns, (1.0, 2.0), 1.0, None))
    assert any(n.startswith("no truth in the bag (a robot): its states and metrics are the state estimator's")
               for n in notes), notes


# --- Upkie in PyBullet ------------------------------------------------------------------------------------------------

pytest.importorskip("pybullet")
pytest.importorskip("upkie")


@pytest.fixture(scope="module")
def upkie():
    from mwip_ros.params.upkie import upkie_config
    from mwip_ros.robot.upkie import UpkieBackend
    values = P.merged_values(P.load_param_files(UPKIE))
    b = UpkieBackend.pybullet(upkie_config(values))
    yield b, values
    b.close()


def test_upkie_dscndo_through_the_estimator_catches_its_lean(upkie):
    backend, values = upkie
    loop = P.typed.closed_loop(values, controller="dscndo")
    traj = run(backend, loop, 1.0)
    s = summary(traj, (0.7, 1.0))
    assert s["upright"] and s["covers_window"]
    assert traj["theta_b"][0] == pytest.approx(0.05, abs=2e-4)
    assert s["theta_b_max_abs"] < 0.01   # from 0.05 rad to within 0.01 rad in 0.7 s
    assert s["theta_b_est_err_rms"] < 0.005
    assert np.all(np.abs(traj["u"]) <= values["torque_limit"] + 1e-12)
    again = run(backend, loop, 0.25)
    np.testing.assert_array_equal(again["theta_b"], traj["theta_b"][:51])   # lockstep: the same numbers to the bit


def test_upkie_push_moves_the_robot_and_a_reset_lets_go(upkie):
    backend, values = upkie
    loop = P.typed.closed_loop(values, controller="dscndo")
    calm = run(backend, loop, 0.5)
    pushed = run(backend, loop, 0.5, push=Push(0.2, 1.0, 15.7))   # still pushing when the run ends
    assert np.array_equal(calm["x"][:41], pushed["x"][:41])   # nothing before the push
    assert pushed["x"][-1] > calm["x"][-1] + 0.01   # pushed forward
    again = run(backend, loop, 0.25)
    np.testing.assert_array_equal(again["x"], calm["x"][:51])
