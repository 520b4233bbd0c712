"""The raw sensors cross-checked against MuJoCo's own (issue 32 item 3; docs/theory.md 6.4 and 6.10): MuJoCo's gyro
and accelerometer at the IMU site (0, 0, sensors.imu.offset) on the body and the wheels' hinge angles, at the
instant of each raw sample (t_k^-), against core.raw_sensors' IMU and encoder model, over the paper's
scenario under DSCNDO with ideal raw sensors.  On the spatial plant the raw sample's specific force is MuJoCo's own
(the planar model's a_x = r theta_w'' assumes rolling without slip), cross-checked here against that model; the
yaw gyro (the IMU's z axis, core.raw_sensors.YawGyro) is MuJoCo's gyro z, over a turn."""
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from mwip_ros import params as P  # noqa: E402
from mwip_ros.core import loop as loop_module  # noqa: E402
from mwip_ros.core.raw_sensors import specific_force  # noqa: E402
from mwip_ros.core.sim import simulate  # noqa: E402
from mwip_ros.params.paths import default_params_file  # noqa: E402

pytestmark = pytest.mark.unit

SETTLED = 10   # samples: the soft contact carries the first period's step of torque within ~50 ms (theory 6.10)
# the tolerances measured (docs/theory.md 6.10): the gyro and the hinge angles to rounding, the accelerometer to
# what the contact's compliance moves the axle off r theta_w'' (2.0e-5 and 9.9e-6 m/s^2 measured)
GYRO_TOL, HINGE_TOL, ACCEL_X_TOL, ACCEL_Z_TOL = 1e-14, 1e-13, 3e-5, 1.5e-5


@pytest.fixture(scope="module")
def readings():
    """(the mwip_sim run with backend mujoco and raw sensors, MuJoCo's readings at each sample: gyro xyz,
    accelerometer xyz, the left and right hinge angles)."""
    mp = pytest.MonkeyPatch()
    out = []
    sense = loop_module.PlantSide.sense

    def sensing(side):
        sample = sense(side)   # the plant's sample_accel: mj_forward at x_k with the previous period's inputs
        gyro, accel = side.plant.imu_reading()
        p = side.plant   # the planar model's specific force at the same instant (mj_forward again: the same inputs)
        model = specific_force(p.x, p.sample_accel(), side.cfg.actual.r, side.cfg.raw.offset, side.cfg.actual.g)
        out.append((*gyro, *accel, p.data.qpos[7], p.data.qpos[8], *model))
        return sample

    mp.setattr(loop_module.PlantSide, "sense", sensing)
    try:
        values = dict(P.merged_values(P.load_param_file(default_params_file())), backend="mujoco",
                      **{"sensors.model": "raw"})
        run = simulate(P.closed_loop(values, controller="dscndo"))
    finally:
        mp.undo()
    return run, np.array(out)


def test_the_paper_scenario_runs_whole_with_a_sample_each_period(readings):
    run, mj = readings
    assert not run.fallen and len(run) == len(mj) == 2001


def test_mujocos_gyro_is_the_models_pitch_rate(readings):
    run, mj = readings
    np.testing.assert_allclose(mj[:, 1], run["gyro"], rtol=0, atol=GYRO_TOL)
    assert np.abs(mj[:, [0, 2]]).max() < 1e-12   # no roll or yaw rate: straight ahead on flat ground
    assert np.abs(run["gyro"]).max() > 0.1       # the scenario moves the body


def test_mujocos_hinge_angles_are_the_encoders_relative_angle(readings):
    run, mj = readings
    for side in (6, 7):
        np.testing.assert_allclose(mj[:, side], run["encoder"], rtol=0, atol=HINGE_TOL)
    assert np.abs(run["encoder"]).max() > 1.0


def test_mujocos_accelerometer_is_the_models_specific_force_after_the_startup(readings):
    run, mj = readings
    np.testing.assert_array_equal(mj[:, [3, 5]], np.column_stack([run["accel_x"], run["accel_z"]]))   # MuJoCo's
    dx, dz = np.abs(mj[:, 3] - mj[:, 8]), np.abs(mj[:, 5] - mj[:, 9])
    assert dx[SETTLED:].max() < ACCEL_X_TOL and dz[SETTLED:].max() < ACCEL_Z_TOL, (dx[SETTLED:].max(),
                                                                                   dz[SETTLED:].max())
    assert np.abs(mj[:, 4]).max() < 1e-10         # no lateral specific force
    # the first sample: the contact has not yet carried the startup's acceleration (measured 8.5e-3, 5.6e-2)
    assert ACCEL_Z_TOL < dz[0] < 0.1 and dx[0] < 0.1
    assert math.isclose(float(np.median(mj[:, 5])), 9.81, abs_tol=0.5)   # upright: about +g on z


def test_the_yaw_gyro_is_mujocos_gyro_z_over_a_turn():
    """Ideal raw sensors, the yaw stage turning at 0.5 rad/s from 3 s: the yaw gyro the loop reads (column gyro_z, no
    delay) is MuJoCo's gyro z at the IMU site at each sample, and the robot turned."""
    mp = pytest.MonkeyPatch()
    out = []
    sense = loop_module.PlantSide.sense

    def sensing(side):
        sample = sense(side)
        out.append(side.plant.imu_reading()[0][2])
        return sample

    mp.setattr(loop_module.PlantSide, "sense", sensing)
    try:
        files = [default_params_file(), Path(__file__).resolve().parents[2] / "config" / "motion.yaml"]
        values = dict(P.merged_values(P.load_param_files(files)), backend="mujoco", **{"sensors.model": "raw"},
                      **{"motion.profile": [0.0, 0.0], "motion.yaw_profile": [0.0, 0.0, 3.0, 0.0, 3.5, 0.5],
                         "method": "kalman", "kalman.accel_noise_std": 1.0})   # config/square.yaml's, turning
        run = simulate(P.closed_loop(values, controller="dscndo", duration=6.0))
    finally:
        mp.undo()
    assert not run.fallen and len(out) == len(run) == 1201
    np.testing.assert_allclose(run["gyro_z"], out, rtol=0, atol=GYRO_TOL)
    assert np.unwrap(run["yaw"])[-1] - run["yaw"][0] > 0.3 and max(out) > 0.4
