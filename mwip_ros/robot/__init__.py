"""The robot side (no ROS): one small interface, :class:`~.backend.Backend`, and what stands behind it
(docs/hardware.md). Simulators, mock wheels and real devices share the interface; the node that owns the robot's
clock drives whichever is chosen."""
from .backend import Backend, BackendError, Command, Imu, Observation, Wheel, finite_command

__all__ = ["Backend", "BackendError", "Command", "Imu", "Observation", "Wheel", "finite_command"]
