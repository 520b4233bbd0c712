"""Sensing and actuation (docs/theory.md, section 6.2): what a real robot measures, and when its torque acts.

All off by default; with every option off nothing here runs, and every number of the paper's
scenario is unchanged bit for bit.

* Measurement noise: zero-mean Gaussian, standard deviation ``noise_std`` per channel
  (theta_w, theta_b, theta_w', theta_b'), drawn once per control period from a generator of
  its own (seeded with the plant's ``seed`` and stream 1), so that turning noise on does not
  change the D_w draws.
* Encoder: the measured theta_w is quantized to 2 pi / ``encoder_counts_per_rev`` (0 = ideal),
  after the noise.
* Measurement delay: the state published at step k is the measurement of step k - d (the
  first d steps publish the first measurement); the torque reported with it is delayed alike.
* Actuator delay: the command answering state k is applied over [t_{k+d}, t_{k+d+1}); zero
  torque before the first command arrives.

One implementation serves the scalar loop, the ``plant_sim`` node (floats, ``math``) and the
batch simulator (arrays of scenarios, ``numpy``): only the source of the normal draws differs
(:class:`Normals` for one plant, the batch's per-scenario generators).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Deque, List, Optional, Sequence, Tuple

import numpy as np

from .model import State

__all__ = ["SensingConfig", "SENSOR_STREAM", "NOISE_BLOCK", "sensor_rng", "measure", "quantize", "Normals",
           "Sensors", "Actuator"]

SENSOR_STREAM = 1    # the sensor noise generator is default_rng([seed, SENSOR_STREAM]); D_w uses default_rng(seed)
NOISE_BLOCK = 256    # periods of draws per generator call (the same sequence as one call per period)


@dataclass(frozen=True)
class SensingConfig:
    noise_std: Tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)   # theta_w, theta_b, theta_w', theta_b'
    encoder_counts_per_rev: int = 0      # 0 = ideal
    delay_periods: int = 0               # measurement delay d
    actuator_delay_periods: int = 0      # actuator delay

    @property
    def noisy(self) -> bool:
        return any(s != 0.0 for s in self.noise_std)

    @property
    def measuring(self) -> bool:
        """Does the published state differ from the true one (noise, encoder or delay)?"""
        return self.noisy or self.encoder_counts_per_rev > 0 or self.delay_periods > 0

    @property
    def active(self) -> bool:
        return self.measuring or self.actuator_delay_periods > 0


def sensor_rng(seed: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), SENSOR_STREAM])


def measure(x, z, std, counts, m=math) -> State:
    """The measurement of state ``x``: noise ``std * z`` per channel (``z`` None: no noise), then theta_w
    quantized to 2 pi / ``counts`` (0: not).  ``m``: ``math`` for floats, ``numpy`` for arrays."""
    if z is not None:
        x = tuple(v + s * n for v, s, n in zip(x, std, z))
    w = x[0]
    if counts:
        w = quantize(w, counts, m)
    return State(w, x[1], x[2], x[3])


def quantize(w, counts, m=math):
    """theta_w at the nearest count of an encoder with ``counts`` per revolution (> 0)."""
    q = 2.0 * math.pi / counts
    return q * m.floor(w / q + 0.5)


class Normals:
    """Four standard normal draws per period from one generator, drawn in blocks."""

    def __init__(self, rng: np.random.Generator):
        self.rng, self.used = rng, NOISE_BLOCK
        self.block: List[List[float]] = []   # filled at the first call (used == NOISE_BLOCK)

    def __call__(self) -> Tuple[float, float, float, float]:
        if self.used == NOISE_BLOCK:
            self.block, self.used = self.rng.standard_normal((NOISE_BLOCK, 4)).tolist(), 0
        z = self.block[self.used]
        self.used += 1
        return z[0], z[1], z[2], z[3]


class Sensors:
    """``sample(x_true, u_prev)`` once per period: the (state, torque) to publish at this step.

    ``normals`` gives the four standard normal draws of a period (None: no noise); ``std`` and
    ``counts`` are floats (one plant) or arrays (a batch, ``m = numpy``)."""

    def __init__(self, delay_periods: int, counts, std, normals: Optional[Callable[[], Sequence]] = None, m=math):
        self.counts, self.std, self.normals, self.m = counts, std, normals, m
        self.queue: Deque[Tuple[Any, Any]] = deque(maxlen=int(delay_periods) + 1)

    @classmethod
    def for_plant(cls, cfg: SensingConfig, seed: int) -> "Sensors":
        """One plant's sensors, noise from its own stream (:func:`sensor_rng`)."""
        return cls(cfg.delay_periods, cfg.encoder_counts_per_rev, cfg.noise_std,
                   Normals(sensor_rng(seed)) if cfg.noisy else None)

    def sample(self, x, u_prev):
        z = self.normals() if self.normals is not None else None
        self.queue.append((measure(x, z, self.std, self.counts, self.m), u_prev))
        return self.queue[0]   # the measurement of step k - d (or the first one while k < d)


class Actuator:
    """``apply(u_k)`` once per period: the torque acting over [t_k, t_{k+1}), the command of d periods ago."""

    def __init__(self, delay_periods: int, zero=0.0):
        self.queue: Deque[Any] = deque(maxlen=delay_periods + 1)
        self.zero = zero

    def apply(self, u):
        self.queue.append(u)
        return self.queue[0] if len(self.queue) == self.queue.maxlen else self.zero
