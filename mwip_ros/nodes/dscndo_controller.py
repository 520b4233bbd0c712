"""``dscndo_controller``: DSC / DSCNDO (eq. 16-28, 19-21) as a node.

Subscribes ``joint_states`` and (with ``use_observer``) ``disturbance_estimate``,
pairs them by stamp, publishes ``wheel_torque_cmd`` once per state and the
internal signals on ``controller_internals`` (a JointState whose ``name`` lists
S1, S2, x4d, x4_bar, u_dsc, u_taud, u, x1 and whose ``position`` holds them).
"""
from __future__ import annotations

import sys

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from mwip_ros import params as P
from mwip_ros.core.controller import DscController
from mwip_ros.core.theorem import controller_conditions
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import GRAPH_QOS
from mwip_ros.nodes.params import declare
from mwip_ros.nodes.runtime import GracefulNodeMixin, Rejects, run_node

NAME = "dscndo_controller"
_MAX_PENDING = 64


class DscndoController(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv, on_change=self._on_change)
        self.ctrl = DscController(P.physical(self.v, "nominal"), P.gains(self.v), P.period(self.v),
                                  use_observer=self.v["use_observer"])
        self._warn_theorem()
        self.states = {}      # stamp -> State waiting for an estimate
        self.estimates = {}   # stamp -> (tau_hat1, tau_hat2) waiting for a state
        self.last_answered = None
        self.count = 0
        self.rejects = Rejects(self.get_logger())
        self.cmd_pub = self.create_publisher(Float64, "wheel_torque_cmd", GRAPH_QOS)
        self.int_pub = self.create_publisher(JointState, "controller_internals", GRAPH_QOS)
        self.create_subscription(JointState, "joint_states", self._on_state, GRAPH_QOS, raw=True)
        self.create_subscription(WrenchStamped, "disturbance_estimate", self._on_estimate, GRAPH_QOS, raw=True)
        g = self.ctrl.gains
        self.get_logger().info(f"{'DSCNDO' if self.ctrl.use_observer else 'DSC'} ready: k1 = {g.k1}, k2 = {g.k2}, "
                               f"tau4 = {g.tau4}")

    def _warn_theorem(self):
        th = controller_conditions(self.ctrl.nominal, self.ctrl.gains)
        if not th.satisfied:
            self.get_logger().warning(f"gains break Theorem 2 (eq. 35): a1 = {th.a1:.4f}, a2 = {th.a2:.4f}, "
                                      f"a3 = {th.a3:.4f} (all must be > 0); allowed, but stability is not "
                                      "guaranteed. Run mwip_theorem for a1..a5")

    def _on_change(self, changed):
        if {"k1", "k2", "tau4"} & set(changed):
            self.ctrl.gains = P.gains(self.v)
            self._warn_theorem()
        if "use_observer" in changed:
            self.ctrl.use_observer = self.v["use_observer"]

    def _on_state(self, data: bytes) -> None:
        try:
            stamp, x, _ = L.parse_joint_state(data)
        except BadMessage as exc:
            self.rejects("joint_states", str(exc))
            return
        if self.last_answered is not None and stamp <= self.last_answered:
            return  # already answered (a resent state): one command per state
        self.states[stamp] = x
        self._try(stamp)

    def _on_estimate(self, data: bytes) -> None:
        try:
            stamp, t1, t2 = L.parse_wrench(data)
        except BadMessage as exc:
            self.rejects("disturbance_estimate", str(exc))
            return
        if self.last_answered is not None and stamp <= self.last_answered:
            return
        self.estimates[stamp] = (t1, t2)
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
        out = self.ctrl.step(x, tau_hat)
        self.cmd_pub.publish(L.encode_command(out.u))
        self.int_pub.publish(L.encode_internals(stamp, out))
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

    def on_shutdown(self) -> None:
        self.get_logger().info(f"answered {self.count} states; rejected: {self.rejects.summary()}")


def main(argv=None) -> int:
    return run_node(DscndoController, argv)


if __name__ == "__main__":
    sys.exit(main())
