"""What a recorder wrote, per topic, and whether a lockstep run is complete in it.

In lockstep the plant steps on a grid, t_k = k h from 0, and every state gets exactly one
answer on every topic of the loop.  So a complete recording has, for every stamp of that
grid up to the last one recorded, one message of that stamp on each stamped topic
(``joint_states``, ``/clock``, ``disturbance_estimate``, ``lumped_disturbance``,
``controller_internals``; with raw sensors ``imu/data_raw`` and ``wheel_encoder`` too, with a spatial plant
``true_pose`` and ``true_wheel_states``) and as many
``wheel_torque_cmd`` as states; ``external_wrench`` and ``emergency_stop`` are whatever a user sent,
``robot_markers`` a view of the states, ``driver_state`` the driver's transitions and ``/rosout``,
``/parameter_events``, ``/diagnostics`` ROS's own: those are not compared.  A recorder that joined
late lacks the first stamps everywhere: the grid from 0 still shows it; one that never matched the
plant's own writers (``/clock``, ``joint_states``) still has the answers' stamps on that grid, and the plant's
topics are named as missing (:meth:`Ledger.lockstep_states`).  A state the plant resent
before the graph had matched shows as a repeated stamp: it counts once.  :class:`Ledger` keeps each
topic's stamps as runs of evenly spaced ones (:class:`Runs`: first, step, count; a topic's stamps in a complete
lockstep recording are one run, and each gap or reset starts another), so its memory does not grow with the length
of the recording, and says which topics lack which stamps; no ROS here.
"""
from __future__ import annotations

from array import array
from typing import Dict, Iterator, List, Optional, Tuple

import numpy as np

from mwip_ros.msgs.cdr import peek_stamp
from mwip_ros.msgs.topics import leaf

__all__ = ["Ledger", "Runs", "GAPS_KEY", "MAX_STAMPS", "MAX_RUNS"]

GAPS_KEY = "mwip_ros.lockstep_gaps"    # the bag's custom_data entry that says what a lockstep recording lacks
STAMPED = {"sensor_msgs/msg/JointState", "geometry_msgs/msg/WrenchStamped", "rosgraph_msgs/msg/Clock",
           "geometry_msgs/msg/PoseStamped"}
NOT_COMPARED = {"external_wrench", "emergency_stop", "cmd_vel",   # what a user sent;
                "robot_markers", "driver_state",          # a view, not the loop; the driver's transitions;
                "odom", "robot_description", "wheel_joint_states",   # robot_state's view of the states;
                "rosout", "parameter_events", "diagnostics"}   # ROS's own topics
# published only with sensing options on (the truth), raw sensors (the IMU, the encoder), a spatial plant (its
# pose and wheel angles) or the yaw stage (the two wheel torques), or only by plant_sim (the true lumped
# disturbance: a robot's side, wheel_driver, has none; it publishes each wheel's read on wheel_states): judged when
# they have messages
OPTIONAL = {"true_joint_states", "data_raw", "wheel_encoder", "true_pose", "true_wheel_states", "wheel_torques_cmd",
            "lumped_disturbance", "wheel_states"}
MAX_STAMPS = 10_000_000     # per topic; past it a topic is only counted (its judgement would hold them all at once)
MAX_RUNS = 100_000          # per topic (2.4 MB); past it (stamps on no grid) a topic is only counted


class Runs:
    """A topic's stamps in the order they came, as runs of evenly spaced stamps: three int64 per run."""

    def __init__(self):
        self.first, self.step, self.count = array("q"), array("q"), array("q")
        self.total = 0

    def __len__(self) -> int:
        return self.total

    def runs(self) -> int:
        return len(self.first)

    @property
    def last(self) -> Optional[int]:
        return self.first[-1] + (self.count[-1] - 1) * self.step[-1] if self.first else None

    def add(self, stamp: int) -> None:
        if self.first:
            n, first = self.count[-1], self.first[-1]
            if n == 1 and stamp > first:
                self.step[-1], self.count[-1] = stamp - first, 2
                self.total += 1
                return
            if n > 1 and stamp == first + n * self.step[-1]:
                self.count[-1] = n + 1
                self.total += 1
                return
        self.first.append(stamp)
        self.step.append(0)
        self.count.append(1)
        self.total += 1

    def __iter__(self) -> Iterator[int]:
        for first, step, n in zip(self.first, self.step, self.count):
            yield from range(first, first + n * step, step) if step else (first,)

    def array(self) -> np.ndarray:
        """Every stamp (int64), in the order they came."""
        parts = [np.arange(n, dtype=np.int64) * step + first for first, step, n in zip(self.first, self.step,
                                                                                      self.count)]
        return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


class Ledger:
    def __init__(self):
        self.counts: Dict[str, int] = {}
        self.stamps: Dict[str, Runs] = {}
        self.repeats: Dict[str, int] = {}
        self.overflow = False

    def add(self, topic: str, type_name: str, data) -> None:
        self.counts[topic] = self.counts.get(topic, 0) + 1
        if type_name not in STAMPED:
            return
        stamp = peek_stamp(data)
        if stamp is None:
            return
        seen = self.stamps.setdefault(topic, Runs())
        if seen.last == stamp:
            self.repeats[topic] = self.repeats.get(topic, 0) + 1   # a resend: recorded, counted once
        elif len(seen) < MAX_STAMPS and seen.runs() < MAX_RUNS:
            seen.add(stamp)
        else:
            self.overflow = True

    def _seen(self) -> np.ndarray:
        """Every stamp seen on any topic, sorted, once."""
        return np.unique(np.concatenate([r.array() for r in self.stamps.values()] or [np.zeros(0, np.int64)]))

    @staticmethod
    def _grid(seen: np.ndarray) -> Optional[np.ndarray]:
        """The grid from 0 to the last of ``seen`` (at least 2 stamps) with their smallest spacing, or None when
        they are not on such a grid (the first not a multiple of the spacing) or it would be mostly empty."""
        step = int(np.diff(seen).min())
        last = int(seen[-1])
        points = last // step + 1
        if int(seen[0]) % step or points > 2 * len(seen) + 1000:  # not one plant's grid from 0
            return None
        return np.arange(0, last + 1, step, dtype=np.int64)

    def _expected(self) -> Tuple[np.ndarray, bool]:
        """(:meth:`expected`, whether that is the grid from 0)."""
        seen = self._seen()
        grid = self._grid(seen) if len(seen) >= 2 else None
        return (seen, False) if grid is None else (grid, True)

    def expected(self) -> np.ndarray:
        """The stamps a complete lockstep recording has (sorted): the grid from 0 to the last stamp seen (or, when
        the stamps are not on such a grid or it would be mostly empty, every stamp seen on any topic)."""
        return self._expected()[0]

    def lockstep_states(self) -> Optional[np.ndarray]:
        """:meth:`expected` when this is a recording of a lockstep run, else None. It is one when it has /clock (only
        the lockstep plant publishes it), or when the stamps lie on one grid from 0 (a lockstep plant's t_k = k h; a
        realtime plant's start at its clock's time is off it): a recorder that never matched the plant's own topics
        still has the answers' stamps, so its recording is judged, and the plant's topics are named as missing."""
        states, on_grid = self._expected()
        return states if on_grid or any(leaf(t) == "clock" for t in self.stamps) else None

    def lockstep(self) -> bool:
        """Whether this is a recording of a lockstep run (:meth:`lockstep_states`)."""
        return self.lockstep_states() is not None

    def gaps(self, states: Optional[np.ndarray] = None) -> List[Tuple[str, int, int, Optional[int]]]:
        """[(topic, messages it has, messages it should have, first missing stamp or None)] for every topic of
        the loop that lacks some; empty when the recording is complete (or is not of a lockstep run,
        :meth:`lockstep_states`, or is too long to judge: ``overflow``). ``states``: :meth:`lockstep_states` when the
        caller has it already."""
        if self.overflow:
            return []
        if states is None:
            states = self.lockstep_states()
        if states is None:
            return []
        out = []
        for topic, count in sorted(self.counts.items()):
            if leaf(topic) in NOT_COMPARED or (leaf(topic) in OPTIONAL and not count):
                continue
            if topic in self.stamps:
                have = np.isin(states, self.stamps[topic].array())
                n = int(have.sum())
                if n < len(states):
                    out.append((topic, n, len(states), int(states[np.argmin(have)])))
            elif count < len(states):
                out.append((topic, count, len(states), None))
        return out

    def gaps_text(self, states: Optional[np.ndarray] = None) -> str:
        """One line per incomplete topic (empty when complete); ``states`` as for :meth:`gaps`."""
        return "; ".join(
            f"{t}: {have} of {want}" + (f", first missing stamp t = {first * 1e-9:.3f} s" if first is not None else "")
            for t, have, want, first in self.gaps(states))
