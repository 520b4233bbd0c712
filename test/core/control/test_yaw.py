"""The yaw stage (docs/theory.md 6.13): the PI on the yaw rate, the wheels' pair, the stage in the offline loop."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.control.yaw import YawConfig, YawLoop, wheel_torques
from mwip_ros.params.paths import default_params_file

pytestmark = pytest.mark.unit


def test_the_pair_is_u_over_two_minus_and_plus_u_psi_over_two_each_clipped():
    assert wheel_torques(10.0, 4.0, 0.0) == (3.0, 7.0)
    assert wheel_torques(10.0, -4.0, 0.0) == (7.0, 3.0)
    # torque_limit 100: each wheel at most 50 N m; u = 90, u_psi = 30: (30, 60) -> (30, 50)
    assert wheel_torques(90.0, 30.0, 100.0) == (30.0, 50.0)
    assert wheel_torques(-90.0, 30.0, 100.0) == (-50.0, -30.0)
    assert wheel_torques(7.0, 0.0, 0.0) == (3.5, 3.5)


def test_the_pi_by_hand():
    loop = YawLoop(YawConfig(kp=2.0, ki=10.0), 0.01)
    # e = 0.5: I = 0.005, u = 1.0 + 0.05; then e = 0.25: I = 0.0075, u = 0.5 + 0.075
    assert loop.step(1.0, 0.5) == pytest.approx(1.05, abs=1e-15)
    assert loop.step(1.0, 0.75) == pytest.approx(0.575, abs=1e-15)
    assert loop.step(1.0, math.nan) == 0.0 and loop.integral == pytest.approx(0.0075, abs=1e-15)
    loop.reset()
    assert loop.integral == 0.0


def test_the_calibration_by_hand():
    """motion.yaw_gyro_calibration_s = 0.03 s at h = 0.01: three readings averaged, no torque, then the PI on the
    reading less their mean; reset calibrates again."""
    loop = YawLoop(YawConfig(kp=2.0, ki=10.0, calibration_s=0.03), 0.01)
    assert [loop.step(1.0, w) for w in (0.01, 0.02, 0.03)] == [0.0, 0.0, 0.0] and loop.integral == 0.0
    assert loop.bias == pytest.approx(0.02, abs=1e-15)
    # e = 1.0 - (0.52 - 0.02) = 0.5: as the PI by hand's first step
    assert loop.step(1.0, 0.52) == pytest.approx(1.05, abs=1e-14)
    loop.reset()
    assert loop.step(1.0, 0.52) == 0.0 and loop.bias == 0.52


def test_balance_first_the_pair_gets_what_u_leaves_of_each_wheel_and_does_not_wind_up():
    """motion.yaw_wheel_limit L = 60: |u_psi| <= 2 L - |u|, so neither wheel passes L; while clipped the integral
    stops growing toward the clip (conditional integration), and grows again once there is room."""
    loop = YawLoop(YawConfig(kp=2.0, ki=10.0, wheel_limit=60.0), 0.01)
    # e = 50: PI 100 + 10 * 0.5 = 105; room 2 * 60 - 100 = 20: u_psi = 20, the integral taken back to 0
    assert loop.step(50.0, 0.0, u=100.0) == 20.0 and loop.integral == 0.0
    assert max(map(abs, wheel_torques(100.0, 20.0, 0.0))) == pytest.approx(60.0, abs=1e-12)
    assert loop.step(50.0, 0.0, u=-130.0) == 0.0 and loop.integral == 0.0   # no room at all: no yaw, no wind-up
    assert loop.step(50.0, 0.0, u=math.nan) == 0.0 and loop.integral == 0.0
    assert loop.step(-50.0, 0.0, u=100.0) == -20.0 and loop.integral == 0.0  # clipped the other way: same
    # room enough (u = 0, room 120): the PI as without a limit
    assert loop.step(50.0, 0.0, u=0.0) == pytest.approx(105.0, abs=1e-12) and loop.integral == pytest.approx(0.5)
    # clipped while the error opposes the clip's sign: the integral unwinds (it moves away from the clip)
    loop.integral = 20.0                                     # PI = 2 * (-1) + 10 * (20 - 0.01) = 197.9 > room 20
    assert loop.step(-1.0, 0.0, u=100.0) == 20.0 and loop.integral == pytest.approx(19.99, abs=1e-12)
    unlimited = YawLoop(YawConfig(kp=2.0, ki=10.0), 0.01)
    assert unlimited.step(50.0, 0.0, u=100.0) == pytest.approx(105.0, abs=1e-12)   # 0: no limit, u ignored


def _values(backend, **over):
    files = [default_params_file(), default_params_file().parent / "motion.yaml"]
    v = dict(P.merged_values(P.load_param_files(files)), backend=backend)
    v.update(over)
    return v


def test_the_planar_plant_has_no_yaw_stage_bit_for_bit():
    """rk4 with motion on: the yaw gains are there (ClosedLoop.yaw) but the planar plant runs no yaw stage; the run
    equals the one without them to the bit, and has no yaw column."""
    from dataclasses import replace

    from mwip_ros.core.closed_loop.sim import simulate
    lp = P.closed_loop(_values("rk4", **{"motion.yaw_profile": [0.0, 0.5]}), controller="dscndo", duration=3.0)
    assert lp.yaw is not None
    a, b = simulate(lp), simulate(replace(lp, yaw=None))
    assert "u_psi" not in a.columns
    assert a.columns.keys() == b.columns.keys()
    assert all(np.array_equal(a[c], b[c], equal_nan=True) for c in a.columns)


def test_motion_off_has_no_yaw_config():
    v = P.merged_values(P.load_param_file(default_params_file()))
    assert P.closed_loop(dict(v, backend="mujoco"), controller="dscndo", duration=0.1).yaw is None


def test_the_3d_plant_turns_in_place_at_the_reference_rate():
    """0.5 rad/s from 1 s to 5 s, no forward speed: the robot turns psi = 2 rad (the reference's integral) within
    2 %, stays up, and the axle's centre stays within 0.4 m of where it started (the paper's initial tilt and
    disturbances move it 0.30 m; the position hold's lambda = 0.2 /s brings it back slowly)."""
    pytest.importorskip("mujoco")
    from mwip_ros.core.closed_loop.sim import simulate
    v = _values("mujoco", **{"motion.profile": [0.0, 0.0], "motion.yaw_profile": [0.0, 0.0, 1.0, 0.5, 5.0, 0.0]})
    run = simulate(P.closed_loop(v, controller="dscndo", duration=8.0))
    assert not run.fallen
    yaw = np.unwrap(run["yaw"])
    ideal = float(np.sum(run["dpsi_ref"][:-1]) * 0.005)   # psi'* held over each period
    assert ideal == pytest.approx(2.0, abs=0.01)
    assert abs(yaw[-1] - ideal) < 0.02 * ideal, (yaw[-1], ideal)
    assert np.hypot(run["x"] - run["x"][0], run["y"] - run["y"][0]).max() < 0.4
    u, u_psi = run["u"], run["u_psi"]
    assert np.max(np.abs(u_psi)) > 50.0 and np.all(np.isfinite(u))


def test_without_the_yaw_loop_the_3d_plant_does_not_turn():
    """Gains zero: u_psi = 0, the wheels get u / 2 each, the yaw stays below 1e-12 rad (the cross-check of 6.10)."""
    pytest.importorskip("mujoco")
    from mwip_ros.core.closed_loop.sim import simulate
    v = _values("mujoco", **{"motion.profile": [0.0, 0.0], "motion.yaw_profile": [0.0, 0.5],
                             "motion.yaw_kp": 0.0, "motion.yaw_ki": 0.0})
    run = simulate(P.closed_loop(v, controller="lqr", duration=2.0))
    assert np.max(np.abs(run["u_psi"])) == 0.0
    assert np.max(np.abs(run["yaw"])) < 1e-12


def test_the_default_gains_row_of_theory_6_13():
    """docs/theory.md 6.13's default row: yaw-rate error RMS 0.0202 rad/s and the yaw 1.9894 rad at 8 s (measured
    with MuJoCo's physics step at 1 ms; the same to the digit at the default 5 ms: theory 6.10's contact)."""
    pytest.importorskip("mujoco")
    from mwip_ros.core.closed_loop.sim import simulate
    v = _values("mujoco", **{"motion.profile": [0.0, 0.0], "motion.yaw_profile": [0.0, 0.0, 1.0, 0.5, 5.0, 0.0],
                             "mujoco.timestep": 0.001})
    assert (v["motion.yaw_kp"], v["motion.yaw_ki"]) == (400.0, 4000.0)
    run = simulate(P.closed_loop(v, controller="dscndo", duration=8.0))
    yaw = np.unwrap(run["yaw"])
    e = np.diff(yaw) / 0.005 - run["dpsi_ref"][:-1]
    assert f"{np.sqrt(np.mean(e ** 2)):.4f}" == "0.0202" and f"{yaw[-1]:.4f}" == "1.9894"
    assert f"{np.max(np.abs(run['theta_b'][run['t'] > 1.0])):.4f}" == "0.0340"


def test_with_raw_sensors_the_yaw_stage_runs_on_the_imus_z_gyro():
    """docs/theory.md 6.13: with raw sensors the yaw stage reads the IMU's z-axis gyro (core.plants.raw_sensors.YawGyro,
    the realistic overlay's bias 0.01 rad/s): at rest before any turn it reads the bias, not the ideal 0, and the stage
    turns the robot when psi'* says so."""
    pytest.importorskip("mujoco")
    from mwip_ros.core.closed_loop.sim import simulate
    files = [default_params_file(), default_params_file().parent / "sensors_raw_realistic.yaml",
             default_params_file().parent / "motion.yaml"]
    v = dict(P.merged_values(P.load_param_files(files)), backend="mujoco",
             **{"motion.profile": [0.0, 0.0], "motion.yaw_profile": [0.0, 0.0, 3.0, 0.0, 3.5, 0.5]},
             **{"mujoco.timestep": 0.005})   # the default step (until issue 47's contact this turn fell at it)
    run = simulate(P.closed_loop(v, controller="dscndo", duration=6.0))
    assert not run.fallen and "u_psi" in run.columns
    assert abs(run["gyro_z"][0] - 0.01) < 0.02   # the turn-on bias, within the noise (0.004) and the first rate
    assert np.unwrap(run["yaw"])[-1] - run["yaw"][0] > 0.5
