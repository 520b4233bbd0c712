"""``dscndo_controller``: DSC / DSCNDO (eq. 16-28, 19-21), the LQR baseline, or any registered law, as a node.

The parameter ``law`` picks a law's family from the registry (``core.laws``: ``dsc``, the paper;
``lqr``, the baseline, whose gain K, designed from ``lqr.Q``, ``lqr.R`` and the nominal model, is
logged at start-up and whenever it changes; a plug-in's, ``$MWIP_ROS_LAWS``); ``use_observer``
adds the observer term u_taud (DSCNDO, LQR+NDO).  All of them change at run time (``ros2 param
set``); switching to a law starts it afresh (DSC: its filter), switching ``use_observer`` keeps it.

Subscribes ``joint_states`` and (with ``use_observer``) ``disturbance_estimate``,
pairs them by stamp, publishes ``wheel_torque_cmd`` once per state and the
internal signals on ``controller_internals`` (a JointState whose ``name`` lists the law's
``internal_names``, for DSC and LQR S1, S2, x4d, x4_bar, u_dsc, u_taud, u, x1, and whose
``position`` holds them).
A message it cannot use (malformed, non-finite, implausible, a stamp outside the
stream's window; :mod:`.guards`) is rejected, counted and logged and changes nothing;
so is a state for which the law gives a non-finite command (nothing is published).
A stream that restarted re-initialises the filter.  At most ``_MAX_PENDING`` states
and estimates wait for their partner.

With ``motion.enabled`` (docs/theory.md 6.11) the law tracks references: from ``motion.profile`` (offline and
lockstep scenarios: the graph then equals ``mwip_sim``) or, without one, from ``cmd_vel`` (geometry_msgs/Twist,
REP-103: linear.x, angular.z).  A Twist only sets the target (:class:`mwip_ros.core.control.motion.Shaper`); the
references of period k are made inside the period, in ``core.closed_loop.loop.command``, as offline.  A Twist that is
not one, not finite or absurd is dropped by DDS (a content filter, ``layouts.CMD_VEL_FILTER``: logged and on
/diagnostics as such, not counted) or, where the middleware does not filter, rejected and counted; one over the limits
is clipped and counted; no cmd_vel for
``motion.cmd_vel_timeout_s`` ramps the references to zero (logged once per silence, counted on /diagnostics).
While no torque acts (``driver_state``, the plant's driver: disabled, in fault, the emergency stop held; docs/theory.md
6.8) the references hold at the measured state (the position target, v* and psi'* do not advance), the yaw integral
stays zero and a cmd_vel is not taken (counted): on enable the robot starts from where it is, at rest.  Until a
``driver_state`` comes the torque is taken to act.  ``cmd_vel`` and ``driver_state`` are read with each state and
between the executor's callbacks, the newest one (:class:`~mwip_ros.nodes.runtime.rclpy_compat.PolledInput`), not as
they arrive: a flood of them costs the controller one message per look.  In realtime cmd_vel is read on a DDS
participant of its own whose threads run at nice 19 (:class:`~mwip_ros.nodes.runtime.rclpy_compat.IsolatedInput`):
a flood of valid Twists does not share the receive thread of ``joint_states``.
With motion on and a state that carries the gyro's yaw rate (a spatial plant's ``joint_states``: the joint ``yaw``),
the yaw stage runs after the law (docs/theory.md 6.13, ``core.control.yaw``) and the answer is the two wheels' torques
on ``wheel_torques_cmd`` (sensor_msgs/JointState, names wheel_left_joint, wheel_right_joint, effort [u_L, u_R]) instead
of ``wheel_torque_cmd``.
"""
from __future__ import annotations

import math
import sys

from geometry_msgs.msg import Twist, WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String

from mwip_ros import params as P
from mwip_ros.core import laws
from mwip_ros.core.identification.excitation import Excitation
from mwip_ros.core.closed_loop.loop import command
from mwip_ros.core.control.motion import ABSURD_SPEED, ABSURD_YAW_RATE, Shaper
from mwip_ros.core.control.yaw import YawLoop, wheel_torques
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import DRIVER_STATE_QOS, qos_for
from mwip_ros.params.motion import motion as motion_config, wheel_limit_warning, yaw as yaw_config
from mwip_ros.nodes.runtime.diagnostics import OK
from mwip_ros.nodes.runtime.guards import REPEAT, RESTART, STAMP_WINDOW_PERIODS, PublisherWatch, Rejects
from mwip_ros.nodes.runtime.content_filter import filter_readers
from mwip_ros.nodes.runtime.state_input import StateInput
from mwip_ros.nodes.runtime.params import declare, plant_file_values
from mwip_ros.nodes.runtime.rclpy_compat import IsolatedInput, PolledInput
from mwip_ros.nodes.runtime.process import GracefulNodeMixin, run_node

NAME = "dscndo_controller"
_MAX_PENDING = 64


def _installed(values) -> None:
    """ParamError naming ``law`` when the law chosen needs an optional package that is not installed (mpc: daqp):
    at start-up one line and exit 2, at run time the change is refused; the other laws run without it."""
    law = laws.lookup(values["law"], values["use_observer"])
    text = laws.unavailable(law) if law is not None else None
    if text:
        raise P.ParamError("law", text)


def _drive_values(argv) -> dict:
    """plant_sim's drive (``params.motion.DRIVE_KEYS``) from the plant_sim sections of the command line's parameter
    files, the later file winning (the yaw stage's wheel limit is derived from it)."""
    from mwip_ros.params.motion import DRIVE_KEYS
    return plant_file_values(argv, DRIVE_KEYS)


class DscndoController(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv, on_change=self._on_change, check=_installed)
        self.nominal, self.h = P.physical(self.v, "nominal"), P.period(self.v)
        # one instance of each family's law (core.laws) whose packages are installed; use_observer wraps it with
        # the observer term
        self.laws = laws.instances(self.v, self.nominal, self.h)
        self._composed = {}
        for law in self.laws.values():
            self._warn(law)
        # identification's known torque (core.identification.excitation), added to the command
        exc = P.typed.excitation(self.v)
        self.excitation = Excitation(exc, self.h) if exc is not None else None
        self.stamp0 = None    # the stamp of the run's first state: period k of the excitation counts from it
        self.states = {}      # stamp -> State waiting for an estimate
        self.estimates = {}   # stamp -> (tau_hat1, tau_hat2) waiting for a state
        self.last_answered = None
        self.count = 0
        self.rejects = Rejects(self.get_logger())
        pub_qos, in_qos = qos_for(self.v["mode"])   # msgs.qos: lockstep loses nothing, realtime keeps the newest
        self.cmd_pub = self.create_publisher(Float64, "wheel_torque_cmd", pub_qos)
        self.cmds_pub = self.create_publisher(JointState, "wheel_torques_cmd", pub_qos)   # the yaw stage's pair
        self.int_pub = self.create_publisher(JointState, "controller_internals", pub_qos)
        state_sub = self.create_subscription(JointState, "joint_states", self._on_state, in_qos, raw=True)
        estimate_sub = self.create_subscription(WrenchStamped, "disturbance_estimate", self._on_estimate, in_qos,
                                                raw=True)
        self.input = StateInput(self, self.rejects, STAMP_WINDOW_PERIODS * round(P.period(self.v) * 1e9),
                                "controller")
        if self.v["mode"] == "realtime":   # a flood of absurd inputs is dropped by DDS (issue 46)
            self.input.filter_readers({"joint_states": (state_sub, L.STATE_FILTER),
                                       "disturbance_estimate": (estimate_sub, L.ESTIMATE_FILTER)})
        self.watch = PublisherWatch(self, ["joint_states", "disturbance_estimate"])
        mc = motion_config(self.v)   # docs/theory.md 6.11: None while motion.enabled is false (nothing changes)
        self.motion = Shaper(mc, self.h, self.nominal) if mc is not None else None
        # theory 6.13, with a yaw rate: the wheel limit is the drive's (plant_sim's sections of the same files) unless
        # motion.yaw_wheel_limit says less (more: the drive's, and a warning)
        with_drive = {**self.v, **_drive_values(argv)}
        self.yaw = YawLoop(yaw_config(with_drive), self.h) if mc is not None else None
        if mc is not None and wheel_limit_warning(with_drive):
            self.get_logger().warning(wheel_limit_warning(with_drive))
        self.yaw_rates = {}   # stamp -> the gyro's yaw rate of that state (a spatial plant's joint_states)
        # the plant's driver (docs/theory.md 6.8): None until a driver_state came (the torque is taken to act)
        self.driver = None
        self.ignored = 0            # cmd_vel that came while no torque acts: not taken
        self.driver_in = PolledInput(self, String, "driver_state", DRIVER_STATE_QOS, self._on_driver_state)
        self.cmd_vel_sub = None
        self.cmd_vel_filtered = False   # layouts.CMD_VEL_FILTER on the cmd_vel reader (the middleware drops)
        if mc is not None and not (mc.profile or mc.yaw_profile):   # cmd_vel sets the target; the newest counts
            from rclpy.qos import QoSProfile, ReliabilityPolicy
            qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
            if self.v["mode"] == "realtime":   # a participant of its own at the lowest priority (issue 46 item 2)
                try:
                    self.cmd_vel_sub = IsolatedInput(self, Twist, "cmd_vel", qos, self._on_cmd_vel)
                except Exception as exc:   # rcl could not make a second context: the node's own participant
                    self.get_logger().warning(f"cmd_vel on the node's own participant ({exc}): a flood of valid "
                                              f"Twists shares the receive thread of joint_states")
            if self.cmd_vel_sub is None:
                self.cmd_vel_sub = PolledInput(self, Twist, "cmd_vel", qos, self._on_cmd_vel)
            self.cmd_vel_filtered = self._filter_cmd_vel()
            if isinstance(self.cmd_vel_sub, IsolatedInput):
                self.get_logger().info(f"cmd_vel is read on a DDS participant of its own, its "
                                       f"{self.cmd_vel_sub.niced} threads at nice {self.cmd_vel_sub.nice}: a flood "
                                       f"of valid Twists takes only the CPU the loop leaves")
        self.get_logger().info(self._ready_text())

    @property
    def ctrl(self) -> laws.Law:
        """The law in use: the family's law, with the observer term when ``use_observer``."""
        family, observer = self.v["law"], self.v["use_observer"]
        law = self.laws.get(family)
        if law is None or observer:
            key = (family, bool(observer))
            if key not in self._composed:   # around the family's instance: its state survives the switch
                cls = laws.variant(family, observer)
                self._composed[key] = cls.wrap(law) if law is not None and hasattr(cls, "wrap") else \
                    cls.from_params(self.v, self.nominal, self.h)
            law = self._composed[key]
        return law

    def _name(self) -> str:
        return laws.variant(self.v["law"], self.v["use_observer"]).title

    def _describe(self) -> str:
        text = self.ctrl.summary()
        return f"{self._name()} ({text})" if text else self._name()

    def _ready_text(self) -> str:
        ctrl = self.ctrl
        own = ", ".join(t for t in (ctrl.summary(), ctrl.design_text(self.v)) if t)
        others = "".join(f"; ({law.design_text(self.v)}, not in use)" for family, law in self.laws.items()
                         if family != self.v["law"] and law.announce and law.design_text(self.v))
        mc = self.motion.cfg if self.motion is not None else None
        moving = "" if mc is None else (
            f"; tracking motion.profile ({len(mc.profile)} points, yaw_profile {len(mc.yaw_profile)}; cmd_vel is not "
            f"read)" if mc.profile or mc.yaw_profile else
            f"; tracking cmd_vel (|v| <= {mc.max_speed:g} m/s, {mc.max_accel:g} m/s^2, |psi'| <= {mc.max_yaw_rate:g} "
            f"rad/s, stop after {mc.timeout_s:g} s without one)")
        return f"{self._name()} ready: {own}{others}{moving}"

    def _warn(self, law) -> None:
        for text in law.warnings():
            self.get_logger().warning(text)

    def _on_change(self, changed):
        changed = set(changed)
        for law in self.laws.values():   # every law's design was checked before the change was accepted
            if set(law.param_keys) & changed:
                try:
                    law.params = type(law).design(self.v, self.nominal, self.h)
                except (ArithmeticError, ValueError) as exc:   # not expected: params.schema.check_derived designed it
                    self.get_logger().error(f"{law.title}: {exc}; its parameters stay as they were")
                    continue
                self._warn(law)
                text = law.design_text(self.v)
                if text:
                    self.get_logger().info(text)
        if "law" in changed:
            self.ctrl.reset()   # the law starts afresh (DSC: its filter) from the next state
        if {"law", "use_observer"} & changed:
            self.get_logger().info(f"law now {self._describe()}")

    def _filter_cmd_vel(self) -> bool:
        """A DDS content filter on cmd_vel (layouts.CMD_VEL_FILTER): a Twist whose linear.x or angular.z is not
        finite or absurd, or that cannot be deserialized, is dropped by the middleware, in C++, before the reader's
        depth-1 history (issue 46 item 2): a flood of them cannot displace the operator's valid command, and Fast DDS
        filters at the writer when it can, so such a flood costs this process nothing.  What it drops is not counted
        (the log and /diagnostics' ``cmd_vel_filter`` say so); Shaper.command still judges what passes."""
        return filter_readers(self.get_logger(), {"cmd_vel": (self.cmd_vel_sub, L.CMD_VEL_FILTER)},
                              f"a Twist whose linear.x is not finite or beyond {ABSURD_SPEED:g} m/s, or angular.z "
                              f"beyond {ABSURD_YAW_RATE:g} rad/s, or that cannot be deserialized,")

    @property
    def driving(self) -> bool:
        """Whether the torque acts: the driver enabled, or no driver_state yet."""
        return self.driver in (None, "enabled")

    def _on_driver_state(self, data: bytes) -> None:
        try:
            state = L.parse_driver_state(data)
        except BadMessage as exc:
            self.rejects("driver_state", str(exc))
            return
        if state != self.driver and self.motion is not None:
            self.get_logger().info(f"driver {state}: " + (
                "the references start from the measured state" if state == "enabled" else
                "no torque acts; the references hold at the measured state and cmd_vel is not taken"))
        self.driver = state

    def _poll_side_inputs(self) -> None:
        """driver_state and cmd_vel: what came since the last look (the newest of each: depth 1)."""
        self.driver_in.poll()
        if self.cmd_vel_sub is not None:
            self.cmd_vel_sub.poll()

    def spin_step(self, executor) -> None:
        """Between the executor's callbacks too (a command before the first state is taken then, within 0.1 s)."""
        self._poll_side_inputs()
        GracefulNodeMixin.spin_step(self, executor)

    def _on_state(self, data: bytes) -> None:
        self._poll_side_inputs()   # before the state is answered: what came before it counts for it
        taken = self.input.take(data)
        if taken is None:
            return
        verdict, stamp, x, _u_prev, _last = taken
        if verdict == REPEAT:
            return  # a resent state: one command per state
        if verdict == RESTART:
            for law in (*self.laws.values(), *self._composed.values()):
                law.reset()
            self.states.clear()
            self.estimates = {s: e for s, e in self.estimates.items() if s >= stamp}
            self.last_answered = None
            self.stamp0 = None
            if self.motion is not None:
                self.motion.reset()   # the references start again from the new stream's first state
                self.yaw.reset()
            self.yaw_rates.clear()
        if self.stamp0 is None:
            self.stamp0 = stamp
        if self.yaw is not None:
            try:
                w = L.parse_yaw_rate(data)
            except BadMessage as exc:
                self.rejects("joint_states", str(exc))
                return
            if w is not None:
                self.yaw_rates[stamp] = w
        self.states[stamp] = x
        self._try(stamp)

    def _on_estimate(self, data: bytes) -> None:
        try:
            stamp, t1, t2 = L.parse_wrench(data)
        except BadMessage as exc:
            self.rejects("disturbance_estimate", str(exc))
            return
        if self.last_answered is not None and stamp <= self.last_answered:
            return  # an estimate answering a resent state: its state is answered already
        last, window_ns = self.input.guard.last, self.input.guard.window_ns
        if last is not None and stamp > last + window_ns:
            self.rejects("disturbance_estimate", f"stamp {stamp * 1e-9:.6f} s is ahead of the states "
                                                 f"({last * 1e-9:.6f} s) by more than {window_ns * 1e-9:g} s")
            return
        self.estimates[stamp] = (t1, t2)
        self._trim()
        self._try(stamp)

    def _try(self, stamp: int) -> None:
        if stamp not in self.states:
            return
        tau_hat = self.estimates.get(stamp)
        ctrl = self.ctrl
        if ctrl.observer and tau_hat is None:
            self._trim()
            return  # wait for the estimate of this very state
        x = self.states.pop(stamp)
        self.estimates.pop(stamp, None)
        before = ctrl.snapshot()
        shaped = self.motion.snapshot() if self.motion is not None else None
        k = round((stamp - self.stamp0) / (self.h * 1e9)) if self.stamp0 is not None else 0
        driving = self.driving
        gap = round((stamp - self.last_answered) / (self.h * 1e9)) if self.last_answered is not None else 1
        if gap > 1:   # realtime: states lost; the law's filters (DSC's eq. 25) advance over the time that passed
            ctrl.elapsed(gap * self.h)
        try:   # core.closed_loop.loop: the law stage (no torque acting: the references hold)
            u, internals = command(ctrl, x, tau_hat, self.excitation, k, self.motion, driving)
            ok = math.isfinite(u) and ctrl.finite()
        except (ArithmeticError, ValueError):
            ok = False
        if not ok:
            ctrl.restore(before)  # keep the law's state as it was: setting a bad gain back repairs the loop
            if shaped is not None:
                self.motion.restore(shaped)   # and the references' (the period did not happen)
            self.rejects("joint_states", f"the law gives no finite command for t = {stamp * 1e-9:.3f} s "
                                         f"({self._describe()}); nothing published")
            return
        if self.motion is not None and self.motion.stopped_now:
            self.get_logger().warning(f"cmd_vel: none for {self.motion.cfg.timeout_s:g} s: the references ramp to zero "
                                      f"and the robot holds its position (stop #{self.motion.timeouts})")
        w = self.yaw_rates.pop(stamp, None)
        if w is not None:   # stage yaw (docs/theory.md 6.13): the two wheels' torques answer the state
            u_psi = self.yaw.step(self.motion.ref.dpsi, w, u) if driving else self.yaw.idle(w)
            self.cmds_pub.publish(L.encode_wheel_torques(stamp, *wheel_torques(u, u_psi, 0.0)))
        else:
            self.cmd_pub.publish(L.encode_command(u))
        names = ctrl.internal_names + (("excitation",) if self.excitation is not None else ())
        self.int_pub.publish(L.encode_internals(stamp, internals, names))
        self.input.answered(stamp)
        self.last_answered = stamp
        self.count += 1
        for d in (self.states, self.estimates, self.yaw_rates):  # usually empty by now: drop what is older
            if d:
                for s in [s for s in d if s < stamp]:
                    del d[s]

    def _on_cmd_vel(self, data: bytes) -> None:
        """A Twist sets the target of the coming periods (core.control.motion.Shaper.command), or is rejected and
        counted."""
        try:
            vx, wz = L.parse_twist(data)
        except BadMessage as exc:
            self.rejects("cmd_vel", str(exc))
            self.motion.rejected += 1
            return
        if not self.driving:   # no torque acts: a command now would be stored up and hit the robot on enable
            self.ignored += 1
            if self.ignored in (1, 10) or self.ignored % 1000 == 0:
                self.get_logger().warning(f"cmd_vel while the driver is {self.driver}: not taken ({self.ignored} so "
                                          f"far); enable the driver first")
            return
        why = self.motion.command(vx, wz)
        if why is not None:
            self.rejects("cmd_vel", why)

    def _trim(self):
        for d in (self.states, self.estimates, self.yaw_rates):
            while len(d) > _MAX_PENDING:
                d.pop(min(d))

    def diagnostic_count(self) -> int:
        return self.count

    def diagnostic_status(self):
        values = {"commands": self.count, "law": self._name(), "waiting_states": len(self.states),
                  "driver": self.driver or "unknown", "input_filter": self.input.filter_status()}
        if self.motion is not None:   # docs/theory.md 6.11: the stops and the refused or clipped cmd_vel
            m = self.motion
            values.update(cmd_vel_accepted=m.accepted, cmd_vel_timeouts=m.timeouts, cmd_vel_rejected=m.rejected,
                          cmd_vel_clipped=m.clipped, cmd_vel_not_driving=self.ignored,
                          cmd_vel_filter="on: non-finite or absurd Twists are dropped by DDS, not counted"
                          if self.cmd_vel_filtered else "off",
                          v_ref=m.ref.v if m.ref is not None else 0.0)
        return OK, f"{self._describe()} answering", values

    def on_shutdown(self) -> None:
        self.get_logger().info(f"answered {self.count} states; rejected: {self.rejects.summary()}")
        if self.motion is not None:
            m = self.motion
            self.get_logger().info(f"cmd_vel: {m.accepted} accepted, {m.timeouts} timeout stop(s), {m.rejected} "
                                   f"rejected, {m.clipped} clipped")


def main(argv=None) -> int:
    return run_node(DscndoController, argv)


if __name__ == "__main__":
    sys.exit(main())
