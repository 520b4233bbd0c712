"""The control inputs' DDS content filters (layouts.STATE_FILTER and ESTIMATE_FILTER, content_filter.StampBound; issue
46 item 2): a flood of absurd or far-future ``joint_states`` or ``disturbance_estimate`` messages is dropped by the
middleware before a realtime observer's or controller's reader, so it costs their Python nothing (before: each one
was parsed, judged by the StampGuard and counted; a flood of 17-42 k/s felled the realtime robot).

In this process (test/nodeharness.py: the publisher and the reader are peers in one private context, no discovery,
no other process). The process-level flood: ``scripts/bench_input_flood.py --topics joint_states,disturbance_estimate``
(BENCHMARKS.md, "Input floods").
"""
import math

import pytest

from mwip_ros.msgs import BadMessage, cdr
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import REALTIME_QOS
from mwip_ros.nodes.runtime.content_filter import NO_BOUND, StampBound, set_content_filter
from nodeharness import NodeHarness, node_class

S = 10 ** 9
BOUND = 100   # [s] the stamp bound the contract tests give the filters
NAN, INF = math.nan, math.inf
_REVERSED = cdr.JointStateEncoder(tuple(reversed(L.JOINT_NAMES)))


def _state(stamp_s: float, x=(0.0, 0.05, 0.0, 0.0), u: float = 1.0) -> bytes:
    return L.encode_state(round(stamp_s * S), x, u)


def _state_cases():
    """joint_states messages: those the parser takes (with stamps either side of BOUND), and absurd ones."""
    good = _state(50.0)
    return [good, _state(BOUND - 1e-3), _state(BOUND), _state(BOUND + 900.0), _state(0.0),
            _state(50.0, (1e8, -0.1, -999.0, 999.0), -150.0),
            _REVERSED(round(50 * S), (0.05, 3.0), (0.0, 1.0), (0.0, 1.0)),   # body_pitch first: order-free
            *[_state(50.0, tuple(v if j == i else 0.0 for j in range(4))) for i in range(4) for v in (NAN, INF, -INF)],
            _state(50.0, (2e9, 0.0, 0.0, 0.0)), _state(50.0, (0.0, 0.0, 1e4, 0.0)), _state(50.0, (0.0, 0.0, 0.0, -1e4)),
            good[:-8], good[:20]]


def _estimate_cases():
    return [L.encode_wrench(50 * S, 3.0, -2.0), L.encode_wrench(round((BOUND - 1e-3) * S), 0.0, 0.0),
            L.encode_wrench(BOUND * S, 0.0, 0.0), L.encode_wrench(1000 * S, 0.0, 0.0),
            L.encode_wrench(50 * S, 9e5, -9e5),
            *[L.encode_wrench(50 * S, *(v if j == i else 0.0 for j in range(2))) for i in range(2)
              for v in (NAN, INF, -INF, 2e6)],
            L.encode_wrench(50 * S, 1.0, 1.0)[:30]]


def _taken(parse, data) -> bool:
    """The node's parser takes ``data`` and its stamp is below BOUND seconds."""
    try:
        stamp = parse(data)[0]
    except BadMessage:
        return False
    return stamp < BOUND * S


def _passed(h, msg_type, topic, expression, cases):
    """Which of ``cases`` a reader filtered by ``expression`` (bound BOUND) receives (each sent with a marker after
    it: the first case, taken, with another last byte)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    got = []
    sub = h.node.create_subscription(msg_type, topic, lambda data: got.append(bytes(data)),
                                     QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE), raw=True)
    assert set_content_filter(sub, expression, [str(BOUND)]) is None
    pub = h.peer("writer").create_publisher(msg_type, topic, 100)
    assert h.spin(lambda: pub.get_subscription_count() >= 1, 5)
    passed = []
    for k, data in enumerate(cases):
        marker = cases[0][:-1] + bytes([k + 1])   # comes after it, in order
        n = len(got)
        pub.publish(data)
        pub.publish(marker)
        assert h.spin(lambda: marker in got[n:], 5), k
        passed.append(len(got) - n == 2)
    return passed


def _reader(h_name: str):
    from rclpy.node import Node

    class Reader(Node):
        def __init__(self, context=None, argv=()):
            super().__init__(h_name, context=context)
    return Reader


@pytest.mark.node
def test_the_state_filter_passes_what_the_parser_takes_below_the_bound_and_drops_absurd_values_and_stamps():
    from sensor_msgs.msg import JointState
    cases = _state_cases()
    with NodeHarness(_reader("state_reader"), params=None, name="state_reader") as h:
        passed = _passed(h, JointState, "joint_states", L.STATE_FILTER, cases)
    expected = [_taken(L.parse_joint_state, c) for c in cases]
    # the filter is looser than the parser in one place: theta_b is bounded by theta_w's limit (the joints may come
    # in either order); case 6 (theta_b = 3.0 rad, body_pitch first) is taken by both
    assert expected.count(True) >= 5 and expected.count(False) >= 15   # both kinds are tried
    assert passed == expected


@pytest.mark.node
def test_the_estimate_filter_passes_what_the_parser_takes_below_the_bound_and_drops_the_rest():
    from geometry_msgs.msg import WrenchStamped
    cases = _estimate_cases()
    with NodeHarness(_reader("estimate_reader"), params=None, name="estimate_reader") as h:
        passed = _passed(h, WrenchStamped, "disturbance_estimate", L.ESTIMATE_FILTER, cases)
    expected = [_taken(L.parse_wrench, c) for c in cases]
    assert expected.count(True) >= 3 and expected.count(False) >= 8
    assert passed == expected


@pytest.mark.unit
def test_the_stamp_bound_follows_the_stream_its_window_and_its_silence_in_whole_seconds():
    b = StampBound({}, window_ns=100_000_000)   # no reader: the bound alone
    assert b.bound_for(None, 5.0) == NO_BOUND   # before the stream's first stamp: none
    # the newest stamp 41.95 s + the 0.1 s window = 42.05 s: floor 42, + 1, + the slack of 2 s
    assert b.bound_for(round(41.95 * S), 0.0) == 42 + 1 + StampBound.SLACK_S
    assert b.bound_for(round(41.95 * S), 3.5) == 45 + 1 + StampBound.SLACK_S   # silent 3.5 s: a paused publisher
    assert b.bound_for(0, 0.0) == 1 + StampBound.SLACK_S                       # a reset: back near the start
    assert b.bound_for(2 ** 62, 0.0) == NO_BOUND                               # never beyond an int32
    assert b.follow(round(41.95 * S), 0.0) and b.bound == 45 and b.moves == 1
    assert not b.follow(round(41.99 * S), 0.5) and b.moves == 1                # the same whole second: no move
    assert b.follow(round(42.95 * S), 0.0) and b.bound == 46 and b.moves == 2


@pytest.mark.node
@pytest.mark.parametrize("name, args, readers", [
    ("disturbance_observer", (), ["joint_states"]),
    ("dscndo_controller", ("-p", "use_observer:=false"), ["joint_states", "disturbance_estimate"])])
def test_a_realtime_loop_node_never_sees_a_flood_of_far_future_or_absurd_states(name, args, readers):
    """The realtime node's readers are filtered, their bound follows the stream, and a flood of far-future and NaN
    states sent between two genuine ones never reaches the node (not counted: without the filter each is judged
    and counted as rejected); the genuine next state is answered."""
    from sensor_msgs.msg import JointState
    with NodeHarness(node_class(name), "-p", "mode:=realtime", *args) as h:
        node = h.node
        assert node.input.bound is not None and not node.input.bound.unfiltered
        assert list(node.input.bound.readers) == readers
        assert "content filter on joint_states" in h.logs()
        assert node.diagnostic_status()[2]["input_filter"].startswith("on: ")
        pub = h.peer("plant").create_publisher(JointState, "joint_states", REALTIME_QOS)
        assert h.spin(lambda: pub.get_subscription_count() >= 1, 5)
        for k in range(400):   # 2 s of the stream, 5 ms apart
            pub.publish(_state(k * 0.005))
        assert h.spin(lambda: node.input.guard.last == round(399 * 0.005 * S), 10), node.input.guard.last
        assert h.spin(lambda: node.input.bound.bound == 2 + 1 + StampBound.SLACK_S, 2), node.input.bound.bound
        answered = node.diagnostic_count()
        for i in range(300):   # the hostile publisher: 1,000 s ahead, then NaN
            pub.publish(_state(1000.0 + i * 0.005) if i % 2 else _state(2.0, (NAN, 0.0, 0.0, 0.0)))
        pub.publish(_state(2.0))
        assert h.spin(lambda: node.input.guard.last == 2 * S, 5), node.input.guard.last
        assert node.diagnostic_count() == answered + 1
        assert "joint_states" not in node.rejects.counts, node.rejects.summary()   # dropped by DDS: none judged
