"""``bag_replay``: play a recorded MCAP bag back into the graph, or re-simulate it.

usage:
    bag_replay --ros-args -p bag:=BAG_DIR [-p rate:=2.0] [-p loop:=true] [-p publish_clock:=true]
               [-p "topics:=[joint_states, wheel_torque_cmd]"] [-p wait_for_subscribers:=1]
    bag_replay --ros-args -p bag:=BAG_DIR -p mode:=resim [-p tolerance:=1e-9] [-p timeout_s:=10.0]
               (with a freshly started disturbance_observer and dscndo_controller,
                both with use_sim_time:=true, on the same or a changed parameter file)

mode ``replay`` (default): republish the bag's topics (all, or ``topics``) with their recorded
timing (log times, scaled by 1/``rate``), as the exact recorded CDR bytes, reliable QoS.
``publish_clock``: publish ``/clock`` with the bag's time (the log time of each next message)
and do not republish a recorded ``/clock``.  ``loop``: start again at the end.  Progress is
logged every few seconds, a count per topic at the end.  ``wait_for_subscribers``: wait (up to
``timeout_s``) until every replayed topic has that many matched subscriptions (0 = start at once).

mode ``resim``: act as the lockstep plant with the bag's states: for every recorded
``joint_states`` (in order; a resent duplicate stamp once) publish ``/clock`` (its stamp) and
the recorded state, wait for the one ``wheel_torque_cmd`` that answers it, collect the new
``disturbance_estimate`` and ``controller_internals`` by stamp.  Then compare with the recorded
outputs (the k-th recorded command answers the k-th state; estimates and internals by stamp),
print a table of the largest absolute difference per topic and per field, the number of
compared samples and of recorded samples that were not reproduced, and whether everything is
within ``tolerance``.  Before the first state it waits (up to ``timeout_s``) until the
controller's publishers are matched and ``joint_states`` has ``wait_for_subscribers``
subscriptions (0 = automatic: the controller, plus the observer - and its publisher matched -
when the bag has estimates; set 1 to re-simulate plain DSC without an observer).  Recorded
outputs that are not reproduced count as differences; new ones the bag lacks (plain DSC may
not have recorded the last estimates) are listed but not compared.  The controller and the
observer answer each stamp once: restart them before every resim.

exit codes:
    0  replay: finished;  resim: every output reproduced within tolerance
    1  runtime error: resim lockstep timeout (names the missing node), replay subscribers
       never matched, unreadable message data, or interrupted before the end of a resim
    2  bad parameters (a missing or unreadable bag names 'bag')
    4  resim: outputs differ (a difference above tolerance, or a recorded output not reproduced)
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Tuple

from geometry_msgs.msg import WrenchStamped
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from mwip_ros.bag.reader import raw_messages, topic_counts, topic_types
from mwip_ros.bag.schema import BagError
from mwip_ros.nodes import _msgs as M
from mwip_ros.nodes._params import declare
from mwip_ros.nodes._runtime import EXIT_ERROR, EXIT_OK, GracefulNodeMixin, run_node
from mwip_ros.params import ParamError
from mwip_ros.topics import leaf, msg_class

NAME = "bag_replay"
EXIT_DIFFERENT = 4          # resim: outputs differ from the recording
PROGRESS_PERIOD_S = 3.0
RESEND_S = 0.5              # resim: resend a state nobody answered (lost before the graph matched)
COLLECT_IDLE_S = 1.0        # resim: after the last command, wait this long without news for stragglers
COLLECT_MAX_S = 5.0
ESTIMATE_FIELDS = ("tau_hat1", "tau_hat2")  # wrench.torque.x, wrench.torque.y


def _diff(a: float, b: float) -> float:
    if math.isnan(a) and math.isnan(b):
        return 0.0
    if a == b:  # also equal infinities
        return 0.0
    d = abs(a - b)
    return math.inf if math.isnan(d) else d


class Stat:
    """Largest absolute difference and the number of compared / not reproduced samples."""

    def __init__(self):
        self.compared = 0
        self.missing = 0
        self.extra = 0
        self.max_diff = 0.0

    def add(self, d: float) -> None:
        self.max_diff = max(self.max_diff, d)

    def ok(self, tol: float) -> bool:
        return self.missing == 0 and self.max_diff <= tol


def _estimate(msg) -> Dict[str, float]:
    return {"tau_hat1": float(msg.wrench.torque.x), "tau_hat2": float(msg.wrench.torque.y)}


def _compare_stamped(rec: Dict[int, Dict[str, float]], new: Dict[int, Dict[str, float]], fed, names):
    """Compare recorded and new stamped outputs field by field, for the stamps that were fed.

    Returns the topic's Stat and {field: Stat}; a recorded stamp with no new output counts as missing,
    a recorded field the new output lacks as an infinite difference.
    """
    st = Stat()
    names = list(names)
    for fields in rec.values():
        names += [n for n in fields if n not in names]
    fs = {n: Stat() for n in names}
    for stamp, r in rec.items():
        if stamp not in fed:
            continue
        n_new = new.get(stamp)
        if n_new is None:
            st.missing += 1
            continue
        st.compared += 1
        for n, a in r.items():
            d = _diff(a, n_new[n]) if n in n_new else math.inf
            fs[n].add(d)
            fs[n].compared += 1
            st.add(d)
    st.extra = sum(1 for s in new if s not in rec)
    return st, fs


class BagReplay(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        bag = str(self.v["bag"]).strip()
        if not bag:
            raise ParamError("bag", "required: the bag directory to replay (e.g. -p bag:=bags/run1)")
        self.bag = str(Path(bag).expanduser())
        try:
            self.types = topic_types(self.bag)
            self.counts = topic_counts(self.bag)
        except BagError as exc:
            raise ParamError("bag", f"cannot read the bag: {exc}") from None
        except (OSError, ValueError) as exc:
            raise ParamError("bag", f"cannot read the bag {self.bag}: {exc}") from None
        self.mode = self.v["mode"]
        self.log = self.get_logger()
        self.t_wall0: Optional[float] = None
        self.wait_since = time.monotonic()
        self.last_wait_log = 0.0
        self.started = False
        if self.mode == "replay":
            self._init_replay()
        else:
            self._init_resim()

    # ================================================================================ replay
    def _select(self, names: List[str]) -> List[str]:
        bag_topics = sorted(self.types)
        if not names:
            return bag_topics
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

    def _init_replay(self) -> None:
        self.rate = self.v["rate"]
        selected = self._select(self.v["topics"])
        self.clock_pub = None
        if self.v["publish_clock"]:
            self.clock_pub = self.create_publisher(Clock, "/clock", M.GRAPH_QOS)
            if "/clock" in selected:
                selected.remove("/clock")
                self.log.info("publish_clock: the recorded /clock is not republished (the bag's time is)")
        self.pubs = {}
        for topic in selected:
            try:
                cls = msg_class(self.types[topic])
            except ValueError as exc:
                if self.v["topics"]:
                    raise ParamError("topics", f"cannot replay {topic}: {exc}") from None
                self.log.warning(f"skipping {topic}: {exc}")
                continue
            self.pubs[topic] = self.create_publisher(cls, topic, M.GRAPH_QOS)
        if not self.pubs and self.clock_pub is None:
            raise ParamError("topics" if self.v["topics"] else "bag", f"nothing to replay in {self.bag}")
        self.sent: Dict[str, int] = {t: 0 for t in self.pubs}
        self.clock_count = 0
        self.total = sum(self.counts.get(t, 0) for t in self.pubs)
        self.loops = 0
        self.stream: Optional[Iterator] = None
        self.pending: Optional[Tuple[int, str, bytes]] = None
        self.first_log: Optional[int] = None
        self.bag_duration = 0.0
        self.last_clock: Optional[int] = None
        self.last_progress = time.monotonic()
        self.log.info(f"replaying {self.bag} at rate {self.rate:g}{' (looping)' if self.v['loop'] else ''}: "
                      + ", ".join(f"{t} {self.counts.get(t, 0)}" for t in self.pubs)
                      + (" + /clock from the bag's time" if self.clock_pub is not None else ""))

    def _replay_ready(self, executor) -> bool:
        need = self.v["wait_for_subscribers"]
        lacking = {t: p.get_subscription_count() for t, p in self.pubs.items() if p.get_subscription_count() < need}
        if not lacking:
            return True
        now = time.monotonic()
        if now - self.wait_since > self.v["timeout_s"]:
            self.log.error(f"subscribers not matched after timeout_s = {self.v['timeout_s']:g} s (want {need} each): "
                           + ", ".join(f"{t} {n}" for t, n in lacking.items()))
            self.exit_code = EXIT_ERROR
            self.done = True
        elif now - self.last_wait_log > 2.0:
            self.last_wait_log = now
            self.log.info(f"waiting for {need} subscriber(s) on: " + ", ".join(lacking))
        executor.spin_once(timeout_sec=0.02)
        return False

    def _start_pass(self) -> None:
        self.stream = raw_messages(self.bag, list(self.pubs))
        self.pending = None
        self.first_log = None
        self.t_pass0 = time.monotonic()

    def _next(self) -> Optional[Tuple[int, str, bytes]]:
        if self.pending is None:
            self.pending = next(self.stream, None)
        return self.pending

    def _replay_step(self, executor) -> None:
        if not self.started:
            if not self._replay_ready(executor):
                return
            self.started = True
            self.t_wall0 = time.monotonic()
            self._start_pass()
        try:
            item = self._next()
        except BagError as exc:
            self.log.error(str(exc))
            self.exit_code = EXIT_ERROR
            self.done = True
            return
        if item is None:  # end of the bag
            self.loops += 1
            if self.v["loop"] and self.first_log is not None:
                self.log.info(f"end of bag (pass {self.loops}); starting again")
                self._start_pass()
                return
            self.done = True
            return
        log_time, topic, data = item
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
        if self.clock_pub is not None and log_time != self.last_clock:
            self.clock_pub.publish(Clock(clock=M.to_time(log_time)))
            self.last_clock = log_time
            self.clock_count += 1
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

    def _replay_report(self) -> None:
        wall = (time.monotonic() - self.t_wall0) if self.t_wall0 else 0.0
        for pub in (*self.pubs.values(), self.clock_pub):
            if pub is not None:  # let the subscribers receive the last messages before this process exits
                pub.wait_for_all_acked(Duration(seconds=2.0))
        n = sum(self.sent.values())
        per = ", ".join(f"{t} {c}" for t, c in self.sent.items())
        if self.clock_pub is not None:
            per += f", /clock {self.clock_count} (from the bag's time)"
        if self.v["loop"]:
            what = f"{n} messages ({self.total} per pass, {self.loops} complete pass(es))"
        else:
            what = f"{n} of {self.total} messages" + ("" if self.loops >= 1 else " (interrupted)")
        self.log.info(f"replayed {what} in {wall:.3f} s wall (bag span {self.bag_duration:.3f} s, "
                      f"rate {self.rate:g}): {per}")

    # ================================================================================= resim
    def _bag_topic(self, name: str, required: bool) -> Optional[str]:
        cands = [t for t in self.types if leaf(t) == name]
        if len(cands) > 1:
            exact = [t for t in cands if t == "/" + name]
            if len(exact) != 1:
                raise ParamError("bag", f"several {name} topics in the bag ({', '.join(sorted(cands))}); "
                                        f"resim needs one")
            cands = exact
        if not cands:
            if required:
                raise ParamError("bag", f"{self.bag} has no {name} topic (it has: {', '.join(sorted(self.types))}); "
                                        f"resim needs the recorded states")
            return None
        return cands[0]

    def _init_resim(self) -> None:
        if self.v["loop"]:
            raise ParamError("loop", "loop is for mode replay; resim feeds every recorded state once")
        ignored = [k for k, d in (("rate", 1.0), ("publish_clock", False)) if self.v[k] != d]
        if self.v["topics"]:
            ignored.append("topics")
        if ignored:
            self.log.info(f"resim: ignoring {', '.join(ignored)} (lockstep, /clock from each state's stamp)")
        t_state = self._bag_topic("joint_states", True)
        t_cmd = self._bag_topic("wheel_torque_cmd", False)
        t_est = self._bag_topic("disturbance_estimate", False)
        t_int = self._bag_topic("controller_internals", False)
        self.states: List[Tuple[int, bytes]] = []
        self.rec_cmds: List[float] = []
        self.rec_est: Dict[int, Dict[str, float]] = {}
        self.rec_int: Dict[int, Dict[str, float]] = {}
        seen = set()
        dropped = 0
        try:
            wanted = [t for t in (t_state, t_cmd, t_est, t_int) if t]
            for _lt, topic, data in raw_messages(self.bag, wanted):
                if topic == t_state:
                    stamp = M.stamp_ns(deserialize_message(data, JointState).header.stamp)
                    if stamp in seen:
                        continue  # a state the plant resent: fed (and answered) once
                    if self.states and stamp < self.states[-1][0]:
                        dropped += 1
                        continue
                    seen.add(stamp)
                    self.states.append((stamp, data))
                elif topic == t_cmd:
                    self.rec_cmds.append(float(deserialize_message(data, Float64).data))
                elif topic == t_est:
                    m = deserialize_message(data, WrenchStamped)
                    self.rec_est.setdefault(M.stamp_ns(m.header.stamp), _estimate(m))
                elif topic == t_int:
                    m = deserialize_message(data, JointState)
                    self.rec_int.setdefault(M.stamp_ns(m.header.stamp),
                                            {n: float(x) for n, x in zip(m.name, m.position)})
        except BagError as exc:
            raise ParamError("bag", f"cannot read the bag: {exc}") from None
        except Exception as exc:  # undecodable CDR
            raise ParamError("bag", f"cannot decode the recorded messages of {self.bag}: "
                                    f"{type(exc).__name__}: {exc}") from None
        if not self.states:
            raise ParamError("bag", f"{self.bag} has no joint_states messages to re-simulate")
        if dropped:
            self.log.warning(f"skipped {dropped} recorded state(s) older than the one before them")
        if t_cmd and len(self.rec_cmds) != len(self.states):
            self.log.warning(f"the bag has {len(self.rec_cmds)} wheel_torque_cmd for {len(self.states)} states; "
                             f"commands are compared in order (k-th command = answer to the k-th state)")
        self.has = {"wheel_torque_cmd": t_cmd is not None, "disturbance_estimate": t_est is not None,
                    "controller_internals": t_int is not None}
        self.stamp_set = set(seen)
        self.new_cmds: List[float] = []
        self.new_est: Dict[int, Dict[str, float]] = {}
        self.new_int: Dict[int, Dict[str, float]] = {}
        self.extra_cmds = 0
        self.k = 0
        self.awaiting: Optional[int] = None
        self.sent_at = self.resent_at = 0.0
        self.collecting_since: Optional[float] = None
        self.last_news = 0.0
        self.finished = False
        self.failed = False
        self.result: Optional[bool] = None

        self.clock_pub = self.create_publisher(Clock, "/clock", M.GRAPH_QOS)
        self.state_pub = self.create_publisher(JointState, "joint_states", M.GRAPH_QOS)
        self.cmd_sub = self.create_subscription(Float64, "wheel_torque_cmd", self._on_cmd, M.GRAPH_QOS)
        self.est_sub = self.create_subscription(WrenchStamped, "disturbance_estimate", self._on_est, M.GRAPH_QOS)
        self.int_sub = self.create_subscription(JointState, "controller_internals", self._on_int, M.GRAPH_QOS)
        need = self.v["wait_for_subscribers"]
        self.need_subs = need if need > 0 else (2 if self.has["disturbance_estimate"] else 1)
        t0, t1 = self.states[0][0] * 1e-9, self.states[-1][0] * 1e-9
        self.log.info(f"resim of {self.bag}: {len(self.states)} states (t = {t0:.3f} .. {t1:.3f} s), recorded "
                      f"{len(self.rec_cmds)} commands, {len(self.rec_est)} estimates, {len(self.rec_int)} "
                      f"internals; tolerance {self.v['tolerance']:g}")

    # --- inputs
    def _on_cmd(self, msg: Float64) -> None:
        if self.awaiting is None:
            self.extra_cmds += 1
            if self.extra_cmds <= 3:
                self.log.warning("a wheel_torque_cmd while no state was waiting for one (ignored)")
            return
        self.new_cmds.append(float(msg.data))
        self.awaiting = None
        self.k += 1
        self.last_news = time.monotonic()
        if self.k < len(self.states):
            self._send()
        else:
            self.collecting_since = time.monotonic()
            self.log.info(f"all {len(self.states)} states answered in {time.monotonic() - self.t_wall0:.2f} s; "
                          f"collecting the last estimates and internals")

    def _on_est(self, msg: WrenchStamped) -> None:
        stamp = M.stamp_ns(msg.header.stamp)
        self.new_est.setdefault(stamp, _estimate(msg))
        self.last_news = time.monotonic()

    def _on_int(self, msg: JointState) -> None:
        stamp = M.stamp_ns(msg.header.stamp)
        self.new_int.setdefault(stamp, {n: float(x) for n, x in zip(msg.name, msg.position)})
        self.last_news = time.monotonic()

    # --- lockstep
    def _publish_state(self) -> None:
        stamp, data = self.states[self.k]
        self.clock_pub.publish(Clock(clock=M.to_time(stamp)))
        self.state_pub.publish(data)

    def _send(self) -> None:
        self._publish_state()
        self.awaiting = self.states[self.k][0]
        self.sent_at = self.resent_at = time.monotonic()

    def _missing(self) -> str:
        what = M.lockstep_missing(self, self.state_pub, self.need_subs)
        return "; ".join(what) or ("an answer from the running dscndo_controller: it and the disturbance_observer "
                                   "answer each stamp once, so restart both before every resim")

    def _graph_ready(self) -> bool:
        if self.cmd_sub.get_publisher_count() < 1:
            return False
        if self.has["controller_internals"] and self.int_sub.get_publisher_count() < 1:
            return False
        if self.has["disturbance_estimate"] and self.v["wait_for_subscribers"] == 0 \
                and self.est_sub.get_publisher_count() < 1:
            return False
        return self.state_pub.get_subscription_count() >= self.need_subs

    def _fail(self, text: str) -> None:
        self.log.error(text)
        self.failed = True
        self.exit_code = EXIT_ERROR
        self.done = True

    def _resim_step(self, executor) -> None:
        now = time.monotonic()
        timeout = self.v["timeout_s"]
        if not self.started:
            if self._graph_ready():
                self.started = True
                self.t_wall0 = now
                self.log.info("graph matched; starting the lockstep re-simulation")
                self._send()
            elif now - self.wait_since > timeout:
                self._fail(f"resim timeout: graph not ready after timeout_s = {timeout:g} s; waiting for: "
                           f"{self._missing()}")
                return
            elif now - self.last_wait_log > 2.0:
                self.last_wait_log = now
                self.log.info(f"waiting for: {self._missing()}")
            executor.spin_once(timeout_sec=0.02)
            return
        executor.spin_once(timeout_sec=0.05)
        now = time.monotonic()
        if self.collecting_since is not None:
            if self._all_collected() or now - self.last_news > COLLECT_IDLE_S \
                    or now - self.collecting_since > COLLECT_MAX_S:
                self.finished = True
                self.done = True
            return
        if self.awaiting is not None:
            if now - self.sent_at > timeout:
                self._fail(f"resim timeout: no wheel_torque_cmd answered state k = {self.k} (stamp "
                           f"{self.awaiting * 1e-9:.3f} s) within timeout_s = {timeout:g} s; "
                           f"missing: {self._missing()}")
            elif now - self.resent_at > RESEND_S:
                self.resent_at = now
                self._publish_state()

    def _all_collected(self) -> bool:
        return all(s in self.new_est for s in self.rec_est if s in self.stamp_set) and \
            all(s in self.new_int for s in self.rec_int if s in self.stamp_set)

    # --- comparison
    def compare(self):
        """{topic: Stat}, {topic: {field: Stat}}."""
        fed = set(s for s, _ in self.states[:self.k])
        topics: Dict[str, Stat] = {}
        fields: Dict[str, Dict[str, Stat]] = {}
        if self.has["wheel_torque_cmd"]:
            st = topics["wheel_torque_cmd"] = Stat()
            n = min(len(self.rec_cmds), len(self.new_cmds))
            for a, b in zip(self.rec_cmds[:n], self.new_cmds[:n]):
                st.add(_diff(a, b))
            st.compared = n
            st.missing = max(0, min(len(self.rec_cmds), self.k) - n)
            st.extra = len(self.new_cmds) - n + self.extra_cmds
        if self.has["disturbance_estimate"]:
            topics["disturbance_estimate"], fields["disturbance_estimate"] = _compare_stamped(
                self.rec_est, self.new_est, fed, ESTIMATE_FIELDS)
        if self.has["controller_internals"]:
            st, fs = _compare_stamped(self.rec_int, self.new_int, fed, M.INTERNAL_NAMES)
            topics["controller_internals"] = st
            fields["controller_internals"] = {n: f for n, f in fs.items() if f.compared}
        return topics, fields

    def _resim_report(self) -> None:
        tol = self.v["tolerance"]
        topics, fields = self.compare()
        wall = (time.monotonic() - self.t_wall0) if self.t_wall0 else 0.0
        lines = [f"bag_replay resim of {self.bag}",
                 f"  states fed: {self.k} of {len(self.states)} in {wall:.2f} s wall; tolerance {tol:g}",
                 f"  {'topic / field':<28}{'compared':>9}{'missing':>9}{'max |diff|':>14}  within",
                 "  " + "-" * 68]
        for topic, st in topics.items():
            lines.append(f"  {topic:<28}{st.compared:>9}{st.missing:>9}{st.max_diff:>14.3e}  "
                         f"{'yes' if st.ok(tol) else 'NO'}")
            for f, fst in fields.get(topic, {}).items():
                lines.append(f"    {f:<26}{fst.compared:>9}{'':>9}{fst.max_diff:>14.3e}  "
                             f"{'yes' if fst.max_diff <= tol else 'NO'}")
        extras = {t: st.extra for t, st in topics.items() if st.extra}
        if extras:
            lines.append("  not in the recording (not compared): " + ", ".join(f"{t} {n}" for t, n in extras.items()))
        absent = [t for t, h in self.has.items() if not h]
        if absent:
            lines.append("  not recorded (not compared): " + ", ".join(absent))
        bad = [t for t, st in topics.items() if not st.ok(tol)]
        if not self.finished:
            why = "failed" if self.failed else "interrupted"
            lines.append(f"  RESULT: INCOMPLETE - the re-simulation {why} after {self.k} of {len(self.states)} "
                         f"states; the table compares those (exit {EXIT_ERROR})")
            if not self.failed:
                self.exit_code = EXIT_ERROR
        elif bad:
            self.exit_code = EXIT_DIFFERENT
            lines.append(f"  RESULT: DIFFERENT - {', '.join(bad)} not within tolerance {tol:g} "
                         f"(exit {EXIT_DIFFERENT})")
        else:
            self.exit_code = EXIT_OK
            lines.append(f"  RESULT: REPRODUCED - every compared output within tolerance {tol:g} (exit {EXIT_OK})")
        self.result = self.finished and not bad
        print("\n".join(lines), flush=True)

    # ================================================================================ common
    def spin_step(self, executor) -> None:
        if self.mode == "replay":
            self._replay_step(executor)
        else:
            self._resim_step(executor)

    def on_shutdown(self) -> None:
        if self.mode == "replay":
            self._replay_report()
        else:
            self._resim_report()


def main(argv=None) -> int:
    args = list(sys.argv if argv is None else argv)
    head = args[1:args.index("--ros-args")] if "--ros-args" in args else args[1:]
    if "-h" in head or "--help" in head:
        print(__doc__)
        return EXIT_OK
    return run_node(BagReplay, args)


if __name__ == "__main__":
    sys.exit(main())
