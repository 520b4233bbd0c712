"""``plant_sim``: the true MWIP as a node (docs/theory.md: the plant and discrete time).

lockstep: publish /clock and state k, wait for the command that answers it, publish
the true lumped disturbance at t_k, integrate to t_{k+1}, repeat (the lockstep driver,
:mod:`.lockstep`).  The graph then reproduces ``mwip_sim`` sample by sample.
realtime: a timer at ``control_rate_hz`` on the node's clock; the last command is held; a
command older than ``stale_command_periods`` periods is replaced by zero torque.  State k
is stamped t_0 + k h, t_0 the node clock's time at the start (wall time, or simulated time
under ``use_sim_time`` with a ``/clock``): the stamps are the clock's, on one grid, so the
observer counts periods by them; the ``csv`` then has a ``stamp`` column beside ``t``
(time since the start).  Lockstep stamps are simulated time from 0.

Services: ``~/reset`` (``std_srvs/Trigger``) puts the robot back in its initial state and its time back to the
run's start, at a period boundary (lockstep once the state in flight is answered, realtime at the next tick);
stamps restart at the run's start, so the loop re-initialises and a recording splits there
(:mod:`mwip_ros.bag.segments`).  A reset at the initial state changes nothing; one asked while another is pending
joins it; every request is answered (docs/graph.md, "Reset and push").  To push
the robot, publish ``external_wrench`` (``geometry_msgs/Wrench``: ``torque.x`` adds to
tau_ext1, ``torque.y`` to tau_ext2, until the next one; a zero wrench clears it; with
``backend: mujoco`` ``force.y`` pushes the body sideways at its centre of gravity and
``torque.z`` turns it about the vertical, both in the robot's heading frame; rk4 ignores them).
``external_wrench``, ``emergency_stop`` and a raw plant's ``/diagnostics`` are read between the node's callbacks, the
newest :data:`SIDE_DEPTH` of each (:class:`~mwip_ros.nodes.runtime.rclpy_compat.PolledInput`): within a period while
the loop runs, and a flood of them queues nothing in front of the period.

The driver's state machine (docs/theory.md 6.8; the pure machine, its states, faults, levels and answers:
:mod:`mwip_ros.core.control.safety`; one machine for the node's life) stands between the command and the plant: not
enabled, the bridge is open (no current, no torque: ``effort``, ``u`` and ``u_applied`` are exactly zero).  The
node feeds it its faults (the realtime watchdog, counted from the first state published and naming the first
stage that did not answer; the lockstep timeout; a bad command; a fall, which with ``exit_on_fall: true`` ends the
run, exit 3), its two levels (``emergency_stop``, std_msgs/Bool on a reliable and a best-effort subscription; with
raw sensors the estimator's latest ``/diagnostics`` level) and the services ``~/enable``, ``~/disable`` and
``~/reset`` (std_srvs/Trigger, every call answered).  Each transition is logged, counted on ``/diagnostics`` and
published on ``driver_state`` (std_msgs/String, JSON; latched at depth 1,
:data:`~mwip_ros.msgs.qos.DRIVER_STATE_QOS`: a late reader gets the current state only).

With ``sensors.model: raw`` (docs/theory.md 6.4) the plant publishes what its sensors measure instead of a state:
per state k ``imu/data_raw`` (sensor_msgs/Imu, frame ``imu_link``, no orientation, the pitch rate and the
specific force) and ``wheel_encoder`` (sensor_msgs/JointState ``[wheel]``: the wheel's angle relative to
the body, its rate and the torque that acted), both stamped t_k, and the truth on ``true_joint_states``;
a ``state_estimator`` publishes ``joint_states`` (the lockstep chain waits for it first).  The sample is
the plant's stage ``sensors`` (:meth:`mwip_ros.core.closed_loop.loop.PlantSide.sense`).

With ``backend: mujoco`` (docs/theory.md 6.10: a plant with a 3D pose, ``Plant.spatial``) the plant publishes its
pose per state on ``true_pose`` (geometry_msgs/PoseStamped, frame ``odom``) and each wheel's angle on
``true_wheel_states`` (:mod:`.plant_truth`), and its csv has the pose columns; a
simulation that diverges (``PlantDiverged``) is the driver's fault ``diverged``: one line, no state past it, exit 1.

The plant's trajectory table (its ``csv``) has the states, the commands it applied and
the true disturbance; it does not listen to the observer: estimates join the
trajectory by stamp where a report needs them (the bag, or the observer's own ``csv``).

Exit code 0 when the run completed (or, with ``duration_s: 0``, was stopped), 3 when
the robot fell (with ``exit_on_fall: false``: when the run reached ``duration_s`` with the robot down), 1 on
a lockstep timeout or a diverged simulation (``backend: mujoco``: a ``diverged`` fault), 2 on bad parameters,
128 + the signal (130, 143) when SIGINT/SIGTERM stopped it before ``duration_s``.
"""
from __future__ import annotations

import json
import math
import sys
import time
from collections import deque
from dataclasses import replace
from typing import Optional

from geometry_msgs.msg import Wrench
from rclpy.duration import Duration
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Bool, Float64, String
from std_srvs.srv import Trigger

from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.closed_loop.loop import PlantSide, answering
from mwip_ros.core.plants.plant import PlantDiverged
from mwip_ros.core.control.safety import HISTORY, DriverStateMachine, Transition, Watchdog
from mwip_ros.core.closed_loop.trajectory import TrajectoryTable
from mwip_ros.msgs import BadMessage, cdr
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import BEST_EFFORT_INPUT_QOS, DRIVER_STATE_QOS, INPUT_QOS, SERVICE_QOS, qos_for
from mwip_ros.nodes.runtime.diagnostics import ERROR, OK, WARN, StepRate
from mwip_ros.nodes.runtime.driver_state import publish_transition
from mwip_ros.nodes.runtime.guards import PublisherWatch, Rejects
from mwip_ros.nodes.runtime.lockstep import SETTLE_S, LockstepDriver, subscriber_floor
from mwip_ros.nodes.runtime.params import declare
from mwip_ros.nodes.runtime.rclpy_compat import SIDE_DEPTH, PolledInput
from mwip_ros.nodes.loop.plant_runners import RUNNERS
from mwip_ros.nodes.loop.plant_truth import TruthPublishers
from mwip_ros.nodes.runtime.process import EXIT_ERROR, EXIT_FALLEN, GracefulNodeMixin, run_node
from mwip_ros.params import plant_config
from mwip_ros.params.typed import limit_warnings
from mwip_ros.runs import CsvStream

NAME = "plant_sim"
ESTIMATOR = "state_estimator"   # the node whose /diagnostics status a raw plant watches (its namespace's)


class PlantSimNode(Node, GracefulNodeMixin):
    """The plant's stages (:class:`~mwip_ros.core.closed_loop.loop.PlantSide`) as a node; its mode is a runner
    (:mod:`.plant_runners`: lockstep or realtime), which decides when a period is finished."""

    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        self.cfg = plant_config(self.v)
        sc = self.cfg.sensing
        # the driver's state machine (theory 6.8): one for the node's life, handed to every PlantSide (_initial_state)
        self.safety = DriverStateMachine(require_enable=self.cfg.require_enable, max_command=L.LIMITS["torque"])
        self.watchdog = Watchdog(self.v["watchdog_s"])   # realtime: armed at the first state, fed by every good
                                                          # command, checked per tick (the realtime runner)
        self._watch_stamp = 0                             # the stamp of the newest state when it was armed or fed
        self.steps = 0                                    # periods stepped since the start, across resets
        self.rate = StepRate()
        self.transitions: deque = deque(maxlen=HISTORY)   # what driver_state published (the summary's list)
        self.fell_at: Optional[float] = None
        self.diverged_at: Optional[float] = None          # the physics diverged (backend mujoco): the run ended
        self._initial_state()
        self.mode = self.v["mode"]
        self.h = self.cfg.h
        self.period_ns = round(self.h * 1e9)
        self.n_steps = int(round(self.v["duration_s"] / self.h)) if self.v["duration_s"] > 0 else None
        self.extra = (0.0, 0.0)
        self.stamp0 = 0               # realtime: the node clock's time at the start [ns]; lockstep: 0
        self.resets = 0
        self.reset_calls = 0
        self._reset_pending = False   # reset at the next period boundary (lockstep: the state in flight answered)
        self.csv = None               # the csv, streamed as the run goes (opened at its first row)
        self.table = self._new_table()
        self.rejects = Rejects(self.get_logger())
        self.fallen = False
        self.started = False
        self.t_wall0 = None
        self.last_progress = time.monotonic()
        runner = RUNNERS[self.mode]

        pub_qos, in_qos = qos_for(self.mode)   # msgs.qos: lockstep loses nothing, realtime keeps the newest
        self.raw = self.cfg.raw is not None    # sensors.model: raw: the IMU and the encoder, not the state
        self.state_pub = self.imu_pub = self.encoder_pub = None
        if self.raw:
            r = self.cfg.raw
            self.imu_pub = self.create_publisher(Imu, "imu/data_raw", pub_qos)
            self.encoder_pub = self.create_publisher(JointState, "wheel_encoder", pub_qos)
            self.imu_variances = (r.gyro_noise_std ** 2, r.accel_noise_std ** 2)
        else:
            self.state_pub = self.create_publisher(JointState, "joint_states", pub_qos)
        # the truth (.plant_truth): tau_d; the state when the loop reads a measurement (sensing or actuation options,
        # raw sensors); a spatial plant's (backend mujoco, docs/theory.md 6.10) 3D pose and wheel angles
        self.truth = TruthPublishers(self, pub_qos, measured=sc.active or self.raw, spatial=self.plant.spatial)
        self.clock_pub = self.create_publisher(Clock, "/clock", pub_qos) if runner.publishes_clock else None
        cmd_sub = self.create_subscription(Float64, "wheel_torque_cmd", self._on_cmd, in_qos, raw=True)
        if self.plant.spatial:   # the yaw stage's two torques (docs/theory.md 6.13), instead of wheel_torque_cmd
            self.create_subscription(JointState, "wheel_torques_cmd", self._on_wheel_cmd, in_qos, raw=True)
        # the side inputs are read between the node's callbacks, the newest few of each (rclpy_compat.PolledInput):
        # a flood of them cannot queue up in front of the period (the realtime tick, the lockstep command)
        self.wrench_in = PolledInput(self, Wrench, "external_wrench", INPUT_QOS, self._on_wrench, SIDE_DEPTH)
        self.create_service(Trigger, "~/reset", self._on_reset, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, "~/enable", self._on_enable, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, "~/disable", self._on_disable, qos_profile=SERVICE_QOS)
        self.driver_pub = self.create_publisher(String, "driver_state", DRIVER_STATE_QOS)
        # users publish it with any QoS: reliable (nothing lost) and best effort (matches a best-effort publisher);
        # the e-stop is a level (core.control.safety): the latest value heard on each subscription, asserted while one
        # is true
        self.estop_heard: dict = {}
        self.side_inputs = [self.wrench_in] + [
            PolledInput(self, Bool, "emergency_stop", qos, lambda data, via=via: self._on_estop(data, via), SIDE_DEPTH)
            for via, qos in (("reliable", INPUT_QOS), ("best_effort", BEST_EFFORT_INPUT_QOS))]
        self.estimator_status = None
        if self.raw:   # the estimator reports its health on /diagnostics (ERROR: diverged)
            from diagnostic_msgs.msg import DiagnosticArray
            self.estimator_status = f"{self.get_namespace().rstrip('/')}/{ESTIMATOR}"
            self.side_inputs.append(PolledInput(self, DiagnosticArray, "/diagnostics", INPUT_QOS,
                                                self._on_diagnostics, SIDE_DEPTH))
        # one graph, one controller: a second publisher of commands or states means mixed streams
        self.watch = PublisherWatch(self, ["wheel_torque_cmd", "joint_states",
                                           *(("wheel_torques_cmd",) if self.plant.spatial else ()),
                                           *(("imu/data_raw", "wheel_encoder") if self.raw else ())])
        # both runners wait for the graph of core.closed_loop.loop.STAGES' answering stages (lockstep also steps with
        # it): a raw plant's chain starts with the state estimator, the one node listening to the first topic
        answers = answering(estimator=self.raw)
        first_pub = self.imu_pub if self.raw else self.state_pub
        self.lockstep = LockstepDriver(
            self, first_pub, self.clock_pub, cmd_sub,
            need_subs=subscriber_floor(self.v["expected_subscribers"], answers),
            timeout_s=self.v["lockstep_timeout_s"], timeout_param="lockstep_timeout_s", settle_s=SETTLE_S,
            idle_hint="a wheel_torque_cmd (the controller is running but did not answer)",
            also_published=tuple(p for p in (self.encoder_pub,) if p is not None) + self.truth.publishers,
            answers=answers)
        self.runner = runner(self)
        dur = f"{self.v['duration_s']:g} s" if self.n_steps is not None else "until stopped"
        self.get_logger().info(f"{self.mode} plant: h = {self.h * 1e3:.3f} ms, {self.plant.integration}, "
                               f"{dur}, seed {self.cfg.seed}")
        if self.raw:
            r = self.cfg.raw
            self.get_logger().info(
                f"raw sensors: IMU {r.offset:g} m above the axle (gyro noise {r.gyro_noise_std:g} rad/s, bias "
                f"{r.gyro_bias:g} rad/s walking {r.gyro_bias_walk:g} rad/s/sqrt(s), accelerometer noise "
                f"{r.accel_noise_std:g} m/s^2), encoder {r.encoder_counts_per_rev or 'ideal'} counts/rev, "
                f"measurement delay {sc.delay_periods}, actuator delay {sc.actuator_delay_periods} period(s); "
                f"publishing imu/data_raw and wheel_encoder, the true state on true_joint_states (a "
                f"state_estimator publishes joint_states)")
        elif sc.active:
            self.get_logger().info(
                f"sensing: noise std {list(sc.noise_std)} (theta_w, theta_b, theta_w', theta_b'), encoder "
                f"{sc.encoder_counts_per_rev or 'ideal'} counts/rev, measurement delay {sc.delay_periods}, actuator "
                f"delay {sc.actuator_delay_periods} period(s); the true state is on true_joint_states")
        if self.cfg.motor.enabled:
            mc = self.cfg.motor
            self.get_logger().info(f"motor: K_t = {mc.torque_constant:g} N m/A, R = {mc.resistance:g} ohm, V_max = "
                                   f"{mc.voltage_limit:g} V, I_max = {mc.current_limit:g} A ({mc.peak_torque:g} N m at "
                                   f"most); the torque that acted is joint_states' effort")
        for warning in limit_warnings(self.v):   # allowed: a weak drive (or torque_limit) is worth simulating
            self.get_logger().warning(warning)
        self._publish_transition(Transition(0.0, "", self.safety.state, "start",
                                            f"require_enable: {str(self.cfg.require_enable).lower()}"), start=True)

    @property
    def plant(self):
        return self.side.plant

    # --- inputs ---------------------------------------------------------------------------
    def _on_wrench(self, data: bytes) -> None:
        try:
            e = L.parse_external_wrench(data)
        except BadMessage as exc:
            self.rejects("external_wrench", str(exc))
            return
        if e == self.extra:   # the same wrench again: nothing changes, nothing to say
            return
        self.extra = e
        self.get_logger().info(f"external wrench: tau_ext1 += {e[0]:g}, tau_ext2 += {e[1]:g} N m, force.y {e[2]:g} N, "
                               f"torque.z {e[3]:g} N m" if any(e) else "external wrench cleared")

    def _on_estop(self, data: bytes, via: str = "reliable") -> None:
        """``emergency_stop``, a level (module doc): true asserts it (a fault, held), false releases it."""
        try:
            stop = L.parse_bool(data)
        except BadMessage as exc:
            self.rejects("emergency_stop", str(exc))
            return
        was = "emergency_stop" in self.safety.held
        self.estop_heard[via] = stop
        asserted = any(self.estop_heard.values())
        self._publish_transition(self.safety.set_level(self.plant.t, "emergency_stop", asserted,
                                                       "a std_msgs/Bool true"))
        if was and not asserted:
            self.get_logger().warning("driver: emergency stop released; the fault stays latched until ~/reset")

    def _on_diagnostics(self, data: bytes) -> None:
        """A raw plant's state estimator's health, a level (module doc): ERROR asserts it, OK or WARN releases it."""
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.serialization import deserialize_message
        try:
            arr = deserialize_message(bytes(data), DiagnosticArray)
        except Exception:   # another node's report that does not decode: not ours to judge
            return
        for st in arr.status:
            if st.name != self.estimator_status:
                continue
            level = st.level[0] if isinstance(st.level, (bytes, bytearray)) else int(st.level)
            if level not in (OK, WARN, ERROR):   # STALE: no news of its health, the level stays as it was
                continue
            was = "estimator_unhealthy" in self.safety.held
            self._publish_transition(self.safety.set_level(self.plant.t, "estimator_unhealthy", level == ERROR,
                                                           f"{st.name}: {st.message}"))
            if was and level != ERROR:
                self.get_logger().warning(f"driver: {st.name} is healthy again; the fault stays latched until ~/reset")

    def _answer(self, response, answer):
        """A std_srvs/Trigger response from core.control.safety's answer (and its transition published)."""
        self._publish_transition(answer.transition)
        response.success, response.message = answer.success, answer.message
        return response

    def _on_enable(self, request, response):
        return self._answer(response, self.safety.enable(self.plant.t))

    def _on_disable(self, request, response):
        return self._answer(response, self.safety.disable(self.plant.t))

    def _on_reset(self, request, response):
        """``~/reset``: the initial state at the run's start time, at the next period boundary (module doc); the
        driver's fault, if any, is cleared at once and the driver goes back to its start state."""
        self.reset_calls += 1
        response.success = True
        if self.done:
            response.success = False
            response.message = "the run has ended; nothing to reset"
            return response
        faulted = self.safety.faulted
        driver = self.safety.reset(self.plant.t)
        self._publish_transition(driver.transition)
        if faulted and driver.success:   # the watchdog counts again from the reset
            self.watchdog.reset()
            if self.started:
                self._arm_watchdog()
        self._plant_reset_answer(response)   # the robot's reset applies no torque: done even if the driver's is refused
        response.success = driver.success
        response.message += f"; driver: {driver.message}"
        return response

    def _plant_reset_answer(self, response) -> None:
        """The plant's part of a ``~/reset`` answer (module doc), the reset made pending if there is one to make."""
        if self.plant.k == 0:   # state 0 is in flight (or not sent yet): a new state 0 would repeat its stamp
            response.message = ("already at the initial state (t = 0: no period has run since the "
                                + ("last reset" if self.resets else "start") + "); nothing to reset")
        elif self._reset_pending:
            response.message = f"a reset is already pending (#{self.resets + 1}); this call joins it"
        else:
            self._reset_pending = True
            response.message = (f"reset #{self.resets + 1} at t = {self.plant.t:.3f} s: back to the initial state "
                                f"{self.runner.reset_when}; stamps restart at the run's start")

    def _initial_state(self) -> None:
        """The robot at its initial state, with fresh noise streams (sensors, D_w) and an empty actuator delay."""
        self.side = PlantSide(self.cfg)
        self.side.safety = self.safety   # the one machine: a reset restores the plant, ~/reset the driver

    def _new_table(self) -> TrajectoryTable:
        """The run's table, bounded: rows kept to the metrics window's end (and the newest), every row streamed to
        the csv."""
        return TrajectoryTable(drive=self.cfg.motor.enabled or self.cfg.raw is not None, pose=self.plant.spatial,
                               keep_until=metrics.WINDOW[1] + self.h, sink=self._csv_row if self.v["csv"] else None)

    def _csv_row(self, k: int, row) -> None:
        """Row k of the run to the csv (with its message stamp in seconds, realtime)."""
        if self.csv is None:
            self.csv = CsvStream(self.v["csv"], self.table.names + (["stamp"] if self.stamp0 else []))
        self.csv.row((*row, self._stamp(k) * 1e-9) if self.stamp0 else row)

    def _reset(self) -> str:
        dropped, t = len(self.table), self.plant.t
        self._initial_state()
        self.table = self._new_table()
        if self.csv is not None:
            self.csv.restart()
        self.resets += 1
        self._reset_pending = False
        self.fallen, self.fell_at = False, None
        self.watchdog.reset()   # armed again by the new run's state 0
        self._arm_watchdog()
        text = (f"reset #{self.resets} at t = {t:.3f} s: back to the initial state at t = 0; stamps restart at "
                f"the run's start (the csv keeps the run from here; {dropped} periods before it are only in a "
                f"recording, as a segment of their own)")
        self.get_logger().warning(text)
        return text

    def _on_cmd(self, data: bytes) -> None:
        try:
            u = L.parse_command(data)
        except BadMessage as exc:
            self.rejects("wheel_torque_cmd", str(exc))
            try:
                value = cdr.decode_float64(data)
            except cdr.CdrError:   # not a Float64 at all: not a command, only rejected
                return
            self._publish_transition(self.safety.check_command(self.plant.t, value))   # non-finite or implausible
            self.runner.on_bad_command()
            return
        self.watchdog.feed(time.monotonic())
        self._watch_stamp = self._stamp()
        self.runner.on_command(u)

    def _on_wheel_cmd(self, data: bytes) -> None:
        """wheel_torques_cmd (theory 6.13): (u_L, u_R) answers the state; malformed: rejected and counted, and a torque
        not finite or implausible faults the driver (``bad_command``), as on wheel_torque_cmd."""
        try:
            _stamp, ul, ur = L.parse_wheel_torques(data)
        except BadMessage as exc:
            self.rejects("wheel_torques_cmd", str(exc))
            try:
                effort = cdr.decode_joint_state(data)[5]
            except cdr.CdrError:
                return
            bad = [v for v in effort if not (math.isfinite(v) and abs(v) <= self.safety.max_command)]
            if bad:
                self._publish_transition(self.safety.check_command(self.plant.t, bad[0]))
                self.runner.on_bad_command()
            return
        self.watchdog.feed(time.monotonic())
        self._watch_stamp = self._stamp()
        self.runner.on_command((ul, ur))

    # --- the driver's state machine (docs/theory.md 6.8) ----------------------------------------------------
    def _fault(self, reason: str, detail: str, **extra) -> None:
        self._publish_transition(self.safety.fault(self.plant.t, reason, detail), **extra)

    def _arm_watchdog(self) -> None:
        """A run's first state is out (the start, a reset): the watchdog counts from now
        (core.control.safety.Watchdog)."""
        self.watchdog.arm(time.monotonic())
        self._watch_stamp = self._stamp()

    def _publish_transition(self, tr: Optional[Transition], start: bool = False, **extra) -> None:
        """Log a transition (one line), publish it on ``driver_state`` and keep it for the summary."""
        if tr is not None:
            publish_transition(self, self.driver_pub, self.transitions, tr, self._stamp(), start, **extra)

    # --- the plant's stages, the same for both runners ------------------------------------------
    def _stamp(self, k: Optional[int] = None) -> int:
        """The stamp of state ``k`` (default: the current one) [ns]."""
        return self.stamp0 + (self.plant.k if k is None else k) * self.period_ns

    def _sample_messages(self):
        """Period k's messages as published (stage ``sensors``, once per step): [(publisher, bytes)], the
        measured state (core.plants.sensing) on ``joint_states``, or a raw plant's sample (core.plants.raw_sensors) on
        ``imu/data_raw`` and ``wheel_encoder``; the truth beside them when sensing or actuation options or
        raw sensors are on."""
        p = self.plant
        stamp = self._stamp()
        self.truth.sample(stamp, p)
        measured, u_prev = self.side.sense()
        yaw_rate = self.side.sense_yaw_rate() if p.spatial else None   # the yaw stage's input (theory 6.13)
        if not self.raw:   # a spatial plant adds the gyro's yaw rate (raw: the IMU's z axis)
            return [(self.state_pub, L.encode_state(stamp, measured, u_prev, yaw_rate))]
        gyro_var, accel_var = self.imu_variances
        return [(self.imu_pub, L.encode_imu(stamp, measured.gyro, measured.accel_x, measured.accel_z, gyro_var,
                                            accel_var, yaw_rate or 0.0)),
                (self.encoder_pub, L.encode_encoder(stamp, measured.encoder, measured.encoder_rate, u_prev))]

    def _finish_period(self, u_cmd) -> bool:
        """Stages ``drive`` and ``plant`` for the command answering state k (a torque, or the yaw stage's pair
        (u_L, u_R)): record row k with the torque that acts, publish tau_d at t_k; integrate unless the run ends.
        True = ended."""
        p = self.plant
        self.steps += 1
        pair = u_cmd if isinstance(u_cmd, tuple) else None
        u, tau_d = self.side.act(0.0 if pair else u_cmd, self.extra, wheels=pair)
        self.truth.lumped_disturbance(self._stamp(), tau_d)
        self.table.append(p.t, p.x, u, tau_d=tau_d, pose=p.pose)
        if p.fallen and not self.fallen:
            self.fallen, self.fell_at = True, p.t
            self._publish_transition(self.safety.check_fall(p.t, p.x[1], self.cfg.fall_angle))
            text = f"FALLEN at t = {p.t:.3f} s: |theta_b| = {abs(p.x[1]):.4f} > fall_angle {self.cfg.fall_angle}"
            if self.v["exit_on_fall"]:
                self.finish(EXIT_FALLEN, text)
                return True
            self.get_logger().error(f"{text}; the robot lies where it fell, the driver holds zero torque in fault "
                                    f"until ~/reset (exit_on_fall: false)")
        if self.n_steps is not None and p.k >= self.n_steps:
            if self.fallen:
                self.finish(EXIT_FALLEN, f"the run ended with the robot down (FALLEN at t = {self.fell_at:.3f} s, "
                                         f"no ~/reset since)")
            else:
                self.finish()
            return True
        if self.fallen:
            self._lie()
            self.table.set_drive(p.u_prev, p.saturation)   # no torque acted over period k: exactly zero
            return False
        try:
            self.side.advance(u, self.extra)
            self.table.set_drive(p.u_prev, p.saturation)   # the torque that acted over period k (motor model)
            finite = all(map(math.isfinite, p.x))
        except (ArithmeticError, ValueError):  # e.g. sin of an infinite angle
            finite = False
        except PlantDiverged as exc:   # the physics diverged (backend mujoco, theory 6.10): a driver fault, exit 1
            tr = self.safety.fault(p.t, "diverged", str(exc))   # its line names the time and the cause
            self.diverged_at = p.t
            self._publish_transition(tr)
            self.finish(EXIT_ERROR, None if tr else f"{exc}; stopping")   # (in another fault already: said here)
            return True
        if not finite:
            self.finish(EXIT_ERROR, f"state became non-finite at t = {p.t:.3f} s; stopping")
            return True
        return False

    def _lie(self) -> None:
        """A fallen robot (``exit_on_fall: false``) lies where it fell, at rest: the model has no ground (its body
        would swing through the floor), so the period passes without integrating, no torque acting."""
        self.plant.lie()   # MuJoCo's velocities too (core.plants.mujoco_plant.MujocoPlant.lie)

    def _start(self, why: str) -> None:
        self.started = True
        self.t_wall0 = time.monotonic()
        self.rate.add(self.t_wall0, self.steps)
        self.get_logger().info(f"{why}; starting {self.mode} run")
        self.runner.start()

    def poll_inputs(self) -> None:
        """The side inputs (external_wrench, emergency_stop, a raw plant's /diagnostics): what came since the last
        look, at most :data:`SIDE_DEPTH` of each, in order."""
        for side in self.side_inputs:
            side.poll()

    def spin_step(self, executor) -> None:
        self.poll_inputs()
        if not self.started:
            ready = self.lockstep.wait_for_graph()
            if ready:
                self._start("graph matched")
            elif ready is False:  # both runners wait for the graph; what a timeout means is theirs
                self.runner.graph_timed_out()
            executor.spin_once(timeout_sec=0.02)
            return
        executor.spin_once(timeout_sec=0.05)
        self._progress()
        crowded = self.watch.check()
        if not self.done:
            self.runner.watch(crowded)

    def _progress(self) -> None:
        now = time.monotonic()
        if now - self.last_progress < 2.0 or self.t_wall0 is None:
            return
        self.last_progress = now
        total = f" / {self.n_steps * self.h:g}" if self.n_steps is not None else ""
        rate = self.rate.add(now, self.steps)   # over the last seconds of wall time: a reset restarts k, not this
        self.get_logger().info(f"t = {self.plant.t:.2f}{total} s simulated, "
                               f"{rate or 0.0:.0f} steps/s, theta_b = {self.plant.x[1]:+.4f} rad")

    # --- health (nodes.runtime.diagnostics) -------------------------------------------------------------
    def diagnostic_count(self) -> int:
        return self.steps   # grows across resets (plant.k goes back to 0)

    def diagnostic_status(self):
        p = self.plant
        values = {"mode": self.mode, "t_sim_s": f"{p.t:.3f}", "theta_b_rad": f"{p.x[1]:+.5f}"}
        values.update(self.runner.diagnostic_values())
        sm = self.safety
        values.update({"driver_state": sm.state, "fault_reason": sm.fault_reason or "none",
                       "held": ", ".join(sm.held) or "none"})
        level, driver = sm.diagnostic()
        if self.fallen:
            down = "" if self.done else "; lying in fault until ~/reset"
            return ERROR, f"FALLEN at t = {self.fell_at:.3f} s{down}", values
        if level == ERROR:
            return ERROR, f"driver {driver}", values
        if not self.started:
            return WARN, f"waiting for the graph (missing: {self.lockstep.missing()})", values
        problem = self.runner.diagnostic_problem()
        if problem:
            return ERROR, problem, values
        if level == WARN:
            return WARN, f"driver disabled (zero torque until ~/enable); {self.mode} run at t = {p.t:.2f} s", values
        return OK, f"{self.mode} run at t = {p.t:.2f} s", values

    # --- end of run: the one report of both runners -------------------------------------------------
    def note_unanswered_state(self) -> None:
        """At the lockstep timeout: the robot down in the last state, which no stage answered, is a fall there."""
        if self.plant.fallen and not self.fallen:
            self.fallen, self.fell_at = True, self.plant.t

    def _verdict(self) -> str:
        """The run's end in a word: a diverged simulation is never scored upright, nor a run a failure ended."""
        if self.diverged_at is not None or self.fallen:
            return "DIVERGED" if self.diverged_at is not None else f"FALLEN (fell at {self.fell_at:.3f} s)"
        return f"ended by an error at t = {self.plant.t:.3f} s" if self.failure else "upright"

    def on_shutdown(self) -> None:
        log = self.get_logger()
        if self.stop_signal is not None and self.n_steps is not None and not self.done:
            self.finish(128 + self.stop_signal)  # interrupted: the run did not reach duration_s
            log.warning(f"interrupted at t = {self.plant.t:.3f} s of {self.n_steps * self.h:g} s")
        wall = (time.monotonic() - self.t_wall0) if self.t_wall0 else 0.0
        n, steps = len(self.table), self.steps   # the table holds the run since the last reset; steps all of it
        for pub in (self.state_pub, self.imu_pub, self.encoder_pub, self.clock_pub, self.driver_pub,
                    *self.truth.publishers):
            if pub is not None:  # let a recorder receive the last states before this process exits
                pub.wait_for_all_acked(Duration(seconds=2.0))
        summary = {"mode": self.mode, "control_rate_hz": 1.0 / self.h, "periods": n, "steps": steps, "wall_s": wall,
                   "steps_per_s": steps / wall if wall > 0 else None, "fallen": self.fallen,
                   "diverged_at": self.diverged_at,
                   "exit_code": self.exit_code, "rejected": dict(self.rejects.counts),
                   "resets": self.resets, "reset_calls": self.reset_calls,
                   "driver_state": self.safety.state, "fault_reason": self.safety.fault_reason,
                   "transitions": list(self.transitions)}
        if n:
            since = f" since the last of {self.resets} reset(s), {steps} in all" if self.resets else ""
            log.info(f"{self.mode} run: {n} periods{since}, {self.table.last('t'):.3f} s simulated in {wall:.2f} s "
                     f"wall ({steps / max(wall, 1e-9):.0f} steps/s); {self._verdict()}")
        summary.update(self.runner.summary())
        log.info(f"rejected messages: {self.rejects.summary()}")
        self.table.flush()
        if self.csv is not None:
            self.csv.close()
        if n:
            run = self.table.trajectory(NAME, self.fallen, self.h)   # to the window's end, and the last row
            t_end = run.t[-1]
            win = metrics.WINDOW if t_end >= metrics.WINDOW[1] - 1e-9 else (t_end / 2, t_end)
            failed = self.fell_at if self.diverged_at is None else self.diverged_at   # never upright when diverged
            m = metrics.compute(run.columns, win, self.cfg.fall_angle, t_fall=failed)
            if self.table.dropped and self.table.drive:   # saturated_s is of the whole run
                m = replace(m, saturated_s=self.table.saturated * self.h)
            summary["metrics"] = {"window_s": list(win), **m.as_dict()}
            log.info(f"metrics t in [{win[0]:g}, {win[1]:g}] s: theta_b p2p = {m.theta_b_p2p:.5f} rad, RMS = "
                     f"{m.theta_b_rms:.5f} rad, max|theta_b| = {m.theta_b_max_abs:.5f} rad, u RMS = {m.u_rms:.3f} "
                     f"N m")
            if self.csv is not None:
                log.info(f"wrote {self.v['csv']}")
        if self.v["summary_json"]:
            with open(self.v["summary_json"], "w") as f:
                json.dump(metrics.json_safe(summary), f, indent=1, allow_nan=False)
            log.info(f"wrote {self.v['summary_json']}")


def main(argv=None) -> int:
    return run_node(PlantSimNode, argv)


if __name__ == "__main__":
    sys.exit(main())
