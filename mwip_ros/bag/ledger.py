"""What a recorder wrote, per topic, and whether a lockstep run is complete in it.

In lockstep the plant steps on a grid, t_k = k h from 0, and every state gets exactly one
answer on every topic of the loop.  So a complete recording has, for every stamp of that
grid up to the last one recorded, one message of that stamp on each stamped topic
(``joint_states``, ``/clock``, ``disturbance_estimate``, ``lumped_disturbance``,
``controller_internals``; with raw sensors ``imu/data_raw`` and ``wheel_encoder`` too) and as many
``wheel_torque_cmd`` as states; ``external_wrench`` and ``emergency_stop`` are whatever a user sent,
``robot_markers`` a view of the states, ``driver_state`` the driver's transitions and ``/rosout``,
``/parameter_events``, ``/diagnostics`` ROS's own: those are not compared.  A recorder that joined
late lacks the first stamps everywhere: the grid from 0 still shows it.  A state the plant resent
before the graph had matched shows as a repeated stamp: it counts once.  :class:`Ledger` keeps the
stamps (8 bytes each) and says which topics lack which stamps; no ROS here.
"""
from __future__ import annotations

from array import array
from typing import Dict, List, Optional, Tuple

from mwip_ros.msgs.cdr import peek_stamp
from mwip_ros.msgs.topics import leaf

__all__ = ["Ledger", "GAPS_KEY", "MAX_STAMPS"]

GAPS_KEY = "mwip_ros.lockstep_gaps"    # the bag's custom_data entry that says what a lockstep recording lacks
STAMPED = {"sensor_msgs/msg/JointState", "geometry_msgs/msg/WrenchStamped", "rosgraph_msgs/msg/Clock"}
NOT_COMPARED = {"external_wrench", "emergency_stop",     # what a user sent;
                "robot_markers", "driver_state",          # a view, not the loop; the driver's transitions;
                "rosout", "parameter_events", "diagnostics"}   # ROS's own topics
# published only with sensing options on (the truth) or raw sensors (the IMU, the encoder): judged when they have
# messages
OPTIONAL = {"true_joint_states", "data_raw", "wheel_encoder"}
MAX_STAMPS = 10_000_000     # per topic (80 MB); past it a topic is only counted


class Ledger:
    def __init__(self):
        self.counts: Dict[str, int] = {}
        self.stamps: Dict[str, array] = {}
        self.repeats: Dict[str, int] = {}
        self.overflow = False

    def add(self, topic: str, type_name: str, data) -> None:
        self.counts[topic] = self.counts.get(topic, 0) + 1
        if type_name not in STAMPED:
            return
        stamp = peek_stamp(data)
        if stamp is None:
            return
        seen = self.stamps.setdefault(topic, array("q"))
        if seen and seen[-1] == stamp:
            self.repeats[topic] = self.repeats.get(topic, 0) + 1   # a resend: recorded, counted once
        elif len(seen) < MAX_STAMPS:
            seen.append(stamp)
        else:
            self.overflow = True

    def expected(self) -> set:
        """The stamps a complete lockstep recording has: the grid from 0 to the last stamp seen (or, when
        the stamps are not on such a grid or it would be mostly empty, every stamp seen on any topic)."""
        seen = set()
        for stamps in self.stamps.values():
            seen.update(stamps)
        if len(seen) < 2:
            return seen
        ordered = sorted(seen)
        step = min(b - a for a, b in zip(ordered, ordered[1:]))
        points = ordered[-1] // step + 1
        if ordered[0] % step or points > 2 * len(seen) + 1000:  # not one plant's grid from 0
            return seen
        return set(range(0, ordered[-1] + 1, step))

    def gaps(self) -> List[Tuple[str, int, int, Optional[int]]]:
        """[(topic, messages it has, messages it should have, first missing stamp or None)] for every topic of
        the loop that lacks some; empty when the recording is complete (or is not of a lockstep run, or is
        too long to judge: ``overflow``)."""
        # only the lockstep plant publishes /clock
        if self.overflow or not any(leaf(t) == "clock" for t in self.stamps):
            return []
        states = self.expected()
        out = []
        for topic, count in sorted(self.counts.items()):
            if leaf(topic) in NOT_COMPARED or (leaf(topic) in OPTIONAL and not count):
                continue
            if topic in self.stamps:
                have = states.intersection(self.stamps[topic])
                if len(have) < len(states):
                    out.append((topic, len(have), len(states), min(states - have)))
            elif count < len(states):
                out.append((topic, count, len(states), None))
        return out

    def gaps_text(self) -> str:
        """One line per incomplete topic (empty when complete)."""
        return "; ".join(
            f"{t}: {have} of {want}" + (f", first missing stamp t = {first * 1e-9:.3f} s" if first is not None else "")
            for t, have, want, first in self.gaps())
