"""The state_estimator node alone, in this process, fed by the test (test/nodeharness.py): pairing by stamp,
resends, hostile samples, health on /diagnostics, a second publisher's stray stamps."""
import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray

from graphproc import PARAMS
from injector import rejected_counts
from mwip_ros.msgs import cdr
from mwip_ros.msgs import layouts as L
from nodeharness import NodeHarness, node_class

pytestmark = pytest.mark.node

RAW = (PARAMS, PARAMS.parent / "sensors_raw_realistic.yaml")
H = 5_000_000   # the period [ns] at 200 Hz
G = 9.81


def _estimator(*args):
    """The state estimator in this process, with its /diagnostics reporter (as run_node attaches it)."""
    h = NodeHarness(node_class("state_estimator"), *args, params=RAW)
    h.diagnostics()
    return h


def _statuses(h):
    """The estimator's /diagnostics statuses, in order."""
    return [s for m in h.messages("/diagnostics", DiagnosticArray) for s in m.status if s.name == "/state_estimator"]


def _rejected_on_diagnostics(h):
    """{topic: rejected} of a /diagnostics report made now (the report the node sends once a second)."""
    h.node.diagnostics.tick(now=True)
    values = {kv.key: kv.value for kv in _statuses(h)[-1].values}
    return rejected_counts(values.get("rejected_by_topic", ""))


def _pair(h, k, gyro=0.0, phi=0.0, torque=0.0, feeder="feeder"):
    h.feed("imu/data_raw", L.encode_imu(k * H, gyro, 0.0, G), feeder)
    h.feed("wheel_encoder", L.encode_encoder(k * H, phi, 0.0, torque), feeder)


def _stamps(answers):
    return [L.parse_joint_state(a)[0] for a in answers]


def test_hostile_raw_samples_are_rejected_counted_and_never_integrated():
    with _estimator() as h:
        _pair(h, 1, torque=2.5)
        answers = h.sent("joint_states")
        assert len(answers) == 1
        stamp, x, u_prev = L.parse_joint_state(answers[0])
        assert stamp == H and u_prev == 2.5 and all(math.isfinite(v) for v in x)   # effort: the encoder's torque
        _pair(h, 1)                            # a resend: answered again with the same message, once
        answers = h.sent("joint_states")
        assert len(answers) == 2 and answers[1] == answers[0]
        bad_imu = [L.encode_imu(2 * H, math.nan, 0.0, G),                # non-finite
                   L.encode_imu(2 * H, 0.0, 2e3, G),                     # |accel| > 1e3 m/s^2
                   L.encode_imu(2 * H, 0.0, 0.0, G)[:-40],               # cut short
                   L.encode_imu(0, 0.0, 0.0, G),                         # older than the stream
                   L.encode_imu(1 * H + 10 ** 9, 0.0, 0.0, G)]           # 1 s ahead: beyond the window
        bad_imu.append(cdr.ImuEncoder("base_link")(2 * H, (0.0,) * 4, (-1.0,) + (0.0,) * 8, (0.0,) * 3,
                                                   (0.0,) * 9, (0.0, 0.0, G), (0.0,) * 9))   # not imu_link
        bad_enc = [cdr.JointStateEncoder(("left",))(2 * H, (0.0,), (0.0,), (0.0,)),   # wrong joint
                   cdr.JointStateEncoder(("wheel",), "imu_link")(2 * H, (0.0,), (0.0,), (0.0,)),   # a frame_id
                   L.encode_encoder(2 * H, 2e9, 0.0, 0.0),               # |phi| > 1e9
                   L.encode_encoder(2 * H, 0.0, 0.0, math.inf),          # non-finite torque
                   L.encode_encoder(0, 0.0, 0.0, 0.0)]                   # older than the stream
        for data in bad_imu:
            h.feed("imu/data_raw", data)
        for data in bad_enc:
            h.feed("wheel_encoder", data)
        # an IMU that gives an orientation is no error: paired with its encoder sample, answered
        h.feed("imu/data_raw", cdr.ImuEncoder("imu_link")(2 * H, (0.0, 0.0, 0.0, 1.0), (0.01,) * 9, (0.0, 0.0, 0.0),
                                                          (0.0,) * 9, (0.0, 0.0, G), (0.0,) * 9))
        h.feed("wheel_encoder", L.encode_encoder(2 * H, 0.0, 0.0, 0.0))
        h.feed("imu/data_raw", L.encode_imu(3 * H, 0.0, 0.0, G))   # its encoder sample never comes ...
        _pair(h, 4)                                                # ... and a later pair is complete: dropped, counted
        answers = h.sent("joint_states")
        assert _stamps(answers) == [H, H, 2 * H, 4 * H]   # nothing answered a bad sample or the lone one
        assert all(all(math.isfinite(v) for v in L.parse_joint_state(a)[1]) for a in answers)
        counts = {"imu/data_raw": 7, "wheel_encoder": 5}
        assert _rejected_on_diagnostics(h) == counts      # the rejections on /diagnostics, by topic
    out = h.logs()
    assert "estimated 3 samples" in out and "unpaired dropped: 1" in out, out
    assert rejected_counts(out.split("rejected: ")[-1].splitlines()[0]) == counts
    for words in ("non-finite IMU reading", "implausible linear_acceleration 2000", "not a sensor_msgs/Imu",
                  "is older than the stream's", "jumps ahead", "joint names ['left'], expected ['wheel']",
                  "implausible encoder angle", "non-finite encoder reading", "had no wheel_encoder sample",
                  "frame_id 'base_link', expected 'imu_link'", "frame_id 'imu_link', expected ''"):
        assert words in out, words


def test_a_restarted_stream_reinitialises_the_estimator():
    """Stamps that go back to the run's start (a plant's reset): rejected until three agree, then the estimator
    starts afresh."""
    with _estimator() as h:
        for k in range(0, 6):
            _pair(h, k)
            assert len(h.sent("joint_states")) == k + 1
        for _ in range(3):          # the new run's state 0, as the lockstep plant resends it
            _pair(h, 0)
        answers = h.sent("joint_states")
        assert len(answers) == 7 and L.parse_joint_state(answers[-1])[0] == 0
        _pair(h, 1)
        assert len(h.sent("joint_states")) == 8
    out = h.logs()
    assert "re-initialising the Kalman filter estimator" in out, out
    assert "estimated 8 samples" in out
    assert rejected_counts(out.split("rejected: ")[-1].splitlines()[0]) == {"imu/data_raw": 2, "wheel_encoder": 2}


def test_a_diverged_estimate_is_withheld_and_its_error_reported_at_once():
    """An encoder that runs away from what the IMU says (a slipping wheel, a broken cable): the filter's NIS passes
    kalman.nis_limit; /diagnostics says ERROR at once (the report right after the step that diverged, not at the next
    second: the plant's driver faults on it), no diverged estimate is published, and a reset (the stream back to its
    start) brings it back to OK or WARN, again at once."""
    with _estimator() as h:
        published = []
        for k in range(0, 31):
            _pair(h, k, phi=0.0 if k < 20 else 0.2 * (k - 20))
            if not published and any(s.level == b"\x02" for s in _statuses(h)):
                published = sorted(set(_stamps(h.sent("joint_states"))))   # the estimates out when it was reported
        assert published, [s.level for s in _statuses(h)]
        assert sorted(set(_stamps(h.sent("joint_states")))) == published   # none after the divergence
        for _ in range(3):   # the plant's reset: its stamps back to the run's start
            _pair(h, 0)
        reports = _statuses(h)
        assert reports[-1].level != b"\x02", reports[-1]
    bad = next(s for s in reports if s.level == b"\x02")
    values = {kv.key: kv.value for kv in bad.values}
    assert "diverged" in bad.message and values["diverged"] == "true" and float(values["nis_mean"]) > 50, values
    assert {"innovation", "nis", "nis_mean", "estimates", "withheld_diverged"} <= set(values)
    # reported right after the step that diverged: the estimates it counts are those published and that one
    assert int(values["estimates"]) == len(published) + 1 and values["withheld_diverged"] == "1", (values, published)
    assert published == [k * H for k in range(len(published))] and len(published) < 31   # none after divergence
    out = h.logs()
    withheld = int(out.split("withheld diverged: ")[1].split(";")[0])
    assert withheld == 31 - len(published) and "estimator diverged at t = " in out, out
    good = {kv.key: kv.value for kv in reports[-1].values}
    assert good["diverged"] == "false" and "re-initialising the Kalman filter" in out


def test_stray_future_pairs_from_another_publisher_restart_nothing_and_are_never_published():
    """Three pairs stamped 1,000 s ahead and a lone sample a little ahead, from a publisher that is not the stream's
    (a second publisher on the topics, as the node's graph lists it): rejected and counted; nothing with their
    stamps is published, the filter is not re-initialised (it keeps its bias: every estimate equals the core
    estimator's fed the genuine samples alone), no genuine sample is lost."""
    from mwip_ros import params as P
    values = P.merged_values(P.load_param_files(RAW))
    nominal = P.physical(values, "nominal")
    offline = P.typed.estimator(values).make(P.period(values), nominal.r, nominal.g)
    genuine = [(0.03 + 0.001 * math.sin(k), 1e-3 * k) for k in range(100)]   # gyro (biased), phi
    with _estimator() as h:
        for k in range(60):   # the stream starts (its publisher alone on the topics)
            _pair(h, k, gyro=genuine[k][0], phi=genuine[k][1])
        assert len(h.sent("joint_states")) == 60
        for k in range(3):    # hostile values, stamped 1,000 s ahead, agreeing with each other
            h.feed("imu/data_raw", L.encode_imu(10 ** 12 + k * H, 0.5, 3.0, G), "rogue")
            h.feed("wheel_encoder", L.encode_encoder(10 ** 12 + k * H, 0.3, 0.0, 50.0), "rogue")
        h.feed("imu/data_raw", L.encode_imu(64 * H + H // 2, 0.5, 3.0, G), "rogue")   # a lone one within the window
        # taken: the three refused (the lone one is counted when dropped, after PAIR_WAIT_S or a later pair)
        assert _rejected_on_diagnostics(h).get("wheel_encoder") == 3
        for k in range(60, 100):
            _pair(h, k, gyro=genuine[k][0], phi=genuine[k][1])
        answers = h.sent("joint_states")
    out = h.logs()
    assert _stamps(answers) == [k * H for k in range(100)], _stamps(answers)
    for k, data in enumerate(answers):
        want = offline.step((genuine[k][0], 0.0, G, genuine[k][1], 0.0))
        np.testing.assert_allclose(L.parse_joint_state(data)[1], want, rtol=0, atol=1e-12, err_msg=str(k))
    assert "re-initialising" not in out and "but the topic has more than one publisher: no restart" in out, out
    assert rejected_counts(out.split("rejected: ")[-1].splitlines()[0]) == {"imu/data_raw": 4, "wheel_encoder": 3}
    assert "unpaired dropped: 1" in out
