"""The control inputs' DDS content filters (layouts.STATE_FILTER and ESTIMATE_FILTER; issue 46 item 2): a flood of
``joint_states`` or ``disturbance_estimate`` messages with non-finite or absurd values is dropped by the middleware
before a realtime observer's or controller's reader, so it costs their Python nothing (before: each one was parsed,
rejected and counted). Stamps are not filtered (layouts says why): the StampGuard judges them.

In this process (test/nodeharness.py: the publisher and the reader are peers in one private context, no discovery,
no other process). The process-level flood: ``scripts/bench_input_flood.py --topics joint_states,disturbance_estimate``
(BENCHMARKS.md, "Input floods").
"""
import math

import pytest

from mwip_ros.msgs import BadMessage, cdr
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import REALTIME_QOS
from mwip_ros.nodes.runtime.content_filter import set_content_filter
from nodeharness import NodeHarness, node_class

S = 10 ** 9
NAN, INF = math.nan, math.inf
_REVERSED = cdr.JointStateEncoder(tuple(reversed(L.JOINT_NAMES)))


def _state(stamp_s: float, x=(0.0, 0.05, 0.0, 0.0), u: float = 1.0) -> bytes:
    return L.encode_state(round(stamp_s * S), x, u)


def _state_cases():
    """joint_states messages: those the parser takes (any stamp), and absurd ones."""
    good = _state(50.0)
    return [good, _state(1000.0), _state(0.0),
            _state(50.0, (1e8, -0.1, -999.0, 999.0), -150.0),
            _REVERSED(round(50 * S), (0.05, 3.0), (0.0, 1.0), (0.0, 1.0)),   # body_pitch first: order-free
            *[_state(50.0, tuple(v if j == i else 0.0 for j in range(4))) for i in range(4) for v in (NAN, INF, -INF)],
            _state(50.0, (2e9, 0.0, 0.0, 0.0)), _state(50.0, (0.0, 0.0, 1e4, 0.0)), _state(50.0, (0.0, 0.0, 0.0, -1e4)),
            good[:-8], good[:20]]


def _estimate_cases():
    return [L.encode_wrench(50 * S, 3.0, -2.0), L.encode_wrench(1000 * S, 0.0, 0.0),
            L.encode_wrench(50 * S, 9e5, -9e5),
            *[L.encode_wrench(50 * S, *(v if j == i else 0.0 for j in range(2))) for i in range(2)
              for v in (NAN, INF, -INF, 2e6)],
            L.encode_wrench(50 * S, 1.0, 1.0)[:30]]


def _taken(parse, data) -> bool:
    """The node's parser takes ``data``."""
    try:
        parse(data)
    except BadMessage:
        return False
    return True


def _passed(h, msg_type, topic, expression, cases):
    """Which of ``cases`` a reader filtered by ``expression`` receives (each sent with a marker after
    it: the first case, taken, with another last byte)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    got = []
    sub = h.node.create_subscription(msg_type, topic, lambda data: got.append(bytes(data)),
                                     QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE), raw=True)
    assert set_content_filter(sub, expression) is None
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
def test_the_state_filter_passes_what_the_parser_takes_and_drops_absurd_values():
    from sensor_msgs.msg import JointState
    cases = _state_cases()
    with NodeHarness(_reader("state_reader"), params=None, name="state_reader") as h:
        passed = _passed(h, JointState, "joint_states", L.STATE_FILTER, cases)
    expected = [_taken(L.parse_joint_state, c) for c in cases]
    # the filter is looser than the parser in one place: theta_b is bounded by theta_w's limit (the joints may come
    # in either order); the case with body_pitch first (theta_b = 3.0 rad) is taken by both
    assert expected.count(True) >= 5 and expected.count(False) >= 15   # both kinds are tried
    assert passed == expected


@pytest.mark.node
def test_the_estimate_filter_passes_what_the_parser_takes_and_drops_the_rest():
    from geometry_msgs.msg import WrenchStamped
    cases = _estimate_cases()
    with NodeHarness(_reader("estimate_reader"), params=None, name="estimate_reader") as h:
        passed = _passed(h, WrenchStamped, "disturbance_estimate", L.ESTIMATE_FILTER, cases)
    expected = [_taken(L.parse_wrench, c) for c in cases]
    assert expected.count(True) >= 3 and expected.count(False) >= 8
    assert passed == expected


@pytest.mark.node
@pytest.mark.parametrize("name, args, readers", [
    ("disturbance_observer", (), ["joint_states"]),
    ("dscndo_controller", ("-p", "use_observer:=false"), ["joint_states", "disturbance_estimate"])])
def test_a_realtime_loop_node_never_sees_a_flood_of_absurd_states(name, args, readers):
    """The realtime node's readers are filtered: a flood of NaN and absurd states sent between two genuine ones never
    reaches the node (not counted: without the filter each is parsed, rejected and counted); the genuine next state
    is answered."""
    from sensor_msgs.msg import JointState
    with NodeHarness(node_class(name), "-p", "mode:=realtime", *args) as h:
        node = h.node
        assert node.input.filtered
        assert f"content filter on {' and '.join(readers)}:" in h.logs()
        assert node.diagnostic_status()[2]["input_filter"].startswith("on: ")
        pub = h.peer("plant").create_publisher(JointState, "joint_states", REALTIME_QOS)
        assert h.spin(lambda: pub.get_subscription_count() >= 1, 5)
        for k in range(400):   # 2 s of the stream, 5 ms apart
            pub.publish(_state(k * 0.005))
        assert h.spin(lambda: node.input.guard.last == round(399 * 0.005 * S), 10), node.input.guard.last
        answered = node.diagnostic_count()
        for i in range(300):   # the hostile publisher: NaN, inf and absurd values in turn
            bad = (NAN, INF, 2e9, -1e4)[i % 4]
            pub.publish(_state(1.995 + i * 1e-6, tuple(bad if j == i % 4 else 0.0 for j in range(4))))
        pub.publish(_state(2.0))
        assert h.spin(lambda: node.input.guard.last == 2 * S, 5), node.input.guard.last
        assert node.diagnostic_count() == answered + 1
        assert "joint_states" not in node.rejects.counts, node.rejects.summary()   # dropped by DDS: none judged
