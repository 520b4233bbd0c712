"""The robot side behind one small interface: what the node that owns the robot's clock reads and writes.

A :class:`Backend` is four methods, as Upkie's ``upkie.envs.backends.Backend`` is (``get_spine_observation``,
``reset``, ``step``, ``close``): :meth:`Backend.observe`, :meth:`Backend.reset`, :meth:`Backend.step` and
:meth:`Backend.close`. Behind it: a simulator the project wrote (rk4 of eq. 1, MuJoCo), ros2_control-style mock
wheels, Upkie through the ``upkie`` package's own backends, moteus controllers through mjbots' ``moteus`` package.

Conventions (SPEC section 16, docs/hardware.md):

- a wheel is read as its servo measures it: its angle relative to the body (phi = theta_w - theta_b), its rate and
  its torque, each in the robot's forward sense (a backend applies its robot's joint signs: on Upkie forward
  rolling is +phi_L and -phi_R);
- a :class:`Command` is the torque of each wheel [N m], forward positive; eq. (1)'s lumped u is their sum (each
  wheel u/2 without yaw, u/2 -+ u_psi/2 with it);
- an IMU reading is in REP-145's ``imu_link`` axes (REP-103: x forward, y left, z up): the angular velocity
  [rad/s] and the proper acceleration [m/s^2] (what an accelerometer reads: (0, 0, +g) at rest, upright);
- ``time`` is the backend's own clock at the read [s]: simulated time for a simulator, ``time.monotonic()`` for
  a device.

A simulated backend (:attr:`Backend.simulated`) advances only in :meth:`Backend.step`, so it can run in
lockstep; a device runs on the wall clock, and the node paces it. ``step(None)`` is a stop: no torque, and on a
device its own stop command (moteus ``make_stop``), sent first when anything goes wrong (Upkie's stop-first
rule). A device's own fault (a fault code, an over-temperature, a controller that does not answer) comes back in
:attr:`Observation.fault`; the node hands it to the driver's state machine (:mod:`mwip_ros.core.control.safety`) as the
fault's reason. This module imports no ROS.
"""
from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import ClassVar, Optional, Tuple

__all__ = ["Wheel", "Imu", "Observation", "Command", "Backend", "BackendError", "finite_command"]

Vector3 = Tuple[float, float, float]


class BackendError(RuntimeError):
    """A backend cannot start or go on (a device path that does not open, a package that is missing, a
    simulation that diverged); the message is one line naming the backend and the cause."""


@dataclass(frozen=True)
class Wheel:
    """One wheel as its servo measures it, in the robot's forward sense."""

    position: float   # phi [rad]: the wheel's angle relative to the body (theta_w - theta_b)
    velocity: float   # phi' [rad/s]
    torque: float     # [N m]: the torque the servo reports (a simulator: the torque that acted)


@dataclass(frozen=True)
class Imu:
    """One IMU sample in ``imu_link``'s axes (REP-145)."""

    angular_velocity: Vector3       # [rad/s]
    linear_acceleration: Vector3    # [m/s^2], proper acceleration


@dataclass(frozen=True)
class Observation:
    """What one read of the robot gives.

    ``imu`` is None when the backend has no IMU of its own (on a moteus robot the IMU is read by its own driver and
    published at its own rate). ``fault`` is None while every device is healthy, else one line naming the device
    and its fault. ``truth`` is a simulator's true planar state (theta_w, theta_b, theta_w', theta_b'), None on a
    device. ``stale`` is True when a device did not answer this exchange and a wheel reads its last answer (a
    moteus reply lost): that read is no sample of ``time`` (published with it, the state estimator would take the
    wheels as standing still since their answer), so the driver publishes no ``wheel_encoder`` for it."""

    time: float
    left: Wheel
    right: Wheel
    imu: Optional[Imu] = None
    fault: Optional[str] = None
    truth: Optional[Tuple[float, float, float, float]] = None
    stale: bool = False

    @property
    def phi(self) -> float:
        """The lumped wheel angle relative to the body [rad]: the mean of both wheels."""
        return 0.5 * (self.left.position + self.right.position)

    @property
    def phi_rate(self) -> float:
        """Its rate [rad/s]."""
        return 0.5 * (self.left.velocity + self.right.velocity)

    @property
    def torque(self) -> float:
        """The lumped torque u [N m] (eq. 1): both wheels together."""
        return self.left.torque + self.right.torque


@dataclass(frozen=True)
class Command:
    """The torque of each wheel [N m], forward positive."""

    left: float
    right: float

    @classmethod
    def lumped(cls, u: float, u_psi: float = 0.0) -> "Command":
        """Eq. (1)'s u split over the two wheels, with the yaw stage's u_psi (SPEC 15-16): (u - u_psi) / 2 on the
        left wheel, (u + u_psi) / 2 on the right."""
        return cls(0.5 * (u - u_psi), 0.5 * (u + u_psi))


def finite_command(command: Optional[Command], limit: float) -> bool:
    """Whether ``command`` may be written: both torques finite and within ``limit`` [N m] (a stop, None, always
    may)."""
    if command is None:
        return True
    return all(math.isfinite(v) and abs(v) <= limit for v in (command.left, command.right))


class Backend(abc.ABC):
    """The robot side: read it, reset it, write a command and take the next read, close it.

    Subclasses set :attr:`name` (the ``backend`` parameter's value) and :attr:`simulated`."""

    name: ClassVar[str] = ""
    simulated: ClassVar[bool] = False   # True: time advances only in step() (lockstep possible)

    @abc.abstractmethod
    def observe(self) -> Observation:
        """Read the robot now, changing nothing (a device: a query; a simulator: its current sample)."""

    @abc.abstractmethod
    def reset(self) -> Observation:
        """Back to the initial state (a simulator) or to a known one (a device: stopped, faults cleared where the
        device allows), and the first read."""

    @abc.abstractmethod
    def step(self, command: Optional[Command]) -> Observation:
        """Write ``command`` (None: stop) and return the next read. A simulator integrates one period first; a
        device writes and reads in its own round trip, and the node keeps the period."""

    @abc.abstractmethod
    def close(self) -> None:
        """Stop first (no torque; a device's own stop), then release what the backend holds. Idempotent."""

    def __enter__(self) -> "Backend":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
