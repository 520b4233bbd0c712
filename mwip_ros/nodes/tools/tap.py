"""Raw subscriptions to a set of the graph's topics, for nodes that pass bytes on unread.

Used by ``mcap_recorder`` (into a bag) and ``foxglove_server`` (to a WebSocket): each gets
every message as the exact CDR bytes received, through ``on_message(topic, type_name, data)``.

* The loop's own topics (every graph topic but :data:`~mwip_ros.msgs.topics.USER_TOPICS`)
  are subscribed at once with :data:`~mwip_ros.msgs.qos.RECORD_QOS` (reliable, keep last
  1000, transient local, as the graph's nodes publish them): the subscription exists before
  the nodes do, so a plant told to wait for it (``expected_subscribers``) starts only once
  it listens, and a writer that matches a moment late still hands over its last 1000
  messages.
* Should a publisher offer a QoS that cannot match it (``ros2 topic pub`` or ``ros2 bag play
  --clock`` are volatile), the topic is subscribed again with a QoS adapted to its publishers,
  as ``ros2 bag record`` does: keep last 1000, reliable unless a publisher is best effort,
  transient local only when every publisher is.
* ``external_wrench`` (users publish it by hand) and the ROS system topics
  (:data:`~mwip_ros.msgs.topics.SYSTEM_TOPICS`: ``/rosout``, ``/parameter_events``,
  ``/diagnostics``, each published with its own QoS) are subscribed that way once their first
  publisher is discovered.

The owner's loop calls :meth:`TopicTap.spin` (or :meth:`TopicTap.poll` between callbacks: the
subscriptions are created and replaced there, never inside a callback, and spins with
:meth:`TopicTap.spin_timeout`).  A callback that raises in the executor (a hostile parameter request
that got past :mod:`.rclpy_compat`, say) is logged and the owner goes on recording or forwarding.
"""
from __future__ import annotations

import time
import traceback
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from mwip_ros.bag import BagError, message_definition
from mwip_ros.bag import type_hash as installed_type_hash
from mwip_ros.msgs.qos import DEPTH, RECORD_QOS
from mwip_ros.msgs.topics import GRAPH_TOPICS, SYSTEM_TOPICS, USER_TOPICS, graph_type, leaf, msg_class, topic_type
from mwip_ros.params import ParamError

__all__ = ["TopicTap", "adapted_qos", "resolve_topics", "DISCOVERY_POLL_S"]

DISCOVERY_POLL_S = 0.02  # how often to look for the first publisher of a topic not yet subscribed
PROGRESS_PERIOD_S = 5.0  # a progress line at most this often, when messages came
BROKEN_AFTER_S = 5.0     # an executor whose every turn raised for this long is broken: the owner ends its run


def adapted_qos(infos) -> QoSProfile:
    """The subscription QoS that matches every publisher in ``infos`` and loses nothing they keep."""
    profiles = [i.qos_profile for i in infos]
    reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in profiles)
    transient = all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in profiles)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)


def resolve_topics(node, names: Optional[Sequence[str]], param: str = "topics") -> List[Tuple[str, str, str]]:
    """[(name as given, fully resolved name, type)] of ``names`` (empty: every graph and system topic);
    :class:`ParamError` naming ``param`` for a name that is not one of them or cannot be resolved."""
    names = [n.strip() for n in (names or []) if n.strip()] or [*GRAPH_TOPICS, *SYSTEM_TOPICS]
    out: List[Tuple[str, str, str]] = []
    seen = set()
    for name in names:
        type_name = topic_type(name)
        if type_name is None:
            raise ParamError(param, f"unknown topic {name!r}; the topics are: "
                                    + ", ".join([*GRAPH_TOPICS, *SYSTEM_TOPICS]))
        if graph_type(name) is None:
            name = "/" + name.strip("/")   # a system topic: absolute, whatever the node's namespace
        try:
            resolved = node.resolve_topic_name(name)
        except Exception as exc:
            raise ParamError(param, f"invalid topic name {name!r}: {exc}") from None
        if resolved in seen:
            continue
        seen.add(resolved)
        try:
            message_definition(type_name)  # fail now, not at the first message
            msg_class(type_name)
        except (BagError, ValueError) as exc:
            raise ParamError(param, f"cannot subscribe {name!r}: {exc}") from None
        out.append((name, resolved, type_name))
    return out


class TopicTap:
    """Raw subscriptions to ``topics`` ([(name, resolved, type)], see :func:`resolve_topics`)."""

    def __init__(self, node, topics: Sequence[Tuple[str, str, str]],
                 on_message: Callable[[str, str, bytes], None], what: str = "recorded"):
        self.node, self.on_message, self.what = node, on_message, what
        self.types: Dict[str, str] = {resolved: type_name for _, resolved, type_name in topics}
        self.subs: Dict[str, object] = {}
        self.pending: Dict[str, Tuple[str, str]] = {}   # resolved -> (name as given, type): no publisher seen yet
        self._readapt: set = set()                      # subscribed with RECORD_QOS, but a publisher cannot match it
        self._next_poll = 0.0
        self._last_progress, self._last_count = time.monotonic(), 0
        self.callback_errors = 0                        # exceptions the executor raised from a callback
        self._failing_since: Optional[float] = None     # the first of the turns that raised in a row
        for name, resolved, type_name in topics:
            if leaf(resolved) in USER_TOPICS or resolved in SYSTEM_TOPICS:
                self.pending[resolved] = (name, type_name)
            else:
                self._subscribe(resolved, name, type_name, RECORD_QOS)
        self._subscribe_discovered()

    def poll(self) -> None:
        """Between callbacks: subscribe again what could not match, and what has a first publisher now."""
        if self._readapt:
            for resolved in sorted(self._readapt):
                self.node.destroy_subscription(self.subs.pop(resolved))
                self.pending[resolved] = (resolved, self.types[resolved])
            self._readapt.clear()
            self._next_poll = 0.0
        if self.pending and time.monotonic() >= self._next_poll:
            self._next_poll = time.monotonic() + DISCOVERY_POLL_S
            self._subscribe_discovered()

    def spin(self, executor, count: Callable[[], int], progress: Callable[[], str],
             failed: Callable[[str], None]) -> None:
        """One turn of the owner's loop: subscribe what is due, take what arrived (a callback that raised is
        logged and the loop goes on; an executor that raises on every turn for ``BROKEN_AFTER_S`` goes to
        ``failed(text)``), and every ``PROGRESS_PERIOD_S`` log ``progress()`` if ``count()`` moved."""
        self.poll()
        try:
            executor.spin_once(timeout_sec=self.spin_timeout())
        except Exception as exc:  # noqa: BLE001 - one callback's error: logged, the node goes on
            self._callback_failed(exc, failed)
            return
        self._failing_since = None
        now = time.monotonic()
        if now - self._last_progress >= PROGRESS_PERIOD_S:
            self._last_progress = now
            n = count()
            if n != self._last_count:
                self._last_count = n
                self.node.get_logger().info(progress())

    def _callback_failed(self, exc: Exception, failed: Callable[[str], None]) -> None:
        """A callback raised in the executor (a service's, a timer's; the owner's message callbacks handle their
        own errors): log it (the first few, then every 100th) and go on, so a request that makes rclpy raise
        ends neither the recording nor the live view.  Only an executor that raises on every turn for
        :data:`BROKEN_AFTER_S` goes to ``failed``."""
        self.callback_errors += 1
        now = time.monotonic()
        if self._failing_since is None:
            self._failing_since = now
        text = f"{type(exc).__name__}: {exc}"
        if now - self._failing_since >= BROKEN_AFTER_S:
            failed(f"the executor raised on every turn for {BROKEN_AFTER_S:g} s (the last: {text})")
            return
        n = self.callback_errors
        if n <= 3 or n % 100 == 0:
            frames = traceback.extract_tb(exc.__traceback__)
            where = f" in {frames[-1].name} ({frames[-1].filename}:{frames[-1].lineno})" if frames else ""
            self.node.get_logger().error(f"a callback raised {text}{where}; going on (messages are still "
                                         f"{self.what}; {n} such error(s) so far)")

    def spin_timeout(self, idle: float = 0.1) -> float:
        """How long the owner's ``spin_once`` may block: short while a topic waits for its publisher."""
        return DISCOVERY_POLL_S if self.pending else idle

    def publisher_metadata(self, topic: str, type_name: str) -> Tuple[list, str]:
        """(the QoS profiles its publishers offer, the type hash they announce, else the installed one)."""
        infos = []
        try:
            infos = self.node.get_publishers_info_by_topic(topic)
        except Exception as exc:  # pragma: no cover - graph queries do not fail in practice
            self.node.get_logger().warning(f"cannot query the publishers of {topic}: {exc}")
        hashes = [str(i.topic_type_hash) for i in infos if str(i.topic_type_hash).startswith("RIHS")]
        return [i.qos_profile for i in infos], (hashes[0] if hashes else installed_type_hash(type_name))

    # --- subscriptions ---------------------------------------------------------------------------

    def _subscribe(self, resolved: str, name: str, type_name: str, qos: QoSProfile) -> None:
        # One argument: rclpy's EventsExecutor cannot hand a raw subscription its MessageInfo (SystemError).
        def on_message(data, _topic=resolved, _type=type_name) -> None:
            self.on_message(_topic, _type, data)
        self.subs[resolved] = self.node.create_subscription(
            msg_class(type_name), name, on_message, qos, raw=True,
            event_callbacks=self._events(resolved, adapted=qos is not RECORD_QOS))

    def _subscribe_discovered(self) -> None:
        """Subscribe each pending topic that has a publisher now, with a QoS that matches them."""
        for resolved in list(self.pending):
            infos = self.node.get_publishers_info_by_topic(resolved)
            if not infos:
                continue
            name, type_name = self.pending.pop(resolved)
            qos = adapted_qos(infos)
            self._subscribe(resolved, name, type_name, qos)
            self.node.get_logger().info(f"subscribed {resolved} ({len(infos)} publisher(s); "
                                        f"{qos.reliability.name.lower()}, {qos.durability.name.lower()})")

    def _events(self, name: str, adapted: bool):
        try:
            from rclpy.event_handler import SubscriptionEventCallbacks
        except ImportError:  # pragma: no cover
            return None

        def incompatible(event) -> None:
            kind = getattr(event, "last_policy_kind", "?")
            if not adapted:
                if name not in self._readapt:
                    self.node.get_logger().info(
                        f"a publisher on {name} cannot match the graph's QoS (reliable, transient local; policy "
                        f"kind {kind}): subscribing with a QoS adapted to the publishers instead")
                self._readapt.add(name)
                return
            self.node.get_logger().warning(
                f"a publisher on {name} offers a QoS incompatible with the one chosen for the publishers found "
                f"first (last policy kind {kind}): its messages are NOT {self.what}")

        return SubscriptionEventCallbacks(incompatible_qos=incompatible)
