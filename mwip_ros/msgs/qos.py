"""The QoS of the graph's topics, and why.

* Publishers (:data:`GRAPH_QOS`): reliable, keep last 1000, **transient local**.  In
  lockstep nothing may be lost, also not by a recorder that matched a moment after the
  run started: a transient-local writer hands a late reader its last 1000 samples, which
  covers the first five seconds of a lockstep run at 200 Hz (several seconds of wall time).
* The loop's own subscriptions (:data:`INPUT_QOS`, observer, controller, plant): reliable,
  keep last 1000, **volatile**: a node that joins late must not integrate a backlog of old
  states; the lockstep driver resends the one state that is waiting.
* Realtime (``mode: realtime`` of the plant, the state estimator, the observer and the
  controller): publishers (:data:`REALTIME_QOS`) are reliable, transient local and keep the
  last 10 (a recorder that joins gets 50 ms at 200 Hz, not seconds).  The loop's
  subscriptions (:data:`REALTIME_INPUT_QOS`: the estimator's ``imu/data_raw`` and
  ``wheel_encoder``, the observer's ``joint_states``, the controller's ``joint_states`` and
  ``disturbance_estimate``, the plant's ``wheel_torque_cmd``) keep the last
  :data:`REALTIME_INPUT_DEPTH`, volatile, and the node takes every message (the executor
  calls back once per message; a rejection costs microseconds).  A reader's history is one
  queue for all of a topic's publishers: with a depth of one, a flood of messages that are
  all rejected pushed the genuine samples out before the node saw them (issue 30: 45,000 a
  second on the raw topics, the filter diverged, the robot fell).  Now a flood displaces a
  genuine message only when it outruns what the node rejects a second, or fills the queue
  while the node is not scheduled.  The state estimator's two raw subscriptions also carry a DDS content filter
  in realtime (:data:`mwip_ros.msgs.layouts.RAW_FILTERS`, :mod:`mwip_ros.nodes.runtime.content_filter`): what
  has a wrong frame or joint, a value outside the limits or bytes that cannot be deserialized is dropped by the
  middleware before the queue, and not counted.  A node that fell behind works through what waited (the
  stamp guards and the pairing judge each message; the plant holds the newest command;
  the estimator integrates over the stamps' time, so a lost sample costs a longer step).
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
  :data:`BEST_EFFORT_INPUT_QOS` (which also matches a best-effort publisher; it keeps
  :data:`DEPTH` too, so a flood cannot push a best-effort stop out of the queue); a message
  that comes twice latches the same fault.
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["GRAPH_QOS", "INPUT_QOS", "RECORD_QOS", "REALTIME_QOS", "REALTIME_INPUT_QOS", "REALTIME_INPUT_DEPTH",
           "SERVICE_QOS", "DRIVER_STATE_QOS", "DRIVER_STATE_READER_QOS", "BEST_EFFORT_INPUT_QOS", "DEPTH", "qos_for",
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
REALTIME_INPUT_DEPTH = DEPTH   # a flood's backlog while the node is not scheduled (0.2 s of 5,000 a second)
REALTIME_INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=REALTIME_INPUT_DEPTH,
                                reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)

SERVICE_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
DRIVER_STATE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.TRANSIENT_LOCAL)
DRIVER_STATE_READER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                                     reliability=ReliabilityPolicy.RELIABLE,
                                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
BEST_EFFORT_INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH,
                                   reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)


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
