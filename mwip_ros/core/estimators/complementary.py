"""The estimator ``complementary``: the gyro integrated, blended with the accelerometer's pitch (docs/theory.md 6.4).

Per sample k (gyro w_k, specific force (f_x, f_z), encoder phi_k and its rate; dt the time since the last sample,
h when none was lost)::

    theta_acc = atan2(-f_x, f_z)                                 exact when the IMU does not accelerate
    theta_k   = a (theta_{k-1} + dt (w_k - b)) + (1 - a) theta_acc,  a = tau / (tau + dt)
    theta_k'  = w_k - b
    theta_w   = phi_k + theta_k,   theta_w' = phi_k' + theta_k'

a first-order filter of time constant ``tau``: the accelerometer below 1/tau, the gyro above it.  The
bias b is a parameter (``complementary.gyro_bias``): the filter does not estimate it, and an error
in it becomes a pitch error of (bias error) x tau.  At k = 0 theta_0 = theta_acc.

Health: the innovation theta_acc - (theta_{k-1} + dt (w_k - b)), its NIS against
``complementary.innovation_std``, their running mean over NIS_WINDOW_S; ``diverged`` when the estimate
is not finite or the mean NIS exceeds ``complementary.nis_limit``.
"""
from __future__ import annotations

import math

from .base import NIS_WINDOW_S, Estimator, EstimatorParam

__all__ = ["ComplementaryFilter", "complementary_step"]


def complementary_step(P, dt, sample, s, first, m=math):
    """One period of the complementary filter as a pure function (:attr:`~.Estimator.pure_step`).

    ``P`` = (tau, gyro_bias, innovation_std, nis_limit); ``dt`` the time since the last sample [s]; ``sample`` =
    (gyro, accel_x, accel_z, encoder, encoder_rate); ``s`` = (theta_b, nis_mean).  Returns ((theta_w, theta_b,
    theta_w', theta_b'), (theta_b, nis_mean), (innovation, nis, nis_mean, diverged))."""
    tau, bias, innovation_std, nis_limit = P[0], P[1], P[2], P[3]
    gyro, f_x, f_z, phi, phi_rate = sample[0], sample[1], sample[2], sample[3], sample[4]
    theta_acc = m.atan2(-f_x, f_z)                 # the accelerometer's pitch
    rate = gyro - bias
    if first:
        theta, innovation, nis_mean = theta_acc, 0.0, 0.0
    else:
        pred = s[0] + dt * rate                     # the gyro integrated
        a = tau / (tau + dt)
        theta = a * pred + (1.0 - a) * theta_acc    # first-order blend, time constant tau
        innovation = theta_acc - pred
        nis_mean = s[1]
    nis = (innovation / innovation_std) ** 2
    nis_mean = nis_mean + (dt / (NIS_WINDOW_S + dt)) * (nis - nis_mean)
    est = (phi + theta, theta, phi_rate + rate, rate)
    finite = m.isfinite(est[0]) and m.isfinite(theta) and m.isfinite(est[2]) and m.isfinite(rate)
    diverged = (not finite) or nis_mean > nis_limit
    return est, (theta, nis_mean), (innovation, nis, nis_mean, diverged)


class ComplementaryFilter(Estimator):
    """theta_b from the gyro (above 1/tau) and the accelerometer's pitch (below), the bias given."""

    name = "complementary"
    title = "complementary filter"
    state_size = 2
    parameters = (
        EstimatorParam("complementary.tau", "double", 1.0,
                       "time constant of the blend [s]: the accelerometer's pitch below 1/tau, the gyro above", 1e-3,
                       1e3),
        EstimatorParam("complementary.gyro_bias", "double", 0.0,
                       "the gyro's bias subtracted from its rate [rad/s] (not estimated)", -1.0, 1.0),
        EstimatorParam("complementary.innovation_std", "double", 0.05,
                       "the expected spread of the accelerometer's pitch about the prediction [rad] (health only)",
                       1e-6, 10.0),
        EstimatorParam("complementary.nis_limit", "double", 100.0,
                       "diverged when the running mean of (innovation / innovation_std)^2 exceeds this", 1.0, 1e9),
    )

    @staticmethod
    def pure_params(values, r, d, g) -> tuple:
        return (float(values["complementary.tau"]), float(values["complementary.gyro_bias"]),
                float(values["complementary.innovation_std"]), float(values["complementary.nis_limit"]))

    pure_step = staticmethod(complementary_step)
