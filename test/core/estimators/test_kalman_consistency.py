"""The kalman filter's statistics by Monte Carlo (docs/theory.md 6.4): the pitch variance it predicts is the variance
of its pitch error across runs, and its mean NIS lies in the chi-square band; and a stream with lost samples, integrated
over the stamps' time, trips no fault."""
import math

import numpy as np
import pytest
import yaml
from scipy.stats import chi2

from mwip_ros.core import estimators
from mwip_ros.core.estimators.kalman import STATE_NAMES
from mwip_ros.core.plants.raw_sensors import raw_sample
from mwip_ros.params.paths import default_params_file

pytestmark = pytest.mark.unit

R, D, G, H = 0.254, 0.3, 9.81, 0.005
SPEED = 0.9833        # m/s: about 1 m/s (12.6 encoder counts a period, so the rounding error is not periodic)
SWAY = (0.005, 3.0)   # the body's pitch: amplitude [rad] and angular frequency [rad/s]
I_P00 = STATE_NAMES.index("P00")


def _realistic():
    """The sensors of config/sensors_raw_realistic.yaml (the plant's) and the filter's parameters there."""
    with open(default_params_file().parent / "sensors_raw_realistic.yaml") as f:
        doc = yaml.safe_load(f)
    sensors = doc["plant_sim"]["ros__parameters"]["sensors"]
    kalman = doc["state_estimator"]["ros__parameters"]["kalman"]
    return sensors, {f"kalman.{k}": v for k, v in kalman.items()}


def _truth(t, w0):
    """The true state and accelerations: rolling at SPEED, the body swaying by SWAY."""
    a, om = SWAY
    return ((w0 + SPEED * t / R, a * math.sin(om * t), SPEED / R, a * om * math.cos(om * t)),
            (0.0, -a * om * om * math.sin(om * t)))


def _monte_carlo(runs, steps, gyro_scale=1.0, gaussian_encoder=False, seed=7):
    """Pitch errors, the filter's P00 and NIS, (runs, steps) each.  Each run draws its own noise, its first wheel
    angle and its gyro bias (from the filter's prior, kalman.initial_bias_std).  ``gaussian_encoder``: the encoder
    reads the true angle plus white noise of kalman.encoder_noise_std (the filter's model) instead of rounding it to
    a count, whose error at a constant speed is not white."""
    sensors, kparams = _realistic()
    imu = sensors["imu"]
    gyro_std = imu["gyro_noise_std"] * gyro_scale
    kparams["kalman.gyro_noise_std"] = kparams["kalman.gyro_noise_std"] * gyro_scale
    counts = 0 if gaussian_encoder else int(sensors["encoder_counts_per_rev"])
    se = kparams["kalman.encoder_noise_std"]
    rng = np.random.default_rng(seed)
    cls = estimators.get("kalman")
    err, p00, nis = np.zeros((runs, steps)), np.zeros((runs, steps)), np.zeros((runs, steps))
    for i in range(runs):
        est = cls(kparams, H, R, D, G)
        w0, bias, phi_prev = rng.uniform(0.0, 2 * math.pi), rng.normal(0.0, kparams["kalman.initial_bias_std"]), 0.0
        z = rng.standard_normal((steps, 5))
        for k in range(steps):
            x, ddq = _truth(k * H, w0)
            gyro, fx, fz, phi, rate, bias = raw_sample(x, ddq, z[k, :4], bias, phi_prev, k == 0, H, R, D, G, gyro_std,
                                                       imu["gyro_bias_walk"], imu["accel_noise_std"], counts)
            phi_prev = phi
            if gaussian_encoder:
                phi += se * z[k, 4]
            err[i, k] = est.step((gyro, fx, fz, phi, rate)).theta_b - x[1]
            p00[i, k], nis[i, k] = est.s[I_P00], est.health.nis
    return err, p00, nis


def _variance_ratio(err, p00):
    """The pitch error's variance across runs over the filter's predicted variance, averaged over the second half
    (the filter has converged from its first sample there)."""
    late = slice(err.shape[1] // 2, None)
    return float(np.mean(np.var(err[:, late], axis=0) / p00[:, late].mean(axis=0)))


def _nis_band(nis):
    """The mean NIS over the second half, and its 99 % chi-square band (N samples of 1 degree of freedom)."""
    late = nis[:, nis.shape[1] // 2:]
    n = late.size
    return float(late.mean()), (chi2.ppf(0.005, n) / n, chi2.ppf(0.995, n) / n)


@pytest.mark.parametrize("gyro_scale", [1.0, 10.0])
def test_the_predicted_pitch_variance_and_the_nis_match_the_monte_carlo(gyro_scale):
    """The trapezoid uses each gyro sample in two periods: the filter carries the last sample's noise (the state n),
    so its pitch variance grows by h^2 s_g^2 a period as the error's does (it added h^2 s_g^2 / 2: 2.0x too small a
    variance with ten times the gyro noise, and a mean NIS of 1.16, outside the band; 1.4x with the realistic gyro)."""
    err, p00, nis = _monte_carlo(100, 300, gyro_scale, gaussian_encoder=True)
    ratio = _variance_ratio(err, p00)
    mean, (lo, hi) = _nis_band(nis)
    print(f"gyro x{gyro_scale:g}: actual / predicted pitch variance {ratio:.3f}; mean NIS {mean:.4f} in "
          f"[{lo:.4f}, {hi:.4f}]")
    assert abs(ratio - 1.0) < 0.2, ratio
    assert lo <= mean <= hi, (mean, lo, hi)


def test_with_the_realistic_quantized_encoder_the_predicted_pitch_variance_holds():
    err, p00, _ = _monte_carlo(100, 300)
    ratio = _variance_ratio(err, p00)
    print(f"realistic sensors: actual / predicted pitch variance {ratio:.3f}")
    assert abs(ratio - 1.0) < 0.2, ratio


def _with_drops(dropped, stamps_time, slip_gate=None):
    """The max mean NIS and whether the filter said diverged, over 3 s at about 1 m/s with the realistic sensors, the
    pairs of ``dropped`` (period indices) lost; ``stamps_time``: each step over the time since the last pair;
    ``slip_gate``: kalman.slip_gate instead of the file's."""
    sensors, kparams = _realistic()
    if slip_gate is not None:
        kparams["kalman.slip_gate"] = slip_gate
    imu = sensors["imu"]
    est = estimators.get("kalman")(kparams, H, R, D, G)
    rng = np.random.default_rng(3)
    bias, phi_prev, last, worst, diverged = imu["gyro_bias"], 0.0, None, 0.0, False
    for k in range(600):
        x, ddq = _truth(k * H, 0.3)
        gyro, fx, fz, phi, rate, bias = raw_sample(x, ddq, rng.standard_normal(4), bias, phi_prev, k == 0, H, R, D, G,
                                                   imu["gyro_noise_std"], imu["gyro_bias_walk"],
                                                   imu["accel_noise_std"], int(sensors["encoder_counts_per_rev"]))
        phi_prev = phi
        if k in dropped:
            continue
        est.step((gyro, fx, fz, phi, rate), (k - last) * H if stamps_time and last is not None else None)
        last = k
        worst, diverged = max(worst, est.health.nis_mean), diverged or est.health.diverged
    return worst, diverged


def test_ten_lost_pairs_in_a_second_at_1_m_s_trip_no_fault_when_the_stamps_give_the_time():
    """A lost pair is two periods between samples: integrated over h the IMU's position lags the encoder's by
    h v (a 1 m/s robot: 5 mm), a spike in the NIS; ten in a second took the mean NIS past kalman.nis_limit."""
    dropped = set(range(200, 400, 20))                        # ten pairs in the second from t = 1 s
    limit = _realistic()[1]["kalman.nis_limit"]
    worst, diverged = _with_drops(dropped, stamps_time=True)
    clean, _ = _with_drops(set(), stamps_time=True)
    print(f"max mean NIS: {worst:.2f} with ten lost pairs, {clean:.2f} without (limit {limit:g})")
    assert not diverged and worst < 3.0 * max(clean, 1.0) < limit
    worst_h, diverged_h = _with_drops(dropped, stamps_time=False, slip_gate=0.0)   # stepping by h whatever the
    print(f"stepping by h: max mean NIS {worst_h:.1f}")                              # stamps did (no slip gate)
    assert diverged_h and worst_h > limit
