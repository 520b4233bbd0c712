"""The state_estimator node alone, fed by the test: pairing by stamp, resends, hostile samples, health."""
import math
import signal

import pytest

from graphproc import PARAMS, Graph
from injector import Injector, health, rejected_counts
from mwip_ros.msgs import cdr
from mwip_ros.msgs import layouts as L

pytestmark = pytest.mark.graph

RAW = (PARAMS, PARAMS.parent / "sensors_raw_realistic.yaml")
H = 5_000_000   # the period [ns] at 200 Hz
G = 9.81


def _estimator(g, *args):
    from sensor_msgs.msg import Imu, JointState
    est = g.start("state_estimator", *args, params=RAW)
    inj = Injector(g.domain_id)
    imu = inj.publisher("imu/data_raw", Imu)
    enc = inj.publisher("wheel_encoder", JointState)
    answers = inj.record("joint_states", JointState)
    assert inj.wait(lambda: imu.get_subscription_count() >= 1 and enc.get_subscription_count() >= 1, 30), est.output()
    return est, inj, imu, enc, answers


def _pair(imu, enc, k, gyro=0.0, phi=0.0, torque=0.0):
    imu.publish(L.encode_imu(k * H, gyro, 0.0, G))
    enc.publish(L.encode_encoder(k * H, phi, 0.0, torque))


def _stamps(answers):
    return [L.parse_joint_state(a)[0] for a in answers]


def test_hostile_raw_samples_are_rejected_counted_and_never_integrated(tmp_path):
    with Graph(tmp_path) as g:
        est, inj, imu, enc, answers = _estimator(g)
        try:
            latest = health(inj)
            _pair(imu, enc, 1, torque=2.5)
            assert inj.wait(lambda: len(answers) == 1, 20), est.output()
            stamp, x, u_prev = L.parse_joint_state(answers[0])
            assert stamp == H and u_prev == 2.5 and all(math.isfinite(v) for v in x)   # effort: the encoder's torque
            _pair(imu, enc, 1)                     # a resend: answered again with the same message, once
            assert inj.wait(lambda: len(answers) == 2, 20) and answers[1] == answers[0]
            bad_imu = [L.encode_imu(2 * H, math.nan, 0.0, G),                # non-finite
                       L.encode_imu(2 * H, 0.0, 2e3, G),                     # |accel| > 1e3 m/s^2
                       L.encode_imu(2 * H, 0.0, 0.0, G)[:-40],               # cut short
                       L.encode_imu(0, 0.0, 0.0, G),                         # older than the stream
                       L.encode_imu(1 * H + 10 ** 9, 0.0, 0.0, G)]           # 1 s ahead: beyond the window
            bad_enc = [cdr.JointStateEncoder(("left",))(2 * H, (0.0,), (0.0,), (0.0,)),   # wrong joint
                       L.encode_encoder(2 * H, 2e9, 0.0, 0.0),               # |phi| > 1e9
                       L.encode_encoder(2 * H, 0.0, 0.0, math.inf),          # non-finite torque
                       L.encode_encoder(0, 0.0, 0.0, 0.0)]                   # older than the stream
            for data in bad_imu:
                imu.publish(data)
            for data in bad_enc:
                enc.publish(data)
            # an IMU that gives an orientation is no error: paired with its encoder sample, answered
            imu.publish(cdr.ImuEncoder("imu_link")(2 * H, (0.0, 0.0, 0.0, 1.0), (0.01,) * 9, (0.0, 0.0, 0.0),
                                                   (0.0,) * 9, (0.0, 0.0, G), (0.0,) * 9))
            enc.publish(L.encode_encoder(2 * H, 0.0, 0.0, 0.0))
            imu.publish(L.encode_imu(3 * H, 0.0, 0.0, G))   # its encoder sample never comes ...
            _pair(imu, enc, 4)                              # ... and a later pair is complete: dropped, counted
            # each topic is delivered in order: the answer for k = 4 comes after every message above was taken
            assert inj.wait(lambda: 4 * H in _stamps(answers), 20), est.output()
            assert _stamps(answers) == [H, H, 2 * H, 4 * H]   # nothing answered a bad sample or the lone one
            assert all(all(math.isfinite(v) for v in L.parse_joint_state(a)[1]) for a in answers)
            # the rejections on /diagnostics, by topic
            counts = {"imu/data_raw": 6, "wheel_encoder": 4}
            assert inj.wait(lambda: latest.get("/state_estimator", (0, {}))[1] == counts, 10), latest
        finally:
            inj.close()
        assert est.stop(signal.SIGINT, timeout=20) == 0, est.output()
    out = est.output()
    assert "estimated 3 samples" in out and "unpaired dropped: 1" in out, out
    assert rejected_counts(out.split("rejected: ")[-1].splitlines()[0]) == counts
    for words in ("non-finite IMU reading", "implausible linear_acceleration 2000", "not a sensor_msgs/Imu",
                  "is older than the stream's", "jumps ahead", "joint names ['left'], expected ['wheel']",
                  "implausible encoder angle", "non-finite encoder reading", "had no wheel_encoder sample"):
        assert words in out, words
    assert "Traceback" not in out


def test_a_restarted_stream_reinitialises_the_estimator(tmp_path):
    """Stamps that go back (a plant's reset): rejected until three agree, then the estimator starts afresh."""
    with Graph(tmp_path) as g:
        est, inj, imu, enc, answers = _estimator(g)
        try:
            for k in range(1, 6):
                _pair(imu, enc, k)
                assert inj.wait(lambda: len(answers) == k, 20), est.output()
            for _ in range(3):          # the new run's state 0, as the lockstep plant resends it
                _pair(imu, enc, 0)
            assert inj.wait(lambda: len(answers) == 6, 20), est.output()
            assert L.parse_joint_state(answers[-1])[0] == 0
            _pair(imu, enc, 1)
            assert inj.wait(lambda: len(answers) == 7, 20), est.output()
        finally:
            inj.close()
        assert est.stop(signal.SIGINT, timeout=20) == 0
    out = est.output()
    assert "re-initialising the Kalman filter estimator" in out, out
    assert "estimated 7 samples" in out
    assert rejected_counts(out.split("rejected: ")[-1].splitlines()[0]) == {"imu/data_raw": 2, "wheel_encoder": 2}


def test_a_diverged_estimator_reports_error_on_diagnostics(tmp_path):
    """An encoder that runs away from what the IMU says (a slipping wheel, a broken cable): the filter's NIS
    passes kalman.nis_limit, the node logs it and /diagnostics says ERROR with the health values."""
    from diagnostic_msgs.msg import DiagnosticArray
    with Graph(tmp_path) as g:
        est, inj, imu, enc, answers = _estimator(g)
        try:
            reports = []
            inj.node.create_subscription(DiagnosticArray, "/diagnostics",
                                         lambda m: reports.extend(s for s in m.status if s.name == "/state_estimator"),
                                         100)
            for k in range(1, 31):
                _pair(imu, enc, k, phi=0.0 if k < 20 else 0.2 * (k - 20))
            assert inj.wait(lambda: any(s.level == b"\x02" for s in reports), 20), (reports, est.output())
        finally:
            inj.close()
        est.stop(signal.SIGINT, timeout=20)
    bad = next(s for s in reports if s.level == b"\x02")
    values = {kv.key: kv.value for kv in bad.values}
    assert "diverged" in bad.message and values["diverged"] == "true" and float(values["nis_mean"]) > 50, values
    assert {"innovation", "nis", "nis_mean", "estimates"} <= set(values)
    assert "estimator diverged at t = " in est.output()
