"""``disturbance_observer``: the NDO (eq. 12-15) as a node.

Subscribes ``joint_states``; for each new state k publishes ``disturbance_estimate``
(tau_hat_k, stamped with state k's stamp).  A repeated state (same stamp, e.g. the
plant resending at start-up) gets the same estimate again and is not integrated twice.
A state it cannot use (malformed, non-finite, implausible, a stamp outside the stream's
window; :mod:`.guards`) is rejected, counted and logged, and changes nothing; a stream
that restarted (a new plant, a reset) re-initialises the observer.  With ``csv`` set it
writes its estimates (``t, tau_hat1, tau_hat2``) as it goes, which
``mwip_report --estimates`` joins to the plant's CSV by stamp.
"""
from __future__ import annotations

import math
import sys

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState

from mwip_ros import params as P
from mwip_ros.core.control.observer import DiscreteObserver
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import qos_for
from mwip_ros.nodes.runtime.diagnostics import OK
from mwip_ros.nodes.runtime.guards import REPEAT, RESTART, STAMP_WINDOW_PERIODS, PublisherWatch, Rejects
from mwip_ros.nodes.runtime.state_input import StateInput
from mwip_ros.nodes.runtime.params import declare
from mwip_ros.nodes.runtime.process import GracefulNodeMixin, run_node
from mwip_ros.runs import CsvStream

NAME = "disturbance_observer"


class DisturbanceObserver(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv, on_change=self._on_change)
        self.h = P.period(self.v)
        self.period_ns = round(self.h * 1e9)
        self.obs = DiscreteObserver(P.physical(self.v, "nominal"), P.observer_gain(self.v), self.h)
        self._warn_theorem()
        self.last_msg = None
        self.count = 0
        self.written = (CsvStream(self.v["csv"], ("t", "tau_hat1", "tau_hat2"))   # streamed, one row per estimate
                        if self.v["csv"] else None)
        self.rejects = Rejects(self.get_logger())
        self.input = StateInput(self, self.rejects, STAMP_WINDOW_PERIODS * self.period_ns, "observer")
        pub_qos, in_qos = qos_for(self.v["mode"])   # msgs.qos: lockstep loses nothing, realtime keeps the newest
        self.pub = self.create_publisher(WrenchStamped, "disturbance_estimate", pub_qos)
        sub = self.create_subscription(JointState, "joint_states", self._on_state, in_qos, raw=True)
        if self.v["mode"] == "realtime":   # a flood of absurd states is dropped by DDS (issue 46)
            self.input.filter_readers({"joint_states": (sub, L.STATE_FILTER)})
        self.watch = PublisherWatch(self, ["joint_states"])
        self.get_logger().info(f"NDO ready: X = {self.v['X']}, h = {self.h * 1e3:.3f} ms")

    def _warn_theorem(self):
        for text in P.typed.observer_warnings(self.v):   # what mwip_ctl param set prints too
            self.get_logger().warning(text)

    def _on_change(self, changed):
        if "X" in changed:
            self.obs.X = P.observer_gain(self.v)
            self._warn_theorem()

    def _on_state(self, data: bytes) -> None:
        taken = self.input.take(data)
        if taken is None:
            return
        verdict, stamp, x, u_prev, last = taken
        if verdict == REPEAT:
            if self.last_msg is not None:
                self.pub.publish(self.last_msg)  # a resent state: answer it again, integrate nothing
            return
        h = None
        snap = self.obs.snapshot()
        if verdict == RESTART:
            self.obs.reset()
        else:
            n = round((stamp - last) / self.period_ns) if last is not None else 1
            if n > 1:  # realtime: states were lost; integrate over the whole gap (at most the window) in steps of
                h = n * self.h   # at most one period (core.control.observer.substeps: one step of n h is unstable)
        try:
            tau_hat = self.obs.update(x, u_prev, h)
            ok = math.isfinite(tau_hat[0]) and math.isfinite(tau_hat[1])
        except (ArithmeticError, ValueError):
            ok = False
        if not ok:
            self.obs.restore(snap)
            self.input.guard.last = last
            self.rejects("joint_states", f"the estimate for t = {stamp * 1e-9:.3f} s is not finite; the state is "
                                         "not integrated")
            return
        self.last_msg = L.encode_wrench(stamp, tau_hat[0], tau_hat[1])
        self.pub.publish(self.last_msg)
        self.input.answered(stamp)
        self.count += 1
        if self.written is not None:
            self.written.row((stamp * 1e-9, tau_hat[0], tau_hat[1]))

    def diagnostic_count(self) -> int:
        return self.count

    def diagnostic_status(self):
        return OK, f"estimating; X = {self.v['X']}", {"estimates": self.count,
                                                       "input_filter": self.input.filter_status()}

    def on_shutdown(self) -> None:
        self.get_logger().info(f"estimated {self.count} states; rejected: {self.rejects.summary()}")
        if self.written is not None:
            self.written.close()
            self.get_logger().info(f"wrote {self.v['csv']}")


def main(argv=None) -> int:
    return run_node(DisturbanceObserver, argv)


if __name__ == "__main__":
    sys.exit(main())
