"""The one lockstep driver: publish a state, wait for the command that answers it, and say who is missing.

Used by ``plant_sim`` (both modes wait for the graph; lockstep also steps with it) and by
``bag_replay``'s re-simulation, which drives the observer and controller with recorded
states the way the plant drives them with simulated ones.

1. **Wait for the graph** (:meth:`LockstepDriver.wait_for_graph`): until the controller
   publishes ``wheel_torque_cmd``, any further required publishers are there and
   ``joint_states`` has ``need_subs`` matched subscriptions (the floor the user gives);
   then until the discovered graph is complete and stable: every subscriber discovered on
   a topic the driver's node publishes has matched its writer, and the set of nodes and
   those counts have not changed for ``settle_s``.  So a recorder that is running when
   the plant starts is part of the run from its first message, without the user counting
   it; what a late match still misses the transient-local writers hand over (msgs.qos).
   A discovered subscriber that never matches (incompatible QoS) holds the start for at
   most ``COMPLETE_WAIT_S``, then the run starts with a warning naming it.  While waiting
   it logs progress: "waiting for the graph to come up" at once (discovery takes a moment:
   the normal start), then, after ``WAIT_GRACE_S``, every 2 s the nodes still missing; after
   ``timeout_s`` it reports the wait as failed, naming them and why.
2. **Step** (:meth:`send`, :meth:`take_answer`): publish ``/clock`` and the state (the bytes for
   ``state_pub``, or several messages, e.g. a raw plant's ``imu/data_raw`` and ``wheel_encoder``:
   a list of (publisher, bytes), published in order), then exactly one ``wheel_torque_cmd`` answers it.
   A command while no state waits is the caller's to reject.
3. **Watch** (:meth:`check`): a state nobody answered within ``RESEND_S`` is published
   again (only states sent before every subscription matched are lost; the observer
   answers a repeated stamp again and the controller answers each stamp once, so a
   resend is harmless).  After ``timeout_s`` without an answer the step has failed; the
   text names the node that is missing.  A node that died keeps its place in the graph for
   a while, so from the first resend on the driver also listens to the chain's intermediate
   answers (``disturbance_estimate``): the observer answers a resent state again, and if it does
   not, it is the one to name.

The chain is data (``answers``, :func:`mwip_ros.core.closed_loop.loop.answering`, from
:data:`mwip_ros.core.closed_loop.loop.STAGES`): the nodes that answer a state, in order, and the topic each
answers on.  The plant, the re-simulation and the tests' graph wait all use it.  With a state
estimator in the chain (``answering(estimator=True)``: a raw plant), the estimator alone listens to the
plant's measurement and the observer and the controller to the estimator's ``joint_states``: the
floor of matched subscriptions then counts the estimator instead of them (:func:`subscriber_floor`).
"""
from __future__ import annotations

import time
from typing import Optional, Sequence, Tuple, Union

from mwip_ros.core.closed_loop.loop import STAGES, Answer, answering
from mwip_ros.msgs.cdr import peek_stamp
from mwip_ros.msgs.layouts import encode_clock

__all__ = ["LockstepDriver", "RESEND_S", "SETTLE_S", "graph_missing", "CHAIN", "measurement_listeners",
           "subscriber_floor"]

CHAIN = answering()   # the answering stages of today's loop: the observer, then the law (core.closed_loop.loop.STAGES)

RESEND_S = 0.5          # resend a state nobody answered after this long [s]
HEARD_DEPTH = 10        # the chain's intermediate answers kept between two looks (the newest)
WAIT_GRACE_S = 2.0      # discovery takes a moment: until then a wait for the graph is the normal start
WAIT_LOG_PERIOD_S = 2.0
SETTLE_S = 0.3          # a robot side (plant_sim, wheel_driver): the discovered graph unchanged this long before the
                        # first state
COMPLETE_WAIT_S = 3.0   # once the required nodes are there, wait at most this long for every discovered subscriber
NOT_FOUND_HINT = "started? same ROS_DOMAIN_ID?"


def measurement_listeners(answers: Sequence[Answer]) -> int:
    """How many of the chain's nodes subscribe to the plant's first published topic: a state estimator alone
    when the chain has one (it reads the raw sensors; the others read its ``joint_states``), else every
    answering stage that reads ``joint_states`` (the observer and the controller)."""
    if any(a.stage == "estimator" for a in answers):
        return 1
    inputs = {s.name: s.inputs for s in STAGES}
    return sum(1 for a in answers if "joint_states" in inputs.get(a.stage, ()))


def subscriber_floor(expected: int, answers: Sequence[Answer]) -> int:
    """The matched subscriptions the plant's first published topic needs before the first state, for the
    ``expected_subscribers`` of the chain without an estimator (default 2: the observer and the controller,
    +1 per recorder): what it counts beyond those loop nodes (recorders, viewers) plus the chain's own
    listeners (:func:`measurement_listeners`).  Without an estimator that is ``expected`` itself."""
    return max(0, int(expected) - measurement_listeners(CHAIN) + measurement_listeners(answers))


def _graph_gaps(node, state_pub, need_subs: int, answers: Sequence[Answer]) -> list:
    """What the graph lacks: [(what, why, is a node)], the answer that ends a period (the command) first."""
    gaps = []
    last = answers[-1].topic if answers else None
    for a in reversed(answers):
        if node.count_publishers(a.topic) == 0:
            gaps.append((a.node, f"nothing publishes {a.topic}" + (f"; {a.why}" if a.why and a.topic != last else ""),
                         True))
    matched = state_pub.get_subscription_count()
    if matched < need_subs:
        gaps.append((f"{need_subs} subscribers on {state_pub.topic_name.lstrip('/')}", f"matched: {matched}", False))
    return gaps


def graph_missing(node, state_pub, need_subs: int, answers: Sequence[Answer] = CHAIN) -> list:
    """What a lockstep driver is waiting for, in words naming the nodes."""
    return [f"{what} ({why})" for what, why, _ in _graph_gaps(node, state_pub, need_subs, answers)]


class LockstepDriver:
    """Graph wait, one state in flight, resend and timeout, for a node that publishes states.

    ``answers`` are the answering stages of the chain, in order (:func:`mwip_ros.core.closed_loop.loop.answering`):
    each names its node and the topic it answers on, the last one the command ``cmd_sub`` reads.  An
    extra answering node (a state estimator) is one more entry, not new code here.  ``needed`` are
    further subscriptions of the caller whose topics must have a publisher before the start (e.g.
    ``controller_internals`` for a re-simulation); ``idle_hint`` is what to say when the graph is
    complete but no answer comes.
    """

    def __init__(self, node, state_pub, clock_pub, cmd_sub, *, need_subs: int, timeout_s: float,
                 timeout_param: str, settle_s: float = 0.0, needed: Sequence = (), idle_hint: str = "",
                 also_published: Sequence = (), answers: Sequence[Answer] = CHAIN):
        self.node = node
        self.answers = tuple(answers)
        self.state_pub, self.clock_pub, self.cmd_sub = state_pub, clock_pub, cmd_sub
        self.own_pubs = [p for p in (state_pub, clock_pub, *also_published) if p is not None]
        self.need_subs = need_subs
        self.timeout_s = timeout_s
        self.timeout_param = timeout_param
        self.settle_s = settle_s
        self.needed = tuple(needed)
        self.idle_hint = idle_hint
        self.awaiting: Optional[Tuple[int, int]] = None   # (k, stamp) of the state waiting for its command
        self._last: Optional[Tuple[int, bytes]] = None     # (stamp, bytes) of the last state sent
        self.sent_at = self.resent_at = 0.0
        self.wait_since = time.monotonic()
        self._required_at: Optional[float] = None         # since when the required nodes are there
        self._signature = None                             # the discovered graph, to see it settle
        self._stable_since = 0.0
        self._last_wait_log = 0.0
        self._listening = None                             # subscriptions to the intermediate answers (1st resend)
        self._heard: dict = {}                             # answer topic -> stamp of its newest message heard since

    # --- the graph -----------------------------------------------------------------------------
    def ready(self) -> bool:
        return (self.cmd_sub.get_publisher_count() >= 1
                and all(s.get_publisher_count() >= 1 for s in self.needed)
                and self.state_pub.get_subscription_count() >= self.need_subs)

    def unmatched(self) -> list:
        """Subscribers discovered on our own topics that have not matched our writers: [(topic, matched, found)]."""
        out = []
        for pub in self.own_pubs:
            found, matched = self.node.count_subscribers(pub.topic_name), pub.get_subscription_count()
            if matched < found:
                out.append((pub.topic_name, matched, found))
        return out

    def _graph_signature(self) -> tuple:
        return (tuple(sorted(self.node.get_node_names_and_namespaces())),
                tuple((self.node.count_subscribers(p.topic_name), p.get_subscription_count()) for p in self.own_pubs))

    def missing(self) -> str:
        what = graph_missing(self.node, self.state_pub, self.need_subs, self.answers)
        what += [f"{t}: {m} of {n} discovered subscribers matched" for t, m, n in self.unmatched()]
        if self.awaiting is not None and self._listening is not None:
            self._poll_heard()
            k, stamp = self.awaiting
            for a in self.answers[:-1]:   # the first stage of the chain that did not answer the resent state
                if any(a.node in w for w in what):
                    break
                heard = self._heard.get(a.topic)
                if heard is None or heard < stamp:
                    said = "none since" if heard is None else f"the last for t = {heard * 1e-9:.3f} s, before"
                    what.append(f"{a.node} (it did not answer state k = {k}: no {a.topic} for it, {said} the "
                                f"state was resent; stopped, or killed?)")
                    break
        return "; ".join(what) or self.idle_hint

    def silent_stage(self, since_stamp: int, stamp0: int = 0) -> Tuple[str, str]:
        """(the stage, in words why) of the first answering stage of the chain from which no answer to a state
        stamped ``since_stamp`` or later was heard (:meth:`listen` first); the last stage (the command's) when
        every other one answered.  The realtime watchdog names it (lockstep names it in :meth:`missing`); times
        are said from ``stamp0`` (the run's first stamp) [ns]."""
        self._poll_heard()
        for a in self.answers[:-1]:
            heard = self._heard.get(a.topic)
            if heard is None or heard < since_stamp:
                said = "none ever" if heard is None else f"the last for t = {(heard - stamp0) * 1e-9:.3f} s"
                return a.stage, (f"{a.stage} ({a.node}: no {a.topic} for a state since t = "
                                 f"{(since_stamp - stamp0) * 1e-9:.3f} s, {said})")
        a = self.answers[-1]
        gaps = graph_missing(self.node, self.state_pub, 0, (a,))
        return a.stage, f"{a.stage} ({a.node}: {gaps[0] if gaps else 'every earlier stage answered'})"

    def listen(self, qos=None) -> None:
        """Hear the chain's intermediate answers from now on (once; ``qos`` default INPUT_QOS)."""
        if self._listening is None:
            self._listen_to_answers(qos)

    def _listen_to_answers(self, qos=None) -> None:
        """Hear the chain's intermediate answers (the observer's estimate, ...): a node that died keeps its place
        in the graph for a while, so this is how the driver learns which one stopped answering."""
        from mwip_ros.msgs.qos import INPUT_QOS
        from mwip_ros.msgs.topics import graph_type, msg_class
        qos = INPUT_QOS if qos is None else qos

        def on_answer(topic):
            def heard(data) -> None:
                stamp = peek_stamp(data)
                if stamp is not None and (self._heard.get(topic) is None or stamp > self._heard[topic]):
                    self._heard[topic] = stamp
            return heard

        # read when a verdict needs them (the newest few: keep-last), not as they come: the chain's answers are a
        # side input of the plant, and a flood of them must not queue up in front of its period
        from mwip_ros.nodes.runtime.rclpy_compat import PolledInput
        self._listening = [PolledInput(self.node, msg_class(graph_type(a.topic)), a.topic, qos, on_answer(a.topic),
                                       HEARD_DEPTH) for a in self.answers[:-1]]

    def _poll_heard(self) -> None:
        for sub in self._listening or ():
            sub.poll()

    def wait_for_graph(self) -> Optional[bool]:
        """True once the graph is ready, complete and settled; False when ``timeout_s`` passed; else None."""
        now = time.monotonic()
        if self.ready():
            if self._required_at is None:
                self._required_at = now
            sig = self._graph_signature()
            if sig != self._signature:
                self._signature, self._stable_since = sig, now
            unmatched = self.unmatched()
            if now - self._stable_since >= self.settle_s and (
                    not unmatched or now - self._required_at >= COMPLETE_WAIT_S):
                if unmatched:
                    self.node.get_logger().warning(
                        "starting although discovered subscribers have not matched (incompatible QoS?): "
                        + ", ".join(f"{t} {m} of {n}" for t, m, n in unmatched) + "; they may miss messages")
                return True
        else:
            self._required_at = self._signature = None
        if now - self.wait_since > self.timeout_s:
            return False
        if not self._last_wait_log:
            self._last_wait_log = now
            self.node.get_logger().info("waiting for the graph to come up")
        elif now - self.wait_since >= WAIT_GRACE_S and now - self._last_wait_log >= WAIT_LOG_PERIOD_S:
            self._last_wait_log = now
            self.node.get_logger().info(self.waiting_text())
        return None

    def waiting_text(self) -> str:
        """The progress line of a wait for the graph: what is still missing, in short (the timeout says why)."""
        gaps = _graph_gaps(self.node, self.state_pub, self.need_subs, self.answers)
        nodes = [what for what, _, is_node in gaps if is_node]
        parts = [f"{', '.join(nodes)} ({NOT_FOUND_HINT})"] if nodes else []
        parts += [f"{what} ({why})" for what, why, is_node in gaps if not is_node]
        parts += [f"{t}: {m} of {n} discovered subscribers matched" for t, m, n in self.unmatched()]
        return f"waiting for the graph: {'; '.join(parts)}" if parts else "waiting for the graph to settle"

    def graph_timeout_text(self) -> str:
        return f"graph not ready after {self.timeout_s:g} s; waiting for: {self.missing()}"

    # --- steps ---------------------------------------------------------------------------------
    def _publish(self) -> None:
        stamp, data = self._last
        if self.clock_pub is not None:
            self.clock_pub.publish(encode_clock(stamp))
        if isinstance(data, (bytes, bytearray, memoryview)):
            self.state_pub.publish(data)
        else:
            for pub, message in data:
                pub.publish(message)

    def send(self, k: int, stamp: int, state: Union[bytes, Sequence[Tuple[object, bytes]]]) -> None:
        """Publish ``/clock`` and state k and wait for its command: ``state`` is the serialized state for
        ``state_pub``, or the period's messages as (publisher, bytes) pairs, published in order (a resend
        publishes them all again)."""
        self._last = (stamp, state if isinstance(state, (bytes, bytearray, memoryview)) else tuple(state))
        self._publish()
        self.awaiting = (k, stamp)
        self.sent_at = self.resent_at = time.monotonic()

    def take_answer(self) -> bool:
        """A command came: True (and no state waits any more) if a state was waiting for it."""
        if self.awaiting is None:
            return False
        self.awaiting = None
        return True

    def check(self) -> Optional[str]:
        """Resend a state nobody answered; the failure text once ``timeout_s`` passed without an answer."""
        if self.awaiting is None:
            return None
        now = time.monotonic()
        if now - self.sent_at > self.timeout_s:
            k, stamp = self.awaiting
            return (f"lockstep timeout: no wheel_torque_cmd answered state k = {k} (t = {stamp * 1e-9:.3f} s) "
                    f"within {self.timeout_param} = {self.timeout_s:g} s; missing: {self.missing()}")
        if now - self.resent_at > RESEND_S:
            self.resent_at = now
            if self._listening is None:
                self._listen_to_answers()
            self._publish()
        return None
