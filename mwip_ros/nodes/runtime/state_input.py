"""``joint_states`` as the observer and the controller take it: :class:`StateInput`.

Each state is parsed by the message layer (:func:`mwip_ros.msgs.layouts.parse_joint_state`) and judged by a
:class:`~.guards.StampGuard`; a rejection is counted (:class:`~.guards.Rejects`), a restart logged.  Without
``use_sim_time`` the node's clock follows the stream (:func:`.rclpy_compat.use_ros_time_override`).  Here, not in
:mod:`.guards`: the guards are plain Python that :mod:`.rclpy_compat` uses, and this reaches into rclpy through
:mod:`.rclpy_compat`, so the imports go one way (guards <- rclpy_compat <- state_input).
"""
from __future__ import annotations

from typing import Dict, Tuple

from mwip_ros.msgs import BadMessage
from mwip_ros.msgs.layouts import parse_joint_state
from mwip_ros.nodes.runtime.content_filter import filter_readers
from mwip_ros.nodes.runtime.guards import NEW, REPEAT, RESTART, StampGuard, sole_publisher
from mwip_ros.nodes.runtime.rclpy_compat import use_ros_time_override

__all__ = ["StateInput"]


class StateInput:
    """``take(data)``: None for a state that is rejected (counted), else ``(verdict, stamp, x, u_prev, last)``
    with verdict :data:`NEW`, :data:`REPEAT` or :data:`RESTART` (logged; the caller re-initialises) and
    ``last`` the stream's stamp before this one.

    Without ``use_sim_time`` the node's clock follows the stream: it reads the stamp of the last state
    answered (:meth:`answered`).  So a parameter change (``ros2 param set``) is stamped, in its
    ``/parameter_events`` message, with the state after which it took effect: it applies from the next
    state on, which is how ``bag_replay`` resim applies a recorded change at the same state."""

    def __init__(self, node, rejects, window_ns: int, who: str):
        self.guard = StampGuard(window_ns, "joint_states stamp", sole_publisher(node, "joint_states"))
        self.node, self.rejects, self.who = node, rejects, who
        self.filtered = False   # DDS content filters on the node's readers of the stream (realtime)
        self._clock = None
        if not node.get_parameter("use_sim_time").value:
            from rclpy.time import Time
            self._time = Time
            self._clock = node.get_clock()
            use_ros_time_override(self._clock)
            self._clock.set_ros_time_override(Time(nanoseconds=0))

    def take(self, data):
        try:
            stamp, x, u_prev = parse_joint_state(data)
        except BadMessage as exc:
            self.rejects("joint_states", str(exc))
            return None
        last = self.guard.last
        verdict = self.guard.check(stamp)
        if verdict == RESTART:
            self.node.get_logger().warning(f"joint_states restarted at t = {stamp * 1e-9:.3f} s (the last state was "
                                           f"t = {last * 1e-9:.3f} s): re-initialising the {self.who}")
        elif verdict not in (NEW, REPEAT):
            self.rejects("joint_states", verdict)
            return None
        return verdict, stamp, x, u_prev, last

    def filter_readers(self, readers: Dict[str, Tuple[object, str]]) -> None:
        """Realtime: a DDS content filter on each reader ``{topic: (subscription, expression)}`` (the expressions
        ``layouts.STATE_FILTER``, ``ESTIMATE_FILTER``), so that a flood of absurd or undecodable inputs is dropped by
        the middleware, at the writer where it can, and costs the control loop nothing (logged). What is dropped is
        not counted; the parsers and the StampGuard still judge what passes (stamps: not filtered)."""
        self.filtered = filter_readers(self.node.get_logger(), readers, "a message with a value that is not finite "
                                       "or beyond the plausible limits, or that cannot be deserialized,")

    def filter_status(self) -> str:
        """/diagnostics' ``input_filter``: whether DDS filters the stream's readers."""
        return "on: non-finite or absurd values are dropped by DDS, not counted" if self.filtered else "off"

    def answered(self, stamp: int) -> None:
        """The node published its answer to the state of ``stamp``: its clock reads that stamp now."""
        if self._clock is not None:
            self._clock.set_ros_time_override(self._time(nanoseconds=stamp))
