"""The control inputs' DDS content filters on the realtime loop nodes (layouts.STATE_FILTER and ESTIMATE_FILTER; issue
46 item 2): a flood of ``joint_states`` messages with non-finite or absurd values is dropped by the middleware before
a realtime observer's or controller's reader, so it costs their Python nothing (before: each one was parsed, rejected
and counted). What each filter passes and drops: test_content_filter.py.

In this process (test/nodeharness.py: the publisher and the reader are peers in one private context, no discovery,
no other process). The process-level flood: ``scripts/bench_input_flood.py --topics joint_states_bad,
disturbance_estimate_bad`` (BENCHMARKS.md, "Input floods").
"""
import math

import pytest

from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import REALTIME_QOS
from nodeharness import NodeHarness, node_class

S = 10 ** 9
NAN, INF = math.nan, math.inf

def _state(stamp_s: float, x=(0.0, 0.05, 0.0, 0.0), u: float = 1.0) -> bytes:
    return L.encode_state(round(stamp_s * S), x, u)


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
