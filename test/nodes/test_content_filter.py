"""The raw topics' DDS content filters (layouts.RAW_FILTERS, nodes.runtime.content_filter) drop exactly what the
parsers reject for its bytes, frame, names or values, and pass what they accept (the limits' boundaries too): each
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

H, G = 5_000_000, 9.81
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


@pytest.mark.parametrize("topic, msg_type, parse, cases, genuine", [
    ("imu/data_raw", "Imu", L.parse_imu, _imu_cases, lambda k: L.encode_imu(k * H, 0.0, 0.0, G)),
    ("wheel_encoder", "JointState", L.parse_encoder, _encoder_cases, lambda k: L.encode_encoder(k * H, 0.0, 0.0, 0.0)),
])
def test_the_content_filter_passes_what_the_parser_accepts_and_drops_the_rest(topic, msg_type, parse, cases, genuine):
    import sensor_msgs.msg
    from rclpy.node import Node

    class Reader(Node):
        def __init__(self, context=None, argv=()):
            super().__init__("filtered_reader", context=context)

    with NodeHarness(Reader, params=None, name="filtered_reader") as h:
        kind = getattr(sensor_msgs.msg, msg_type)
        got = []
        sub = h.node.create_subscription(kind, topic, lambda data: got.append(bytes(data)), REALTIME_INPUT_QOS,
                                         raw=True)
        assert set_content_filter(sub, L.RAW_FILTERS[topic]) is None
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
