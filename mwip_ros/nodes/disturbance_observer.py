"""``disturbance_observer``: the NDO (eq. 12-15) as a node.

Subscribes ``joint_states``; for each new state k publishes ``disturbance_estimate``
(tau_hat_k, stamped with state k's stamp).  A repeated state (same stamp, e.g. the
plant resending at start-up) gets the same estimate again and is not integrated twice.
"""
from __future__ import annotations

import sys

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState

from mwip_ros import params as P
from mwip_ros.observer import DiscreteObserver, gain_matrix
from mwip_ros.theorem import theorem2
from mwip_ros.controller import DscGains
from mwip_ros.nodes import _msgs as M
from mwip_ros.nodes._params import declare
from mwip_ros.nodes._runtime import GracefulNodeMixin, run_node

NAME = "disturbance_observer"


class DisturbanceObserver(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv, on_change=self._on_change)
        self.h = P.period(self.v)
        self.obs = DiscreteObserver(P.physical(self.v, "nominal"), gain_matrix(self.v["X"]), self.h)
        self._warn_theorem()
        self.last_stamp = None
        self.last_msg = None
        self.count = 0
        self.rejects = M.Rejects(self.get_logger())
        self.pub = self.create_publisher(WrenchStamped, "disturbance_estimate", M.GRAPH_QOS)
        self.create_subscription(JointState, "joint_states", self._on_state, M.GRAPH_QOS, raw=True)
        self.get_logger().info(f"NDO ready: X = {self.v['X']}, h = {self.h * 1e3:.3f} ms")

    def _warn_theorem(self):
        th = theorem2(self.obs.nominal, DscGains(), self.obs.X)
        if th.a4 <= 0 or th.a5 <= 0:
            self.get_logger().warning(f"observer gains break Theorem 2 (eq. 35): a4 = {th.a4:.4f}, a5 = {th.a5:.4f} "
                                      "(must be > 0); run mwip_theorem for the full table")

    def _on_change(self, changed):
        if "X" in changed:
            self.obs.X = gain_matrix(changed["X"])
            self._warn_theorem()

    def _on_state(self, data: bytes) -> None:
        try:
            stamp, q, dq, u_prev = M.parse_joint_state(data)
        except M.BadMessage as exc:
            self.rejects("joint_states", str(exc))
            return
        if self.last_stamp is not None and stamp <= self.last_stamp:
            if stamp == self.last_stamp and self.last_msg is not None:
                self.pub.publish(self.last_msg)  # a resent state: answer it again, integrate nothing
            else:
                self.rejects("joint_states", f"stamp {stamp} ns older than the last state {self.last_stamp} ns")
            return
        if self.last_stamp is not None:
            n = max(1, round((stamp - self.last_stamp) * 1e-9 / self.h))
            if n != 1:  # realtime: a state was lost; integrate over the whole gap
                self.obs.h = n * self.h
        tau_hat = self.obs.update(q, dq, u_prev)
        self.obs.h = self.h
        self.last_stamp = stamp
        self.last_msg = M.encode_wrench(stamp, tau_hat[0], tau_hat[1])
        self.pub.publish(self.last_msg)
        self.count += 1

    def on_shutdown(self) -> None:
        self.get_logger().info(f"estimated {self.count} states; rejected: {self.rejects.summary()}")


def main(argv=None) -> int:
    return run_node(DisturbanceObserver, argv)


if __name__ == "__main__":
    sys.exit(main())
