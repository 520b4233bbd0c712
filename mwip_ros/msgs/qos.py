"""The QoS of the graph's topics, and why.

* Publishers (:data:`GRAPH_QOS`): reliable, keep last 1000, **transient local**.  In
  lockstep nothing may be lost, also not by a recorder that matched a moment after the
  run started: a transient-local writer hands a late reader its last 1000 samples, which
  covers the first five seconds of a lockstep run at 200 Hz (several seconds of wall time).
* The loop's own subscriptions (:data:`INPUT_QOS`, observer, controller, plant): reliable,
  keep last 1000, **volatile**: a node that joins late must not integrate a backlog of old
  states; the lockstep driver resends the one state that is waiting.
* Realtime (``mode: realtime`` of the plant, the observer and the controller): the newest
  state matters, not a backlog.  Publishers (:data:`REALTIME_QOS`) are reliable, transient
  local and keep the last 10 (a recorder that joins gets 50 ms at 200 Hz, not seconds);
  the loop's subscriptions (:data:`REALTIME_INPUT_QOS`) keep the last one only, so a node
  that fell behind answers the newest state and never works through old ones.
* The recorder (:data:`RECORD_QOS`): reliable, keep last 1000, transient local, so it gets
  that backlog.  A volatile publisher (``ros2 topic pub`` by default) does not match a
  transient-local reader: the recorder takes ``external_wrench``, which users publish by
  hand, and any topic with such a publisher, with a QoS adapted to its publishers.
* Services the graph offers (:data:`SERVICE_QOS`, ``plant_sim``'s ``~/reset``): reliable,
  **keep all**: every request is kept until the node takes it, so a burst of calls (1,000
  at once) is answered call by call.  ROS's default (keep last 10) drops the requests that
  find ten waiting; a client that sends many at once wants the same profile for its answers.
  ``~/enable`` and ``~/disable`` have it too.
* The driver's state (:data:`DRIVER_STATE_QOS`, ``plant_sim``'s ``driver_state``): reliable,
  transient local, keep last **1**: latched, a reader that joins late (a recorder, a viewer,
  ``ros2 topic echo --once --qos-durability transient_local``) gets the current state only (at
  depth 100 it got the oldest of the kept transitions first: the start state while in fault).
  Every message carries the whole state, so a reader needs no history to know it.  A reader
  that wants each transition while it runs subscribes with :data:`DRIVER_STATE_READER_QOS`
  (the same, keep last 100 on its side: a burst is not overwritten before its callback runs).
* ``emergency_stop``, which users publish with any QoS: the plant subscribes twice, with
  :data:`INPUT_QOS` (reliable: nothing a reliable publisher sends is lost) and with
  :data:`BEST_EFFORT_INPUT_QOS` (which also matches a best-effort publisher); a message that
  comes twice latches the same fault.
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["GRAPH_QOS", "INPUT_QOS", "RECORD_QOS", "REALTIME_QOS", "REALTIME_INPUT_QOS", "SERVICE_QOS",
           "DRIVER_STATE_QOS", "DRIVER_STATE_READER_QOS", "BEST_EFFORT_INPUT_QOS", "DEPTH", "qos_for",
           "recorded_qos"]

DEPTH = 1000

GRAPH_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
RECORD_QOS = GRAPH_QOS
REALTIME_DEPTH = 10
REALTIME_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=REALTIME_DEPTH,
                          reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
REALTIME_INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.VOLATILE)

SERVICE_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
DRIVER_STATE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.TRANSIENT_LOCAL)
DRIVER_STATE_READER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                                     reliability=ReliabilityPolicy.RELIABLE,
                                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
BEST_EFFORT_INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.BEST_EFFORT,
                                   durability=DurabilityPolicy.VOLATILE)


def qos_for(mode: str):
    """(publisher QoS, loop-subscription QoS) of a loop node in ``mode`` ('lockstep' or 'realtime')."""
    return (REALTIME_QOS, REALTIME_INPUT_QOS) if mode == "realtime" else (GRAPH_QOS, INPUT_QOS)


def recorded_qos(profiles) -> QoSProfile:
    """The QoS to replay a topic with: what its recorded publishers offered (``offered_qos_profiles``, v9
    dicts). Reliable / transient local only if every recorded publisher was; the largest recorded depth
    (keep last); with nothing recorded, :data:`GRAPH_QOS`."""
    if not profiles:
        return GRAPH_QOS
    reliable = all(str(p.get("reliability")) == "reliable" for p in profiles)
    transient = all(str(p.get("durability")) == "transient_local" for p in profiles)
    depth = max(int(p.get("depth") or 0) for p in profiles) or DEPTH
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)
