"""The runs in one recording: a bag's state stream split where its stamps go back.

``plant_sim``'s ``~/reset`` (and a new plant started into the same recording) restarts the
stamps at the run's start, so a bag of a run with resets holds several runs under the
same stamps.  Merged by stamp they would be one run with two states per stamp; this module
tells them apart, for the readers (``mwip_report``, ``bag_replay`` resim).

* **Order**: the recording's own order (:func:`recorded_messages`: each file as written,
  the files of a split bag one after the other), which is the order the recorder received
  the messages in.  Log times follow it when the recorder's clock is wall time; a recorder
  under ``use_sim_time`` takes its log times from ``/clock``, which a lockstep reset sends
  back with the stamps, so log-time order would interleave the runs.
* **Split** (:func:`split`): in that order, the stamps of ``joint_states`` (valid states
  only: the message layer's parse) form a run while they go forward; a stamp equal to the
  one before is a resend (the lockstep driver's; the same run); a stamp below it starts a
  new run (a *segment*).  The plant never repeats the answered stamp after a reset (its new
  state 0 goes back below it), so a reset always shows.
* **Strays**: one state that does not belong to the stream (a foreign publisher) would
  split it twice; so a segment of one stamp that the stream then leaves for a stamp past
  the previous segment's last is no segment but a stray (a stamp thrown back), and a
  stamp that went forward only to be followed by one between it and the stamp before it
  is a stray too (a stamp thrown ahead).  Strays are counted, and belong to no segment.
* **Ranges**: each :class:`Segment` has the positions in the recording (``first_index``,
  ``last_index``: of all messages, in recording order) and the log times of its first and
  last state, its first and last stamp, its distinct stamps (``states``) and its state
  messages with resends (``messages``).
* **Membership** (:meth:`Segments.which`): a message is in the segment whose range holds
  its position (from a segment's first state to the next one's; what comes before the
  first state is in the first), except the stamped answers (``disturbance_estimate``,
  ``lumped_disturbance``, ``controller_internals``, ``true_joint_states``, ``true_pose``, ``true_wheel_states``):
  they go with the state of their stamp nearest them in the recording, so an answer received just after the
  next run began still counts for the run it answers.  A stray state is in none (None).

Nothing here imports ROS.
"""
from __future__ import annotations

import bisect
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterable, Iterator, List, Optional, Tuple

from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import cdr
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.topics import leaf

__all__ = ["Segment", "Segments", "SpliceError", "split", "recorded_messages", "STATE_TOPIC", "STAMPED"]

STATE_TOPIC = "joint_states"
STAMPED = ("true_joint_states", "disturbance_estimate", "lumped_disturbance", "controller_internals", "true_pose",
           "true_wheel_states")

Message = Tuple[int, str, bytes]   # (log time, topic, data), as raw_messages yields them


class SpliceError(ValueError):
    """A bag holds several runs (segments) and the reader was not told which one."""


def recorded_messages(bag, topics: Optional[Iterable[str]] = None) -> Iterator[Message]:
    """``(log_time_ns, topic, cdr_bytes)`` of every message in the order they were recorded (module doc).

    Chunk CRCs are checked as :func:`~mwip_ros.bag.reader.raw_messages` checks them."""
    from .reader import _file_messages, mcap_files
    wanted = None if topics is None else list(topics)
    for path in mcap_files(bag):
        yield from _file_messages(path, wanted, log_time_order=False)


@dataclass
class Segment:
    """One run of a recording: its states' stamps (distinct, rising) and the positions of their first messages
    (flat int64 arrays: a recording of hours holds millions of states)."""
    index: int
    stamps: array = field(default_factory=lambda: array("q"))
    positions: array = field(default_factory=lambda: array("q"))   # in the recording, first message of each stamp
    messages: int = 0                                                # state messages, resends included
    first_log_time: int = 0
    last_index: int = 0                                              # position of its last state message
    last_log_time: int = 0

    @property
    def states(self) -> int:
        return len(self.stamps)

    @property
    def first_stamp(self) -> int:
        return self.stamps[0]

    @property
    def last_stamp(self) -> int:
        return self.stamps[-1]

    @property
    def first_index(self) -> int:
        return self.positions[0]

    @property
    def duration_s(self) -> float:
        return (self.last_stamp - self.first_stamp) * 1e-9

    @property
    def resends(self) -> int:
        return self.messages - len(self.stamps)

    def position_of(self, stamp: int) -> Optional[int]:
        """The position of the first state of ``stamp`` in this run, or None."""
        i = bisect.bisect_left(self.stamps, stamp)
        return self.positions[i] if i < len(self.stamps) and self.stamps[i] == stamp else None

    def _add(self, pos: int, log_time: int, stamp: int) -> None:
        if not self.stamps:
            self.first_log_time = log_time
        self.stamps.append(stamp)
        self.positions.append(pos)
        self._again(pos, log_time)

    def _again(self, pos: int, log_time: int) -> None:
        self.messages += 1
        self.last_index, self.last_log_time = pos, log_time

    def _drop_last(self) -> Tuple[int, int]:
        self.messages -= 1
        return self.positions.pop(), self.stamps.pop()

    def describe(self) -> str:
        return (f"segment {self.index}: {self.states} states ({self.resends} resent), t = 0 .. {self.duration_s:.3f} s "
                f"(stamps {self.first_stamp} .. {self.last_stamp} ns), messages {self.first_index} .. "
                f"{self.last_index} of the recording, log time {self.first_log_time} .. {self.last_log_time} ns")


def split(stream: Iterable[Tuple[int, int, int]]) -> Tuple[List[Segment], List[Tuple[int, int]]]:
    """``stream``: (position, log time, stamp) of the states in recording order ->
    (segments, strays [(position, stamp)])."""
    segs: List[Segment] = []
    strays: List[Tuple[int, int]] = []
    last_stray: Optional[int] = None   # the stamp of the last stray: its resends are strays too
    for pos, log_time, stamp in stream:
        if not segs:
            segs.append(Segment(0))
            segs[-1]._add(pos, log_time, stamp)
            continue
        cur = segs[-1]
        last = cur.last_stamp
        if stamp == last:                       # a resend
            cur._again(pos, log_time)
            continue
        if stamp == last_stray:
            strays.append((pos, stamp))
            continue
        if stamp > last:
            if len(segs) > 1 and cur.states == 1 and stamp > segs[-2].last_stamp:
                # a stamp thrown back: the stream goes on past the segment before it
                segs.pop()
                strays.append((cur.positions[0], cur.stamps[0]))
                last_stray = cur.stamps[0]
                cur = segs[-1]
            cur._add(pos, log_time, stamp)
            continue
        # the stamp goes back
        if cur.states >= 2 and stamp > cur.stamps[-2]:
            # a stamp thrown ahead: the stream comes back between it and the one before it
            strays.append(cur._drop_last())
            last_stray = strays[-1][1]
            cur._add(pos, log_time, stamp)
            continue
        segs.append(Segment(len(segs)))
        segs[-1]._add(pos, log_time, stamp)
    return segs, strays


def _state_topic(types: Iterable[str]) -> Optional[str]:
    cands = sorted(t for t in types if leaf(t) == STATE_TOPIC)
    if len(cands) > 1 and "/" + STATE_TOPIC in cands:
        return "/" + STATE_TOPIC
    return cands[0] if cands else None


class Segments:
    """The segments of one state stream, and which segment any message of the recording belongs to."""

    def __init__(self, segments: List[Segment], strays: Iterable[Tuple[int, int]] = (),
                 topic: str = "/" + STATE_TOPIC, bag: Optional[str] = None):
        self.segments = list(segments)
        self.strays = list(strays)
        self.topic = topic
        self.bag = bag
        self._starts = [s.first_index for s in self.segments]
        self._stray_set = set(self.strays)

    # --- building
    @classmethod
    def from_messages(cls, messages: Iterable[Message], topic: Optional[str] = None,
                      bag: Optional[str] = None) -> "Segments":
        """From the messages of a recording in recording order (:func:`recorded_messages`, all topics: a
        message's position counts every topic); ``topic``: the state topic (default: the first one named
        ``joint_states``)."""
        chosen = [topic]

        def stream() -> Iterator[Tuple[int, int, int]]:
            for pos, (log_time, t, data) in enumerate(messages):
                if chosen[0] is None and leaf(t) == STATE_TOPIC:
                    chosen[0] = t
                if t != chosen[0]:
                    continue
                try:
                    yield pos, log_time, L.parse_joint_state(data)[0]
                except BadMessage:
                    continue   # not the graph's message: not part of any run
        segs, strays = split(stream())
        return cls(segs, strays, chosen[0] or "/" + STATE_TOPIC, bag)

    @classmethod
    def from_bag(cls, bag, topic: Optional[str] = None) -> "Segments":
        """The segments of a bag directory or .mcap file (one pass over the recording)."""
        from mwip_ros.bag import topic_types
        topic = topic or _state_topic(topic_types(bag))
        return cls.from_messages(recorded_messages(bag), topic, str(bag))

    # --- what it holds
    def __len__(self) -> int:
        return len(self.segments)

    def __getitem__(self, i: int) -> Segment:
        return self.segments[i]

    def __iter__(self) -> Iterator[Segment]:
        return iter(self.segments)

    @property
    def spliced(self) -> bool:
        """More than one run in the recording."""
        return len(self.segments) > 1

    def _name(self) -> str:
        return Path(self.bag).name if self.bag else "the bag"

    def describe(self) -> str:
        lines = [f"{self._name()}: {len(self.segments)} run(s) in one recording ({self.topic} stamps go back "
                 f"{max(0, len(self.segments) - 1)} time(s): a reset, or a new plant)"]
        lines += ["  " + s.describe() for s in self.segments]
        if self.strays:
            lines.append(f"  {len(self.strays)} stray state(s) outside the stream (in no segment)")
        return "\n".join(lines)

    def refusal(self, what: str = "this reader") -> str:
        """The line a reader that takes one run gives for a splice."""
        runs = "; ".join(f"run {s.index + 1} (segment={s.index}): {s.states} states, t = 0 .. {s.duration_s:.3f} s"
                         for s in self.segments)
        return (f"{self._name()} holds {len(self.segments)} runs under restarting stamps (a reset or a new plant; "
                f"{runs}); {what} does not merge them: choose one (segment=N)")

    # --- membership
    def _at(self, pos: int) -> int:
        return max(0, bisect.bisect_right(self._starts, pos) - 1)

    def which(self, pos: int, topic: str, data) -> Optional[int]:
        """The segment of the message at position ``pos`` of the recording (module doc); None: a stray state."""
        if not self.segments:
            return None
        i = self._at(pos)
        if topic == self.topic:
            try:
                stamp = L.parse_joint_state(data)[0]
            except BadMessage:
                return i
            if (pos, stamp) in self._stray_set or self.segments[i].position_of(stamp) is None:
                return None
            return i
        if leaf(topic) in STAMPED:
            stamp = cdr.peek_stamp(data)
            if stamp is not None:   # the run of the nearest state of that stamp: this one's, or a neighbour's
                near = [(abs(p - pos), j) for j in range(max(0, i - 1), min(len(self.segments), i + 2))
                        for p in (self.segments[j].position_of(stamp),) if p is not None]
                if near:
                    return min(near)[1]
        return i

    def tag(self, messages: Iterable[Message]) -> Iterator[Tuple[Optional[int], int, str, bytes]]:
        """(segment or None, log time, topic, data) of each message (recording order, as given)."""
        for pos, (log_time, topic, data) in enumerate(messages):
            yield self.which(pos, topic, data), log_time, topic, data

    def select(self, index: int, messages: Optional[Iterable[Message]] = None) -> Iterator[Message]:
        """The messages of segment ``index`` (negative: from the end) in recording order, from ``messages``
        (every message of the recording, in recording order; default: read the bag again)."""
        index = range(len(self.segments))[index]
        for seg, log_time, topic, data in self.tag(recorded_messages(self.bag) if messages is None else messages):
            if seg == index:
                yield log_time, topic, data

    def count_topics(self, messages: Optional[Iterable[Message]] = None) -> List[Dict[str, int]]:
        """[{topic: messages}] per segment (a stray state in none)."""
        out: List[Dict[str, int]] = [{} for _ in self.segments]
        for seg, _lt, topic, _data in self.tag(recorded_messages(self.bag) if messages is None else messages):
            if seg is not None:
                out[seg][topic] = out[seg].get(topic, 0) + 1
        return out
