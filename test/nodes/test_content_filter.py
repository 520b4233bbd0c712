"""The DDS content filters (nodes.runtime.content_filter): the raw topics' (layouts.RAW_FILTERS) drop exactly what the
parsers reject for its bytes, frame, names or values, and pass what they accept (the limits' boundaries too); the
control inputs' (layouts.STATE_FILTER, ESTIMATE_FILTER) drop what the parsers reject for its bytes or values and pass
what they accept, whatever its stamp (stamps are the StampGuard's, layouts says why): each
message is followed by a genuine one with a stamp of its own, and the reliable in-order delivery tells whether the
message before it came through. The publisher and the filtered subscription are peers in one private context
(test/nodeharness.py: no discovery, no other process): the middleware filters within the participant as between
processes."""
import math

import pytest

from nodeharness import NodeHarness
from mwip_ros.msgs import BadMessage, cdr
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import REALTIME_INPUT_QOS, REALTIME_QOS
from mwip_ros.nodes.runtime.content_filter import set_content_filter

pytestmark = pytest.mark.node

H, G, S = 5_000_000, 9.81, 10 ** 9
A, R = L.RAW_LIMITS["accel"], L.RAW_LIMITS["rate"]
OUT = math.nextafter(A, math.inf)   # the next double beyond a limit


def _imu_cases():
    cut = L.encode_imu(H, 0.0, 0.0, G)
    return [L.encode_imu(H, 0.0, 0.0, G), L.encode_imu(H, 0.0, A, -A), L.encode_imu(H, -A, 0.0, A),
            L.encode_imu(H, 0.0, OUT, G), L.encode_imu(H, -OUT, 0.0, G), L.encode_imu(H, math.nan, 0.0, G),
            L.encode_imu(H, 0.0, 0.0, -math.inf), cut[:-40], cut[:30],
            cdr.ImuEncoder("base_link")(H, (0.0,) * 4, (-1.0,) + (0.0,) * 8, (0.0, 0.0, math.nan), (0.0,) * 9,
                                        (0.0, 0.0, G), (0.0,) * 9),
            cdr.ImuEncoder("imu_link")(H, (0.0,) * 4, (-1.0,) + (0.0,) * 8, (math.nan, 0.0, 0.0), (0.0,) * 9,
                                       (0.0, 0.0, G), (0.0,) * 9)]


def _encoder_cases():
    phi = L.RAW_LIMITS["phi"]
    return [L.encode_encoder(H, 0.0, 0.0, 0.0), L.encode_encoder(H, phi, R, -L.RAW_LIMITS["torque"]),
            L.encode_encoder(H, math.nextafter(phi, math.inf), 0.0, 0.0),
            L.encode_encoder(H, 0.0, -math.nextafter(R, math.inf), 0.0), L.encode_encoder(H, 0.0, 0.0, math.nan),
            L.encode_encoder(H, math.inf, 0.0, 0.0), L.encode_encoder(H, 0.0, 0.0, 0.0)[:-4],
            cdr.JointStateEncoder(("left",))(H, (0.0,), (0.0,), (0.0,)),
            cdr.JointStateEncoder(("wheel",), "imu_link")(H, (0.0,), (0.0,), (0.0,))]


def _accepted(parse, data) -> bool:
    try:
        parse(data)
    except BadMessage:
        return False
    return True


def _state_cases():
    """joint_states: what parse_joint_state takes (any stamp; the joints in either order) and what it rejects for its
    values or bytes. The filter is looser than the parser in one place: theta_b is bounded by theta_w's limit (the
    joints may come in either order), so no case here has 3.15 < |theta_b| <= 1e9."""
    good = L.encode_state(50 * S, (0.0, 0.05, 0.0, 0.0), 1.0)
    body_first = cdr.JointStateEncoder(tuple(reversed(L.JOINT_NAMES)))
    return [good, L.encode_state(1000 * S, (0.0,) * 4, 0.0), L.encode_state(0, (0.0,) * 4, 0.0),
            L.encode_state(50 * S, (1e8, -0.1, -999.0, 999.0), -150.0),
            body_first(50 * S, (0.05, 3.0), (0.0, 1.0), (0.0, 1.0)),
            *[L.encode_state(50 * S, tuple(v if j == i else 0.0 for j in range(4)), 0.0) for i in range(4)
              for v in (math.nan, math.inf, -math.inf)],
            L.encode_state(50 * S, (2e9, 0.0, 0.0, 0.0), 0.0), L.encode_state(50 * S, (0.0, 0.0, 1e4, 0.0), 0.0),
            L.encode_state(50 * S, (0.0, 0.0, 0.0, -1e4), 0.0), good[:-8], good[:20]]


def _estimate_cases():
    return [L.encode_wrench(50 * S, 3.0, -2.0), L.encode_wrench(1000 * S, 0.0, 0.0), L.encode_wrench(50 * S, 9e5, -9e5),
            *[L.encode_wrench(50 * S, *(v if j == i else 0.0 for j in range(2))) for i in range(2)
              for v in (math.nan, math.inf, -math.inf, 2e6)],
            L.encode_wrench(50 * S, 1.0, 1.0)[:30]]


@pytest.mark.parametrize("topic, msg_type, expression, parse, cases, genuine", [
    ("imu/data_raw", "sensor_msgs/Imu", L.RAW_FILTERS["imu/data_raw"], L.parse_imu, _imu_cases,
     lambda k: L.encode_imu(k * H, 0.0, 0.0, G)),
    ("wheel_encoder", "sensor_msgs/JointState", L.RAW_FILTERS["wheel_encoder"], L.parse_encoder, _encoder_cases,
     lambda k: L.encode_encoder(k * H, 0.0, 0.0, 0.0)),
    ("joint_states", "sensor_msgs/JointState", L.STATE_FILTER, L.parse_joint_state, _state_cases,
     lambda k: L.encode_state(k * H, (0.0,) * 4, 0.0)),
    ("disturbance_estimate", "geometry_msgs/WrenchStamped", L.ESTIMATE_FILTER, L.parse_wrench, _estimate_cases,
     lambda k: L.encode_wrench(k * H, 0.0, 0.0)),
])
def test_the_content_filter_passes_what_the_parser_accepts_and_drops_the_rest(topic, msg_type, expression, parse,
                                                                               cases, genuine):
    import importlib

    from rclpy.node import Node

    class Reader(Node):
        def __init__(self, context=None, argv=()):
            super().__init__("filtered_reader", context=context)

    with NodeHarness(Reader, params=None, name="filtered_reader") as h:
        package, name = msg_type.split("/")
        kind = getattr(importlib.import_module(f"{package}.msg"), name)
        got = []
        sub = h.node.create_subscription(kind, topic, lambda data: got.append(bytes(data)), REALTIME_INPUT_QOS,
                                         raw=True)
        assert set_content_filter(sub, expression) is None
        pub = h.peer("writer").create_publisher(kind, topic, REALTIME_QOS)
        assert h.spin(lambda: pub.get_subscription_count() >= 1, 5)
        passed, expected = [], []
        for k, data in enumerate(cases(), start=100):
            expected.append(_accepted(parse, data))
            n = len(got)
            pub.publish(data)
            pub.publish(genuine(k))   # comes after it, in order
            assert h.spin(lambda: genuine(k) in got[n:], 5), (k, len(got) - n)
            passed.append(len(got) - n == 2)
        assert expected.count(True) >= 2 and expected.count(False) >= 5   # both kinds are tried
        assert passed == expected
