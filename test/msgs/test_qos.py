"""The QoS a replayed topic gets: what its recorded publishers offered."""
import pytest
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from mwip_ros.bag.metadata import qos_profile_dict
from mwip_ros.msgs.qos import GRAPH_QOS, recorded_qos

pytestmark = pytest.mark.unit


def _p(rel, dur, depth):
    return qos_profile_dict({"history": 1, "depth": depth, "reliability": rel, "durability": dur})


def test_every_publisher_reliable_and_transient_local_keeps_them_with_the_largest_depth():
    q = recorded_qos([_p(1, 1, 10), _p(1, 1, 1000)])
    assert (q.reliability, q.durability, q.depth) == (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL,
                                                      1000)


def test_one_best_effort_or_volatile_publisher_makes_the_replay_so():
    q = recorded_qos([_p(1, 1, 5), _p(2, 2, 7)])
    assert (q.reliability, q.durability, q.depth) == (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE, 7)


def test_nothing_recorded_replays_with_the_graphs_qos():
    assert recorded_qos([]) is GRAPH_QOS


def test_the_qos_fits_the_mode():
    """Lockstep loses nothing (deep; transient-local writers); realtime publishers keep a shallow backlog for a
    recorder, and the loop's readers are deep: a flood of rejected messages must not push a genuine one out of a
    queue of one (issue 30).  The graph does not show history depths, so this is checked here."""
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
    from mwip_ros.msgs.qos import BEST_EFFORT_INPUT_QOS, DEPTH, qos_for
    (pub, sub), (rt_pub, rt_sub) = qos_for("lockstep"), qos_for("realtime")
    assert (pub.depth, sub.depth, rt_pub.depth, rt_sub.depth) == (DEPTH, DEPTH, 10, DEPTH)
    assert BEST_EFFORT_INPUT_QOS.depth == DEPTH   # the plant's best-effort emergency_stop reader
    assert pub.durability == rt_pub.durability == DurabilityPolicy.TRANSIENT_LOCAL   # a recorder gets a backlog
    assert sub.durability == rt_sub.durability == DurabilityPolicy.VOLATILE          # a loop node never does
    assert {q.reliability for q in (pub, sub, rt_pub, rt_sub)} == {ReliabilityPolicy.RELIABLE}
