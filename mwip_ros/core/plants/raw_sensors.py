"""Raw sensors (docs/theory.md 6.4): what a real MWIP measures instead of its state.

An IMU rigid on the body, ``offset`` = d metres from the axle along the body axis z_b, gives the
pitch rate (with a bias that walks) and the specific force in the body frame; an encoder on the
motor gives the wheel's angle *relative to the body*, ``phi = theta_w - theta_b`` (the stator is
bolted to the body), quantized, and its rate as a driver reports it (the last difference over h).

Frames follow REP-103 (x forward, y left, z up); the IMU's axes are REP-145's ``imu_link``: the body
frame, origin at the IMU, x_b = [cos th_b, -sin th_b] and z_b = [sin th_b, cos th_b] in world (x, z).
theta_b > 0 puts the centre of gravity ahead of the axle, theta_w > 0 rolls forward, x_axle = r theta_w.
Per sample k (``h`` the period, ``n_*`` four standard normals, drawn in the order n_gyro, n_walk, n_x,
n_z from ``default_rng([seed, 2])``)::

    a_x = r th_w'' + d (cos th_b th_b'' - sin th_b th_b'^2)     IMU point acceleration, world
    a_z = -d (sin th_b th_b'' + cos th_b th_b'^2)
    f_x = a_x cos th_b - (a_z + g) sin th_b                      specific force a - g_vec, body frame
    f_z = a_x sin th_b + (a_z + g) cos th_b
    bias_k  = bias_{k-1} + gyro_bias_walk sqrt(h) n_walk         bias_{-1} = gyro_bias
    gyro_k  = th_b' + bias_k + gyro_noise_std n_gyro
    accel_k = (f_x + accel_noise_std n_x, 0, f_z + accel_noise_std n_z)
    phi_k   = quantize(th_w - th_b),  phi_rate_k = (phi_k - phi_{k-1}) / h  (0 at k = 0)

At rest and upright the IMU reads (0, 0, +g).

**The yaw gyro** (a spatial plant, backend mujoco; docs/theory.md 6.13): the IMU's z axis (REP-145 ``imu_link``, the
body's z_b) reads the body's own z rate w_z (cos(th_b) psi' when the robot turns at psi' about the vertical) with a
bias and noise of the same parameters as the pitch axis, drawn independently from ``default_rng([seed, 3])``
(:class:`YawGyro`: the planar model's draws above are not touched)::

    bias_z,k = bias_z,k-1 + gyro_bias_walk sqrt(h) n_walk,z      bias_z,-1 = gyro_bias
    gyro_z,k = w_z + bias_z,k + gyro_noise_std n_gyro,z

Draws: when any of ``gyro_noise_std``, ``gyro_bias_walk``, ``accel_noise_std`` is nonzero, every period
draws its four normals (even a zero parameter's: turning one noise on never reorders another's); when
all three are zero, nothing is drawn.  The draws come in blocks of :data:`~.sensing.NOISE_BLOCK` periods
x 4 (:class:`~.sensing.Normals`), the same sequence as one call per period.

**Note for the integration (the instant of a sample).**  Sample k is taken at t_k^-: ``ddq`` are the
accelerations (th_w'', th_b'') of eq. (1) at x_k and t_k with everything that acted over the *previous*
period: its torque ``u_{k-1}``, its friction draw D_w (``PlantSim.step`` draws the next period's D_w at
its end: keep the previous one), the external wrench held then, and tau_ext(t_k); at k = 0 zero torque,
the D_w of period 0, no wrench.  The caller computes them with :func:`mwip_ros.core.plants.model.accel` (the true
parameters) and hands them to :meth:`RawSensors.sample` or :func:`raw_sample`; a sample never depends on
the command that answers it.

:func:`specific_force` and :func:`raw_sample` are pure functions of floats and tuples, compiled by numba
as they are (the batch simulator); :class:`RawSensors` keeps one plant's bias, previous phi and draws.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Optional, Tuple

import numpy as np

from .sensing import Normals, quantize

__all__ = ["RAW_STREAM", "YAW_GYRO_STREAM", "raw_rng", "YawGyro", "RawSensorConfig", "RawSample", "specific_force",
           "raw_sample", "RawSensors"]

RAW_STREAM = 2   # the raw sensors' generator is default_rng([seed, RAW_STREAM]); stream 1: state-mode noise
YAW_GYRO_STREAM = 3   # the yaw gyro's own generator (a spatial plant): default_rng([seed, YAW_GYRO_STREAM])


def raw_rng(seed: int) -> np.random.Generator:
    """The raw sensors' own generator, ``numpy.random.default_rng([seed, 2])`` (docs/theory.md 6.4)."""
    return np.random.default_rng([int(seed), RAW_STREAM])


@dataclass(frozen=True)
class RawSensorConfig:
    """The raw sensors of one plant (``plant_sim`` parameters ``sensors.imu.*`` and
    ``sensors.encoder_counts_per_rev``); the defaults are ideal sensors."""

    offset: float = 0.3                 # d [m]: the IMU above the axle along the body
    gyro_noise_std: float = 0.0         # [rad/s] per sample
    gyro_bias: float = 0.0              # [rad/s] at the start (bias_{-1})
    gyro_bias_walk: float = 0.0         # [rad/s/sqrt(s)] random walk of the bias
    accel_noise_std: float = 0.0        # [m/s^2] per sample, each axis
    encoder_counts_per_rev: int = 0     # 0 = ideal; quantizes phi

    @property
    def noisy(self) -> bool:
        """Does a sample draw its four normals (any noise or walk nonzero)?"""
        return self.gyro_noise_std != 0.0 or self.gyro_bias_walk != 0.0 or self.accel_noise_std != 0.0


class RawSample(NamedTuple):
    """One raw sample: what ``imu/data_raw`` and ``wheel_encoder`` carry (SI units)."""

    gyro: float          # pitch rate about +y, with bias and noise [rad/s]
    accel_x: float       # specific force along x_b [m/s^2]
    accel_z: float       # specific force along z_b [m/s^2]
    encoder: float       # phi = theta_w - theta_b, quantized [rad]
    encoder_rate: float  # (phi_k - phi_{k-1}) / h, 0 at k = 0 [rad/s]


def specific_force(x, ddq, r, d, g, m=math) -> Tuple[float, float]:
    """(f_x, f_z): the specific force at the IMU, ``d`` metres up the body axis, in the body frame (docs/theory.md 6.4).

    Parameters
    ----------
    x : tuple of 4 floats
        The state (theta_w, theta_b, dtheta_w, dtheta_b).
    ddq : tuple of 2 floats
        The accelerations (theta_w'', theta_b'') of eq. (1).
    r, d, g : float
        Wheel radius [m], IMU offset [m], gravitational acceleration [m/s^2].
    m : module
        The math namespace (``math``; ``numpy`` for arrays).

    Returns
    -------
    tuple of 2 floats
        f_x, f_z [m/s^2]; (0, g) at rest and upright.
    """
    th, dth = x[1], x[3]
    s, c = m.sin(th), m.cos(th)
    ddw, ddb = ddq[0], ddq[1]
    a_x = r * ddw + d * (c * ddb - s * dth * dth)   # IMU point acceleration, world x
    a_z = -d * (s * ddb + c * dth * dth)            # world z
    return a_x * c - (a_z + g) * s, a_x * s + (a_z + g) * c   # a - g_vec in the body frame


def raw_sample(x, ddq, z, bias_prev, phi_prev, first, h, r, d, g, gyro_noise_std, gyro_bias_walk,
               accel_noise_std, counts, m=math):
    """One period of the raw sensors as a pure function (numba compiles it as is).

    Parameters
    ----------
    x, ddq : tuples of floats
        The true state at t_k and the accelerations of eq. (1) at t_k^- (module docstring).
    z : tuple of 4 floats
        The period's standard normals (n_gyro, n_walk, n_x, n_z); zeros when nothing is drawn.
    bias_prev : float
        The gyro bias of the previous sample (``gyro_bias`` at k = 0).
    phi_prev : float
        The previous sample's phi (ignored when ``first``).
    first : bool
        k = 0: the encoder rate is 0.
    h, r, d, g : float
        Period [s], wheel radius [m], IMU offset [m], gravity [m/s^2].
    gyro_noise_std, gyro_bias_walk, accel_noise_std : float
        The noise parameters of :class:`RawSensorConfig`.
    counts : int
        Encoder counts per revolution, 0 = ideal.
    m : module
        The math namespace.

    Returns
    -------
    tuple
        (gyro, accel_x, accel_z, phi, phi_rate, bias): the sample and this period's bias (the next
        call's ``bias_prev``).
    """
    f_x, f_z = specific_force(x, ddq, r, d, g, m)
    bias = bias_prev + gyro_bias_walk * m.sqrt(h) * z[1]      # bias_k = bias_{k-1} + walk sqrt(h) n_walk
    gyro = x[3] + bias + gyro_noise_std * z[0]                 # gyro_k = th_b' + bias_k + noise
    phi = x[0] - x[1]                                          # the stator is on the body
    if counts > 0:
        phi = quantize(phi, counts, m)
    rate = 0.0 if first else (phi - phi_prev) / h
    return gyro, f_x + accel_noise_std * z[2], f_z + accel_noise_std * z[3], phi, rate, bias


class RawSensors:
    """One plant's raw sensors: ``sample(x_k, ddq_k)`` once per period, in order from k = 0."""

    def __init__(self, cfg: RawSensorConfig, h: float, r: float, g: float, normals: Optional[Normals] = None):
        self.cfg, self.h, self.r, self.g, self.normals = cfg, float(h), float(r), float(g), normals
        self.reset()

    @classmethod
    def for_plant(cls, cfg: RawSensorConfig, seed: int, h: float, r: float, g: float) -> "RawSensors":
        """The sensors of a plant with ``seed`` (draws from :func:`raw_rng` when ``cfg.noisy``), period ``h``,
        the true wheel radius ``r`` and gravity ``g``."""
        return cls(cfg, h, r, g, Normals(raw_rng(seed)) if cfg.noisy else None)

    def reset(self) -> None:
        """Back to k = 0: the bias at ``gyro_bias``, no previous phi (the generator is not rewound)."""
        self.bias, self.phi, self.first = float(self.cfg.gyro_bias), 0.0, True

    def sample(self, x, ddq, force: Optional[Tuple[float, float]] = None) -> RawSample:
        """The raw sample of the state ``x`` at t_k and its accelerations ``ddq`` at t_k^-.  ``force``: the specific
        force (f_x, f_z) the physics measures at the IMU (a spatial plant's own accelerometer, MuJoCo's), used
        instead of :func:`specific_force`, whose a_x = r th_w'' + ... assumes the wheels roll without slipping (a
        turn in place scrubs them: they slip, the body does not follow); the noise is drawn and added alike."""
        c = self.cfg
        z = self.normals() if self.normals is not None else (0.0, 0.0, 0.0, 0.0)
        gyro, ax, az, phi, rate, self.bias = raw_sample(
            x, ddq, z, self.bias, self.phi, self.first, self.h, self.r, c.offset, self.g, c.gyro_noise_std,
            c.gyro_bias_walk, c.accel_noise_std, int(c.encoder_counts_per_rev))
        if force is not None:
            ax, az = force[0] + c.accel_noise_std * z[2], force[1] + c.accel_noise_std * z[3]
        self.phi, self.first = phi, False
        return RawSample(gyro, ax, az, phi, rate)


class YawGyro:
    """The IMU's z-axis gyro of a spatial plant (module docstring, "The yaw gyro"): ``sample(w_z)`` once per period,
    in order from k = 0, after the planar sample of the same period."""

    def __init__(self, cfg: RawSensorConfig, h: float, normals: Optional[Normals] = None):
        self.cfg, self.h, self.normals = cfg, float(h), normals
        self.reset()

    @classmethod
    def for_plant(cls, cfg: RawSensorConfig, seed: int, h: float) -> "YawGyro":
        """The yaw gyro of a plant with ``seed``: its draws from ``default_rng([seed, 3])`` when ``cfg.noisy``."""
        rng = np.random.default_rng([int(seed), YAW_GYRO_STREAM])
        return cls(cfg, h, Normals(rng) if cfg.noisy else None)

    def reset(self) -> None:
        """Back to k = 0: the bias at ``gyro_bias`` (the generator is not rewound)."""
        self.bias = float(self.cfg.gyro_bias)

    def sample(self, rate_z: float) -> float:
        """gyro_z,k for the body's true z rate ``rate_z`` [rad/s]."""
        c = self.cfg
        z = self.normals() if self.normals is not None else (0.0, 0.0)
        self.bias += c.gyro_bias_walk * math.sqrt(self.h) * z[1]
        return rate_z + self.bias + c.gyro_noise_std * z[0]
