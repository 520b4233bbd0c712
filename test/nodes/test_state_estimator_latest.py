"""The state estimator with an IMU of its own rate (``imu_sync: latest``, docs/hardware.md), in this process: each
encoder sample is estimated with the newest IMU sample, at the encoder's stamp; an IMU sample too far from it is not
used (the encoder sample dropped and counted); a resent encoder stamp is answered again."""
import pytest

from graphproc import PARAMS
from mwip_ros import params as P
from mwip_ros.core.plants.raw_sensors import RawSample
from mwip_ros.msgs import layouts as L
from nodeharness import NodeHarness, node_class

pytestmark = pytest.mark.node

RAW = (PARAMS, PARAMS.parent / "sensors_raw_realistic.yaml")
H = 5_000_000      # the encoders' period [ns] (200 Hz)
IMU = 2_500_000    # the IMU's (400 Hz)
G = 9.81


def _latest(*args):
    return NodeHarness(node_class("state_estimator"), "-p", "imu_sync:=latest", *args, params=RAW)


def test_each_encoder_sample_is_estimated_with_the_newest_imu_sample_at_its_stamp():
    """The node's estimates equal the estimator core's, stepped by hand with the sample pairs the newest-IMU rule
    makes: the IMU 400 Hz with stamps 0.7 ms off the encoders', its readings changing every sample."""
    imu_samples = [(k * IMU + 700_000, 0.01 * k, -0.02 * k, G - 0.001 * k) for k in range(40)]
    enc_samples = [(k * H, 0.003 * k, 0.05, 0.1 * k) for k in range(1, 19)]
    events = sorted([(s[0], "imu", s) for s in imu_samples] + [(s[0], "enc", s) for s in enc_samples])
    expected, newest = [], None
    values = P.load_param_files(list(RAW)).for_node("state_estimator")
    est = P.typed.estimator(values).make(H * 1e-9, values["nominal.r"], values["nominal.g"])
    last = None
    with _latest() as h:
        for _t, kind, s in events:
            if kind == "imu":
                h.feed("imu/data_raw", L.encode_imu(*s))
                newest = s
                continue
            h.feed("wheel_encoder", L.encode_encoder(*s))
            dt = None if last is None or s[0] - last == H else (s[0] - last) * 1e-9
            x = est.step(RawSample(newest[1], newest[2], newest[3], s[1], s[2]), dt)
            expected.append((s[0], x, s[3]))
            last = s[0]
        got = [L.parse_joint_state(m) for m in h.sent("joint_states")]
    assert [g[0] for g in got] == [e[0] for e in expected]   # one estimate per encoder sample, at its stamp
    assert [tuple(g[1]) for g in got] == [tuple(e[1]) for e in expected]
    assert [g[2] for g in got] == [e[2] for e in expected]   # the effort: the encoder's reported torque


def test_an_imu_sample_too_far_from_the_encoder_sample_is_not_used():
    with _latest("-p", "imu_max_age_s:=0.01") as h:
        h.feed("wheel_encoder", L.encode_encoder(H, 0.0, 0.0, 0.0))    # no IMU sample yet
        h.feed("imu/data_raw", L.encode_imu(2 * H, 0.0, 0.0, G))
        h.feed("wheel_encoder", L.encode_encoder(3 * H, 0.0, 0.0, 0.0))   # 5 ms after the IMU's: used
        h.feed("wheel_encoder", L.encode_encoder(5 * H, 0.0, 0.0, 0.0))   # 15 ms after it: stale
        h.feed("imu/data_raw", L.encode_imu(9 * H, 0.0, 0.0, G))         # 15 ms ahead of the next encoder sample
        h.feed("wheel_encoder", L.encode_encoder(6 * H, 0.0, 0.0, 0.0))
        stamps = [L.parse_joint_state(m)[0] for m in h.sent("joint_states")]
        assert stamps == [3 * H]
        assert h.node.imu_stale == 3 and h.node.rejects.counts == {"wheel_encoder": 3}
        assert "no imu/data_raw sample within imu_max_age_s = 10 ms (the newest is +15.0 ms from it)" in h.logs()
        assert "(the newest is -15.0 ms from it)" in h.logs() and "(none has come)" in h.logs()


def test_a_resent_encoder_sample_is_answered_again_and_integrated_once():
    with _latest() as h:
        h.feed("imu/data_raw", L.encode_imu(H - IMU, 0.0, 0.0, G))
        h.feed("wheel_encoder", L.encode_encoder(H, 0.0, 0.0, 0.0))
        h.feed("imu/data_raw", L.encode_imu(H, 0.2, 0.0, G))
        h.feed("wheel_encoder", L.encode_encoder(H, 0.0, 0.0, 0.0))   # the same stamp: the same answer
        sent = h.sent("joint_states")
        assert len(sent) == 2 and sent[0] == sent[1] and h.node.count == 1
