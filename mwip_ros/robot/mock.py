"""Mock wheels for checking the wiring: :class:`MockBackend`, commands mirrored into states as ros2_control's mock
components do.

ros2_control's ``mock_components/GenericSystem`` (hardware_interface, ``GenericSystem::read``) copies each command
interface's value into the state interface of the same name, skipping a command that is NaN (the state keeps its
value); a joint's position changes only through a position command (integrated from a velocity or acceleration
command only with ``calculate_dynamics``), so a joint commanded in effort keeps the position and velocity it started
with, and its effort state is the effort command.  Its ``disable_commands`` parameter stops the mirroring (a
driver that is disconnected).  This backend is that system for two wheels commanded in torque:

- each wheel's ``torque`` state is its last finite torque command (a NaN or infinite one leaves it as it was), 0 after
  a stop (``step(None)``) and at the start;
- each wheel's ``position`` and ``velocity`` are the configured initial values, always (nothing moves);
- with ``disable_commands`` nothing is mirrored (every state keeps its initial value);
- the IMU reads a robot at rest and upright (REP-145 ``imu_link``: no rotation, a proper acceleration (0, 0, +g)),
  or nothing (``imu=False``: a robot whose IMU has its own driver);
- its clock advances by the period ``h`` at each :meth:`MockBackend.step` (:attr:`MockBackend.simulated`: lockstep
  is possible); it has no truth and no fault.

So a graph run against it shows each command arrive, with its sign and its wheel, in the encoders' effort, and
nothing else happening: what the mock is for.  No ROS here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Tuple

from .backend import Backend, Command, Imu, Observation, Wheel

__all__ = ["MockConfig", "MockBackend"]


@dataclass(frozen=True)
class MockConfig:
    """The mock's settings.

    Parameters
    ----------
    h : float
        The period one step advances the clock by [s] (> 0).
    position : tuple of 2 floats
        Each wheel's (left, right) angle relative to the body [rad], held.
    velocity : tuple of 2 floats
        Each wheel's rate [rad/s], held.
    imu : bool
        Whether the mock has an IMU (at rest, upright).
    g : float
        Gravity [m/s^2]: what the IMU's z axis reads.
    disable_commands : bool
        ros2_control's ``disable_commands``: no command is mirrored.
    """

    h: float = 0.005
    position: Tuple[float, float] = (0.0, 0.0)
    velocity: Tuple[float, float] = (0.0, 0.0)
    imu: bool = True
    g: float = 9.81
    disable_commands: bool = False

    def __post_init__(self):
        if not (math.isfinite(self.h) and self.h > 0.0):
            raise ValueError(f"mock: h must be a finite period > 0 s, got {self.h!r}")
        for name in ("position", "velocity"):
            if len(getattr(self, name)) != 2 or not all(math.isfinite(v) for v in getattr(self, name)):
                raise ValueError(f"mock: {name} must be two finite numbers (left, right), got {getattr(self, name)!r}")


class MockBackend(Backend):
    """Two wheels whose torque state mirrors the torque command (module docstring).

    Parameters
    ----------
    cfg : MockConfig
        The mock's settings.
    """

    name = "mock"
    simulated = True

    def __init__(self, cfg: MockConfig = MockConfig()):
        self.cfg = cfg
        self.reset()

    def observe(self) -> Observation:
        """The states now."""
        c = self.cfg
        imu = Imu((0.0, 0.0, 0.0), (0.0, 0.0, c.g)) if c.imu else None
        return Observation(time=self.k * c.h,
                           left=Wheel(c.position[0], c.velocity[0], self.torque[0]),
                           right=Wheel(c.position[1], c.velocity[1], self.torque[1]), imu=imu)

    def reset(self) -> Observation:
        """The initial states (no torque), time 0."""
        self.k = 0
        self.torque = (0.0, 0.0)
        return self.observe()

    def step(self, command: Optional[Command]) -> Observation:
        """Mirror ``command`` into the torque states (None: a stop, no torque), advance the clock by one period.

        Parameters
        ----------
        command : Command or None
            Each wheel's torque [N m]; a value that is not finite leaves that wheel's state unchanged.

        Returns
        -------
        Observation
            The states after the period.
        """
        if not self.cfg.disable_commands:
            if command is None:
                self.torque = (0.0, 0.0)
            else:
                self.torque = tuple(new if math.isfinite(new) else old
                                    for new, old in zip((command.left, command.right), self.torque))
        self.k += 1
        return self.observe()

    def close(self) -> None:
        """Nothing to release (idempotent)."""
