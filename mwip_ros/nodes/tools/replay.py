"""``bag_replay`` mode ``replay``: republish a bag's topics with their recorded timing.

The exact recorded CDR bytes go out on each topic (all but ROS's own ``/rosout``,
``/parameter_events`` and ``/diagnostics``, which tell of the recorded run and would only
confuse the live one; or ``topics``, which may name them) at the recorded
log times scaled by 1/``rate``; ``publish_clock`` publishes ``/clock`` with the bag's time
instead of a recorded ``/clock``; ``loop`` starts again at the end;
``wait_for_subscribers`` waits (up to ``timeout_s``) for that many matched subscriptions
on every replayed topic.  A stamped message with the same stamp as the one before it on
its topic (a state the lockstep plant resent before the graph had matched, and the
observer's repeated answer to it) is recorded twice but replayed once.  Progress every
few seconds, a count per topic at the end.
"""
from __future__ import annotations

import time
from typing import Dict, Iterator, List, Optional, Tuple

from rclpy.duration import Duration
from rosgraph_msgs.msg import Clock

from mwip_ros.bag import BagError, raw_messages
from mwip_ros.msgs.cdr import peek_stamp
from mwip_ros.msgs.layouts import encode_clock
from mwip_ros.msgs.qos import GRAPH_QOS, recorded_qos
from mwip_ros.msgs.topics import SYSTEM_TOPICS, leaf, msg_class
from mwip_ros.nodes.runtime.process import EXIT_ERROR, EXIT_OK
from mwip_ros.params import ParamError

__all__ = ["Replay"]

PROGRESS_PERIOD_S = 3.0


class Replay:
    """The replay mode of the ``bag_replay`` node ``node`` (its parameters ``v``, ``bag``, ``types``, ``counts``)."""

    def __init__(self, node):
        self.node = node
        self.v = node.v
        self.log = node.get_logger()
        self.rate = self.v["rate"]
        selected = self._select(self.v["topics"])
        self.clock_pub = None
        if self.v["publish_clock"]:
            self.clock_pub = node.create_publisher(Clock, "/clock", GRAPH_QOS)
            if "/clock" in selected:
                selected.remove("/clock")
                self.log.info("publish_clock: the recorded /clock is not republished (the bag's time is)")
        self.pubs = {}
        for topic in selected:
            try:
                cls = msg_class(node.types[topic])
            except ValueError as exc:
                if self.v["topics"]:
                    raise ParamError("topics", f"cannot replay {topic}: {exc}") from None
                self.log.warning(f"skipping {topic}: {exc}")
                continue
            qos = recorded_qos(node.qos.get(topic, []))   # as the recorded publishers offered it
            self.pubs[topic] = node.create_publisher(cls, topic, qos)
        if not self.pubs and self.clock_pub is None:
            raise ParamError("topics" if self.v["topics"] else "bag", f"nothing to replay in {node.bag}")
        self.sent: Dict[str, int] = {t: 0 for t in self.pubs}
        stamped = ("sensor_msgs/msg/JointState", "geometry_msgs/msg/WrenchStamped", "rosgraph_msgs/msg/Clock")
        self.last_stamp = {t: None for t in self.pubs if node.types[t] in stamped}  # resends are replayed once
        self.resends = 0
        self.clock_count = 0
        self.total = sum(node.counts.get(t, 0) for t in self.pubs)
        self.loops = 0
        self.started = False
        self.t_wall0: Optional[float] = None
        self.wait_since = time.monotonic()
        self.behind = 0.0   # the most a message was published after its time [s]
        self.last_wait_log = 0.0
        self.stream: Optional[Iterator] = None
        self.pending: Optional[Tuple[int, str, bytes]] = None
        self.first_log: Optional[int] = None
        self.bag_duration = 0.0
        self.last_clock: Optional[int] = None
        self.last_progress = time.monotonic()
        self.log.info(f"replaying {node.bag} at rate {self.rate:g}{' (looping)' if self.v['loop'] else ''}: "
                      + ", ".join(f"{t} {node.counts.get(t, 0)}" for t in self.pubs)
                      + (" + /clock from the bag's time" if self.clock_pub is not None else ""))

    def _select(self, names: List[str]) -> List[str]:
        bag_topics = sorted(self.node.types)
        if not names:
            return [t for t in bag_topics if t not in SYSTEM_TOPICS]
        out = []
        for name in names:
            name = name.strip()
            cands = [t for t in bag_topics if t == name] or [t for t in bag_topics if t == "/" + name.lstrip("/")] \
                or [t for t in bag_topics if leaf(t) == leaf(name)]
            if len(cands) != 1:
                what = "is not in the bag" if not cands else f"is ambiguous ({', '.join(cands)})"
                raise ParamError("topics", f"{name!r} {what}; the bag's topics are: {', '.join(bag_topics)}")
            if cands[0] not in out:
                out.append(cands[0])
        return out

    def _ready(self, executor) -> bool:
        need = self.v["wait_for_subscribers"]
        lacking = {t: p.get_subscription_count() for t, p in self.pubs.items() if p.get_subscription_count() < need}
        if not lacking:
            return True
        now = time.monotonic()
        if now - self.wait_since > self.v["timeout_s"]:
            self.node.finish(EXIT_ERROR, f"subscribers not matched after timeout_s = {self.v['timeout_s']:g} s "
                                         f"(want {need} each): " + ", ".join(f"{t} {n}" for t, n in lacking.items()))
        elif now - self.last_wait_log > 2.0:
            self.last_wait_log = now
            self.log.info(f"waiting for {need} subscriber(s) on: " + ", ".join(lacking))
        executor.spin_once(timeout_sec=0.02)
        return False

    def _start_pass(self) -> None:
        self.stream = raw_messages(self.node.bag, list(self.pubs))
        self.pending = None
        self.first_log = None
        self.t_pass0 = time.monotonic()

    def step(self, executor) -> None:
        if not self.started:
            if not self._ready(executor):
                return
            self.started = True
            self.t_wall0 = time.monotonic()
            self._start_pass()
        try:
            if self.pending is None:
                self.pending = next(self.stream, None)
        except BagError as exc:
            self.node.finish(EXIT_ERROR, str(exc))
            return
        if self.pending is None:  # end of the bag
            self.loops += 1
            if self.v["loop"] and self.first_log is not None:
                self.log.info(f"end of bag (pass {self.loops}); starting again")
                self._start_pass()
                return
            self.node.finish(EXIT_OK)
            return
        log_time, topic, data = self.pending
        if self.first_log is None:
            self.first_log = log_time
        due = self.t_pass0 + (log_time - self.first_log) * 1e-9 / self.rate
        wait = due - time.monotonic()
        if wait > 0.02:
            executor.spin_once(timeout_sec=min(wait - 0.01, 0.1))
            self._progress()
            return
        if wait > 0:
            time.sleep(wait)
        else:   # behind the bag's timing (a loaded machine): said in the report
            self.behind = max(self.behind, -wait)
        if self.clock_pub is not None and log_time != self.last_clock:
            self.clock_pub.publish(encode_clock(log_time))
            self.last_clock = log_time
            self.clock_count += 1
        if topic in self.last_stamp:
            stamp = peek_stamp(data)
            if stamp is not None and stamp == self.last_stamp[topic]:
                self.resends += 1
                self.pending = None
                return
            self.last_stamp[topic] = stamp
        self.pubs[topic].publish(data)
        self.sent[topic] += 1
        self.bag_duration = max(self.bag_duration, (log_time - self.first_log) * 1e-9)
        self.pending = None
        self._progress()

    def _progress(self) -> None:
        now = time.monotonic()
        if now - self.last_progress >= PROGRESS_PERIOD_S:
            self.last_progress = now
            n = sum(self.sent.values())
            self.log.info(f"replayed {n} messages (pass {self.loops + 1}, bag time {self.bag_duration:.3f} s, "
                          f"wall {now - self.t_wall0:.2f} s)")

    def report(self) -> None:
        wall = (time.monotonic() - self.t_wall0) if self.t_wall0 else 0.0
        for pub in (*self.pubs.values(), self.clock_pub):
            if pub is not None:  # let the subscribers receive the last messages before this process exits
                pub.wait_for_all_acked(Duration(seconds=2.0))
        n = sum(self.sent.values()) + self.resends  # the bag's messages gone through, a resend counted too
        per = ", ".join(f"{t} {c}" for t, c in self.sent.items())
        if self.clock_pub is not None:
            per += f", /clock {self.clock_count} (from the bag's time)"
        if self.v["loop"]:
            what = f"{n} messages ({self.total} per pass, {self.loops} complete pass(es))"
        else:
            what = f"{n} of {self.total} messages" + ("" if self.loops >= 1 else " (interrupted)")
        if self.resends:
            per += f"; {self.resends} resent message(s) (a stamp repeated on its topic) replayed once"
        self.log.info(f"replayed {what} in {wall:.3f} s wall (bag span {self.bag_duration:.3f} s, "
                      f"rate {self.rate:g}, at most {self.behind:.3f} s behind the bag's timing): {per}")
