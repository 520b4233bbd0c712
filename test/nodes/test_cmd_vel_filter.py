"""cmd_vel's DDS content filter (layouts.CMD_VEL_FILTER, issue 46 item 2), in this process (test/nodeharness.py: the
publisher and the controller's reader are peers in one private context, no discovery, no other process):

* the filter passes exactly the Twists that ``core.control.motion.Shaper.command`` takes (clipped ones too) and drops
  what it
  rejects for its numbers (NaN, inf, beyond the absurd limits) and bytes that cannot be deserialized;
* a flood of such Twists cannot displace the operator's valid command from the controller's depth-1 cmd_vel reader
  (before: the newest NaN displaced it, the controller rejected that and never saw the command), and the log and
  /diagnostics say that the middleware drops them (not counted).
* a realtime controller reads cmd_vel on a DDS participant of its own whose threads run at nice 19
  (rclpy_compat.IsolatedInput), so a flood of valid Twists no longer shares joint_states' receive thread.

The process-level flood (the realtime graph, NaN/inf/1e300 and valid Twists at 70-80 k/s beside a 20 Hz operator):
``scripts/bench_input_flood.py --topics cmd_vel_bad,cmd_vel_valid``, BENCHMARKS.md "Input floods".
"""
import math

import pytest

from mwip_ros.core.control.motion import ABSURD_SPEED, ABSURD_YAW_RATE
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import REALTIME_QOS
from mwip_ros.nodes.runtime.content_filter import set_content_filter
from nodeharness import NodeHarness, node_class

pytestmark = pytest.mark.node

MOTION = ("-p", "motion.enabled:=true", "-p", "use_observer:=false")
NAN, INF = math.nan, math.inf
BAD = [L.encode_twist(NAN, 0.0), L.encode_twist(INF, 0.0), L.encode_twist(-INF, 0.0), L.encode_twist(1e300, 0.0),
       L.encode_twist(0.0, NAN), L.encode_twist(0.0, -INF), L.encode_twist(0.0, -1e300), L.encode_twist(NAN, NAN)]


def _cases():
    out_v, out_w = math.nextafter(ABSURD_SPEED, INF), math.nextafter(ABSURD_YAW_RATE, INF)
    good = L.encode_twist(0.3, 0.1)
    return [good, L.encode_twist(ABSURD_SPEED, -ABSURD_YAW_RATE), L.encode_twist(-ABSURD_SPEED, ABSURD_YAW_RATE),
            L.encode_twist(50.0, 0.0),   # over max_speed: clipped, taken
            L.encode_twist(out_v, 0.0), L.encode_twist(0.0, -out_w), *BAD, good[:-8], good[:20]]


def _taken(data) -> bool:
    """Whether the controller takes ``data`` (parse_twist, then core.control.motion.Shaper.command's judgement of the
    numbers: not finite or beyond the absurd limits is rejected, over max_speed clipped and taken)."""
    try:
        vx, wz = L.parse_twist(data)
    except BadMessage:
        return False
    return math.isfinite(vx) and math.isfinite(wz) and abs(vx) <= ABSURD_SPEED and abs(wz) <= ABSURD_YAW_RATE


def test_the_cmd_vel_filter_passes_what_the_shaper_takes_and_drops_the_rest():
    from geometry_msgs.msg import Twist
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    class Reader(Node):
        def __init__(self, context=None, argv=()):
            super().__init__("filtered_reader", context=context)

    with NodeHarness(Reader, params=None, name="filtered_reader") as h:
        got = []
        sub = h.node.create_subscription(Twist, "cmd_vel", lambda data: got.append(bytes(data)),
                                         QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE), raw=True)
        assert set_content_filter(sub, L.CMD_VEL_FILTER) is None
        pub = h.peer("writer").create_publisher(Twist, "cmd_vel", 100)
        assert h.spin(lambda: pub.get_subscription_count() >= 1, 5)
        passed, expected = [], []
        for k, data in enumerate(_cases()):
            expected.append(_taken(data))
            marker = L.encode_twist(0.001 * (k + 1), 0.0)   # comes after it, in order
            n = len(got)
            pub.publish(data)
            pub.publish(marker)
            assert h.spin(lambda: marker in got[n:], 5), k
            passed.append(len(got) - n == 2)
        assert expected.count(True) >= 4 and expected.count(False) >= 10   # both kinds are tried
        assert passed == expected


def test_a_flood_of_hostile_twists_cannot_displace_the_operators_command():
    from geometry_msgs.msg import Twist
    with NodeHarness(node_class("dscndo_controller"), *MOTION) as h:
        node = h.node
        pub = h.peer("operator").create_publisher(Twist, "cmd_vel", REALTIME_QOS)
        assert h.spin(lambda: pub.get_subscription_count() >= 1, 5)
        pub.publish(L.encode_twist(0.2, 0.0))   # the operator's command, then a flood of hostile ones after it
        for i in range(400):
            pub.publish(BAD[i % len(BAD)])
        assert h.spin(lambda: node.cmd_vel_sub.taken >= 1, 5)
        assert node.motion.accepted == 1 and node.motion.cmd == (0.2, 0.0), (node.motion.accepted, node.motion.cmd)
        assert node.motion.rejected == 0 and "cmd_vel" not in node.rejects.counts   # dropped by DDS, not counted
        assert node.cmd_vel_filtered   # and the log and /diagnostics say so
        status = node.diagnostic_status()[2]
        assert status["cmd_vel_filter"].startswith("on: ") and "dropped by DDS" in status["cmd_vel_filter"]
        assert "content filter on cmd_vel" in h.logs()


def _nice(tid: str) -> int:
    import os
    return os.getpriority(os.PRIO_PROCESS, int(tid))


def test_a_realtime_controller_reads_cmd_vel_on_a_participant_of_its_own_at_the_lowest_priority():
    """Realtime, cmd_vel has a DDS participant of its own (rclpy_compat.IsolatedInput) whose threads run at nice 19:
    a flood of valid Twists, which no filter can tell from the operator's, no longer shares the receive thread that
    carries the controller's joint_states (before: one participant, the flood cost that thread a third of a core and
    the robot fell; BENCHMARKS.md "Input floods").  It is filtered as the shared one is, still one of the node's
    polled inputs (fed, read, reported), and destroyed with the node."""
    import os

    from geometry_msgs.msg import Twist

    import rclpy
    from mwip_ros.nodes.runtime.rclpy_compat import IsolatedInput
    with NodeHarness(node_class("dscndo_controller"), *MOTION, "-p", "mode:=realtime") as h:
        node = h.node
        sub = node.cmd_vel_sub
        assert isinstance(sub, IsolatedInput) and sub in node.polled_inputs
        assert sub.side_context is not node.context and sub.topic == "/cmd_vel"
        assert sub.niced >= 1 and node.cmd_vel_filtered
        main_tid = str(os.getpid())
        assert _nice(main_tid) < 19   # the node's own thread keeps its priority
        assert f"{sub.niced} threads at nice 19" in h.logs()
        # a publisher in the reader's own participant: the flood of hostile Twists is filtered there too
        op = rclpy.create_node("operator", context=sub.side_context, start_parameter_services=False)
        try:
            pub = op.create_publisher(Twist, "/cmd_vel", REALTIME_QOS)
            assert h.spin(lambda: pub.get_subscription_count() >= 1, 5)
            pub.publish(L.encode_twist(0.2, 0.0))
            for i in range(100):
                pub.publish(BAD[i % len(BAD)])
            assert h.spin(lambda: sub.taken >= 1, 5)
            assert node.motion.accepted == 1 and node.motion.cmd == (0.2, 0.0) and node.motion.rejected == 0
            assert h.feed("cmd_vel", L.encode_twist(0.1, 0.0)) == 1 and node.motion.cmd == (0.1, 0.0)
        finally:
            op.destroy_node()
    assert sub.side_node is None and not sub.side_context.ok()
