"""The plant interface: one contract for every simulated plant, its RK4 implementation, and the registry.

**The contract** (:class:`Plant`; a runner: the offline loop's :class:`~.loop.PlantSide`, hence ``mwip_sim``,
the ``plant_sim`` node's lockstep and realtime runners, :class:`mwip_ros.robot.sim.SimBackend`).  A plant is built
once, from its configuration, and then advanced one control period at a time; it has no other way in:

- construction: :func:`make_plant` ``(cfg)``, ``cfg`` a :class:`PlantConfig` (``mwip_ros.params.plant_config``):
  the true physical parameters, the control period h [s], the D_w noise's seed, the initial :class:`~.model.State`,
  the motor and its driver, and for a spatial plant the 3D model and the ground it rolls on (``cfg.mujoco``, a
  :class:`MujocoConfig`: ``slope`` [rad] about y, uphill ahead for > 0; ``bumps`` [x0, h0, ...] [m], steps across
  the path; ``friction``).  The terrain is a construction input: a plant on other ground is another ``cfg``.
- state, read at t_k = k h: :attr:`Plant.k`, :attr:`Plant.t` [s], :attr:`Plant.x` = (theta_w, theta_b,
  theta_w', theta_b') [rad, rad/s] (theta_w the wheel's absolute angle, on a spatial plant the mean of the two
  wheels'; theta_b the body's pitch from upright, positive as eq. 1 has it), :attr:`Plant.u_prev` [N m] the lumped
  torque that acted over [t_k-1, t_k), :attr:`Plant.saturation` the drive's worst code over it (:mod:`.drive`),
  :attr:`Plant.fallen` (|theta_b| beyond ``cfg.fall_angle``, or a state that is not finite).
- one period: :meth:`Plant.step` ``(u, extra, enabled)`` integrates [t_k, t_k+1) with the lumped torque u [N m]
  (eq. 1's u, already clipped; the drive's command when the motor model is on) held; ``extra``, the
  **external wrench** held over the period, is the one input for everything that pushes the robot (the
  configured tau_ext sinusoids are added to it): (tau_ext1 [N m] on the wheels' axis, tau_ext2 [N m] on the
  body's pitch axis[, force.y [N] on the body's centre of gravity along the heading frame's y (REP-103: left),
  torque.z [N m] about the vertical]); the last two act on a spatial plant only (``plant_sim``'s
  ``external_wrench``, :class:`~.loop.Period`'s ``wrench``, the terrain scan's push: :mod:`mwip_ros.sweep.terrain`).
  ``enabled`` False: the driver's bridge is open over the period, no torque at all (:func:`gated_drive`).  A
  simulation that diverges raises :class:`PlantDiverged` and leaves ``x`` at t_k.  :meth:`Plant.lie` is the
  period of a fallen robot lying still (nothing integrated, no torque, no wrench).
- what the runner records and senses, at t_k: :meth:`Plant.lumped_disturbance` ``(u, extra)`` the true tau_d
  (eq. 6-7) [N m] with u applied (NaN on a spatial plant while a wheel is off the ground);
  :meth:`Plant.sample_accel` (theta_w'', theta_b'') [rad/s^2] at t_k^-, a raw sample's instant (docs/theory.md
  6.4); :attr:`Plant.integration`, in words (the node's start line).
- frames: the planar state is along the path (the slope's plane on sloped ground).  ``spatial`` says whether the
  plant has a 3D pose: then :attr:`Plant.pose` is the :class:`Pose` at t_k (the axle's centre (x, y, z) [m] in
  the world frame, REP-103: x forward at the start, z up; yaw, pitch, roll [rad]; each wheel's absolute angle
  [rad]) and the plant is a :class:`SpatialPlant`: the body's yaw rate [rad/s] about its own z, the IMU's
  reading in the body frame (x forward, y left: the pitch axis, z up), and each wheel's torque (u_L, u_R) [N m]
  (``wheels=``, the yaw stage's pair, docs/theory.md 6.13) instead of u / 2 each.

**The implementations.**  :class:`PlantSim` (``backend: rk4``, alias :data:`RK4Plant`), in this module: eq. (1)
integrated with classic RK4 in ``substeps`` equal sub-steps per period, ``u`` and ``D_w`` held over the period and
tau_ext evaluated at each stage time; planar.  :class:`~.mujoco_plant.MujocoPlant` (``backend: mujoco``), in
:mod:`.mujoco_plant`: the 3D model in MuJoCo (docs/theory.md 6.10); spatial.  Both extend
:class:`~.plant_base.PlantBase` (:mod:`.plant_base`: the configuration, the pose, the error, the driver's gate and
the bookkeeping of a period, with ``D_w`` drawn once per period from one seeded generator, Gaussian clipped at 0,
so both see the same friction).  :data:`PLANTS` maps a backend's name to its class, read-only: a new physics is a
new module implementing :class:`Plant` and one more entry there, not a subclass of a plant, and nothing registers
a plant at run time.  The batch simulators (:mod:`.batch`, :mod:`.compiled`, ``mwip_ros.envs.lanes``) run
:func:`rk4_driven` on arrays of scenarios, not through this interface; the lockstep oracle tests keep them equal
to :class:`PlantSim` bit for bit.

**The robot one level up.**  ``mwip_ros/robot/backend.py``'s :class:`~mwip_ros.robot.backend.Backend` is the same
idea where the robot is a device: four methods as Upkie's backends (``observe``, ``reset``, ``step(command)``,
``close``), a :class:`~mwip_ros.robot.backend.Command` of per-wheel torques [N m] in and an
:class:`~mwip_ros.robot.backend.Observation` (each wheel as its servo reads it, the IMU in ``imu_link``) out.
``mwip_ros/robot/sim.py``'s :class:`~mwip_ros.robot.sim.SimBackend` puts any plant of :data:`PLANTS` behind it
(through :class:`~.loop.PlantSide`: the sensors, the drive, the driver's state machine): its ``reset`` is a fresh
:func:`make_plant`, its ``step`` is :meth:`Plant.step` between the drive's stage and the sensors'; the devices
(``robot/mock.py``, ``robot/upkie.py``, ``robot/moteus_backend.py``) implement it directly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Callable, ClassVar, Mapping, Optional, Protocol, Tuple, runtime_checkable

from .drive import motor_torque
from .model import PhysicalParams, Sinusoid, State, accel, lumped_disturbance
from .mujoco_plant import MujocoPlant
from .plant_base import (NO_MOTOR, D_w_of, per_wheel, MujocoConfig, PlantBase, PlantConfig, PlantDiverged, Pose, Wrench,
                         finite_state, gated_drive)

__all__ = ["Plant", "PLANTS", "make_plant", "PlantConfig", "MujocoConfig", "PlantBase", "PlantSim", "RK4Plant",
           "stage_torques", "rk4_period", "rk4_driven", "NO_MOTOR", "saturate", "per_wheel", "D_w_of", "gated_drive",
           "finite_state", "PlantDiverged", "Pose", "SpatialPlant", "Wrench"]


def saturate(u: float, limit: float) -> float:
    """Apply ``torque_limit`` (0 = no limit).  NaN stays NaN (``max(-limit, min(limit, nan))`` gave +limit: a command
    that is not a number read as full torque); the driver refuses it (core.closed_loop.loop.PlantSide.act)."""
    if limit > 0.0:
        return -limit if u < -limit else (limit if u > limit else u)
    return u


@runtime_checkable
class Plant(Protocol):
    """What a runner needs of a plant: the contract of the module docstring (its units and frames).  The state at
    t_k = k h, the torque that acted over the previous period, one period's integration with the torque and the
    external wrench held, the true lumped disturbance; :class:`PlantSim` and :class:`~.mujoco_plant.MujocoPlant`
    implement it, :data:`PLANTS` names them.  :meth:`step` raises :class:`PlantDiverged` when the simulation
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

    def step(self, u: float, extra: Wrench = (0.0, 0.0), enabled: bool = True) -> None: ...

    def lumped_disturbance(self, u: float, extra: Wrench = (0.0, 0.0)) -> Tuple[float, float]: ...

    def lie(self) -> None: ...


class SpatialPlant(Plant, Protocol):
    """A :class:`Plant` whose ``spatial`` is True (:class:`~.mujoco_plant.MujocoPlant`): the body's yaw rate [rad/s]
    about its own z, the IMU's reading in the body frame (angular velocity [rad/s], specific force [m/s^2]) and the
    wheels' own torques (u_L, u_R) [N m] (docs/theory.md 6.13, 6.4)."""

    @property
    def yaw_rate(self) -> float: ...

    def imu_reading(self) -> Tuple[Tuple[float, ...], Tuple[float, ...]]: ...

    def lumped_disturbance(self, u: float, extra: Wrench = (0.0, 0.0), wheels=None) -> Tuple[float, float]: ...

    def step(self, u: float, extra: Wrench = (0.0, 0.0), enabled: bool = True, wheels=None) -> None: ...


@dataclass
class PlantSim(PlantBase):
    """The RK4 plant of eq. (1) (module docstring): the true state ``x`` (a :class:`State`) at t_k = k h.

    The state is four Python floats: the plant evaluates eq. (1) 4 x ``substeps``
    times per period, on scalars rather than 4-element numpy arrays (the cheaper of
    the two for so few numbers).
    """

    spatial: ClassVar[bool] = False  # planar: no 3D pose
    pose: ClassVar[Optional[Pose]] = None

    @property
    def integration(self) -> str:
        return f"{self.cfg.substeps} RK4 sub-steps of eq. (1)"

    @property
    def fallen(self) -> bool:
        """|theta_b| beyond the fall angle, or the state not a number (diverged: NaN or infinite; never upright)."""
        return not (abs(self.x[1]) <= self.cfg.fall_angle and finite_state(self.x))

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


def rk4_period(p: PhysicalParams, D_w, D_b, tau1, tau2, x, u, h: float, n: int, m=math) -> Tuple:
    """The state after one control period [t0, t0 + h] with the torque ``u`` held (the motor model off):
    :func:`rk4_driven` without a motor.  The batch simulator runs this same function compiled by numba, once
    per scenario (``core.kernels.compiled``), which is why it takes the stage torques as numbers and not the
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
    ``m`` is the math namespace of :func:`~.model.accel` (``core.kernels.compiled`` also runs it on SIMD lanes of
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

# backend -> its plant class; read-only: a backend is a module implementing Plant and one entry here (module docstring)
PLANTS: Mapping[str, Callable[[PlantConfig], Plant]] = MappingProxyType({"rk4": PlantSim, "mujoco": MujocoPlant})


def make_plant(cfg: PlantConfig, backend: Optional[str] = None) -> Plant:
    """A fresh plant at the initial state of ``cfg`` (``backend``: a key of :data:`PLANTS`; None: ``cfg.backend``).
    MuJoCo itself is imported when its plant is built (:func:`.mujoco_plant.mujoco_module`), not before."""
    backend = cfg.backend if backend is None else backend
    try:
        cls = PLANTS[backend]
    except KeyError:
        raise ValueError(f"unknown plant backend {backend!r}; known: {', '.join(sorted(PLANTS))}") from None
    return cls(cfg)
