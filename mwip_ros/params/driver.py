"""The ``wheel_driver`` node's parameters (docs/hardware.md): the driver's own settings and each backend's.

:func:`specs` gives their :class:`~.spec.ParamSpec` (``params.schema`` lists them as the node's section).  The robot
a simulated backend runs (its model, initial state, raw sensors, ``torque_limit``, ``fall_angle``, Upkie's
``upkie.*``) is not here: it is the ``plant_sim`` section of the same parameter files, the one description of the
robot that ``mwip_sim``, ``plant_sim``, ``mwip_robot`` and the moteus emulator read too
(:func:`.file.robot_values`).

:func:`driver_config`, :func:`mock_config` and :func:`moteus_config` make the typed settings of
:mod:`mwip_ros.robot.driver`, :mod:`mwip_ros.robot.mock` and :mod:`mwip_ros.robot.moteus_backend` from the values;
a value no backend can run with is a :class:`~.errors.ParamError` naming its key.
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Mapping

from mwip_ros.core.plants.plant_base import per_wheel

from .errors import ParamError
from .spec import ParamSpec

__all__ = ["NODE", "BACKENDS", "SIMULATED", "specs", "wheel_limit", "driver_config", "mock_config",
           "moteus_config"]

NODE = "wheel_driver"
BACKENDS = ("mock", "rk4", "mujoco", "upkie", "moteus")
SIMULATED = ("mock", "rk4", "mujoco", "upkie")   # upkie: its PyBullet (upkie.backend: spine is the robot)


def specs() -> List[ParamSpec]:
    """The ``wheel_driver`` ParamSpecs."""
    from mwip_ros.robot.moteus_backend import MoteusConfig
    m = MoteusConfig(path="-", maximum_torque=1.0)   # the moteus defaults, one place (MoteusConfig)
    time_range: Dict[str, Any] = dict(lo=0.0, hi=10.0, lo_open=True, floor=1e-4, floor_why="a bound below 0.1 ms",
                                      hi_why="")
    return [
        ParamSpec("mode", "string", "realtime", "realtime (the driver keeps the wall-clock schedule: period k due at "
                  "t0 + k h) or lockstep (simulated backends only: /clock and one period per command, as plant_sim's "
                  "lockstep)", choices=("realtime", "lockstep")),
        ParamSpec("backend", "string", "mock", "the robot side (mwip_ros.robot): mock (commands mirrored into the "
                  "wheels' torque states, nothing moves), rk4 or mujoco (the plant_sim section's robot simulated), "
                  "upkie (Upkie through the upkie package: upkie.backend), moteus (two moteus controllers on an "
                  "fdcanusb: moteus.*)", choices=BACKENDS),
        ParamSpec("duration_s", "double", 0.0, "run this long [s] (wall time in realtime, simulated in lockstep), "
                  "then stop; 0 = until stopped", lo=0.0, hi=1e7, unit="s"),
        ParamSpec("read_only", "bool", False, "read and publish, never send torque: every period is a stop "
                  "(Backend.step(None): moteus make_stop; Upkie's --readonly spine); for bring-up by hand"),
        ParamSpec("require_enable", "bool", True, "start disabled (no torque) until ~/enable; false: enabled at once "
                  "(a simulated robot that nobody enables; never on a robot you are bringing up)"),
        ParamSpec("watchdog_s", "double", 0.1, "realtime: no new wheel_torque_cmd for this long is a fault (stop, "
                  "latched until ~/reset), counted from the first command (before it every period is a stop, and "
                  "none within lockstep_timeout_s of the first state is the fault); lockstep: lockstep_timeout_s is "
                  "the watchdog", lo=0.0, hi=1e4, lo_open=True, floor=1e-3,
                  floor_why="a watchdog faster than a millisecond would fire between commands", unit="s"),
        ParamSpec("wheel_torque_limit", "double", 0.0, "each wheel's torque limit [N m] (the moteus maximum_torque "
                  "too); 0 = half of the robot's lumped torque_limit (its plant_sim section; none when that is 0 "
                  "too, refused with moteus); more than that half is refused", lo=0.0, hi=1e6, unit="N m"),
        ParamSpec("expected_subscribers", "integer", 2, "lockstep: matched subscriptions imu/data_raw needs before "
                  "the first state, counted as plant_sim's (2 = observer + controller, +1 per recorder; the "
                  "state_estimator alone listens, so the floor is this - 1)", lo=0),
        ParamSpec("lockstep_timeout_s", "double", 10.0, "wall time [s] to wait for the graph before the first state, "
                  "and in lockstep for each command; lockstep gives up after it, realtime starts without the missing "
                  "nodes", lo=0.0, hi=1e6, lo_open=True, unit="s"),
        ParamSpec("summary_json", "string", "", "write the run's summary (periods, missed deadlines, the period's "
                  "timing, the transitions) to this JSON file at the end; '' = none"),
        ParamSpec("upkie.backend", "string", "pybullet", "upkie: pybullet (Upkie's own simulation, headless; "
                  "simulated, lockstep possible) or spine (the robot's spine over shared memory, upkie.shm_name of "
                  "the plant_sim section; realtime only)", choices=("pybullet", "spine")),
        ParamSpec("mock.imu", "bool", True, "mock: the mock has an IMU (at rest, upright: (0, 0, +g)); false: none "
                  "(a robot whose IMU has its own driver; realtime only)"),
        ParamSpec("mock.disable_commands", "bool", False, "mock: ros2_control's disable_commands: nothing is "
                  "mirrored"),
        ParamSpec("moteus.path", "string", "", "moteus: the fdcanusb's serial device (/dev/fdcanusb, "
                  "/dev/serial/by-id/..., the emulator's pty); required with backend moteus"),
        ParamSpec("moteus.left_id", "integer", m.ids[0], "moteus: the left wheel controller's CAN id", lo=1, hi=126),
        ParamSpec("moteus.right_id", "integer", m.ids[1], "moteus: the right wheel controller's CAN id", lo=1,
                  hi=126),
        ParamSpec("moteus.left_reversed", "bool", m.signs[0] < 0, "moteus: true when the left shaft's positive "
                  "sense rolls the wheel backward (sign -1)"),
        ParamSpec("moteus.right_reversed", "bool", m.signs[1] < 0, "moteus: true when the right shaft's positive "
                  "sense rolls the wheel backward (sign -1; mirrored motors: one of the two)"),
        ParamSpec("moteus.watchdog_timeout", "double", m.watchdog_timeout, "moteus: the controllers' own watchdog "
                  "[s], sent with every command: without a new one for this long they stop by themselves (the driver "
                  "killed)", **time_range, unit="s"),
        ParamSpec("moteus.reply_timeout", "double", m.reply_timeout, "moteus: how long one exchange waits for the "
                  "replies [s]; at most half of moteus.watchdog_timeout, above the transport's latency",
                  **time_range, unit="s"),
        ParamSpec("moteus.silence_limit", "double", m.silence_limit, "moteus: a controller that has not answered for "
                  "this long is a device fault [s]; also the serial write's timeout", **time_range, unit="s"),
    ]


def wheel_limit(values: Mapping[str, Any], robot: Mapping[str, Any]) -> float:
    """Each wheel's torque limit [N m]: ``wheel_torque_limit``, or the wheel's share of the robot's lumped
    ``torque_limit`` (:func:`~mwip_ros.core.plants.plant.per_wheel`, SPEC 16: each wheel gets u/2 and half the limit); 0
    = none.  ParamError naming both keys when ``wheel_torque_limit`` is more than that share (the robot's two limits
    disagree)."""
    own, share = values["wheel_torque_limit"], per_wheel(robot.get("torque_limit", 0.0))
    if own > 0.0 and share > 0.0 and own > share:
        raise ParamError("wheel_torque_limit", f"{own:g} N m is more than plant_sim's torque_limit gives a wheel "
                                               f"(torque_limit / 2 = {share:g} N m): the robot's two limits disagree; "
                                               f"give at most {share:g}, or 0 for the torque_limit's share")
    return own or share


def driver_config(values: Mapping[str, Any], robot: Mapping[str, Any]):
    """The :class:`~mwip_ros.robot.driver.DriverConfig` of the node's values and the robot's (plant_sim's)."""
    from mwip_ros.robot.driver import DriverConfig
    return DriverConfig(h=1.0 / values["control_rate_hz"], wheel_torque_limit=wheel_limit(values, robot),
                        read_only=values["read_only"], require_enable=values["require_enable"],
                        watchdog_s=values["watchdog_s"], fall_angle=robot["fall_angle"])


def mock_config(values: Mapping[str, Any], robot: Mapping[str, Any]):
    """The :class:`~mwip_ros.robot.mock.MockConfig`: the period, ``mock.*``, the robot's g."""
    from mwip_ros.robot.mock import MockConfig
    return MockConfig(h=1.0 / values["control_rate_hz"], imu=values["mock.imu"], g=robot["actual.g"],
                      disable_commands=values["mock.disable_commands"])


def moteus_config(values: Mapping[str, Any], robot: Mapping[str, Any]):
    """The :class:`~mwip_ros.robot.moteus_backend.MoteusConfig` of ``moteus.*`` and the wheel limit; ParamError
    naming the key of a value it refuses (no path, no limit, ids that clash, a reply_timeout above half of the
    watchdog's)."""
    from mwip_ros.robot.moteus_backend import MoteusConfig
    if not values["moteus.path"]:
        raise ParamError("moteus.path", "backend moteus needs the fdcanusb's serial device (e.g. /dev/fdcanusb)")
    limit = wheel_limit(values, robot)
    if not (limit > 0 and math.isfinite(limit)):
        raise ParamError("wheel_torque_limit", "backend moteus needs a torque limit (sent as maximum_torque with every "
                                               "command): give wheel_torque_limit, or torque_limit in the plant_sim "
                                               "section")
    try:
        return MoteusConfig(path=values["moteus.path"], maximum_torque=limit,
                            ids=(values["moteus.left_id"], values["moteus.right_id"]),
                            signs=(-1 if values["moteus.left_reversed"] else 1,
                                   -1 if values["moteus.right_reversed"] else 1),
                            watchdog_timeout=values["moteus.watchdog_timeout"],
                            reply_timeout=values["moteus.reply_timeout"], silence_limit=values["moteus.silence_limit"])
    except ValueError as exc:   # "moteus: KEY: why": the key is moteus.KEY (ids: the two ids)
        text = str(exc)
        key = text.split(":")[1].strip() if text.count(":") >= 2 else "path"
        raise ParamError("moteus.left_id" if key == "ids" else f"moteus.{key}", text.split(": ", 2)[-1]) from None
