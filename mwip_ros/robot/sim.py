"""The project's own plants behind the robot's interface: :class:`SimBackend` (``backend: rk4`` or ``mujoco``).

A :class:`SimBackend` is a :class:`~mwip_ros.core.closed_loop.loop.PlantSide` (the plant of
:func:`~mwip_ros.core.plants.plant.make_plant`, its raw sensors and its drive stage) seen as a
:class:`~.backend.Backend`, so the offline loop, the ``plant_sim`` node and this backend integrate the same numbers.
Nothing of the physics or of the sensors is written here:

- :meth:`SimBackend.step` is the offline loop's stages ``drive`` and ``plant`` (:meth:`PlantSide.act` then
  :meth:`PlantSide.advance`) for u = left + right (eq. 1's lumped torque, SPEC 16); on a spatial plant (MuJoCo) the
  wheels' pair goes to :meth:`PlantSide.act` as the yaw stage's does (each wheel clipped to half of
  ``torque_limit``, docs/theory.md 6.13).  ``step(None)`` is a stop: the drive's bridge open for the period (no
  current, no torque, :func:`~mwip_ros.core.plants.plant.gated_drive`), through the plant side's own driver state
  machine (:mod:`mwip_ros.core.control.safety`);
- each read is stage ``sensors`` (:meth:`PlantSide.sense`) with raw sensors (docs/theory.md 6.4): the IMU's pitch
  gyro and specific force, and the relative encoder phi = theta_w - theta_b with its rate, delayed as the
  configuration says.  A configuration with ``sensors.model: state`` gets ideal raw sensors (the backend reads what
  a robot reads: an IMU and encoders).  On a spatial plant the IMU's z gyro is :meth:`PlantSide.sense_yaw_rate`;
- the wheels: on a planar plant both read the lumped encoder.  On a spatial plant each wheel is the lumped encoder
  plus its own deviation from the two wheels' mean, from the plant's hinges (phi_L,R = phi -+ delta with
  delta = (phi_R,true - phi_L,true) / 2 of the current state, likewise the rates): the mean of the two is the raw
  encoder exactly;
- a wheel's torque is what acted: planar, half the lumped torque as the encoder reports it (``wheel_encoder``'s
  effort); spatial, the pair that acted over the previous period;
- ``truth`` is the plant's true planar state (theta_w, theta_b, theta_w', theta_b') and ``time`` its simulated
  time k h.

A command that is not a finite number (or beyond :data:`~mwip_ros.core.control.safety.PLAUSIBLE_TORQUE`) faults the
plant side's driver (``bad_command``): zero torque from then on, and :attr:`Observation.fault` names it until
:meth:`SimBackend.reset`.  A simulation that diverges raises :class:`~.backend.BackendError`.  No ROS here.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

from mwip_ros.core.closed_loop.loop import PlantSide
from mwip_ros.core.plants.plant import PlantConfig, PlantDiverged, Pose, finite_state
from mwip_ros.core.plants.raw_sensors import RawSensorConfig
from mwip_ros.core.control.safety import FAULT

from .backend import Backend, BackendError, Command, Imu, Observation, Wheel

__all__ = ["SimBackend", "sim_config"]


def sim_config(cfg: PlantConfig) -> PlantConfig:
    """The plant configuration a :class:`SimBackend` runs: ``cfg`` with raw sensors (ideal ones when ``cfg`` has
    none) and its driver enabled from the start (``require_enable`` false: the node that drives the backend owns
    the robot's safety state machine; the plant side's own one only turns a stop or a bad command into an open
    bridge).

    Parameters
    ----------
    cfg : PlantConfig
        The plant of a parameter file (:func:`mwip_ros.params.plant_config`).

    Returns
    -------
    PlantConfig
        The same plant, read through raw sensors.
    """
    return replace(cfg, raw=cfg.raw if cfg.raw is not None else RawSensorConfig(), require_enable=False)


class SimBackend(Backend):
    """The plant of a :class:`~mwip_ros.core.plants.plant.PlantConfig` behind :class:`~.backend.Backend` (module
    docstring).

    Parameters
    ----------
    cfg : PlantConfig
        The plant (``backend`` rk4 or mujoco); its period ``h`` is what one :meth:`step` integrates.
    """

    name = "sim"
    simulated = True

    def __init__(self, cfg: PlantConfig):
        self.cfg = sim_config(cfg)
        self.side: Optional[PlantSide] = None
        self._last: Optional[Observation] = None
        self.reset()

    @property
    def plant(self):
        """The plant (:class:`~mwip_ros.core.plants.plant.Plant`) at the current read."""
        return self.side.plant

    def observe(self) -> Observation:
        """The read of the current period (taken once per period: the raw sensors draw their noise per read)."""
        return self._last

    def reset(self) -> Observation:
        """A fresh plant side at the configuration's initial state, time 0, and its first read."""
        self.side = PlantSide(self.cfg)
        self._last = self._read()
        return self._last

    def step(self, command: Optional[Command]) -> Observation:
        """Integrate one period with ``command`` (None: the bridge open), and read the next state.

        Parameters
        ----------
        command : Command or None
            Each wheel's torque [N m], forward positive; None: a stop.

        Returns
        -------
        Observation
            The read at t_{k+1}.
        """
        side = self.side
        t = side.plant.t
        if command is None:
            side.safety.disable(t)
            u_cmd, pair = 0.0, ((0.0, 0.0) if side.plant.spatial else None)
        else:
            side.safety.enable(t)   # refused (and the torque stays zero) once a bad command faulted it
            u_cmd = command.left + command.right
            pair = (command.left, command.right) if side.plant.spatial else None
        u, _ = side.act(u_cmd, wheels=pair)
        try:
            side.advance(u)
        except (PlantDiverged, ArithmeticError, ValueError) as exc:
            raise BackendError(f"sim: the simulation diverged at t = {t:.3f} s: {exc}") from exc
        if not finite_state(side.plant.x):
            raise BackendError(f"sim: the simulation diverged at t = {t:.3f} s: a state that is not finite")
        self._last = self._read()
        return self._last

    def close(self) -> None:
        """Nothing to release (idempotent)."""

    def true_pose(self) -> Optional[Pose]:
        """A spatial plant's 3D pose at the current read (MuJoCo: :attr:`Plant.pose`); None on the planar plant."""
        return self.side.plant.pose if self.side.plant.spatial else None

    def _read(self) -> Observation:
        """Stage ``sensors`` of the current period as an :class:`~.backend.Observation` (module docstring)."""
        side, p = self.side, self.side.plant
        sample, u_m = side.sense()
        gyro_z = side.sense_yaw_rate() if p.spatial else 0.0
        imu = Imu((0.0, sample.gyro, gyro_z), (sample.accel_x, 0.0, sample.accel_z))
        if p.spatial:
            q, v = p.pose, p.wheel_rates   # each wheel's absolute angle and rate; the hinge is it minus the pitch
            d_pos = 0.5 * ((q.wheel_right - q.pitch) - (q.wheel_left - q.pitch))
            d_vel = 0.5 * (v[1] - v[0])
            tl, tr = p.wheels_prev if p.wheels_prev is not None else (0.5 * u_m, 0.5 * u_m)
            left = Wheel(sample.encoder - d_pos, sample.encoder_rate - d_vel, tl)
            right = Wheel(sample.encoder + d_pos, sample.encoder_rate + d_vel, tr)
        else:
            left = right = Wheel(sample.encoder, sample.encoder_rate, 0.5 * u_m)
        fault = None
        if side.safety.state == FAULT:
            fault = f"sim: {side.safety.fault_reason}: {side.safety.fault_detail}"
        return Observation(time=p.t, left=left, right=right, imu=imu, fault=fault, truth=tuple(p.x))
