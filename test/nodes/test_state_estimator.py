"""The state_estimator node alone, fed by the test: pairing by stamp, resends, hostile samples, health."""
import math
import signal

import numpy as np
import pytest

from graphproc import PARAMS, Graph
from injector import Injector, health, rejected_counts, wait_matched
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
    # the tests send each sample once: the estimator's (volatile) readers must have matched these publishers too
    latest = health(inj)
    assert wait_matched(inj, latest, "/state_estimator", {"/imu/data_raw": 1, "/wheel_encoder": 1}), \
        (latest.get("/state_estimator"), est.output())
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
            bad_imu.append(cdr.ImuEncoder("base_link")(2 * H, (0.0,) * 4, (-1.0,) + (0.0,) * 8, (0.0,) * 3,
                                                       (0.0,) * 9, (0.0, 0.0, G), (0.0,) * 9))   # not imu_link
            bad_enc = [cdr.JointStateEncoder(("left",))(2 * H, (0.0,), (0.0,), (0.0,)),   # wrong joint
                       cdr.JointStateEncoder(("wheel",), "imu_link")(2 * H, (0.0,), (0.0,), (0.0,)),   # a frame_id
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
            counts = {"imu/data_raw": 7, "wheel_encoder": 5}
            assert inj.wait(lambda: latest.get("/state_estimator", (0, {}))[1] == counts, 10), latest
        finally:
            inj.close()
        assert est.stop(signal.SIGINT, timeout=20) == 0, est.output()
    out = est.output()
    assert "estimated 3 samples" in out and "unpaired dropped: 1" in out, out
    assert rejected_counts(out.split("rejected: ")[-1].splitlines()[0]) == counts
    for words in ("non-finite IMU reading", "implausible linear_acceleration 2000", "not a sensor_msgs/Imu",
                  "is older than the stream's", "jumps ahead", "joint names ['left'], expected ['wheel']",
                  "implausible encoder angle", "non-finite encoder reading", "had no wheel_encoder sample",
                  "frame_id 'base_link', expected 'imu_link'", "frame_id 'imu_link', expected ''"):
        assert words in out, words
    assert "Traceback" not in out


def test_a_restarted_stream_reinitialises_the_estimator(tmp_path):
    """Stamps that go back to the run's start (a plant's reset): rejected until three agree, then the estimator
    starts afresh."""
    with Graph(tmp_path) as g:
        est, inj, imu, enc, answers = _estimator(g)
        try:
            for k in range(0, 6):
                _pair(imu, enc, k)
                assert inj.wait(lambda: len(answers) == k + 1, 20), est.output()
            for _ in range(3):          # the new run's state 0, as the lockstep plant resends it
                _pair(imu, enc, 0)
            assert inj.wait(lambda: len(answers) == 7, 20), est.output()
            assert L.parse_joint_state(answers[-1])[0] == 0
            _pair(imu, enc, 1)
            assert inj.wait(lambda: len(answers) == 8, 20), est.output()
        finally:
            inj.close()
        assert est.stop(signal.SIGINT, timeout=20) == 0
    out = est.output()
    assert "re-initialising the Kalman filter estimator" in out, out
    assert "estimated 8 samples" in out
    assert rejected_counts(out.split("rejected: ")[-1].splitlines()[0]) == {"imu/data_raw": 2, "wheel_encoder": 2}


def test_a_diverged_estimate_is_withheld_and_its_error_reported_at_once(tmp_path):
    """An encoder that runs away from what the IMU says (a slipping wheel, a broken cable): the filter's NIS passes
    kalman.nis_limit; /diagnostics says ERROR at once (the report right after the step that diverged, not at the next
    second: the plant's driver faults on it), no diverged estimate is published, and a reset (the stream back to its
    start) brings it back to OK or WARN, again at once."""
    from diagnostic_msgs.msg import DiagnosticArray
    with Graph(tmp_path) as g:
        est, inj, imu, enc, answers = _estimator(g)
        try:
            reports = []
            inj.node.create_subscription(DiagnosticArray, "/diagnostics",
                                         lambda m: reports.extend(s for s in m.status if s.name == "/state_estimator"),
                                         100)
            for k in range(0, 31):
                _pair(imu, enc, k, phi=0.0 if k < 20 else 0.2 * (k - 20))
            assert inj.wait(lambda: any(s.level == b"\x02" for s in reports), 20), (reports, est.output())
            inj.spin(0.5)   # every answer that was published has come
            published = sorted(set(_stamps(answers)))
            for _ in range(3):   # the plant's reset: its stamps back to the run's start
                _pair(imu, enc, 0)
            assert inj.wait(lambda: reports[-1].level != b"\x02", 20), (reports[-1], est.output())
        finally:
            inj.close()
        assert est.stop(signal.SIGINT, timeout=20) == 0
    bad = next(s for s in reports if s.level == b"\x02")
    values = {kv.key: kv.value for kv in bad.values}
    assert "diverged" in bad.message and values["diverged"] == "true" and float(values["nis_mean"]) > 50, values
    assert {"innovation", "nis", "nis_mean", "estimates", "withheld_diverged"} <= set(values)
    # reported right after the step that diverged: the estimates it counts are those published and that one
    assert int(values["estimates"]) == len(published) + 1 and values["withheld_diverged"] == "1", (values, published)
    assert published == [k * H for k in range(len(published))] and len(published) < 31   # none after divergence
    out = est.output()
    withheld = int(out.split("withheld diverged: ")[1].split(";")[0])
    assert withheld == 31 - len(published) and "estimator diverged at t = " in out, out
    good = {kv.key: kv.value for kv in reports[-1].values}
    assert good["diverged"] == "false" and "re-initialising the Kalman filter" in out


def test_stray_future_pairs_from_another_publisher_restart_nothing_and_are_never_published(tmp_path):
    """Three pairs stamped 1,000 s ahead and a lone sample a little ahead, from a publisher that is not the stream's:
    rejected and counted; nothing with their stamps is published, the filter is not re-initialised (it keeps its
    bias: every estimate equals the core estimator's fed the genuine samples alone), no genuine sample is lost."""
    from sensor_msgs.msg import Imu, JointState

    from mwip_ros import params as P
    values = P.merged_values(P.load_param_files(RAW))
    nominal = P.physical(values, "nominal")
    offline = P.typed.estimator(values).make(P.period(values), nominal.r, nominal.g)
    genuine = [(0.03 + 0.001 * math.sin(k), 1e-3 * k) for k in range(100)]   # gyro (biased), phi
    with Graph(tmp_path) as g:
        est, inj, imu, enc, answers = _estimator(g)
        rogue = Injector(g.domain_id, "rogue")
        try:
            latest = health(inj)
            for k in range(60):   # the stream starts (its publisher alone on the topics)
                _pair(imu, enc, k, gyro=genuine[k][0], phi=genuine[k][1])
            assert inj.wait(lambda: len(answers) == 60, 20), est.output()
            r_imu, r_enc = rogue.publisher("imu/data_raw", Imu), rogue.publisher("wheel_encoder", JointState)
            assert rogue.wait(lambda: r_imu.get_subscription_count() >= 1 and r_enc.get_subscription_count() >= 1,
                              30)
            assert wait_matched(inj, latest, "/state_estimator", {"/imu/data_raw": 2, "/wheel_encoder": 2}), \
                latest.get("/state_estimator")
            for k in range(3):   # hostile values, stamped 1,000 s ahead, agreeing with each other
                r_imu.publish(L.encode_imu(10 ** 12 + k * H, 0.5, 3.0, G))
                r_enc.publish(L.encode_encoder(10 ** 12 + k * H, 0.3, 0.0, 50.0))
            r_imu.publish(L.encode_imu(64 * H + H // 2, 0.5, 3.0, G))   # a lone sample within the window
            # taken: the three refused (the lone one is counted when dropped, after PAIR_WAIT_S or a later pair)
            assert inj.wait(lambda: latest.get("/state_estimator", (0, {}))[1].get("wheel_encoder") == 3, 20), latest
            for k in range(60, 100):
                _pair(imu, enc, k, gyro=genuine[k][0], phi=genuine[k][1])
            assert inj.wait(lambda: len(answers) == 100, 20), est.output()
        finally:
            rogue.close()
            inj.close()
        assert est.stop(signal.SIGINT, timeout=20) == 0
    out = est.output()
    assert _stamps(answers) == [k * H for k in range(100)], _stamps(answers)
    for k, data in enumerate(answers):
        want = offline.step((genuine[k][0], 0.0, G, genuine[k][1], 0.0))
        np.testing.assert_allclose(L.parse_joint_state(data)[1], want, rtol=0, atol=1e-12, err_msg=str(k))
    assert "re-initialising" not in out and "but the topic has more than one publisher: no restart" in out, out
    assert rejected_counts(out.split("rejected: ")[-1].splitlines()[0]) == {"imu/data_raw": 4, "wheel_encoder": 3}
    assert "unpaired dropped: 1" in out
