"""Raw sensors (docs/theory.md 6.4): the IMU's specific force in the body frame, the gyro's bias, the relative encoder,
the draws on their own stream in blocks."""
import math

import numpy as np
import pytest

from mwip_ros.core.kernels import compiled
from mwip_ros.core.plants.model import PhysicalParams, accel
from mwip_ros.core.plants.raw_sensors import (RAW_STREAM, RawSample, RawSensorConfig, RawSensors, raw_rng, raw_sample,
                                              specific_force)
from mwip_ros.core.plants.sensing import NOISE_BLOCK, sensor_rng

pytestmark = pytest.mark.unit

R, D, G, H = 0.254, 0.3, 9.81, 0.005
TRUE = PhysicalParams(m_b=310.6, m_w=29.0, I_b=65.0, I_w=0.6, l=0.317, r=R, g=G)
NOISY = RawSensorConfig(offset=D, gyro_noise_std=0.004, gyro_bias=0.01, gyro_bias_walk=0.0005, accel_noise_std=0.02,
                        encoder_counts_per_rev=4096)


def _imu_expected(x, ddq, r, d, g):
    """The specific force written independently: the IMU point's world acceleration (the second derivative of
    x_imu = r th_w + d sin th_b, z_imu = d cos th_b), minus the gravity vector (0, -g), projected on the body axes
    x_b = (cos th_b, -sin th_b), z_b = (sin th_b, cos th_b)."""
    _, th, _, dth = x
    ddw, ddb = ddq
    acc = np.array([r * ddw + d * (math.cos(th) * ddb - math.sin(th) * dth ** 2),
                    -d * (math.sin(th) * ddb + math.cos(th) * dth ** 2)])
    f = acc - np.array([0.0, -g])
    x_b = np.array([math.cos(th), -math.sin(th)])
    z_b = np.array([math.sin(th), math.cos(th)])
    return float(f @ x_b), float(f @ z_b)


def test_at_rest_upright_the_imu_reads_plus_g_and_the_encoder_zero():
    assert specific_force((0.0, 0.0, 0.0, 0.0), (0.0, 0.0), R, D, G) == (0.0, G)
    s = RawSensors.for_plant(RawSensorConfig(), seed=3, h=H, r=R, g=G)
    assert s.sample((0.0, 0.0, 0.0, 0.0), (0.0, 0.0)) == RawSample(0.0, 0.0, G, 0.0, 0.0)


def test_a_tilted_body_at_rest_sees_gravity_along_its_own_axes():
    th = 0.2   # positive: the centre of gravity ahead of the axle, x_b points forward and down
    f_x, f_z = specific_force((0.0, th, 0.0, 0.0), (0.0, 0.0), R, D, G)
    assert f_x == pytest.approx(-G * math.sin(th), abs=1e-12) and f_z == pytest.approx(G * math.cos(th), abs=1e-12)
    assert math.atan2(-f_x, f_z) == pytest.approx(th, abs=1e-12)   # the accelerometer's pitch


def test_a_steady_rotation_gives_the_centripetal_term_and_nothing_else():
    w = 2.0   # rad/s about the axle, no angular acceleration, upright at this instant
    f_x, f_z = specific_force((0.0, 0.0, 0.0, w), (0.0, 0.0), R, D, G)
    assert f_x == pytest.approx(0.0, abs=1e-12)
    assert f_z == pytest.approx(G - D * w * w, abs=1e-12)   # the IMU accelerates d w^2 towards the axle
    f_x, _ = specific_force((0.0, 0.0, 0.0, 0.0), (0.0, 3.0), R, D, G)
    assert f_x == pytest.approx(D * 3.0, abs=1e-12)          # tangential d th_b''
    f_x, f_z = specific_force((0.0, 0.0, 0.0, 0.0), (2.0, 0.0), R, D, G)
    assert (f_x, f_z) == pytest.approx((R * 2.0, G), abs=1e-12)   # the axle's r th_w''


def test_the_specific_force_is_the_second_derivative_of_the_imu_position():
    """Finite differences of x_imu(t) = r th_w + d sin th_b, z_imu = d cos th_b along a smooth motion."""
    def q(t):
        return 0.3 * t * t + math.sin(3 * t), 0.2 * math.sin(1.7 * t) + 0.05 * t

    def pos(t):
        w, b = q(t)
        return np.array([R * w + D * math.sin(b), D * math.cos(b)])

    t, e = 0.8, 1e-4
    (w, b), (w1, b1), (w0, b0) = q(t), q(t + e), q(t - e)
    x = (w, b, (w1 - w0) / (2 * e), (b1 - b0) / (2 * e))
    ddq = ((w1 - 2 * w + w0) / e ** 2, (b1 - 2 * b + b0) / e ** 2)
    acc = (pos(t + e) - 2 * pos(t) + pos(t - e)) / e ** 2
    f = acc + np.array([0.0, G])
    want = (f @ [math.cos(b), -math.sin(b)], f @ [math.sin(b), math.cos(b)])
    np.testing.assert_allclose(specific_force(x, ddq, R, D, G), want, atol=2e-5)


def test_a_recomputation_from_true_rows_agrees():
    rng = np.random.default_rng(7)
    for _ in range(200):
        x = tuple(rng.uniform(-1, 1, 4) * (50.0, 0.8, 5.0, 3.0))
        ddq = accel(TRUE, 0.5, 0.1, x, float(rng.uniform(-80, 80)), 30.0 * math.cos(float(x[0])), 0.2)
        got = specific_force(x, ddq, R, D, G)
        want = _imu_expected(x, ddq, R, D, G)
        assert got == pytest.approx(want, abs=1e-9)
        s = RawSensors(RawSensorConfig(offset=D), H, R, G).sample(x, ddq)
        assert (s.accel_x, s.accel_z, s.gyro) == pytest.approx((*want, x[3]), abs=1e-9)


def test_the_encoder_is_relative_to_the_body_quantized_and_differenced():
    q = 2 * math.pi / 4096
    s = RawSensors(RawSensorConfig(encoder_counts_per_rev=4096), H, R, G)
    w0 = 0.3 + 456 * q   # phi on a count: 456 q (about 0.6995 rad)
    rows = [(w0, 0.3), (w0 + 0.4 * q, 0.3), (w0 + 0.6 * q, 0.3), (w0, 0.3 - 7.6 * q)]
    out = [s.sample((w, b, 0.0, 0.0), (0.0, 0.0)) for w, b in rows]
    phis = [q * round((w - b) / q) for w, b in rows]
    assert [o.encoder for o in out] == pytest.approx(phis, abs=1e-15)
    assert out[0].encoder == pytest.approx(456 * q, abs=1e-12) and out[1].encoder == out[0].encoder
    assert out[2].encoder == pytest.approx(457 * q, abs=1e-12)
    assert out[3].encoder == pytest.approx(464 * q, abs=1e-12)   # the body pitched back: phi grows
    assert [o.encoder_rate for o in out] == pytest.approx([0.0] + [(b - a) / H for a, b in zip(phis, phis[1:])])
    ideal = RawSensors(RawSensorConfig(), H, R, G)
    assert ideal.sample((1.0, 0.3, 0.0, 0.0), (0.0, 0.0)).encoder == pytest.approx(0.7, abs=1e-15)


def test_the_draws_in_blocks_equal_one_call_per_period_in_the_order_of_the_spec():
    n, seed = NOISE_BLOCK * 2 + 17, 11
    s = RawSensors.for_plant(NOISY, seed=seed, h=H, r=R, g=G)
    rng = np.random.default_rng([seed, 2])   # docs/theory.md 6.4: the raw sensors' own stream
    bias = NOISY.gyro_bias
    x, ddq = (0.0, 0.1, 0.0, 0.5), (0.2, -0.3)
    f_x, f_z = _imu_expected(x, ddq, R, D, G)
    for _ in range(n):
        n_gyro, n_walk, n_x, n_z = rng.standard_normal(4)
        bias = bias + NOISY.gyro_bias_walk * math.sqrt(H) * n_walk
        got = s.sample(x, ddq)
        assert got.gyro == pytest.approx(x[3] + bias + NOISY.gyro_noise_std * n_gyro, abs=1e-12)
        assert got.accel_x == pytest.approx(f_x + NOISY.accel_noise_std * n_x, abs=1e-12)
        assert got.accel_z == pytest.approx(f_z + NOISY.accel_noise_std * n_z, abs=1e-12)
    assert s.bias == pytest.approx(bias, abs=1e-12)


def test_the_raw_stream_is_its_own():
    assert RAW_STREAM == 2
    a = raw_rng(5).standard_normal(4)
    np.testing.assert_array_equal(a, np.random.default_rng([5, 2]).standard_normal(4))
    assert not np.allclose(a, sensor_rng(5).standard_normal(4)) and not np.allclose(a, np.random.default_rng(5)
                                                                                     .standard_normal(4))


def test_without_noise_nothing_is_drawn_and_the_bias_stays():
    cfg = RawSensorConfig(gyro_bias=0.02)
    assert not cfg.noisy and RawSensorConfig(gyro_bias_walk=1e-9).noisy
    s = RawSensors.for_plant(cfg, seed=1, h=H, r=R, g=G)
    assert s.normals is None
    assert [s.sample((0.0, 0.0, 0.0, 0.1), (0.0, 0.0)).gyro for _ in range(3)] == pytest.approx([0.12] * 3)


def test_the_noise_and_the_walk_have_their_deviations():
    s = RawSensors.for_plant(NOISY, seed=2, h=H, r=R, g=G)
    out = np.array([(*s.sample((0.0, 0.0, 0.0, 0.0), (0.0, 0.0))[:3], s.bias) for _ in range(20000)])
    np.testing.assert_allclose((out[:, 0] - out[:, 3]).std(), 0.004, rtol=0.03)
    np.testing.assert_allclose(out[:, 1].std(), 0.02, rtol=0.03)
    np.testing.assert_allclose((out[:, 2] - G).std(), 0.02, rtol=0.03)
    np.testing.assert_allclose(np.diff(out[:, 3]).std(), 0.0005 * math.sqrt(H), rtol=0.03)


def test_reset_starts_the_bias_and_the_rate_again():
    s = RawSensors(RawSensorConfig(gyro_bias=0.01, encoder_counts_per_rev=0), H, R, G)
    s.sample((0.0, 0.0, 0.0, 0.0), (0.0, 0.0))
    assert s.sample((0.01, 0.0, 0.0, 0.0), (0.0, 0.0)).encoder_rate == pytest.approx(0.01 / H)
    s.reset()
    assert s.sample((0.5, 0.0, 0.0, 0.0), (0.0, 0.0)).encoder_rate == 0.0


def test_raw_sample_compiles_with_numba_and_equals_python():
    fn = compiled._deep(raw_sample)
    x, ddq, z = (3.0, -0.2, 1.5, 0.7), (2.0, -4.0), (0.3, -1.2, 0.8, 2.1)
    for first in (True, False):
        args = (x, ddq, z, 0.01, 2.9, first, H, R, D, G, 0.004, 0.0005, 0.02, 4096)
        py, nb = raw_sample(*args), fn(*args)
        assert nb == pytest.approx(py, abs=1e-12, rel=0)


def test_the_yaw_gyro_is_the_z_rate_with_its_own_bias_walk_and_noise_on_stream_3():
    """core.plants.raw_sensors.YawGyro (the module docstring's yaw gyro): bias_z,k = bias_z,k-1 + walk sqrt(h) n_walk,z,
    gyro_z = w_z + bias_z,k + std n_gyro,z, the normals (n_gyro,z, n_walk,z, -, -) of default_rng([seed, 3]) in
    blocks; written here from the generator itself."""
    from mwip_ros.core.plants.raw_sensors import YawGyro
    gyro = YawGyro.for_plant(NOISY, 7, H)
    z = np.random.default_rng([7, 3]).standard_normal((NOISE_BLOCK, 4))
    bias, rates = 0.01, [0.3 * math.sin(k) for k in range(50)]
    for k, w in enumerate(rates):
        bias += 0.0005 * math.sqrt(H) * z[k, 1]
        assert gyro.sample(w) == pytest.approx(w + bias + 0.004 * z[k, 0], abs=1e-15)
    ideal = YawGyro.for_plant(RawSensorConfig(), 7, H)
    assert [ideal.sample(w) for w in rates] == rates


def test_the_yaw_gyro_leaves_the_planar_samples_as_they_were():
    """Its own stream: the raw sensors' samples of a seed are the same whether a yaw gyro draws beside them or not."""
    from mwip_ros.core.plants.raw_sensors import YawGyro
    x, ddq = (0.1, 0.02, 0.5, -0.1), (0.3, -0.2)
    alone, paired = RawSensors.for_plant(NOISY, 7, H, R, G), RawSensors.for_plant(NOISY, 7, H, R, G)
    gyro = YawGyro.for_plant(NOISY, 7, H)
    for _ in range(300):
        a = alone.sample(x, ddq)
        b = paired.sample(x, ddq)
        gyro.sample(0.5)
        assert a == b


def test_a_measured_specific_force_replaces_the_model_s_with_the_same_noise():
    """RawSensors.sample(..., force): a spatial plant's own accelerometer (f_x, f_z) plus the draws the model's
    would get; the gyro and the encoder as without it."""
    x, ddq = (0.1, 0.02, 0.5, -0.1), (0.3, -0.2)
    model, measured = RawSensors.for_plant(NOISY, 7, H, R, G), RawSensors.for_plant(NOISY, 7, H, R, G)
    for _ in range(20):
        a, b = model.sample(x, ddq), measured.sample(x, ddq, (1.5, 9.0))
        fx, fz = specific_force(x, ddq, R, D, G)
        assert (b.gyro, b.encoder, b.encoder_rate) == (a.gyro, a.encoder, a.encoder_rate)
        assert b.accel_x - 1.5 == pytest.approx(a.accel_x - fx, abs=1e-12)
        assert b.accel_z - 9.0 == pytest.approx(a.accel_z - fz, abs=1e-12)
        assert abs(b.accel_x - 1.5) < 0.1 and b.accel_x != 1.5
