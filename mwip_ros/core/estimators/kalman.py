"""The estimator ``kalman``: an extended Kalman filter of pitch, gyro bias and the IMU's horizontal motion
(docs/theory.md 6.4).

The accelerometer is not read as a pitch.  Rotated into the world frame with the estimated pitch it is the
IMU point's own horizontal acceleration, which integrated twice must agree with where the encoder says
the IMU is; a pitch error theta_e leaks g theta_e into that acceleration and shows within a fraction of a
second as a position error, and the gyro bias as a growing pitch error.  So the robot's acceleration, which
corrupts the accelerometer's pitch by milliradians to centiradians, is part of the model instead of an error.

State (theta, b, p, v, n): pitch, gyro bias, the IMU point's horizontal position x_imu = r theta_w + d sin theta
and velocity, and n, the white noise of the last gyro sample.  Inputs per sample k: gyro w_k, specific force
(f_x, f_z) at t_k^- (the acceleration over the period that ends at t_k), and the period dt_k = t_k - t_{k-1}
the stamps give (h when none is lost).  Prediction::

    theta_k = theta_{k-1} + dt ((w_{k-1} + w_k) / 2 - b) - dt n_{k-1} / 2      trapezoid (theta' is continuous)
    n_k     = 0 (a new sample's noise, variance gyro_noise_std^2; it enters theta_k as -dt n_k / 2)
    a_k     = f_x cos theta_k + f_z sin theta_k                      world horizontal acceleration of the IMU
    v_k     = v_{k-1} + dt a_k,   p_k = p_{k-1} + dt v_{k-1} + dt^2 a_k / 2,   b_k = b_{k-1}

The trapezoid uses each gyro sample in two periods, so its noise is not white from period to period: n carries
the last sample's noise into the next period, which makes the pitch's variance grow by dt^2 sigma_g^2 a period,
as the integral of the samples does (docs/theory.md 6.4).
Measurement: the encoder, phi_k = (p - d sin theta) / r - theta (since theta_w = phi + theta), noise
``encoder_noise_std``.  The Jacobian of a_k in theta is c = -f_x sin theta + f_z cos theta (about g).
Estimate: theta_b = theta, theta_b' = w_k - b - n, theta_w = phi_k + theta_b and theta_w' = phi' + theta_b' with
phi' the filter's, (v - d cos theta theta_b') / r - theta_b' (``kalman.wheel_rate: 1``, the default; the cosine at
the predicted theta, which the update moves by microradians), or the driver's differenced encoder rate
(``kalman.wheel_rate: 0``).  Nothing of the true state or the true bias enters: r, d, g are the nominal
geometry and the IMU's mounting.

Health: the innovation of phi, its NIS = innovation^2 / S, their running mean over NIS_WINDOW_S;
``diverged`` when the estimate or the covariance is not finite, a variance is not positive, or the mean NIS
exceeds ``kalman.nis_limit``.
"""
from __future__ import annotations

import math
from typing import NamedTuple

from .base import NIS_WINDOW_S, Estimator, EstimatorParam

__all__ = ["KalmanFilter", "KalmanParams", "kalman_step", "STATE_NAMES"]


class KalmanParams(NamedTuple):
    """The numbers :func:`kalman_step` reads, in this order (the compiled batch passes them as an array row)."""

    gyro_noise_std: float      # s_g [rad/s]
    bias_walk: float           # s_w [rad/s/sqrt(s)]
    accel_noise_std: float     # s_a [m/s^2]
    encoder_noise_std: float   # s_e [rad]
    initial_pitch_std: float   # [rad]
    initial_bias_std: float    # [rad/s]
    initial_speed_std: float   # [m/s]
    gyro_bias: float           # the bias at the start [rad/s]
    nis_limit: float
    wheel_rate: float          # 1: phi' from the filter, 0: the driver's
    slip_gate: float           # an encoder sample whose NIS exceeds it is not used (a slipping wheel); 0: all used
    r: float                   # nominal wheel radius [m]
    d: float                   # IMU offset [m]
    g: float                   # gravity [m/s^2]


# the flat state tuple: the estimate, the covariance's upper triangle (row-major, indices 0..4 = theta, b, p, v, n),
# the last gyro, the mean NIS
STATE_NAMES = ("theta", "bias", "p", "v", "n", "P00", "P01", "P02", "P03", "P04", "P11", "P12", "P13", "P14", "P22",
               "P23", "P24", "P33", "P34", "P44", "gyro_prev", "nis_mean")


def kalman_step(prm, dt, sample, s, first, m=math):
    """One period of the EKF as a pure function (:attr:`~.Estimator.pure_step`).

    ``prm`` the 13 numbers of :class:`KalmanParams`; ``dt`` the period [s] since the last sample; ``sample`` =
    (gyro, accel_x, accel_z, encoder, encoder_rate); ``s`` the 22 floats of :data:`STATE_NAMES`.  Returns
    ((theta_w, theta_b, theta_w', theta_b'), s_next, (innovation, nis, nis_mean, diverged))."""
    (sg, sw, sa, se, pitch_std0, bias_std0, speed_std0, bias0, nis_limit, wheel_rate, slip_gate, r, d,
     _g) = prm
    gyro, f_x, f_z, phi, phi_rate = sample
    vg = sg * sg                                # the variance of one gyro sample's noise
    if first:   # pitch from the accelerometer; p, v and their covariance follow from it and the encoder
        th = m.atan2(-f_x, f_z)
        b, n = bias0, 0.0
        cs = m.cos(th)
        lever = r + d * cs                      # d x_imu / d theta at a fixed phi
        p = r * (phi + th) + d * m.sin(th)
        v = lever * (gyro - b) + r * phi_rate   # its errors: -lever (bias error + the gyro's noise)
        vth, vb = pitch_std0 * pitch_std0, bias_std0 * bias_std0
        P00, P01, P02, P03, P04 = vth, 0.0, lever * vth, 0.0, 0.0
        P11, P12, P13, P14 = vb, 0.0, -lever * vb, 0.0
        P22, P23, P24 = lever * lever * vth + r * r * se * se, 0.0, 0.0
        P33, P34 = lever * lever * (vb + vg) + speed_std0 * speed_std0, -lever * vg
        P44 = vg
        nis_mean, innovation, nis, S = 0.0, 0.0, 0.0, 1.0
    else:
        (th, b, p, v, n, P00, P01, P02, P03, P04, P11, P12, P13, P14, P22, P23, P24, P33, P34, P44, gyro_prev,
         nis_mean) = s
        # --- prediction over [t_{k-1}, t_k] ---
        q = 0.5 * dt                            # the weight of each gyro sample in the trapezoid
        th = th + dt * (0.5 * (gyro_prev + gyro) - b) - q * n
        sn, cs = m.sin(th), m.cos(th)
        a = f_x * cs + f_z * sn                 # the IMU point's horizontal acceleration (world)
        c = f_z * cs - f_x * sn                 # d a / d theta
        p = p + dt * v + 0.5 * dt * dt * a
        v = v + dt * a
        # covariance: shear 1 (theta -= dt b + q n, p += dt v; the old n is used up) ...
        P00, P01, P02, P03, P11, P12, P13, P22, P23, P33 = (
            P00 - 2.0 * dt * P01 - 2.0 * q * P04 + dt * dt * P11 + 2.0 * dt * q * P14 + q * q * P44,
            P01 - dt * P11 - q * P14,
            P02 + dt * P03 - dt * (P12 + dt * P13) - q * (P24 + dt * P34),
            P03 - dt * P13 - q * P34,
            P11, P12 + dt * P13, P13, P22 + 2.0 * dt * P23 + dt * dt * P33, P23 + dt * P33, P33)
        # ... the new sample's noise (theta += q n_k; n = n_k, independent of the past) ...
        P00, P04, P14, P24, P34, P44 = P00 + q * q * vg, -q * vg, 0.0, 0.0, 0.0, vg
        n = 0.0
        # ... shear 2 (p += e theta, v += f theta: the acceleration at the predicted pitch)
        e, f = 0.5 * dt * dt * c, dt * c
        P22, P23, P33 = P22 + 2.0 * e * P02 + e * e * P00, P23 + e * P03 + f * P02 + e * f * P00, \
            P33 + 2.0 * f * P03 + f * f * P00
        P02, P03, P12, P13, P24, P34 = P02 + e * P00, P03 + f * P00, P12 + e * P01, P13 + f * P01, P24 + e * P04, \
            P34 + f * P04
        # process noise: the bias walk, the accelerometer's
        qa = sa * sa * dt * dt
        P11 = P11 + sw * sw * dt
        P22, P23, P33 = P22 + 0.25 * dt * dt * qa, P23 + 0.5 * dt * qa, P33 + qa
        # --- update with the encoder: phi = (p - d sin theta) / r - theta (sn, cs: at the predicted theta) ---
        H0, H2 = -(1.0 + d * cs / r), 1.0 / r
        innovation = phi - ((p - d * sn) / r - th)
        g0, g1, g2 = P00 * H0 + P02 * H2, P01 * H0 + P12 * H2, P02 * H0 + P22 * H2
        g3, g4 = P03 * H0 + P23 * H2, P04 * H0 + P24 * H2
        S = H0 * g0 + H2 * g2 + se * se
        iS = 1.0 / S
        nis = innovation * innovation * iS
        # the slip gate: a wheel that slips turns without the body moving as the encoder says; such a sample is
        # left out (no gain), and counts as slip_gate in the mean NIS, so a slip that lasts is still a divergence
        slipped = slip_gate > 0.0 and nis > slip_gate
        gain = 0.0 if slipped else iS
        k0, k1, k2, k3, k4 = g0 * gain, g1 * gain, g2 * gain, g3 * gain, g4 * gain
        th, b, p, v, n = th + k0 * innovation, b + k1 * innovation, p + k2 * innovation, v + k3 * innovation, \
            n + k4 * innovation
        P00, P01, P02, P03, P04 = P00 - k0 * g0, P01 - k0 * g1, P02 - k0 * g2, P03 - k0 * g3, P04 - k0 * g4
        P11, P12, P13, P14 = P11 - k1 * g1, P12 - k1 * g2, P13 - k1 * g3, P14 - k1 * g4
        P22, P23, P24 = P22 - k2 * g2, P23 - k2 * g3, P24 - k2 * g4
        P33, P34, P44 = P33 - k3 * g3, P34 - k3 * g4, P44 - k4 * g4
        if slipped:          # the contact point moved by the slip: p's variance takes it, the next sample decides
            P22 = P22 + innovation * innovation * r * r
        nis_mean = nis_mean + (dt / (NIS_WINDOW_S + dt)) * ((slip_gate if slipped else nis) - nis_mean)
    rate = gyro - b - n
    if wheel_rate > 0.5:   # phi' from the filter's IMU velocity: v = r theta_w' + d cos(theta) theta' (cs: predicted)
        w_rate = (v - d * cs * rate) / r
    else:                  # the driver's differenced encoder rate
        w_rate = phi_rate + rate
    est = (phi + th, th, w_rate, rate)
    finite = m.isfinite(th) and m.isfinite(b) and m.isfinite(p) and m.isfinite(v) and m.isfinite(n) \
        and m.isfinite(w_rate) and m.isfinite(P00 + P01 + P02 + P03 + P04 + P11 + P12 + P13 + P14 + P22 + P23 + P24
                                               + P33 + P34 + P44)
    diverged = (not finite) or P00 <= 0.0 or P11 <= 0.0 or P22 <= 0.0 or P33 <= 0.0 or P44 <= 0.0 or S <= 0.0 \
        or nis_mean > nis_limit
    return est, (th, b, p, v, n, P00, P01, P02, P03, P04, P11, P12, P13, P14, P22, P23, P24, P33, P34, P44, gyro,
                 nis_mean), (innovation, nis, nis_mean, diverged)


class KalmanFilter(Estimator):
    """EKF of (pitch, gyro bias, IMU horizontal position and velocity) from the gyro, accelerometer, encoder."""

    name = "kalman"
    title = "Kalman filter"
    state_size = len(STATE_NAMES)
    parameters = (
        EstimatorParam("kalman.gyro_noise_std", "double", 0.004,
                       "the gyro's white noise per sample the filter assumes [rad/s]", 1e-7, 10.0),
        EstimatorParam("kalman.bias_walk", "double", 0.0005,
                       "the gyro bias's random walk the filter assumes [rad/s/sqrt(s)]", 0.0, 1.0),
        EstimatorParam("kalman.accel_noise_std", "double", 0.02,
                       "the accelerometer's white noise per sample and axis the filter assumes [m/s^2]", 1e-6, 100.0),
        EstimatorParam("kalman.encoder_noise_std", "double", 0.00044,
                       "the encoder angle's noise [rad]: a count / sqrt(12) (4096 counts: 0.00044)", 1e-9, 1.0),
        EstimatorParam("kalman.initial_pitch_std", "double", 0.2,
                       "the standard deviation of the first pitch (the accelerometer's) [rad]", 1e-6, 3.2),
        EstimatorParam("kalman.initial_bias_std", "double", 0.02,
                       "the standard deviation of the gyro bias at the start [rad/s]", 1e-9, 10.0),
        EstimatorParam("kalman.initial_speed_std", "double", 0.5,
                       "the standard deviation of the IMU's first horizontal speed [m/s]", 1e-6, 100.0),
        EstimatorParam("kalman.gyro_bias", "double", 0.0,
                       "the gyro bias at the start [rad/s] (then estimated)", -1.0, 1.0),
        EstimatorParam("kalman.nis_limit", "double", 50.0,
                       "diverged when the running mean of the encoder's NIS exceeds this (about 1 when sound)",
                       1.0, 1e9),
        EstimatorParam("kalman.wheel_rate", "integer", 1,
                       "theta_w' = phi' + theta_b' with phi' from the filter (1) or the driver's encoder rate (0)",
                       0, 1),
        EstimatorParam("kalman.slip_gate", "double", 0.0,
                       "an encoder sample whose NIS exceeds this is left out as wheel slip (0: every sample is used)",
                       0.0, 1e9),
    )

    @staticmethod
    def pure_params(values, r, d, g) -> KalmanParams:
        own = {k: float(values[f"kalman.{k}"]) for k in KalmanParams._fields[:-3]}
        return KalmanParams(**own, r=float(r), d=float(d), g=float(g))

    pure_step = staticmethod(kalman_step)
