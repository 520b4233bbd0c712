"""``dscndo_controller``: DSC / DSCNDO (eq. 16-28, 19-21), or the LQR baseline, as a node.

The parameter ``law`` picks DSC (the paper) or LQR (``core.lqr``: the gain K, designed from
``lqr.Q``, ``lqr.R`` and the nominal model, is logged at start-up and whenever it changes);
``use_observer`` adds the observer term u_taud (DSCNDO, LQR+NDO).  All of them change at run
time (``ros2 param set``); switching to DSC starts its filter afresh.

Subscribes ``joint_states`` and (with ``use_observer``) ``disturbance_estimate``,
pairs them by stamp, publishes ``wheel_torque_cmd`` once per state and the
internal signals on ``controller_internals`` (a JointState whose ``name`` lists
S1, S2, x4d, x4_bar, u_dsc, u_taud, u, x1 and whose ``position`` holds them).
A message it cannot use (malformed, non-finite, implausible, a stamp outside the
stream's window; :mod:`.guards`) is rejected, counted and logged and changes nothing;
so is a state for which the law gives a non-finite command (nothing is published).
A stream that restarted re-initialises the filter.  At most ``_MAX_PENDING`` states
and estimates wait for their partner.
"""
from __future__ import annotations

import math
import sys

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from mwip_ros import params as P
from mwip_ros.core.controller import DscController
from mwip_ros.core.lqr import LqrController
from mwip_ros.core.sim import law_name
from mwip_ros.core.theorem import controller_conditions
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import qos_for
from mwip_ros.nodes.diagnostics import OK
from mwip_ros.nodes.guards import REPEAT, RESTART, STAMP_WINDOW_PERIODS, PublisherWatch, Rejects, StateInput
from mwip_ros.nodes.params import declare
from mwip_ros.nodes.runtime import GracefulNodeMixin, run_node

NAME = "dscndo_controller"
_MAX_PENDING = 64


class DscndoController(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv, on_change=self._on_change)
        nominal = P.physical(self.v, "nominal")
        self.dsc = DscController(nominal, P.gains(self.v), P.period(self.v), use_observer=self.v["use_observer"])
        self.lqr = LqrController(nominal, P.typed.lqr_gain(self.v), use_observer=self.v["use_observer"])
        self._warn_theorem()
        self.states = {}      # stamp -> State waiting for an estimate
        self.estimates = {}   # stamp -> (tau_hat1, tau_hat2) waiting for a state
        self.last_answered = None
        self.count = 0
        self.rejects = Rejects(self.get_logger())
        pub_qos, in_qos = qos_for(self.v["mode"])   # msgs.qos: lockstep loses nothing, realtime keeps the newest
        self.cmd_pub = self.create_publisher(Float64, "wheel_torque_cmd", pub_qos)
        self.int_pub = self.create_publisher(JointState, "controller_internals", pub_qos)
        self.create_subscription(JointState, "joint_states", self._on_state, in_qos, raw=True)
        self.create_subscription(WrenchStamped, "disturbance_estimate", self._on_estimate, in_qos, raw=True)
        self.input = StateInput(self, self.rejects, STAMP_WINDOW_PERIODS * round(P.period(self.v) * 1e9),
                                "controller")
        self.watch = PublisherWatch(self, ["joint_states", "disturbance_estimate"])
        self.get_logger().info(self._ready_text())

    @property
    def ctrl(self):
        """The law in use: ``self.dsc`` or ``self.lqr``."""
        return self.lqr if self.v["law"] == "lqr" else self.dsc

    def _name(self) -> str:
        return {"dsc": "DSC", "dscndo": "DSCNDO", "lqr": "LQR", "lqr_ndo": "LQR+NDO"}[
            law_name(self.v["law"], self.v["use_observer"])]

    def _describe(self) -> str:
        g = self.dsc.gains
        return f"{self._name()} (k1 = {g.k1}, k2 = {g.k2}, tau4 = {g.tau4})" if self.v["law"] == "dsc" else self._name()

    def _ready_text(self) -> str:
        g = self.dsc.gains
        if self.v["law"] == "dsc":
            return f"{self._name()} ready: k1 = {g.k1}, k2 = {g.k2}, tau4 = {g.tau4}; ({self._lqr_text()}, not in use)"
        return f"{self._name()} ready: {self._lqr_text()}"

    def _lqr_text(self) -> str:
        K = self.lqr.K
        return (f"LQR gain K = [{K[0]:.6g}, {K[1]:.6g}, {K[2]:.6g}] on [theta_b, theta_b', theta_w'] "
                f"(lqr.Q = {self.v['lqr.Q']}, lqr.R = {self.v['lqr.R']:g})")

    def _warn_theorem(self):
        th = controller_conditions(self.dsc.nominal, self.dsc.gains)
        if not th.satisfied:
            self.get_logger().warning(f"gains break Theorem 2 (eq. 35): a1 = {th.a1:.4f}, a2 = {th.a2:.4f}, "
                                      f"a3 = {th.a3:.4f} (all must be > 0); allowed, but stability is not "
                                      "guaranteed. Run mwip_theorem for a1..a5")

    def _on_change(self, changed):
        if {"k1", "k2", "tau4"} & set(changed):
            self.dsc.gains = P.gains(self.v)
            self._warn_theorem()
        if "use_observer" in changed:
            self.dsc.use_observer = self.lqr.use_observer = self.v["use_observer"]
        if {"lqr.Q", "lqr.R"} & set(changed):   # the design was checked before the change was accepted
            self.lqr.K = P.typed.lqr_gain(self.v)
            self.get_logger().info(self._lqr_text())
        if "law" in changed:
            self.dsc.x4d = None   # DSC starts its filter afresh from the next state
        if {"law", "use_observer"} & set(changed):
            self.get_logger().info(f"law now {self._describe()}")

    def _on_state(self, data: bytes) -> None:
        taken = self.input.take(data)
        if taken is None:
            return
        verdict, stamp, x, _u_prev, _last = taken
        if verdict == REPEAT:
            return  # a resent state: one command per state
        if verdict == RESTART:
            self.dsc.x4d = None
            self.states.clear()
            self.estimates = {s: e for s, e in self.estimates.items() if s >= stamp}
            self.last_answered = None
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
        if self.ctrl.use_observer and tau_hat is None:
            self._trim()
            return  # wait for the estimate of this very state
        x = self.states.pop(stamp)
        self.estimates.pop(stamp, None)
        ctrl, x4d = self.ctrl, self.dsc.x4d
        try:
            out = ctrl.step(x, tau_hat)
            ok = math.isfinite(out.u) and (ctrl is not self.dsc or math.isfinite(self.dsc.x4d))
        except (ArithmeticError, ValueError):
            ok = False
        if not ok:
            self.dsc.x4d = x4d  # keep the filter as it was: setting a bad gain back repairs the loop
            self.rejects("joint_states", f"the law gives no finite command for t = {stamp * 1e-9:.3f} s "
                                         f"({self._describe()}); nothing published")
            return
        self.cmd_pub.publish(L.encode_command(out.u))
        self.int_pub.publish(L.encode_internals(stamp, out))
        self.input.answered(stamp)
        self.last_answered = stamp
        self.count += 1
        for d in (self.states, self.estimates):  # usually empty by now: drop what is older than this state
            if d:
                for s in [s for s in d if s < stamp]:
                    del d[s]

    def _trim(self):
        for d in (self.states, self.estimates):
            while len(d) > _MAX_PENDING:
                d.pop(min(d))

    def diagnostic_count(self) -> int:
        return self.count

    def diagnostic_status(self):
        return OK, f"{self._describe()} answering", {"commands": self.count, "law": self._name(),
                                                     "waiting_states": len(self.states)}

    def on_shutdown(self) -> None:
        self.get_logger().info(f"answered {self.count} states; rejected: {self.rejects.summary()}")


def main(argv=None) -> int:
    return run_node(DscndoController, argv)


if __name__ == "__main__":
    sys.exit(main())
