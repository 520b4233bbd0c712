"""The true plant as a discrete-time stepper (docs/theory.md: the plant and discrete time).

``PlantSim`` integrates eq. (1) with classic RK4 in ``substeps`` equal sub-steps
per control period, holding ``u`` and ``D_w`` over the period and evaluating
tau_ext at each stage time.  ``D_w`` is drawn once per period from a seeded
generator (Gaussian, clipped at 0).  The offline simulator and the
``plant_sim`` node both drive this class, so they integrate the same numbers.
A period integrated with the driver not enabled (docs/theory.md 6.8) has its bridge open:
no current, no torque, whatever the command or the wheel's speed (:func:`gated_drive`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, ClassVar, Dict, NamedTuple, Optional, Protocol, Tuple, runtime_checkable

import numpy as np

from .drive import MotorConfig, motor_torque
from .model import PhysicalParams, Sinusoid, State, accel, lumped_disturbance
from .raw_sensors import RawSensorConfig
from .sensing import NOISE_BLOCK, SensingConfig

if TYPE_CHECKING:   # for the annotations only: importing it here would import mujoco_plant with every plant
    from .mujoco_plant import MujocoConfig

__all__ = ["Plant", "PLANTS", "make_plant", "PlantConfig", "PlantSim", "RK4Plant", "stage_torques", "rk4_period",
           "rk4_driven", "NO_MOTOR", "saturate", "per_wheel", "D_w_of", "gated_drive", "finite_state", "PlantDiverged",
           "Pose", "SpatialPlant"]


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
    sensing: SensingConfig = SensingConfig()   # measurement noise, encoder, delays (core.sensing); off
    raw: Optional[RawSensorConfig] = None      # sensors.model raw: the IMU and the relative encoder (theory.md 6.4)
    motor: MotorConfig = MotorConfig()         # the DC motor and its driver (docs/theory.md 6.7); off
    require_enable: bool = False               # the driver starts disabled (docs/theory.md 6.8)
    backend: str = "rk4"                       # a key of PLANTS: rk4 (eq. 1, this module) or mujoco (theory.md 6.10)
    mujoco: Optional[MujocoConfig] = None      # the MuJoCo model's own values (core.mujoco_plant.MujocoConfig)

    @property
    def motor_constants(self) -> Tuple[float, float, float, float]:
        """(K_t, R, V_max, I_max) for :func:`rk4_driven`, or :data:`NO_MOTOR` when the motor is off."""
        mc = self.motor
        return (mc.torque_constant, mc.resistance, mc.voltage_limit, mc.current_limit) if mc.enabled else NO_MOTOR


def finite_state(x) -> bool:
    """Every component of the state ``x`` is a finite number (a run whose state is not has diverged)."""
    return all(math.isfinite(v) for v in x)


def D_w_of(mean: float, sd: float, z: float) -> float:
    """The wheel friction of one period from its standard normal draw ``z``: Gaussian, clipped at 0 (table II)."""
    return max(0.0, mean + sd * z)


def per_wheel(lumped: float) -> float:
    """A wheel's share [N m] of a lumped torque (a ``torque_limit``, a motor's peak): half, each wheel drives u / 2;
    0 stays 0 (no limit)."""
    return 0.5 * lumped


def saturate(u: float, limit: float) -> float:
    """Apply ``torque_limit`` (0 = no limit).  NaN stays NaN (``max(-limit, min(limit, nan))`` gave +limit: a command
    that is not a number read as full torque); the driver refuses it (core.loop.PlantSide.act)."""
    if limit > 0.0:
        return -limit if u < -limit else (limit if u > limit else u)
    return u


class Pose(NamedTuple):
    """A spatial plant's 3D pose at t_k (:attr:`Plant.pose`): the axle's centre (x, y, z) [m], the body's yaw, pitch
    (theta_b) and roll [rad] (REP-103: x forward, z up), each wheel's absolute angle [rad]."""

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


@runtime_checkable
class Plant(Protocol):
    """What a runner needs of a plant (the offline loop, the ``plant_sim`` node's lockstep and realtime runners):
    the true state at t_k = k h, the torque that acted over the previous period, one period's integration, and the
    true lumped disturbance.  :class:`PlantSim` (RK4 of eq. 1) implements it, and so does
    :class:`~.mujoco_plant.MujocoPlant` (MuJoCo, docs/theory.md 6.10); a backend is one more entry in :data:`PLANTS`.

    ``spatial`` says whether the plant has a 3D pose: then :attr:`pose` is the :class:`Pose` at t_k (the runners
    record :data:`.trajectory.POSE_COLUMNS` and publish it), else None.  ``integration`` says in words how a period is
    integrated (the node's start line).  :meth:`step` raises :class:`PlantDiverged` when the simulation
    diverges."""

    cfg: PlantConfig
    k: int
    x: State
    u_prev: float
    saturation: int
    spatial: ClassVar[bool]

    @property
    def pose(self) -> Optional[Pose]: ...   # read here: a class constant (planar) or a field (spatial)

    @property
    def integration(self) -> str: ...

    @property
    def t(self) -> float: ...

    @property
    def fallen(self) -> bool: ...

    def sample_accel(self) -> Tuple[float, float]: ...

    def step(self, u: float, extra=(0.0, 0.0), enabled: bool = True) -> None: ...

    def lumped_disturbance(self, u: float, extra=(0.0, 0.0)) -> Tuple[float, float]: ...

    def lie(self) -> None: ...


class SpatialPlant(Plant, Protocol):
    """A :class:`Plant` whose ``spatial`` is True (:class:`~.mujoco_plant.MujocoPlant`): the body's yaw rate and the
    IMU's reading too (docs/theory.md 6.13, 6.4)."""

    @property
    def yaw_rate(self) -> float: ...

    def imu_reading(self) -> Tuple[Tuple[float, ...], Tuple[float, ...]]: ...

    def lumped_disturbance(self, u: float, extra=(0.0, 0.0), wheels=None) -> Tuple[float, float]: ...

    def step(self, u: float, extra=(0.0, 0.0), enabled: bool = True, wheels=None) -> None: ...


@dataclass
class PlantSim:
    """The true state ``x`` (a :class:`State`) at t_k = k h.

    The state is four Python floats: the plant evaluates eq. (1) 4 x ``substeps``
    times per period, on scalars rather than 4-element numpy arrays (the cheaper of
    the two for so few numbers).
    """

    cfg: PlantConfig
    k: int = 0
    x: State = None   # type: ignore[assignment]  # None: cfg.initial; __post_init__ makes it a State
    D_w: float = 0.0                 # ground friction over the current period
    u_prev: float = 0.0              # the torque that acted over the previous period (0 at k = 0)
    u_cmd_prev: float = 0.0          # the command held over the previous period (the motor's input)
    saturation: int = 0              # the drive's worst saturation code over the previous period (core.drive)
    D_w_prev: float = 0.0            # the previous period's D_w (period 0's at k = 0): a raw sample's instant
    extra_prev: Tuple[float, ...] = (0.0, 0.0)   # the external wrench held over the previous period
    enabled_prev: bool = True        # the driver was enabled over the previous period (its bridge closed)
    _rng: np.random.Generator = field(default=None, repr=False)   # type: ignore[assignment]  # set in __post_init__
    _noise: list = field(default_factory=list, repr=False)
    spatial: ClassVar[bool] = False  # planar: no 3D pose
    pose: ClassVar[Optional[Pose]] = None

    def __post_init__(self):
        self.x = State(*(float(v) for v in (self.cfg.initial if self.x is None else self.x)))
        self._rng = np.random.default_rng(self.cfg.seed)
        self.D_w = self.D_w_prev = self._draw_D_w()

    @property
    def t(self) -> float:
        return self.k * self.cfg.h

    @property
    def integration(self) -> str:
        return f"{self.cfg.substeps} RK4 sub-steps of eq. (1)"

    @property
    def fallen(self) -> bool:
        """|theta_b| beyond the fall angle, or the state not a number (diverged: NaN or infinite; never upright)."""
        return not (abs(self.x[1]) <= self.cfg.fall_angle and finite_state(self.x))

    def _draw_D_w(self) -> float:
        c = self.cfg
        if c.D_w_variance == 0.0:
            return c.D_w_mean
        if not self._noise:  # draw in blocks: the same sequence as one standard_normal() per period
            self._noise = self._rng.standard_normal(NOISE_BLOCK).tolist()[::-1]
        return D_w_of(c.D_w_mean, math.sqrt(c.D_w_variance), self._noise.pop())

    def tau_ext(self, t: float, extra: Tuple[float, ...] = (0.0, 0.0)) -> Tuple[float, float]:
        return self.cfg.tau_ext1(t) + extra[0], self.cfg.tau_ext2(t) + extra[1]

    def accel(self, t: float, x, u: float, extra=(0.0, 0.0)) -> Tuple[float, float]:
        """True (theta_w'', theta_b'') at time t, state x, torque u, this period's D_w."""
        e1, e2 = self.tau_ext(t, extra)
        return accel(self.cfg.actual, self.D_w, self.cfg.D_b, x, u, e1, e2)

    def lumped_disturbance(self, u: float, extra=(0.0, 0.0)) -> Tuple[float, float]:
        """True tau_d at t_k with u_k applied (what the observer should estimate)."""
        ddq = self.accel(self.t, self.x, u, extra)
        return lumped_disturbance(self.cfg.nominal, self.x, ddq, u)

    def sample_accel(self) -> Tuple[float, float]:
        """(theta_w'', theta_b'') at t_k^-, the instant of a raw sample (theory 6.4): eq. (1) at x_k and t_k with what
        acted over the previous period (its torque, its D_w, its external wrench) and tau_ext(t_k); at k = 0 zero
        torque, the D_w of period 0 and no wrench."""
        c = self.cfg
        e1, e2 = self.tau_ext(self.t, self.extra_prev)
        u = self.u_prev
        if c.motor.enabled and self.k > 0 and self.enabled_prev:   # the motor's torque at x_k for the previous command
            u = motor_torque(self.u_cmd_prev, self.x[2] - self.x[3], *c.motor_constants)[0]
        return accel(c.actual, self.D_w_prev, c.D_b, self.x, u, e1, e2)

    def step(self, u: float, extra=(0.0, 0.0), enabled: bool = True) -> None:
        """Integrate t_k -> t_{k+1} with the command u (already saturated) and D_w held; RK4, ``substeps`` steps;
        with the motor model on, the drive turns u into the torque at every stage (:func:`rk4_driven`).
        ``enabled`` False: the driver is disabled or in fault over this period, its bridge open
        (:func:`gated_drive`): no torque at all."""
        c = self.cfg
        tau1, tau2 = stage_torques(c.tau_ext1, c.tau_ext2, extra, self.t, c.h, c.substeps)
        u, motor = gated_drive(u, c.motor_constants, enabled)
        w, b, dw, db, acted, self.saturation = rk4_driven(c.actual, self.D_w, c.D_b, tau1, tau2, self.x, u, c.h,
                                                          c.substeps, motor)
        self.x = State(w, b, dw, db)
        self.k += 1
        self.u_prev, self.u_cmd_prev, self.enabled_prev = acted, u, bool(enabled)
        self.D_w_prev, self.extra_prev = self.D_w, (float(extra[0]), float(extra[1]))
        self.D_w = self._draw_D_w()


    def lie(self) -> None:
        """A period of a fallen robot lying where it fell (``plant_sim``, ``exit_on_fall: false``: the model has no
        ground, its body would swing through the floor): t_k -> t_{k+1} at rest, nothing integrated, no rate and
        no torque, no wrench acting (what a sample at t_{k+1}^- sees: :meth:`sample_accel`)."""
        self.x = State(self.x[0], self.x[1], 0.0, 0.0)
        self.k += 1
        self.u_prev = self.u_cmd_prev = 0.0
        self.saturation, self.enabled_prev = 0, False
        self.extra_prev = (0.0, 0.0)


def stage_torques(f1: Sinusoid, f2: Sinusoid, extra, t0: float, h: float, n: int, m=math):
    """tau_ext1 and tau_ext2 (``f1``, ``f2`` plus ``extra``) at the 2n + 1 times RK4 evaluates them over the period
    [t0, t0 + h] in ``n`` sub-steps: t0, then each sub-step's midpoint and end."""
    dt = h / n
    times = [t0]
    for i in range(n):
        times += [t0 + (i + 0.5) * dt, t0 + (i + 1) * dt]
    return [f1.at(t, m) + extra[0] for t in times], [f2.at(t, m) + extra[1] for t in times]


NO_MOTOR = (0.0, 0.0, 0.0, 0.0)   # rk4_driven's ``motor`` when the motor model is off: the torque is the command


def gated_drive(u: float, motor, enabled: bool) -> Tuple[float, Tuple[float, float, float, float]]:
    """The command and the drive (:func:`rk4_driven`'s ``u`` and ``motor``) of a period through the driver's gate
    (docs/theory.md 6.7 and 6.8): enabled, as they are; disabled or in fault, the driver's bridge is open, so no
    current flows (i = 0) whatever the back-EMF: (0.0, :data:`NO_MOTOR`), a torque of exactly zero.  Fed the zero
    command instead, the drive model would apply V = K_t w and, once the wheel turns faster than V_max / K_t,
    drive a braking current (up to I_max K_t) through a bridge that is meant to be open.  The batch simulator
    has no driver state machine (it always runs enabled) and calls :func:`rk4_driven` as it is."""
    return (u, motor) if enabled else (0.0, NO_MOTOR)


def rk4_period(p: PhysicalParams, D_w, D_b, tau1, tau2, x, u, h: float, n: int, m=math) -> Tuple:
    """The state after one control period [t0, t0 + h] with the torque ``u`` held (the motor model off):
    :func:`rk4_driven` without a motor.  The batch simulator runs this same function compiled by numba, once
    per scenario (``core.compiled``), which is why it takes the stage torques as numbers and not the
    ``Sinusoid`` objects."""
    w, b, dw, db, _, _ = rk4_driven(p, D_w, D_b, tau1, tau2, x, u, h, n, NO_MOTOR, m)
    return w, b, dw, db


def rk4_driven(p: PhysicalParams, D_w, D_b, tau1, tau2, x, u, h: float, n: int, motor, m=math) -> Tuple:
    """One control period [t0, t0 + h]: classic RK4 of eq. (1) in ``n`` equal sub-steps, the command ``u`` and
    D_w held; ``tau1[j]``, ``tau2[j]`` are tau_ext at stage time j (:func:`stage_torques`).

    ``motor`` = (K_t, R, V_max, I_max) of the drive (theory.md 6.7, :func:`.drive.motor_torque`), evaluated at every
    stage from that stage's state (w = th_w' - th_b'); :data:`NO_MOTOR` (K_t = 0): the torque is ``u`` at every
    stage (the paper's numbers; the drive's branch is not entered, so the loop costs what it did without a
    motor).  Returns (theta_w, theta_b, theta_w', theta_b', the torque that acted over the period, the drive's
    worst saturation code): the torque that acted is the RK4-weighted mean of the stage torques,
    ``sum (u1 + 2 u2 + 2 u3 + u4) / (6 n)`` (:func:`.drive.acted_torque`), and ``u`` itself without a motor.
    ``m`` is the math namespace of :func:`~.model.accel` (``core.compiled`` also runs it on SIMD lanes of
    scenarios, motorless)."""
    dt = h / n
    half, sixth = dt / 2, dt / 6
    w, b, dw, db = x
    driven = motor[0] > 0.0
    u1 = u2 = u3 = u4 = u
    acted = u * 0.0
    sat = 0
    for i in range(n):
        j = 2 * i   # stage times t, t + dt/2 (twice), t + dt
        if driven:
            u1, c = motor_torque(u, dw - db, motor[0], motor[1], motor[2], motor[3])
            sat = max(sat, c)
        a1w, a1b = accel(p, D_w, D_b, (w, b, dw, db), u1, tau1[j], tau2[j], m)                 # k1
        b2, dw2, db2 = b + half * db, dw + half * a1w, db + half * a1b
        if driven:
            u2, c = motor_torque(u, dw2 - db2, motor[0], motor[1], motor[2], motor[3])
            sat = max(sat, c)
        a2w, a2b = accel(p, D_w, D_b, (w, b2, dw2, db2), u2, tau1[j + 1], tau2[j + 1], m)      # k2
        b3, dw3, db3 = b + half * db2, dw + half * a2w, db + half * a2b
        if driven:
            u3, c = motor_torque(u, dw3 - db3, motor[0], motor[1], motor[2], motor[3])
            sat = max(sat, c)
        a3w, a3b = accel(p, D_w, D_b, (w, b3, dw3, db3), u3, tau1[j + 1], tau2[j + 1], m)      # k3
        b4, dw4, db4 = b + dt * db3, dw + dt * a3w, db + dt * a3b
        if driven:
            u4, c = motor_torque(u, dw4 - db4, motor[0], motor[1], motor[2], motor[3])
            sat = max(sat, c)
            acted = acted + (u1 + 2.0 * u2 + 2.0 * u3 + u4)
        a4w, a4b = accel(p, D_w, D_b, (w, b4, dw4, db4), u4, tau1[j + 2], tau2[j + 2], m)      # k4
        w = w + sixth * (dw + 2 * dw2 + 2 * dw3 + dw4)
        b = b + sixth * (db + 2 * db2 + 2 * db3 + db4)
        dw = dw + sixth * (a1w + 2 * a2w + 2 * a3w + a4w)
        db = db + sixth * (a1b + 2 * a2b + 2 * a3b + a4b)
    return w, b, dw, db, (acted / (6.0 * n) if driven else u), sat

RK4Plant = PlantSim


def _mujoco(cfg: PlantConfig) -> Plant:
    from .mujoco_plant import MujocoPlant   # imports mujoco: only when this backend is chosen
    return MujocoPlant(cfg)


PLANTS: Dict[str, Callable[[PlantConfig], Plant]] = {"rk4": PlantSim, "mujoco": _mujoco}   # backend -> Plant maker


def make_plant(cfg: PlantConfig, backend: Optional[str] = None) -> Plant:
    """A fresh plant at the initial state of ``cfg`` (``backend``: a key of :data:`PLANTS`; None: ``cfg.backend``)."""
    backend = cfg.backend if backend is None else backend
    try:
        cls = PLANTS[backend]
    except KeyError:
        known = ", ".join(sorted(b for b in PLANTS if not b.startswith("_")))   # "_name": a module's own, not a value
        raise ValueError(f"unknown plant backend {backend!r}; known: {known}") from None
    return cls(cfg)
