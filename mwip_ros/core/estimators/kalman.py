"""The estimator ``kalman``: an extended Kalman filter of pitch, gyro bias and the IMU's horizontal motion
(docs/theory.md 6.4).

The accelerometer is not read as a pitch.  Rotated into the world frame with the estimated pitch it is the
IMU point's own horizontal acceleration, which integrated twice must agree with where the encoder says
the IMU is; a pitch error theta_e leaks g theta_e into that acceleration and shows within a fraction of a
second as a position error, and the gyro bias as a growing pitch error.  So the robot's acceleration, which
corrupts the accelerometer's pitch by milliradians to centiradians, is part of the model instead of an error.

State (theta, b, p, v): pitch, gyro bias, the IMU point's horizontal position x_imu = r theta_w + d sin theta
and velocity.  Inputs per sample k: gyro w_k, specific force (f_x, f_z) at t_k^- (the acceleration over
the period that ends at t_k).  Prediction::

    theta_k = theta_{k-1} + h ((w_{k-1} + w_k) / 2 - b)             trapezoid (theta' is continuous)
    a_k     = f_x cos theta_k + f_z sin theta_k                      world horizontal acceleration of the IMU
    v_k     = v_{k-1} + h a_k,   p_k = p_{k-1} + h v_{k-1} + h^2 a_k / 2,   b_k = b_{k-1}

Measurement: the encoder, phi_k = (p - d sin theta) / r - theta (since theta_w = phi + theta), noise
``encoder_noise_std``.  The Jacobian of a_k in theta is c = -f_x sin theta + f_z cos theta (about g).
Estimate: theta_b = theta, theta_b' = w_k - b, theta_w = phi_k + theta_b and theta_w' = phi' + theta_b' with
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

from . import NIS_WINDOW_S, Estimator, EstimatorParam

__all__ = ["KalmanFilter", "kalman_step", "STATE_NAMES"]

# the flat state tuple: the estimate, the covariance's upper triangle (row-major), the last gyro, the mean NIS
STATE_NAMES = ("theta", "bias", "p", "v", "P00", "P01", "P02", "P03", "P11", "P12", "P13", "P22", "P23", "P33",
               "gyro_prev", "nis_mean")


def kalman_step(P, h, sample, s, first, m=math):
    """One period of the EKF as a pure function (:attr:`~.Estimator.pure_step`).

    ``P`` = (gyro_noise_std, bias_walk, accel_noise_std, encoder_noise_std, initial_pitch_std, initial_bias_std,
    initial_speed_std, gyro_bias, nis_limit, wheel_rate, r, d, g); ``sample`` = (gyro, accel_x, accel_z,
    encoder, encoder_rate); ``s`` the 16 floats of :data:`STATE_NAMES`.  Returns ((theta_w, theta_b, theta_w',
    theta_b'), s_next, (innovation, nis, nis_mean, diverged))."""
    sg, sw, sa, se = P[0], P[1], P[2], P[3]
    r, d = P[10], P[11]
    gyro, f_x, f_z, phi, phi_rate = sample[0], sample[1], sample[2], sample[3], sample[4]
    if first:   # pitch from the accelerometer; p, v and their covariance follow from it and the encoder
        th = m.atan2(-f_x, f_z)
        b = P[7]
        cs = m.cos(th)
        lever = r + d * cs                      # d x_imu / d theta at a fixed phi
        p = r * (phi + th) + d * m.sin(th)
        v = lever * (gyro - b) + r * phi_rate
        vth, vb = P[4] * P[4], P[5] * P[5]
        P00, P01, P02, P03 = vth, 0.0, lever * vth, 0.0
        P11, P12, P13 = vb, 0.0, -lever * vb
        P22, P23 = lever * lever * vth + r * r * se * se, 0.0
        P33 = lever * lever * vb + P[6] * P[6]
        nis_mean, innovation, nis, S = 0.0, 0.0, 0.0, 1.0
    else:
        th, b, p, v = s[0], s[1], s[2], s[3]
        P00, P01, P02, P03, P11, P12, P13, P22, P23, P33 = s[4], s[5], s[6], s[7], s[8], s[9], s[10], s[11], \
            s[12], s[13]
        nis_mean = s[15]
        # --- prediction over [t_{k-1}, t_k] ---
        th = th + h * (0.5 * (s[14] + gyro) - b)
        sn, cs = m.sin(th), m.cos(th)
        a = f_x * cs + f_z * sn                 # the IMU point's horizontal acceleration (world)
        c = f_z * cs - f_x * sn                 # d a / d theta
        p = p + h * v + 0.5 * h * h * a
        v = v + h * a
        # covariance: shear 1 (theta -= h b, p += h v), then shear 2 (p += e theta, v += f theta)
        P00, P01, P02, P03, P11, P12, P13, P22, P23, P33 = (
            P00 - 2.0 * h * P01 + h * h * P11, P01 - h * P11, P02 + h * P03 - h * (P12 + h * P13), P03 - h * P13,
            P11, P12 + h * P13, P13, P22 + 2.0 * h * P23 + h * h * P33, P23 + h * P33, P33)
        e, f = 0.5 * h * h * c, h * c
        P22, P23, P33 = P22 + 2.0 * e * P02 + e * e * P00, P23 + e * P03 + f * P02 + e * f * P00, \
            P33 + 2.0 * f * P03 + f * f * P00
        P02, P03, P12, P13 = P02 + e * P00, P03 + f * P00, P12 + e * P01, P13 + f * P01
        # process noise: the gyro's white noise (trapezoid of two samples), the bias walk, the accelerometer's
        qa = sa * sa * h * h
        P00 = P00 + 0.5 * h * h * sg * sg
        P11 = P11 + sw * sw * h
        P22, P23, P33 = P22 + 0.25 * h * h * qa, P23 + 0.5 * h * qa, P33 + qa
        # --- update with the encoder: phi = (p - d sin theta) / r - theta (sn, cs: at the predicted theta) ---
        H0, H2 = -(1.0 + d * cs / r), 1.0 / r
        innovation = phi - ((p - d * sn) / r - th)
        g0, g1, g2, g3 = P00 * H0 + P02 * H2, P01 * H0 + P12 * H2, P02 * H0 + P22 * H2, P03 * H0 + P23 * H2
        S = H0 * g0 + H2 * g2 + se * se
        iS = 1.0 / S
        k0, k1, k2, k3 = g0 * iS, g1 * iS, g2 * iS, g3 * iS
        th, b, p, v = th + k0 * innovation, b + k1 * innovation, p + k2 * innovation, v + k3 * innovation
        P00, P01, P02, P03 = P00 - k0 * g0, P01 - k0 * g1, P02 - k0 * g2, P03 - k0 * g3
        P11, P12, P13 = P11 - k1 * g1, P12 - k1 * g2, P13 - k1 * g3
        P22, P23, P33 = P22 - k2 * g2, P23 - k2 * g3, P33 - k3 * g3
        nis = innovation * innovation * iS
        nis_mean = nis_mean + (h / (NIS_WINDOW_S + h)) * (nis - nis_mean)
    rate = gyro - b
    if P[9] > 0.5:   # phi' from the filter's IMU velocity: v = r theta_w' + d cos(theta) theta' (cs: the prediction's)
        w_rate = (v - d * cs * rate) / r
    else:            # the driver's differenced encoder rate
        w_rate = phi_rate + rate
    est = (phi + th, th, w_rate, rate)
    finite = m.isfinite(th) and m.isfinite(b) and m.isfinite(p) and m.isfinite(v) and m.isfinite(w_rate) \
        and m.isfinite(P00 + P11 + P22 + P33 + P01 + P02 + P03 + P12 + P13 + P23)
    diverged = (not finite) or P00 <= 0.0 or P11 <= 0.0 or P22 <= 0.0 or P33 <= 0.0 or S <= 0.0 \
        or nis_mean > P[8]
    return est, (th, b, p, v, P00, P01, P02, P03, P11, P12, P13, P22, P23, P33, gyro, nis_mean), \
        (innovation, nis, nis_mean, diverged)


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
    )

    @staticmethod
    def pure_params(values, r, d, g) -> tuple:
        keys = ("gyro_noise_std", "bias_walk", "accel_noise_std", "encoder_noise_std", "initial_pitch_std",
                "initial_bias_std", "initial_speed_std", "gyro_bias", "nis_limit", "wheel_rate")
        return tuple(float(values[f"kalman.{k}"]) for k in keys) + (float(r), float(d), float(g))

    pure_step = staticmethod(kalman_step)
