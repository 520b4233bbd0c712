"""``wheel_driver``: the node that owns a robot's clock (docs/hardware.md). Each period it reads the robot's devices
through a backend (mock wheels, the project's rk4 or MuJoCo plant, Upkie through the upkie package, moteus
controllers through mjbots' moteus package), publishes what they measure stamped at the read, and writes the newest
command, gated by the driver's state machine.

**The period** (:mod:`mwip_ros.robot.driver`): the newest command (``wheel_torque_cmd``'s lumped u as u/2 on each
wheel, :meth:`~mwip_ros.robot.backend.Command.lumped`; or ``wheel_torques_cmd``'s u_L, u_R), a stop unless the
driver is enabled (always a stop with ``read_only``), each wheel clipped to ``wheel_torque_limit``, is written and the
devices are read in one exchange (:meth:`~mwip_ros.robot.backend.Backend.step`: on moteus one ``transport.cycle``
carries both controllers' commands with their queries, and each answers with its state as the command arrives,
before the new torque acts; a simulator integrates the period with the command and reads the next state).  The
command that answers read k is computed by the graph after read k is published, so it goes out with exchange k + 1.
Then the read is published, each message stamped at the read:

- ``wheel_encoder`` (sensor_msgs/JointState ``[wheel]``): the lumped angle phi = (phi_L + phi_R) / 2 relative to the
  body, its rate and the torque u_L + u_R the servos report: what the ``state_estimator`` takes;
- ``wheel_states`` (sensor_msgs/JointState ``[wheel_left_joint, wheel_right_joint]``): each wheel's angle relative to
  the body, rate and torque, in the robot's forward sense;
- ``imu/data_raw`` where the backend has an IMU (REP-145, frame ``imu_link``: the pitch and yaw rates, the proper
  acceleration); a moteus robot's IMU has its own driver (the state estimator's ``imu_sync: latest``);
- a simulator's truth: ``true_joint_states`` (eq. 1's state) and, where it has one, ``true_pose`` (for the report).

**Modes.** ``realtime``: period k is due at t0 + k h on the node's clock (:mod:`..runtime.schedule`: absolute deadlines,
no sliding). A device is read at each wake, once (the newest period; the periods whose deadline passed with no wake are
counted as missed); a simulated backend steps every period that came due (its physics goes on as a robot's would) and
publishes the newest. A device's read is stamped at its exchange's middle on the node's clock, a simulator's at its
period's deadline. A read in which a device did not answer (a moteus reply lost: the wheel holds its last answer,
:attr:`~mwip_ros.robot.backend.Observation.stale`) is no sample of now: stamped now it would tell the estimator the
wheels stood still since their answer, so only ``wheel_states`` goes out (each wheel's read, the answering ones') and
the next answer's stamp spans the gap. ``lockstep`` (simulated backends only):
``/clock`` and state k, then the command that answers it (:mod:`..runtime.lockstep`, the chain state_estimator,
observer, controller), then the next period: the graph runs in simulated time, stamps k h.

**Safety** (:mod:`mwip_ros.core.control.safety`, one machine for the node's life): ``~/enable``, ``~/disable``,
``~/reset`` (std_srvs/Trigger; a reset clears the driver's fault and resets the backend at the next period boundary: a
device stopped and its faults cleared, a simulator back at its initial state with its stamps restarting), the e-stop as
a level (``emergency_stop``, std_msgs/Bool, reliable and best effort), the state estimator's ERROR on ``/diagnostics``
as a level, the command watchdog (realtime: ``watchdog_s``; lockstep: ``lockstep_timeout_s``), a bad command, a fall
(|theta_b| > the robot's ``fall_angle``: a simulator's truth, else the estimate on ``joint_states``) and a device's own
fault (fault ``device``, its detail the backend's one line naming the device).  The realtime watchdog counts from the
first command (until one comes every period is a stop); no command at all within ``lockstep_timeout_s`` of the first
state is a ``watchdog`` fault naming the first stage of the chain that did not answer.  Every transition is logged and
published on ``driver_state``; any fault, a disable or an e-stop makes the next period a stop (moteus ``make_stop``).

**Timing**, per period: the exchange (the transport's round trip, a simulator's step), the read-to-publish time (from
the exchange's end to the last message published), the written command's age (from its receipt), the wake's latency
after its deadline (the jitter) and the missed periods: on ``/diagnostics`` once a second (the recorder records
it), in ``summary_json`` and in the last log lines.  ``external_wrench``'s force.x, force.y [N] push a simulated
Upkie's torso (held until the next message; other backends refuse it, counted).

The robot a simulated backend runs is the ``plant_sim`` section of the parameter files (the one description of a
robot that mwip_sim, plant_sim, mwip_robot and the moteus emulator read), at this node's ``control_rate_hz``.

Exit codes: 0 the run ended (duration_s, or SIGINT/SIGTERM with duration_s 0), 1 the run ended in fault (a
device's, the watchdog, a lockstep timeout, a bad command, an e-stop) or a simulation diverged, 2 bad parameters or
a device that does not open (one line naming the key), 3 the robot fell, 128 + the signal (130, 143) when stopped
before duration_s.
"""
from __future__ import annotations

import json
import math
import sys
import time
from collections import deque
from typing import Dict, Optional

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Wrench
from rclpy.duration import Duration
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Bool, Float64, String
from std_srvs.srv import Trigger

from mwip_ros import params as P
from mwip_ros.core.closed_loop.loop import answering
from mwip_ros.core.closed_loop.metrics import json_safe
from mwip_ros.core.control.safety import HISTORY, Transition
from mwip_ros.msgs import BadMessage, cdr
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import BEST_EFFORT_INPUT_QOS, DRIVER_STATE_QOS, INPUT_QOS, SERVICE_QOS, qos_for
from mwip_ros.nodes.runtime import stallprobe
from mwip_ros.nodes.runtime.diagnostics import ERROR, OK, WARN
from mwip_ros.nodes.runtime.driver_state import publish_transition
from mwip_ros.nodes.runtime.guards import PublisherWatch, Rejects
from mwip_ros.nodes.runtime.lockstep import SETTLE_S, LockstepDriver, subscriber_floor
from mwip_ros.nodes.runtime.params import declare, ros_arguments
from mwip_ros.nodes.runtime.process import EXIT_ERROR, EXIT_FALLEN, GracefulNodeMixin, run_node
from mwip_ros.nodes.runtime.schedule import Reservoir, Schedule
from mwip_ros.params import driver as D
from mwip_ros.params.file import robot_values
from mwip_ros.robot.backend import Backend, BackendError, Command, Observation
from mwip_ros.robot.driver import WheelDriver, timing_lines

NAME = "wheel_driver"
ESTIMATOR = "state_estimator"   # the node whose /diagnostics status the driver watches (its namespace's)
WHEEL_JOINTS = L.WHEEL_TORQUE_JOINTS   # wheel_states' names: the URDF's wheel joints (left, right)
TIMING_FIELDS = ("exchange", "read_to_publish", "command_age", "wake_latency")   # a period's timing series [s]

_WHEEL_STATES = cdr.JointStateEncoder(WHEEL_JOINTS)


class PeriodTiming:
    """The period's timing over a run in bounded memory: per series of :data:`TIMING_FIELDS` [s] a uniform sample
    (:class:`~mwip_ros.nodes.runtime.schedule.Reservoir`: exact up to ``size`` periods), its largest and newest
    value; the periods run and missed.

    Parameters
    ----------
    size : int
        Values kept per series.
    """

    def __init__(self, size: int = 16384):
        self.series: Dict[str, Reservoir] = {f: Reservoir(size, seed=i) for i, f in enumerate(TIMING_FIELDS)}
        self.largest: Dict[str, float] = {f: 0.0 for f in TIMING_FIELDS}
        self.newest: Dict[str, float] = {f: math.nan for f in TIMING_FIELDS}
        self.periods = 0
        self.missed = 0

    def add(self, field: str, value: Optional[float]) -> None:
        """One period's ``field`` [s]; None (no command written: a stop) or NaN adds nothing."""
        if value is None or not math.isfinite(value):
            return
        self.series[field].add(value)
        self.largest[field] = max(self.largest[field], value)
        self.newest[field] = value

    def report(self) -> dict:
        """The periods run and missed, and each series' count, p50, p99 and max [ms] (None for an empty one: no
        figure is made of nothing)."""
        out: dict = {"periods": self.periods, "missed": self.missed}
        for f, r in self.series.items():
            v = r.values()
            out[f"{f}_count"] = r.count
            for q in (50, 99):
                out[f"{f}_ms_p{q}"] = float(np.percentile(v, q) * 1e3) if len(v) else None
            out[f"{f}_ms_max"] = self.largest[f] * 1e3 if len(v) else None
        return out


def open_backend(values: dict, robot: dict) -> Backend:
    """The backend ``values['backend']`` names (module doc), opened; ParamError naming its key when it refuses its
    settings or does not open (a serial device that is not there, a spine that does not answer)."""
    name = values["backend"]
    try:
        if name == "mock":
            from mwip_ros.robot.mock import MockBackend
            return MockBackend(D.mock_config(values, robot))
        if name in ("rk4", "mujoco"):
            from mwip_ros.robot.sim import SimBackend
            return SimBackend(P.plant_config({**robot, "backend": name}))
        if name == "upkie":
            from mwip_ros.params.upkie import upkie_config
            from mwip_ros.robot.upkie import UpkieBackend
            config = upkie_config(robot)
            pybullet = values["upkie.backend"] == "pybullet"
            return UpkieBackend.pybullet(config) if pybullet else UpkieBackend.spine(config)
        from mwip_ros.robot.moteus_backend import MoteusBackend
        return MoteusBackend(D.moteus_config(values, robot))
    except BackendError as exc:
        key = {"moteus": "moteus.path", "upkie": "upkie.backend"}.get(name, "backend")
        raise P.ParamError(key, str(exc)) from None
    except ValueError as exc:   # a typed config's refusal (upkie: KEY = value is out of range)
        raise P.ParamError("backend", str(exc)) from None


class WheelDriverNode(Node, GracefulNodeMixin):
    """The wheel driver's period (:class:`mwip_ros.robot.driver.WheelDriver`) as a node; its mode decides when a
    period runs (module doc)."""

    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        v = self.v
        self.mode, self.backend_name = v["mode"], v["backend"]
        files = [arg for kind, arg in ros_arguments(argv) if kind == "--params-file"]
        self.robot = robot_values(files, v["control_rate_hz"])
        simulated = self.backend_name in D.SIMULATED and not (self.backend_name == "upkie"
                                                              and v["upkie.backend"] == "spine")
        if self.mode == "lockstep" and not simulated:   # refused before a device is opened
            what = "upkie.backend spine" if self.backend_name == "upkie" else f"backend {self.backend_name}"
            raise P.ParamError("mode", f"lockstep needs a simulated backend (mock, rk4, mujoco, upkie with "
                                       f"upkie.backend pybullet); {what} is a robot on the wall clock: mode realtime")
        if self.mode == "lockstep" and self.backend_name == "mock" and not v["mock.imu"]:
            raise P.ParamError("mock.imu", "lockstep needs the backend's IMU (the state estimator answers a state of "
                                           "imu/data_raw and wheel_encoder): mock.imu true, or mode realtime with an "
                                           "IMU driver of its own")
        self.cfg = D.driver_config(v, self.robot)
        self.h = self.cfg.h
        self.period_ns = round(self.h * 1e9)
        self.backend = open_backend(v, self.robot)
        self.simulated_backend = bool(self.backend.simulated)   # steps on demand (a simulator) or on the wall clock
        self.driver = WheelDriver(self.backend, self.cfg)
        self.n_steps = int(round(v["duration_s"] / self.h)) if v["duration_s"] > 0 else None
        self.timing = PeriodTiming()
        self.rejects = Rejects(self.get_logger())
        self.transitions: deque = deque(maxlen=HISTORY)
        self.fell_at: Optional[float] = None
        self.started = False
        self.t_wall0: Optional[float] = None
        self.stamp0 = 0                  # realtime: the node clock at period 0's deadline [ns]; lockstep: 0
        self.k_run = 0                   # periods since the start (or the last reset)
        self._reset_pending = False
        self.resets = 0
        self.stale_reads = 0             # realtime reads not published: a device did not answer (Observation.stale)
        self.pushed = (0.0, 0.0)
        obs = self.driver.start()
        self.has_imu = obs.imu is not None
        self.has_truth = obs.truth is not None
        self.has_pose = callable(getattr(self.backend, "true_pose", None)) and self.backend.true_pose() is not None
        self.imu_variances = self._imu_variances()

        pub_qos, in_qos = qos_for(self.mode)
        self.imu_pub = self.create_publisher(Imu, "imu/data_raw", pub_qos) if self.has_imu else None
        self.encoder_pub = self.create_publisher(JointState, "wheel_encoder", pub_qos)
        self.wheels_pub = self.create_publisher(JointState, "wheel_states", pub_qos)
        self.truth_pub = self.create_publisher(JointState, "true_joint_states", pub_qos) if self.has_truth else None
        self.pose_pub = self.create_publisher(PoseStamped, "true_pose", pub_qos) if self.has_pose else None
        self.clock_pub = self.create_publisher(Clock, "/clock", pub_qos) if self.mode == "lockstep" else None
        self.driver_pub = self.create_publisher(String, "driver_state", DRIVER_STATE_QOS)
        cmd_sub = self.create_subscription(Float64, "wheel_torque_cmd", self._on_cmd, in_qos, raw=True)
        self.create_subscription(JointState, "wheel_torques_cmd", self._on_wheel_cmd, in_qos, raw=True)
        self.create_service(Trigger, "~/enable", self._on_enable, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, "~/disable", self._on_disable, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, "~/reset", self._on_reset, qos_profile=SERVICE_QOS)
        self.estop_heard: dict = {}
        for via, qos in (("reliable", INPUT_QOS), ("best_effort", BEST_EFFORT_INPUT_QOS)):
            self.side_input(Bool, "emergency_stop", qos, lambda data, via=via: self._on_estop(data, via))
        self.estimator_status = f"{self.get_namespace().rstrip('/')}/{ESTIMATOR}"
        self.side_input(DiagnosticArray, "/diagnostics", INPUT_QOS, self._on_diagnostics)
        self.side_input(Wrench, "external_wrench", INPUT_QOS, self._on_wrench)
        if not self.has_truth:   # a fall is judged on the estimate
            self.side_input(JointState, "joint_states", in_qos, self._on_estimate)
        self.watch = PublisherWatch(self, ["wheel_torque_cmd", "wheel_torques_cmd", "wheel_encoder",
                                           *(("imu/data_raw",) if self.has_imu else ())])
        # the chain: state_estimator, observer, controller (core.closed_loop.loop.STAGES)
        answers = answering(estimator=True)
        first = self.imu_pub if self.has_imu else self.encoder_pub
        others = [p for p in (self.encoder_pub, self.wheels_pub, self.truth_pub, self.pose_pub)
                  if p is not None and p is not first]
        self.lockstep = LockstepDriver(
            self, first, self.clock_pub, cmd_sub, need_subs=subscriber_floor(v["expected_subscribers"], answers),
            timeout_s=v["lockstep_timeout_s"], timeout_param="lockstep_timeout_s", settle_s=SETTLE_S,
            idle_hint="a wheel_torque_cmd (the controller is running but did not answer)", also_published=others,
            answers=answers)
        self.schedule: Optional[Schedule] = None
        self.wakes = 0
        self._no_command_since: Optional[float] = None   # realtime: since when no command has come (the start-up)
        self._first_stamp = 0
        dur = f"{v['duration_s']:g} s" if self.n_steps is not None else "until stopped"
        limit = f"{self.cfg.wheel_torque_limit:g} N m a wheel" if self.cfg.wheel_torque_limit else "no torque limit"
        self.get_logger().info(
            f"{self.mode} driver: h = {self.h * 1e3:.3f} ms, backend {self.backend_name} ({type(self.backend).__name__}"
            f"{', IMU' if self.has_imu else ', no IMU'}{', truth' if self.has_truth else ''}), {dur}, read_only "
            f"{str(self.cfg.read_only).lower()}, {limit}, watchdog {self.cfg.watchdog_s * 1e3:g} ms")
        self._publish_transition(Transition(0.0, "", self.driver.safety.state, "start",
                                            f"require_enable: {str(self.cfg.require_enable).lower()}"), start=True)

    def side_input(self, msg_type, topic: str, qos, callback):
        """A side input (the e-stop, the estimator's health, a push, the estimate for the fall check): read at the
        node's pace, not the period's.  Today a raw subscription; with issue 46's ``rclpy_compat.PolledInput``
        merged this one line becomes ``PolledInput(self, msg_type, topic, qos, callback, SIDE_DEPTH)`` (polled in
        :meth:`spin_step`), so that a flood on it cannot starve the period."""
        return self.create_subscription(msg_type, topic, callback, qos, raw=True)

    def _imu_variances(self):
        """imu/data_raw's covariance diagonals: the simulated sensors' noise (rk4, MuJoCo), else 0 (unknown)."""
        raw = getattr(getattr(self.backend, "cfg", None), "raw", None)
        return (raw.gyro_noise_std ** 2, raw.accel_noise_std ** 2) if raw is not None else (0.0, 0.0)

    # --- time ------------------------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _t(self, obs: Optional[Observation] = None) -> float:
        """The run's time [s]: a simulator's own (simulated) time, a device's seconds since the start."""
        if self.simulated_backend:
            o = obs or self.driver.obs
            return float(o.time) if o is not None else 0.0
        return time.monotonic() - self.t_wall0 if self.t_wall0 is not None else 0.0

    def _stamp(self, obs: Observation) -> int:
        """The read's stamp [ns] (module doc): a simulator's period on the run's grid, a device's exchange (its
        ``time.monotonic()``) on the node's clock."""
        if self.simulated_backend:
            return self.stamp0 + round(obs.time / self.h) * self.period_ns
        return self._now_ns() - round((time.monotonic() - obs.time) * 1e9)

    # --- inputs ---------------------------------------------------------------------------------------------
    def _on_cmd(self, data: bytes) -> None:
        try:
            u = L.parse_command(data)
        except BadMessage as exc:
            self.rejects("wheel_torque_cmd", str(exc))
            try:
                value = cdr.decode_float64(data)
            except cdr.CdrError:   # not a Float64 at all: only rejected
                return
            self._publish_transition(self.driver.take_command(Command(value, value), self._t()))
            self._answered(None)
            return
        self._command(Command.lumped(u))

    def _on_wheel_cmd(self, data: bytes) -> None:
        try:
            _stamp, ul, ur = L.parse_wheel_torques(data)
        except BadMessage as exc:
            self.rejects("wheel_torques_cmd", str(exc))
            try:
                effort = cdr.decode_joint_state(data)[5]
            except cdr.CdrError:
                return
            if len(effort) == 2:
                self._publish_transition(self.driver.take_command(Command(*effort), self._t()))
                self._answered(None)
            return
        self._command(Command(ul, ur))

    def _command(self, cmd: Command) -> None:
        self._no_command_since = None   # a command came: the watchdog (watchdog_s) counts from it
        self._publish_transition(self.driver.take_command(cmd, self._t()))
        self._answered(cmd)

    def _answered(self, cmd: Optional[Command]) -> None:
        """Lockstep: a command (or a refused one) answers the state in flight: the next period."""
        if self.mode != "lockstep" or not self.started or self.done:
            return
        if not self.lockstep.take_answer():
            self.rejects("wheel_torque_cmd", "command while no state is waiting for one")
            return
        if self._reset_pending:
            self._do_reset()
        elif self._ended():
            return
        else:
            self._run_periods(1)
        if not self.done:
            self._send_lockstep()

    def _on_estop(self, data: bytes, via: str = "reliable") -> None:
        """``emergency_stop``, a level: true asserts it (a fault, held), false releases it."""
        try:
            stop = L.parse_bool(data)
        except BadMessage as exc:
            self.rejects("emergency_stop", str(exc))
            return
        was = "emergency_stop" in self.driver.safety.held
        self.estop_heard[via] = stop
        asserted = any(self.estop_heard.values())
        self._publish_transition(self.driver.set_level(self._t(), "emergency_stop", asserted, "a std_msgs/Bool true"))
        if was and not asserted:
            self.get_logger().warning("driver: emergency stop released; the fault stays latched until ~/reset")

    def _on_diagnostics(self, data: bytes) -> None:
        """The state estimator's health, a level: ERROR asserts it, OK or WARN releases it."""
        from rclpy.serialization import deserialize_message
        try:
            arr = deserialize_message(bytes(data), DiagnosticArray)
        except Exception:   # noqa: BLE001 - another node's report that does not decode: not ours to judge
            return
        for st in arr.status:
            if st.name != self.estimator_status:
                continue
            level = st.level[0] if isinstance(st.level, (bytes, bytearray)) else int(st.level)
            if level not in (OK, WARN, ERROR):
                continue
            self._publish_transition(self.driver.set_level(self._t(), "estimator_unhealthy", level == ERROR,
                                                           f"{st.name}: {st.message}"))

    def _on_estimate(self, data: bytes) -> None:
        """The estimator's ``joint_states``: its pitch is what a fall is judged on without a truth."""
        try:
            _stamp, x, _u = L.parse_joint_state(data)
        except BadMessage as exc:
            self.rejects("joint_states", str(exc))
            return
        self.driver.estimate(x[1])

    def _on_wrench(self, data: bytes) -> None:
        """``external_wrench``: force.x, force.y [N] on a simulated Upkie's torso, held until the next message."""
        try:
            force, _torque = cdr.decode_wrench(data)
        except cdr.CdrError as exc:
            self.rejects("external_wrench", f"not a geometry_msgs/Wrench ({exc})")
            return
        fx, fy = float(force[0]), float(force[1])
        push = getattr(self.backend, "push", None)
        if not (math.isfinite(fx) and math.isfinite(fy) and max(abs(fx), abs(fy)) <= L.LIMITS["torque"]):
            self.rejects("external_wrench", f"force ({fx!r}, {fy!r}) N is not finite or implausible")
        elif push is None or not self.simulated_backend:
            self.rejects("external_wrench", f"backend {self.backend_name} cannot be pushed (a simulated Upkie can)")
        elif (fx, fy) != self.pushed:
            push(fx, fy)
            self.pushed = (fx, fy)
            self.get_logger().info(f"push at t = {self._t():.3f} s: force ({fx:g}, {fy:g}) N on the torso" if fx or fy
                                   else f"push released at t = {self._t():.3f} s")

    # --- services ----------------------------------------------------------------------------------------------
    def _answer(self, response, answer):
        self._publish_transition(answer.transition)
        response.success, response.message = answer.success, answer.message
        return response

    def _on_enable(self, request, response):
        return self._answer(response, self.driver.enable(self._t()))

    def _on_disable(self, request, response):
        return self._answer(response, self.driver.disable(self._t()))

    def _on_reset(self, request, response):
        """``~/reset``: the driver's fault cleared at once (refused while a level is held), the backend reset at the
        next period boundary (a device stopped and its faults cleared; a simulator at its initial state)."""
        if self.done:
            response.success, response.message = False, "the run has ended; nothing to reset"
            return response
        answer = self.driver.reset(self._t())
        self._answer(response, answer)
        if answer.success:
            self._reset_pending = True
            response.message += "; the backend is reset at the next period"
            self._no_command_since = time.monotonic() if self.started else None
        return response

    def _do_reset(self) -> None:
        self._reset_pending = False
        self.resets += 1
        self.fell_at = None
        self.driver.start()
        self.k_run = 0
        what = "its initial state, stamps restart" if self.simulated_backend else "stopped, its faults cleared"
        self.get_logger().warning(f"reset #{self.resets}: the backend reset ({what})")

    # --- transitions ---------------------------------------------------------------------------------------------
    def _publish_transition(self, tr: Optional[Transition], start: bool = False, **extra) -> None:
        """Log a transition (one line), publish it on ``driver_state`` and keep it for the summary."""
        if tr is not None:
            publish_transition(self, self.driver_pub, self.transitions, tr, self._now_ns(), start, **extra)

    # --- the period --------------------------------------------------------------------------------------------
    def _run_periods(self, n: int) -> Optional[Observation]:
        """``n`` periods (a simulator catching up; else 1); the newest read, or None when the run ended."""
        obs = None
        for _ in range(n):
            t0 = time.monotonic()
            try:
                obs, age, trs = self.driver.period(self._t())
            except BackendError as exc:   # a simulation that diverged, a device gone for good
                reason = "diverged" if self.simulated_backend else "device"
                self._publish_transition(self.driver.fault(self._t(), reason, str(exc)))
                self.finish(EXIT_ERROR, f"{reason}: {exc}; stopping")
                return None
            self._read_end = time.monotonic()
            self.timing.add("exchange", self._read_end - t0)
            self.timing.add("command_age", age)
            self.timing.periods += 1
            self.k_run += 1
            for tr in trs:
                self._publish_transition(tr)
            if self.driver.fell_at is not None and self.fell_at is None:
                self.fell_at = self.driver.fell_at
                theta = obs.truth[1] if obs.truth is not None else self.driver.theta_b_estimate
                self.finish(EXIT_FALLEN, f"FALLEN at t = {self.fell_at:.3f} s: |theta_b| = {abs(theta):.4f} > "
                                         f"fall_angle {self.cfg.fall_angle}")
                return None
        return obs

    def _ended(self) -> bool:
        """The run's last period is done (``duration_s``: states 0 to n published, as plant_sim's): finish, True."""
        if self.n_steps is None or self.k_run < self.n_steps:
            return False
        sm = self.driver.safety
        if sm.faulted:
            self.finish(EXIT_ERROR, f"the run ended in fault: {sm.diagnostic()[1]}")
        else:
            self.finish()
        return True

    def _messages(self, obs: Observation, stamp: int) -> list:
        """A read's messages, in order (the lockstep's first topic first): [(publisher, bytes)]."""
        out = []
        if self.imu_pub is not None:
            w, a = obs.imu.angular_velocity, obs.imu.linear_acceleration
            out.append((self.imu_pub, L.encode_imu(stamp, w[1], a[0], a[2], *self.imu_variances, w[2])))
        out.append((self.encoder_pub, L.encode_encoder(stamp, obs.phi, obs.phi_rate, obs.torque)))
        out.append((self.wheels_pub, _WHEEL_STATES(stamp, (obs.left.position, obs.right.position),
                                                   (obs.left.velocity, obs.right.velocity),
                                                   (obs.left.torque, obs.right.torque))))
        if self.truth_pub is not None and obs.truth is not None:
            out.append((self.truth_pub, L.encode_state(stamp, obs.truth, obs.torque)))
        if self.pose_pub is not None:
            pose = self.backend.true_pose()
            if pose is not None and all(map(math.isfinite, pose)):
                out.append((self.pose_pub, L.encode_pose(stamp, pose)))
        return out

    def _publish(self, obs: Observation, stamp: int) -> None:
        for pub, data in self._messages(obs, stamp):
            pub.publish(data)

    def _send_lockstep(self) -> None:
        obs = self.driver.obs
        stamp = self._stamp(obs)
        self.lockstep.send(round(obs.time / self.h), stamp, self._messages(obs, stamp))
        self.timing.add("read_to_publish", time.monotonic() - self._read_end)

    def _tick(self) -> None:
        """A realtime wake: the period(s) due (module doc), then the read published."""
        stallprobe.beat()   # a debugging aid: nothing unless MWIP_STALL_PROBE is set
        wake = self.schedule.wake(self._now_ns())
        if not wake.periods or self.done:
            return
        first = self.wakes == 0
        self.wakes += 1
        self.timing.add("wake_latency", wake.late_ns * 1e-9)
        now = time.monotonic()
        if first:
            self.t_wall0 = now
        elif wake.late and not self._deferred:   # the controller cannot answer what was not published: next tick
            self._deferred = True
        else:
            self._deferred = False
            self._publish_transition(self.driver.check_watchdog(now, self._t()) or self._check_start(now))
        if self._reset_pending:
            self._do_reset()
            obs = self.driver.obs
            self._read_end = time.monotonic()
            if self.simulated_backend:
                self.stamp0 = self.schedule.due(wake.k)   # a simulator's stamps restart on the grid
        elif first and self.simulated_backend:   # state 0: the reset's read, at period 0's deadline
            obs = self.driver.obs
            self._read_end = time.monotonic()
        else:
            if self._ended():
                return
            if not self.simulated_backend:
                self.timing.missed += wake.missed
            n = 1 if first or not self.simulated_backend else min(wake.periods, self.n_steps - self.k_run
                                                                  if self.n_steps is not None else wake.periods)
            obs = self._run_periods(n)
            if obs is None:
                return
            if not self.simulated_backend:   # a device's period is the schedule's: k periods since the start
                self.k_run = wake.k
        if obs.stale:   # a device did not answer: its last answer is no sample of now (module doc); wheel_states
            self.stale_reads += 1   # only (the answering wheels' reads), the next sample's stamp spans the gap
            for pub, data in self._messages(obs, self._stamp(obs)):
                if pub is self.wheels_pub:
                    pub.publish(data)
        else:
            self._publish(obs, self._stamp(obs))
            self.timing.add("read_to_publish", time.monotonic() - self._read_end)
        if first:   # the first state is out: the start-up's bound counts from it (_check_start)
            self._no_command_since = time.monotonic()
            self._first_stamp = self._stamp(obs)

    def _check_start(self, now: float) -> Optional[Transition]:
        """The start-up's bound: no command at all within ``lockstep_timeout_s`` of the first state (or of a reset) is
        a ``watchdog`` fault naming the first stage of the chain that did not answer.  (``watchdog_s`` counts from the
        first command: until one comes the driver writes stops, and a graph that takes a moment to discover the
        IMU's own driver is no fault.)"""
        since = self._no_command_since
        if since is None or self.driver.safety.faulted or now - since <= self.v["lockstep_timeout_s"]:
            return None
        self._no_command_since = None
        _stage, why = self.lockstep.silent_stage(self._first_stamp, self.stamp0)
        return self.driver.fault(self._t(), "watchdog", f"no wheel_torque_cmd within lockstep_timeout_s = "
                                                        f"{self.v['lockstep_timeout_s']:g} s of the first state; the "
                                                        f"stage that did not answer: {why}")

    # --- the run -----------------------------------------------------------------------------------------------
    def _start(self, why: str) -> None:
        self.started = True
        self.get_logger().info(f"{why}; starting {self.mode} run")
        self._read_end = time.monotonic()
        self._deferred = False
        if self.mode == "lockstep":
            self.t_wall0 = time.monotonic()
            self._send_lockstep()
            return
        from mwip_ros.msgs.qos import REALTIME_INPUT_QOS
        if not self.simulated_backend:   # a device: stopped and its faults cleared now, when its periods begin (its
            self.driver.start()          # silence is counted from its last answer: not across the graph's wait)
        self.lockstep.listen(REALTIME_INPUT_QOS)
        timer = self.create_timer(self.h, self._tick)
        now = self._now_ns()
        # period k due at stamp0 + k h on the timer's own grid (as plant_sim's realtime runner)
        self.stamp0 = min(now, now + (timer.time_until_next_call() or self.period_ns) - self.period_ns)
        self.schedule = Schedule(self.period_ns, self.stamp0)
        self._tick()

    def spin_step(self, executor) -> None:
        for side in getattr(self, "polled_inputs", ()):   # issue 46's PolledInput (side_input), once merged
            side.poll()
        if not self.started:
            ready = self.lockstep.wait_for_graph()
            if ready:
                self._start("graph matched")
            elif ready is False:
                if self.mode == "lockstep":
                    self.finish(EXIT_ERROR, "lockstep timeout: " + self.lockstep.graph_timeout_text())
                else:
                    self.get_logger().warning(f"graph not ready after {self.lockstep.timeout_s:g} s (missing: "
                                              f"{self.lockstep.missing()}); starting the realtime run anyway")
                    self._start("realtime without the whole graph")
            executor.spin_once(timeout_sec=0.02)
            return
        executor.spin_once(timeout_sec=0.05)
        crowded = self.watch.check()
        if self.mode == "lockstep" and not self.done:
            failure = self.lockstep.check()
            if failure:   # the lockstep timeout is the watchdog
                self._publish_transition(self.driver.fault(self._t(), "watchdog", failure))
            elif crowded:
                failure = ("lockstep refuses mixed streams: " + "; ".join(
                    f"{len(names)} publishers on {topic} ({', '.join(names)})" for topic, names in crowded.items()))
            if failure:
                self.finish(EXIT_ERROR, failure)

    # --- health ------------------------------------------------------------------------------------------------
    def diagnostic_count(self) -> int:
        return self.timing.periods

    def diagnostic_status(self):
        sm = self.driver.safety
        rep = self.timing.report()
        values = {"mode": self.mode, "backend": self.backend_name, "read_only": str(self.cfg.read_only).lower(),
                  "driver_state": sm.state, "fault_reason": sm.fault_reason or "none",
                  "held": ", ".join(sm.held) or "none", "periods": rep["periods"], "missed_periods": rep["missed"],
                  "torque_writes": self.driver.torque_writes, "stop_writes": self.driver.stops,
                  "stale_reads": self.stale_reads}
        for f in TIMING_FIELDS:
            if rep[f"{f}_ms_p99"] is not None:
                values[f"{f}_ms_newest"] = f"{self.timing.newest[f] * 1e3:.3f}"
                values[f"{f}_ms_p99"] = f"{rep[f'{f}_ms_p99']:.3f}"
                values[f"{f}_ms_max"] = f"{rep[f'{f}_ms_max']:.3f}"
        missed = getattr(self.backend, "missed", None)
        if missed is not None:
            values["device_replies_missed"] = f"{missed[0]}, {missed[1]}"
        level, text = sm.diagnostic()
        if self.fell_at is not None:
            return ERROR, f"FALLEN at t = {self.fell_at:.3f} s", values
        if level == ERROR:
            return ERROR, f"driver {text}", values
        if not self.started:
            return WARN, f"waiting for the graph (missing: {self.lockstep.missing()})", values
        if level == WARN:
            return WARN, f"driver disabled (no torque until ~/enable); {self.mode} run", values
        return OK, f"{self.mode} run, {rep['periods']} periods", values

    def on_shutdown(self) -> None:
        log = self.get_logger()
        if self.stop_signal is not None and self.n_steps is not None and not self.done:
            self.finish(128 + self.stop_signal)
            log.warning(f"interrupted at t = {self._t():.3f} s of {self.n_steps * self.h:g} s")
        try:
            self.backend.close()   # a stop first (moteus make_stop, Upkie's zero torque), then released
        except Exception as exc:   # noqa: BLE001 - closing: the stop was tried
            log.error(f"closing the backend: {exc}")
        for pub in (self.imu_pub, self.encoder_pub, self.truth_pub, self.clock_pub, self.driver_pub):
            if pub is not None:   # let a recorder receive the last reads before this process exits
                pub.wait_for_all_acked(Duration(seconds=2.0))
        rep = self.timing.report()
        if self.schedule is not None:
            rep["periods_due"] = self.schedule.report()["periods_due"]
        for line in timing_lines(rep, self.h):
            log.info(f"timing: {line}")
        wall = time.monotonic() - self.t_wall0 if self.t_wall0 else 0.0
        sm = self.driver.safety
        stops = self.driver.stop_after
        log.info(f"{self.mode} run: {rep['periods']} periods in {wall:.2f} s wall; {self.driver.torque_writes} torque "
                 f"writes, {self.driver.stops} stops; driver {sm.state}"
                 + (f" ({sm.fault_reason})" if sm.faulted else "")
                 + (f"; first stop {max(stops) * 1e3:.3f} ms after leaving enabled (worst)" if stops else "")
                 + f"; reads not published (a device did not answer): {self.stale_reads}"
                 + f"; rejected messages: {self.rejects.summary()}")
        if self.v["summary_json"]:
            summary = {"mode": self.mode, "backend": self.backend_name, "control_rate_hz": 1.0 / self.h,
                       "wall_s": wall, "exit_code": self.exit_code, "fell_at": self.fell_at, "resets": self.resets,
                       "driver_state": sm.state, "fault_reason": sm.fault_reason, "fault_detail": sm.fault_detail,
                       "transitions": list(self.transitions), "timing": rep,
                       "torque_writes": self.driver.torque_writes, "stop_writes": self.driver.stops,
                       "stale_reads": self.stale_reads, "stop_after_s": stops, "rejected": dict(self.rejects.counts),
                       "device_replies_missed": list(getattr(self.backend, "missed", []) or []) or None,
                       "schedule": self.schedule.report() if self.schedule is not None else None}
            with open(self.v["summary_json"], "w") as f:
                json.dump(json_safe(summary), f, indent=1, allow_nan=False)
            log.info(f"wrote {self.v['summary_json']}")


def main(argv=None) -> int:
    return run_node(WheelDriverNode, argv)


if __name__ == "__main__":
    sys.exit(main())
