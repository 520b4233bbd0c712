"""The raw sensors cross-checked against MuJoCo's own (issue 32 item 3; docs/theory.md 6.4 and 6.10): MuJoCo's gyro
and accelerometer at the IMU site (0, 0, sensors.imu.offset) on the body and the wheels' hinge angles, at the
instant of each raw sample (t_k^-), against core.plants.raw_sensors' IMU and encoder model, over the paper's
scenario under DSCNDO with ideal raw sensors, at the default physics step (5 ms, one step a period) and at 1 ms (the
contact, 4 physics steps stiff, 5x stiffer: theory 6.10's figures).  On the spatial plant the raw sample's specific
force is MuJoCo's own (the planar model's a_x = r theta_w'' assumes rolling without slip), cross-checked here against
that model; the yaw gyro (the IMU's z axis, core.plants.raw_sensors.YawGyro) is MuJoCo's gyro z, over a turn."""
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from mwip_ros import params as P  # noqa: E402
from mwip_ros.core.closed_loop import loop as loop_module   # noqa: E402
from mwip_ros.core.plants.raw_sensors import specific_force  # noqa: E402
from mwip_ros.core.closed_loop.sim import simulate  # noqa: E402
from mwip_ros.params.paths import default_params_file  # noqa: E402

pytestmark = pytest.mark.unit

# the gyro: to rounding; the hinge angles: each wheel's to the encoder's of their mean, to the contact solver's
# tolerance (MuJoCo solves the two wheels' contacts one after the other: measured 3.1e-9 rad; docs/theory.md 6.10)
GYRO_TOL, HINGE_TOL = 1e-14, 1e-8
# per physics step: (samples until the soft contact has carried the first period's step of torque, the accelerometer's
# tolerances x and z after them): what the contact's compliance moves the axle off r theta_w'' (docs/theory.md 6.10;
# measured 6.4e-6 and 1.4e-5 m/s^2 at 1 ms from the tenth sample, 6.5e-5 and 4.8e-5 at 5 ms from the fortieth)
ACCEL = {0.001: (10, 3e-5, 2e-5), 0.005: (40, 4e-4, 7e-5)}


@pytest.fixture(scope="module", params=sorted(ACCEL))
def readings(request):
    """(the mwip_sim run with backend mujoco and raw sensors, MuJoCo's readings at each sample: gyro xyz,
    accelerometer xyz, the left and right hinge angles, the physics step)."""
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
                      **{"sensors.model": "raw", "mujoco.timestep": request.param})
        run = simulate(P.closed_loop(values, controller="dscndo"))
    finally:
        mp.undo()
    return run, np.array(out), request.param


def test_the_paper_scenario_runs_whole_with_a_sample_each_period(readings):
    run, mj, _ = readings
    assert not run.fallen and len(run) == len(mj) == 2001


def test_mujocos_gyro_is_the_models_pitch_rate(readings):
    run, mj, _ = readings
    np.testing.assert_allclose(mj[:, 1], run["gyro"], rtol=0, atol=GYRO_TOL)
    assert np.abs(mj[:, [0, 2]]).max() < 1e-12   # no roll or yaw rate: straight ahead on flat ground
    assert np.abs(run["gyro"]).max() > 0.1       # the scenario moves the body


def test_mujocos_hinge_angles_are_the_encoders_relative_angle(readings):
    run, mj, _ = readings
    for side in (6, 7):
        np.testing.assert_allclose(mj[:, side], run["encoder"], rtol=0, atol=HINGE_TOL)
    assert np.abs(run["encoder"]).max() > 1.0


def test_mujocos_accelerometer_is_the_models_specific_force_after_the_startup(readings):
    run, mj, step = readings
    settled, tol_x, tol_z = ACCEL[step]
    np.testing.assert_array_equal(mj[:, [3, 5]], np.column_stack([run["accel_x"], run["accel_z"]]))   # MuJoCo's
    dx, dz = np.abs(mj[:, 3] - mj[:, 8]), np.abs(mj[:, 5] - mj[:, 9])
    assert dx[settled:].max() < tol_x and dz[settled:].max() < tol_z, (dx[settled:].max(), dz[settled:].max())
    assert np.abs(mj[:, 4]).max() < 1e-10         # no lateral specific force
    # the first sample: the contact has not yet carried the startup's acceleration (measured 2.6e-3, 1.5e-2)
    assert tol_z < dz[0] < 0.1 and dx[0] < 0.1
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
        files = [default_params_file(), Path(__file__).resolve().parents[3] / "config" / "motion.yaml"]
        values = dict(P.merged_values(P.load_param_files(files)), backend="mujoco", **{"sensors.model": "raw"},
                      **{"motion.profile": [0.0, 0.0], "motion.yaw_profile": [0.0, 0.0, 3.0, 0.0, 3.5, 0.5],
                         "method": "kalman"})
        run = simulate(P.closed_loop(values, controller="dscndo", duration=6.0))
    finally:
        mp.undo()
    assert not run.fallen and len(out) == len(run) == 1201
    np.testing.assert_allclose(run["gyro_z"], out, rtol=0, atol=GYRO_TOL)
    assert np.unwrap(run["yaw"])[-1] - run["yaw"][0] > 0.3 and max(out) > 0.4
