"""The raw sensors in the closed loop (theory.md 6.4): a run's IMU and encoder samples recomputed from its own rows."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.plants.model import accel
from mwip_ros.core.closed_loop.sim import simulate

pytestmark = pytest.mark.unit

CONFIG = Path(__file__).resolve().parents[3] / "config"


def _values(**over):
    v = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "sensors_raw_realistic.yaml"]))
    v.update(over)
    return v


def test_the_samples_of_a_run_recomputed_from_its_true_rows():
    """gyro, accel_x, accel_z, encoder, encoder_rate of every row from the row's true state, the previous row's
    torque, the D_w draws of default_rng(seed) and the sensor draws of default_rng([seed, 2]), written out here
    from docs/theory.md 6.4's formulas."""
    v = _values(**{"sensors.imu.gyro_bias_walk": 0.01})   # a walk large enough to matter
    loop = P.closed_loop(v, controller="dscndo", duration=2.0)
    run = simulate(loop)
    c, n = run.columns, len(run)
    pc = loop.plant
    a, h, d, g, r = pc.actual, pc.h, pc.raw.offset, pc.actual.g, pc.actual.r
    dw = [max(0.0, pc.D_w_mean + math.sqrt(pc.D_w_variance) * z)
          for z in np.random.default_rng(pc.seed).standard_normal(n + 1)]
    z = np.random.default_rng([pc.seed, 2]).standard_normal((n, 4))
    bias = pc.raw.gyro_bias
    q = 2 * math.pi / pc.raw.encoder_counts_per_rev
    phi_prev = None
    for k in range(n):
        x = (c["theta_w"][k], c["theta_b"][k], c["dtheta_w"][k], c["dtheta_b"][k])
        t = k * h
        u_prev = c["u"][k - 1] if k else 0.0
        e1 = pc.tau_ext1.amplitude * math.sin(pc.tau_ext1.omega * t + pc.tau_ext1.phase)
        e2 = pc.tau_ext2.amplitude * math.sin(pc.tau_ext2.omega * t + pc.tau_ext2.phase)
        ddw, ddb = accel(a, dw[k - 1] if k else dw[0], pc.D_b, x, u_prev, e1, e2)
        b, db = x[1], x[3]
        ax = r * ddw + d * (math.cos(b) * ddb - math.sin(b) * db ** 2)
        az = -d * (math.sin(b) * ddb + math.cos(b) * db ** 2)
        fx = ax * math.cos(b) - (az + g) * math.sin(b)
        fz = ax * math.sin(b) + (az + g) * math.cos(b)
        bias = bias + pc.raw.gyro_bias_walk * math.sqrt(h) * z[k, 1]
        phi = q * math.floor((x[0] - x[1]) / q + 0.5)
        expect = {"gyro": db + bias + pc.raw.gyro_noise_std * z[k, 0],
                  "accel_x": fx + pc.raw.accel_noise_std * z[k, 2], "accel_z": fz + pc.raw.accel_noise_std * z[k, 3],
                  "encoder": phi, "encoder_rate": 0.0 if phi_prev is None else (phi - phi_prev) / h}
        phi_prev = phi
        for name, want in expect.items():
            assert abs(c[name][k] - want) <= 1e-9, (name, k, c[name][k], want)


def test_at_rest_upright_the_imu_reads_gravity_along_the_body():
    v = _values(**{"initial.theta_b": 0.0, "tau_ext1.amplitude": 0.0, "tau_ext2.amplitude": 0.0,
                   "actual.D_w_variance": 0.0, "sensors.imu.gyro_noise_std": 0.0, "sensors.imu.gyro_bias": 0.0,
                   "sensors.imu.gyro_bias_walk": 0.0, "sensors.imu.accel_noise_std": 0.0})
    run = simulate(P.closed_loop(v, controller="dscndo", duration=0.05))
    assert run["accel_x"][0] == 0.0 and run["accel_z"][0] == pytest.approx(9.81, abs=1e-12)
    assert run["gyro"][0] == 0.0 and run["encoder"][0] == 0.0


def test_the_estimator_closes_the_loop_without_being_told_the_bias():
    """The realistic overlay (bias 0.01 rad/s unknown to the kalman filter): the estimate is good and the loop
    balances as with the true state."""
    v = _values()
    assert v["kalman.gyro_bias"] == 0.0 and v["sensors.imu.gyro_bias"] == 0.01
    raw = simulate(P.closed_loop(v, controller="dscndo"))
    truth = simulate(P.closed_loop(P.merged_values(P.load_param_file(CONFIG / "paper.yaml")), controller="dscndo"))
    m_raw = metrics.compute(raw.columns, metrics.WINDOW, 1.0472)
    m_true = metrics.compute(truth.columns, metrics.WINDOW, 1.0472)
    assert m_raw.theta_b_est_err_rms <= 0.003 and m_raw.dtheta_b_est_err_rms < 0.01
    assert m_raw.theta_b_rms <= 1.5 * m_true.theta_b_rms
    assert math.isnan(m_true.theta_b_est_err_rms)   # the true-state run has no estimate


def test_a_raw_plant_refuses_the_state_model_s_noise_naming_the_key():
    v = _values(**{"sensors.noise_std.theta_b": 0.001})
    with pytest.raises(P.ParamError, match=r"sensors\.noise_std\.theta_b.*sensors\.model: state only"):
        P.check_derived(v)
