"""What every simulated plant shares, below both of its implementations (the contract: :mod:`.plant`).

:mod:`.plant` (the interface, the RK4 plant and the registry of backends) and :mod:`.mujoco_plant` (the MuJoCo
plant) both build on this module and neither on the other's internals: the plant's configuration
(:class:`PlantConfig`, with the 3D model's and the ground's :class:`MujocoConfig`), a spatial plant's
:class:`Pose`, :class:`PlantDiverged`, the driver's gate (:func:`gated_drive`) and :class:`PlantBase`, the
bookkeeping of a period (the clock t_k = k h, the seeded D_w draw, what acted over the previous period) that
every plant of this package keeps the same way, so the backends see the same friction sequence.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple, Optional, Tuple

import numpy as np

from .drive import MotorConfig
from .model import PhysicalParams, Sinusoid, State
from .raw_sensors import RawSensorConfig
from .sensing import NOISE_BLOCK, SensingConfig

__all__ = ["PlantConfig", "per_wheel", "MujocoConfig", "PlantBase", "Pose", "PlantDiverged", "Wrench", "NO_MOTOR",
           "gated_drive", "finite_state", "D_w_of"]

# The external wrench held over a period, a plant's one input for pushes (core.plants.plant's module docstring):
# (tau_ext1 [N m] on the wheels' axis, tau_ext2 [N m] on the body's pitch axis[, force.y [N] on the body's centre of
# gravity along the heading frame's y, torque.z [N m] about the vertical]); the last two act on a spatial plant only.
Wrench = Tuple[float, ...]


@dataclass(frozen=True)
class MujocoConfig:
    """What the 3D model has that eq. (1) has not (``actual.track_width``, ``actual.I_b_roll``, ``actual.I_b_yaw``,
    ``ground.friction``, ``mujoco.timestep``; defaults as the schema's), and the terrain it rolls on
    (``ground.slope``, ``ground.bumps``): the spatial plant's construction input for the ground
    (:class:`~.mujoco_plant.MujocoPlant`, :func:`~.mujoco_plant.mjcf`)."""

    track_width: float = 0.5     # wheel to wheel [m]
    I_b_roll: float = 65.0       # the body's inertia about its x axis (through the centre of gravity) [kg m^2]
    I_b_yaw: float = 20.0        # ... about its z axis [kg m^2]
    friction: float = 2.0        # ground sliding friction coefficient
    timestep: float = 5e-3       # largest physics step [s]; a control period is an integer number of steps
    slope: float = 0.0           # the ground's slope about y [rad], uphill ahead for > 0 (ground.slope)
    bumps: Tuple[float, ...] = ()   # steps [x0, h0, x1, h1, ...] along the slope [m] (ground.bumps, params.ground)


@dataclass(frozen=True)
class PlantConfig:
    """Everything the true plant needs; built from the parameter file by ``mwip_ros.params.plant_config``."""

    actual: PhysicalParams
    nominal: PhysicalParams          # only to report the true lumped disturbance
    D_b: float
    D_w_mean: float
    D_w_variance: float
    tau_ext1: Sinusoid
    tau_ext2: Sinusoid
    h: float                         # control period [s]
    substeps: int                    # RK4 sub-steps per period
    seed: int                        # of the D_w noise
    initial: State
    torque_limit: float              # 0 = none
    fall_angle: float                # |theta_b| beyond this is a fall [rad]
    sensing: SensingConfig = SensingConfig()   # measurement noise, encoder, delays (core.plants.sensing); off
    raw: Optional[RawSensorConfig] = None      # sensors.model raw: the IMU and the relative encoder (theory.md 6.4)
    motor: MotorConfig = MotorConfig()         # the DC motor and its driver (docs/theory.md 6.7); off
    require_enable: bool = False               # the driver starts disabled (docs/theory.md 6.8)
    # a key of core.plants.plant.PLANTS: rk4 (eq. 1) or mujoco (theory.md 6.10)
    backend: str = "rk4"
    mujoco: Optional[MujocoConfig] = None      # the MuJoCo model's own values and its ground (MujocoConfig)

    @property
    def motor_constants(self) -> Tuple[float, float, float, float]:
        """(K_t, R, V_max, I_max) for :func:`~.plant.rk4_driven`, or :data:`NO_MOTOR` when the motor is off."""
        mc = self.motor
        return (mc.torque_constant, mc.resistance, mc.voltage_limit, mc.current_limit) if mc.enabled else NO_MOTOR


def finite_state(x) -> bool:
    """Every component of the state ``x`` is a finite number (a run whose state is not has diverged)."""
    return all(math.isfinite(v) for v in x)


def per_wheel(lumped: float) -> float:
    """A wheel's share [N m] of a lumped torque (a ``torque_limit``, a motor's peak): half, each wheel drives u / 2;
    0 stays 0 (no limit)."""
    return 0.5 * lumped


def D_w_of(mean: float, sd: float, z: float) -> float:
    """The wheel friction of one period from its standard normal draw ``z``: Gaussian, clipped at 0 (table II)."""
    return max(0.0, mean + sd * z)


class Pose(NamedTuple):
    """A spatial plant's 3D pose at t_k (:attr:`.plant.Plant.pose`): the axle's centre (x, y, z) [m], the body's yaw,
    pitch (theta_b) and roll [rad] (REP-103: x forward, z up), each wheel's absolute angle [rad]."""

    x: float
    y: float
    z: float
    yaw: float
    pitch: float
    roll: float
    wheel_left: float
    wheel_right: float


class PlantDiverged(RuntimeError):
    """A plant's simulation diverged (a physics engine's warning, a state that is not finite); the message names
    the time and the cause.  The run ends there: no row of it is scored."""


NO_MOTOR = (0.0, 0.0, 0.0, 0.0)   # rk4_driven's ``motor`` when the motor model is off: the torque is the command


def gated_drive(u: float, motor, enabled: bool) -> Tuple[float, Tuple[float, float, float, float]]:
    """The command and the drive (:func:`~.plant.rk4_driven`'s ``u`` and ``motor``) of a period through the driver's
    gate (docs/theory.md 6.7 and 6.8): enabled, as they are; disabled or in fault, the driver's bridge is open, so no
    current flows (i = 0) whatever the back-EMF: (0.0, :data:`NO_MOTOR`), a torque of exactly zero.  Fed the zero
    command instead, the drive model would apply V = K_t w and, once the wheel turns faster than V_max / K_t,
    drive a braking current (up to I_max K_t) through a bridge that is meant to be open.  The batch simulator
    has no driver state machine (it always runs enabled) and calls :func:`~.plant.rk4_driven` as it is."""
    return (u, motor) if enabled else (0.0, NO_MOTOR)



@dataclass
class PlantBase:
    """The bookkeeping a simulated plant keeps per period (:class:`~.plant.PlantSim` and
    :class:`~.mujoco_plant.MujocoPlant` extend it; the physics is theirs): the true state ``x`` at t_k = k h, the
    clock, this period's D_w drawn from a seeded generator (Gaussian, clipped at 0; drawn in blocks, the same
    sequence for every backend), and what acted over the previous period (its torque, command, D_w, external
    wrench, the driver's gate)."""

    cfg: PlantConfig
    k: int = 0
    x: State = None   # type: ignore[assignment]  # None: cfg.initial; __post_init__ makes it a State
    D_w: float = 0.0                 # ground friction over the current period
    u_prev: float = 0.0              # the torque that acted over the previous period (0 at k = 0)
    u_cmd_prev: float = 0.0          # the command held over the previous period (the motor's input)
    saturation: int = 0              # the drive's worst saturation code over the previous period (core.plants.drive)
    D_w_prev: float = 0.0            # the previous period's D_w (period 0's at k = 0): a raw sample's instant
    extra_prev: Wrench = (0.0, 0.0)  # the external wrench held over the previous period
    enabled_prev: bool = True        # the driver was enabled over the previous period (its bridge closed)
    _rng: np.random.Generator = field(default=None, repr=False)   # type: ignore[assignment]  # set in __post_init__
    _noise: list = field(default_factory=list, repr=False)

    def __post_init__(self):
        self.x = State(*(float(v) for v in (self.cfg.initial if self.x is None else self.x)))
        self._rng = np.random.default_rng(self.cfg.seed)
        self.D_w = self.D_w_prev = self._draw_D_w()

    @property
    def t(self) -> float:
        return self.k * self.cfg.h

    def _draw_D_w(self) -> float:
        c = self.cfg
        if c.D_w_variance == 0.0:
            return c.D_w_mean
        if not self._noise:  # draw in blocks: the same sequence as one standard_normal() per period
            self._noise = self._rng.standard_normal(NOISE_BLOCK).tolist()[::-1]
        return D_w_of(c.D_w_mean, math.sqrt(c.D_w_variance), self._noise.pop())
