"""Wheel odometry (docs/theory.md 6.12): hand-computed runs, the covariances from the sensors' noise, and the drift
against the true wheel over the paper's scenario with the realistic raw sensors."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.mobile_base.odometry import (Odometry, OdometryNoise, absolute_wheel_rates, arc_step, body_twist,
                                                encoder_rate_std, odometry_noise, yaw_quaternion)
from mwip_ros.core.closed_loop.sim import simulate

pytestmark = pytest.mark.unit

CONFIG = Path(__file__).resolve().parents[3] / "config"
R, W = 0.25, 0.5


def _run(odo, rates, dt, n, yaw_rate=None):
    for k in range(n + 1):
        odo.update(k * dt, *rates, yaw_rate=yaw_rate)
    return odo


def test_a_straight_run_covers_r_times_the_wheel_angle():
    # both wheels at 4 rad/s for 2 s: v = 0.25 * 4 = 1 m/s, 2 m straight ahead
    o = _run(Odometry(R, W), (4.0, 4.0), 0.01, 200)
    assert o.x == pytest.approx(2.0, abs=1e-12)
    assert o.y == 0.0 and o.yaw == 0.0
    assert (o.v, o.yaw_rate) == (1.0, 0.0)


def test_a_turn_in_place_turns_r_dtheta_over_the_track():
    # left -2, right +2 rad/s: v = 0, psi' = 0.25 * 4 / 0.5 = 2 rad/s; for pi/4 s: a quarter turn on the spot
    o = _run(Odometry(R, W), (-2.0, 2.0), math.pi / 400, 100)
    assert o.yaw == pytest.approx(math.pi / 2, abs=1e-12)
    assert abs(o.x) < 1e-15 and abs(o.y) < 1e-15


def test_a_circle_by_the_wheels_and_by_the_gyro():
    # left 3, right 5 rad/s: v = 0.25 * 4 = 1 m/s, psi' = 0.25 * 2 / 0.5 = 1 rad/s, radius 1 m, centre (0, 1)
    dt, n = 2 * math.pi / 1000, 250   # a quarter of the circle: at (1, 1), heading pi/2
    o = _run(Odometry(R, W), (3.0, 5.0), dt, n)
    assert (o.x, o.y, o.yaw) == pytest.approx((1.0, 1.0, math.pi / 2), abs=1e-12)
    o = _run(Odometry(R, W), (3.0, 5.0), dt, 1000)   # the whole circle: back at the start
    assert (o.x, o.y, o.yaw) == pytest.approx((0.0, 0.0, 2 * math.pi), abs=1e-12)
    # the same circle with the gyro's yaw rate and equal wheels (v 1 m/s): the gyro wins over the wheels
    o = _run(Odometry(R, W), (4.0, 4.0), dt, n, yaw_rate=1.0)
    assert (o.x, o.y) == pytest.approx((1.0, 1.0), abs=1e-12)


def test_the_trapezoid_takes_the_mean_of_the_ends_the_rectangle_the_sample():
    # the wheel's rate ramps 0 -> 4 rad/s over 1 s in 10 samples (v 0 -> 1 m/s): the trapezoid covers the exact
    # 0.5 m; the rectangle holds each sample over the period before it: 0.1 * (0.1 + 0.2 + ... + 1.0) = 0.55 m
    trap, rect = Odometry(R, W, rule="trapezoid"), Odometry(R, W)
    for k in range(11):
        trap.update(0.1 * k, 0.4 * k)
        rect.update(0.1 * k, 0.4 * k)
    assert trap.x == pytest.approx(0.5, abs=1e-12) and rect.x == pytest.approx(0.55, abs=1e-12)
    with pytest.raises(ValueError, match="rule"):
        Odometry(R, W, rule="simpson")


def test_the_planar_robot_one_rate_no_yaw():
    o = Odometry(R, W)
    for k in range(11):
        o.update(0.1 * k, 2.0, yaw_rate=0.0)   # one encoder for both wheels, the planar IMU's yaw rate 0
    assert (o.x, o.y, o.yaw) == pytest.approx((0.5, 0.0, 0.0), abs=1e-15)


def test_absolute_rates_add_the_pitch_rate_and_the_twist():
    assert absolute_wheel_rates(1.0, 2.0, 0.5) == (1.5, 2.5)
    assert body_twist(1.0, 3.0, 0.5, 2.0) == (1.0, 0.5)          # v = 0.5 * 2, psi' = 0.5 * 2 / 2
    assert body_twist(1.0, 3.0, 0.5, 2.0, yaw_rate=-0.1) == (1.0, -0.1)
    assert arc_step(1.0, 2.0, 0.0, 3.0, 0.0, 0.5) == (2.5, 2.0, 0.0)
    assert yaw_quaternion(math.pi) == pytest.approx((0.0, 0.0, 1.0, 0.0))


def test_bad_input_and_time_going_back_change_nothing():
    o = _run(Odometry(R, W), (4.0, 4.0), 0.1, 10)
    before = (o.x, o.t, o.updates)
    assert not o.update(1.1, math.nan)
    assert not o.update(1.1, 1.0, math.inf)
    assert not o.update(1.1, 1.0, yaw_rate=math.nan)
    assert not o.update(0.5, 1.0)
    assert not o.update(1.0, 1.0)   # not advancing
    assert (o.x, o.t, o.updates) == before
    o.reset()
    assert (o.x, o.t, o.updates) == (0.0, None, 0)


def test_noise_from_the_sensors():
    # 4096 counts at h = 5 ms: q = 2 pi / 4096 = 1.534e-3 rad, rate std q / (h sqrt 6) = 0.12525 rad/s
    q = 2 * math.pi / 4096
    assert encoder_rate_std(4096, 0.005) == pytest.approx(0.12525, rel=1e-4)
    assert encoder_rate_std(0, 0.005) == 0.0
    n = odometry_noise(0.254, 0.5, 0.005, 4096, 0.004, encoders=1)
    s = q / (0.005 * math.sqrt(6))
    assert n.speed_std == pytest.approx(0.254 * math.sqrt(s * s + 0.004 ** 2), rel=1e-12)
    assert n.yaw_rate_std == 0.004
    n2 = odometry_noise(0.254, 0.5, 0.005, 4096, 0.0, encoders=2, yaw_gyro=False)
    assert n2.speed_std == pytest.approx(0.254 * s / math.sqrt(2), rel=1e-12)
    assert n2.yaw_rate_std == pytest.approx(math.sqrt(2) * 0.254 / 0.5 * s, rel=1e-12)
    assert odometry_noise(0.254, 0.5, 0.005) == OdometryNoise(0.0, 0.0)
    with pytest.raises(ValueError, match="encoders"):
        odometry_noise(0.254, 0.5, 0.005, encoders=3)


def test_the_covariance_of_a_straight_run_grows_as_n_dt2_var_v():
    # straight at v = 1: x's variance is the sum of n independent (dt sigma_v)^2; y's picks up the yaw's
    o = _run(Odometry(R, W, OdometryNoise(0.1, 0.02)), (4.0, 4.0), 0.01, 100)
    assert o.P[0, 0] == pytest.approx(100 * (0.01 * 0.1) ** 2, rel=1e-12)
    assert o.P[2, 2] == pytest.approx(100 * (0.01 * 0.02) ** 2, rel=1e-12)
    # y: sum over k of (v dt)^2 var(yaw before step k + half of step k's) ~ v^2 sigma_w^2 dt^2 T^3 / 3 / dt
    assert o.P[1, 1] == pytest.approx(1.0 * 0.02 ** 2 * 0.01 * 1.0 ** 3 / 3, rel=0.02)
    cov = o.pose_covariance()
    assert cov[0] == o.P[0, 0] and cov[35] == o.P[2, 2] and cov[14] == 0.0
    tw = o.twist_covariance()
    assert tw[0] == pytest.approx(0.01) and tw[35] == pytest.approx(4e-4)


def test_drift_against_the_true_wheel_in_the_paper_scenario_with_realistic_raw_sensors():
    """The odometry's x against the true r theta_w over the paper's 10 s with config/sensors_raw_realistic.yaml
    (DSCNDO): from the state estimator's theta_w' (what the robot_state node integrates) within 1.3 mm; from the
    encoder and the raw gyro, the gyro's bias (0.01 rad/s, walking) drifts it by r * bias * 10 s = 2.5 cm."""
    v = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "sensors_raw_realistic.yaml"]))
    loop = P.closed_loop(v, controller="dscndo")
    run = simulate(loop)
    c, pc = run.columns, loop.plant
    assert run.t[-1] == pytest.approx(10.0)
    truth = pc.actual.r * (c["theta_w"] - c["theta_w"][0])

    def drift(rates):
        o, xs = Odometry(pc.nominal.r, 0.5), []
        for t, w in zip(c["t"], rates):
            o.update(float(t), float(w), yaw_rate=0.0)
            xs.append(o.x)
        return np.abs(np.asarray(xs) - truth)

    ideal = simulate(P.closed_loop(P.merged_values(P.load_param_file(CONFIG / "paper.yaml")), controller="dscndo"))
    ci = ideal.columns
    o, xs = Odometry(pc.nominal.r, 0.5, rule="trapezoid"), []   # the ideal state: instantaneous rates
    for t, w in zip(ci["t"], ci["dtheta_w"]):
        o.update(float(t), float(w))
        xs.append(o.x)
    ideal_err = np.abs(np.asarray(xs) - pc.actual.r * (ci["theta_w"] - ci["theta_w"][0]))
    assert ideal_err.max() < 5e-6   # 4 um
    ideal_end = ideal_err[-1]
    est = drift(c["dtheta_w_hat"])
    assert est.max() < 1.3e-3 and est[-1] < 7e-4   # docs/theory.md 6.12: 0.67 mm at 10 s, 1.29 mm at most
    raw = drift(c["encoder_rate"] + c["gyro"])
    assert 0.02 < raw[-1] < 0.035                   # the bias: 0.254 * 0.01 * 10 = 0.0254 m, plus its walk
    mixed = drift(c["encoder_rate"] + c["dtheta_b_hat"])   # the encoder plus the estimator's bias-free pitch rate
    assert mixed[-1] < 2e-3
    assert abs(truth[-1]) > 2.0   # the robot rolled 2.35 m: the drift is a fraction of a real distance
    # docs/theory.md 6.12's table prints these, in mm, to its digits
    table = (CONFIG.parent / "docs" / "theory.md").read_text().split("**Drift.**", 1)[1].split("**The URDF.**")[0]
    for value, text in ((est[-1], "| 0.67 mm (1.29 mm at most"), (est.max(), "at most on the way) |"),
                        (mixed[-1], "| 1.2 mm |"), (raw[-1], "| 26.7 mm ")):
        assert text in table, text
    assert f"{est[-1] * 1e3:.2f}" == "0.67" and f"{est.max() * 1e3:.2f}" == "1.29"
    assert f"{mixed[-1] * 1e3:.1f}" == "1.2" and f"{raw[-1] * 1e3:.1f}" == "26.7"
    o = Odometry(pc.nominal.r, 0.5)   # the ideal state with the rectangle rule
    for t, w in zip(ci["t"], ci["dtheta_w"]):
        o.update(float(t), float(w))
    rect_end = abs(o.x - pc.actual.r * (ci["theta_w"][-1] - ci["theta_w"][0]))
    assert f"| {ideal_end * 1e3:.4f} mm ({rect_end * 1e3:.2f} mm with the rectangle rule) |" in table


def test_the_state_update_takes_the_gyro_s_yaw_about_the_vertical():
    """docs/theory.md 6.13: a body pitched by theta_b reads cos(theta_b) psi' about its z; state_update divides it
    back.  A turn in place at psi' = 0.5 rad/s for 1 s with theta_b = 0.3 turns 0.5 rad; without a gyro, none."""
    import math as _m

    from mwip_ros.core.mobile_base.odometry import Odometry, state_update
    o = Odometry(0.25, 0.5)
    for k in range(101):
        assert state_update(o, k * 0.01, 0.0, 0.3, 0.5 * _m.cos(0.3))
    assert o.yaw == pytest.approx(0.5, abs=1e-12) and (o.x, o.y) == (0.0, 0.0)
    p = Odometry(0.25, 0.5)
    for k in range(101):
        state_update(p, k * 0.01, 2.0, 0.3)
    assert p.yaw == 0.0 and p.x == pytest.approx(0.5, abs=1e-12)
