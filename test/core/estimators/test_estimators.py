"""State estimators (theory.md 6.4): the registry, convergence with an unknown gyro bias, the kalman's bias and motion
compensation, health, and the pure step compiled by numba."""
import math

import numba
import numpy as np
import pytest

from mathfixtures import P_FILE
from mwip_ros import params as P
from mwip_ros.core import estimators
from mwip_ros.core.estimators import Estimator, Health
from mwip_ros.core.plants.model import State, accel
from mwip_ros.core.control.observer import DiscreteObserver, gain_matrix
from mwip_ros.core.plants.plant import PlantSim, saturate
from mwip_ros.core.plants.raw_sensors import RawSample, RawSensorConfig, RawSensors

pytestmark = pytest.mark.unit

R, D, G, H = 0.254, 0.3, 9.81, 0.005
REALISTIC = RawSensorConfig(offset=D, gyro_noise_std=0.004, gyro_bias=0.01, gyro_bias_walk=0.0005,
                            accel_noise_std=0.02, encoder_counts_per_rev=4096)


def _make(method, **params):
    return estimators.get(method)(params, H, R, D, G)


def _still(theta, bias, n, seed=0, phi=0.4):
    """Samples of a body held still at pitch ``theta``: the gyro reads its bias, the accelerometer gravity."""
    rng = np.random.default_rng(seed)
    for z in rng.standard_normal((n, 3)):
        yield RawSample(bias + 0.004 * z[0], -G * math.sin(theta) + 0.02 * z[1], G * math.cos(theta) + 0.02 * z[2],
                        phi, 0.0)


_SCENARIO = {}


def _scenario(duration=8.0):
    """(t, true state, raw sample, true gyro bias) of the paper's DSCNDO run (fed the true state) with the realistic
    raw sensors: the accelerations at t_k^- with the previous period's torque and D_w (docs/theory.md 6.4)."""
    if duration in _SCENARIO:
        return _SCENARIO[duration]
    loop = P.closed_loop(P.merged_values(P.load_param_file(P_FILE)), duration=duration, controller="dscndo")
    pc = loop.plant
    plant = PlantSim(pc)
    obs = DiscreteObserver(pc.nominal, gain_matrix(loop.X), pc.h)
    law = loop.law_class(loop.params, pc.nominal, pc.h)
    sensors = RawSensors.for_plant(REALISTIC, pc.seed, pc.h, pc.actual.r, pc.actual.g)
    rows, D_w = [], plant.D_w
    for _ in range(int(round(duration / pc.h)) + 1):
        x = plant.x
        ddq = accel(pc.actual, D_w, pc.D_b, x, plant.u_prev, *plant.tau_ext(plant.t))
        rows.append((plant.t, x, sensors.sample(x, ddq), sensors.bias))
        u, _ = law.step(x, obs.update(x, plant.u_prev))
        D_w = plant.D_w
        plant.step(saturate(u, pc.torque_limit))
    _SCENARIO[duration] = rows
    return rows


def _replay(est, rows, window=(4.0, 8.0)):
    """RMS of the pitch, pitch-rate and wheel-rate errors over ``window``, the final bias estimate, the healths."""
    err, health = [], []
    for t, x, s, _ in rows:
        e = est.step(s)
        health.append(est.health)
        if window[0] <= t <= window[1]:
            err.append(np.subtract(e, x))
    err = np.array(err)
    return np.sqrt((err ** 2).mean(axis=0)), health


def test_the_registry_names_both_and_each_declares_plain_parameters():
    assert estimators.names() == ("complementary", "kalman")
    with pytest.raises(KeyError, match="complementary, kalman"):
        estimators.get("magic")
    for name in estimators.names():
        cls = estimators.get(name)
        assert issubclass(cls, Estimator) and cls.name == name and callable(cls.pure_step)
        for p in cls.parameters:
            assert p.name.startswith(f"{name}.") and p.type in ("double", "integer") and p.description
            assert (p.lo is None or p.lo <= p.default) and (p.hi is None or p.default <= p.hi)
    assert "complementary.tau" in estimators.get("complementary").defaults()


def test_parameters_out_of_range_or_unknown_are_refused_by_name():
    with pytest.raises(ValueError, match="complementary.tau"):
        _make("complementary", **{"complementary.tau": -1.0})
    with pytest.raises(ValueError, match="kalman.nonsense"):
        _make("kalman", **{"kalman.nonsense": 1.0})
    for bad in (-1.0, math.nan, math.inf):   # the slip gate: 0 (off) to 1e9, never a NaN
        with pytest.raises(ValueError, match="kalman.slip_gate"):
            _make("kalman", **{"kalman.slip_gate": bad})
    _make("kalman", **{"complementary.tau": 3.0})   # another method's key: not this one's business


def test_the_estimate_takes_the_wheel_from_the_encoder_relative_to_the_estimated_pitch():
    for est in (_make("complementary"), _make("kalman", **{"kalman.wheel_rate": 0})):
        for s in _still(0.05, 0.0, 5):
            e = est.step(s._replace(encoder=1.25, encoder_rate=0.75))
            assert isinstance(e, State)
            assert e.theta_w == 1.25 + e.theta_b and e.dtheta_w == pytest.approx(0.75 + e.dtheta_b, abs=1e-15)


def test_the_complementary_filter_converges_to_a_still_pitch_and_its_bias_error_costs_tau_times_it():
    theta, bias, tau = 0.05, 0.01, 0.5
    known = _make("complementary", **{"complementary.tau": tau, "complementary.gyro_bias": bias})
    unknown = _make("complementary", **{"complementary.tau": tau})
    for s in _still(theta, bias, 3000):
        a, b = known.step(s), unknown.step(s)
    assert a.theta_b == pytest.approx(theta, abs=2e-3) and a.dtheta_b == pytest.approx(0.0, abs=0.02)
    assert b.theta_b - theta == pytest.approx(tau * bias, rel=0.2)   # the steady error of an unknown bias


def test_the_kalman_filter_finds_a_still_pitch_and_the_unknown_bias():
    theta, bias = -0.08, 0.03
    est = _make("kalman")
    for s in _still(theta, bias, 4000, seed=4):
        e = est.step(s)
    assert e.theta_b == pytest.approx(theta, abs=1e-3)
    assert est.s[1] == pytest.approx(bias, abs=1e-3)                 # the bias state
    assert e.dtheta_b == pytest.approx(0.0, abs=0.015) and not est.diverged


def test_in_the_paper_s_motion_the_kalman_compensates_the_acceleration_the_complementary_cannot():
    """The accelerometer's pitch is wrong by milliradians while the robot swings (theory.md 6.4); the kalman tracks the
    pitch to a fraction of a milliradian without being told the bias, the complementary (bias known) only to
    milliradians."""
    rows = _scenario()
    kal, health = _replay(_make("kalman"), rows)
    comp, _ = _replay(_make("complementary", **{"complementary.tau": 1.0, "complementary.gyro_bias": 0.01}), rows)
    assert kal[1] < 1e-3 and kal[3] < 6e-3 and kal[2] < 0.012
    assert comp[1] > 3 * kal[1]
    acc_pitch = [math.atan2(-s.accel_x, s.accel_z) - x[1] for t, x, s, _ in rows if t >= 4.0]
    assert np.sqrt(np.mean(np.square(acc_pitch))) > 5 * kal[1]      # what the raw accelerometer pitch is worth
    nis = [hl.nis_mean for hl in health[-400:]]
    assert 0.5 < np.mean(nis) < 2.0 and not any(hl.diverged for hl in health)


def test_the_kalman_learns_the_walking_bias_in_motion():
    rows = _scenario()
    est = _make("kalman")
    _replay(est, rows)
    true_bias = rows[-1][3]
    assert est.values["kalman.gyro_bias"] == 0.0                   # it starts knowing nothing of the 0.01 rad/s
    assert est.s[1] == pytest.approx(true_bias, abs=1e-3)


def test_health_flags_a_broken_encoder_and_a_non_finite_sample():
    est = _make("kalman")
    for s in _still(0.0, 0.0, 400):
        est.step(s)
    assert isinstance(est.health, Health) and not est.diverged
    for s in _still(0.0, 0.0, 100):
        est.step(s._replace(encoder=s.encoder + 0.2))                 # the wheel jumped a fifth of a radian
    assert est.diverged and est.health.nis_mean > 50
    for method in estimators.names():
        est = _make(method)
        est.step(RawSample(0.0, 0.0, G, 0.0, 0.0))
        est.step(RawSample(math.nan, 0.0, G, 0.0, 0.0))
        assert est.diverged


def test_the_slip_gate_leaves_a_slipping_wheel_out_and_a_lasting_slip_still_diverges():
    """kalman.slip_gate (theory.md 6.4, Slip): a 0.05 rad encoder jump over 5 periods (a wheel slipping) moves the
    gated filter's pitch by microradians (the clean samples' updates it skipped), the ungated one's by milliradians
    (and it is diverged); the gated filter stays healthy and takes the wheel's new place at once (P_22 takes the
    jump); a wheel that spins on at 2 rad/s under a body that stays (a slip that lasts) is diverged within 1.1 s."""
    still = list(_still(0.02, 0.0, 1000, seed=7))
    slip = [s._replace(encoder=s.encoder + 0.05 * min(k - 399, 5) / 5) if k >= 400 else s for k, s in enumerate(still)]
    gated, ungated, clean = (_make("kalman", **{"kalman.slip_gate": g}) for g in (150.0, 0.0, 150.0))
    pitch = {}
    for name, est, samples in (("gated", gated, slip), ("ungated", ungated, slip), ("clean", clean, still)):
        pitch[name] = [est.step(s).theta_b for s in samples[:405]]
    assert not gated.diverged and not clean.diverged
    assert np.max(np.abs(np.subtract(pitch["gated"], pitch["clean"]))) < 2e-5   # the slipping samples left out
    assert ungated.diverged and abs(pitch["ungated"][-1] - pitch["clean"][-1]) > 1e-3   # pulled, and reported
    left_out = [gated.health.nis > 150.0]                                     # the ramp's last sample, then ...
    for s in slip[405:]:                                                      # ... the wheel where it slipped to
        e = gated.step(s)
        left_out.append(gated.health.nis > 150.0)
    assert sum(left_out) <= 2 and not gated.diverged and abs(e.theta_b - 0.02) < 2e-3   # p took the jump at once
    spin = _make("kalman", **{"kalman.slip_gate": 150.0})
    for s in still[:400]:
        spin.step(s)
    for k, s in enumerate(still[400:620]):
        spin.step(s._replace(encoder=s.encoder + 2.0 * H * k))                # the wheel spins on, the body stays
    assert spin.diverged and spin.health.nis_mean > 50


def test_reset_gives_a_fresh_estimator():
    samples = list(_still(0.1, 0.02, 50))
    for method in estimators.names():
        a, b = _make(method), _make(method)
        for s in samples:
            a.step(s)
        a.reset()
        assert [a.step(s) for s in samples[:10]] == [b.step(s) for s in samples[:10]]


@pytest.mark.parametrize("method", ["complementary", "kalman"])
def test_the_pure_step_compiles_with_numba_and_equals_python(method):
    cls = estimators.get(method)
    est = _make(method)
    fast = numba.njit(error_model="numpy")(cls.pure_step)
    s_py = s_nb = (0.0,) * cls.state_size
    for k, (_, _, sample, _) in enumerate(_scenario()[:300]):
        py = cls.pure_step(est.P, H, tuple(sample), s_py, k == 0)
        nb = fast(est.P, H, tuple(sample), s_nb, k == 0)
        for a, b in zip(py[0] + py[1] + py[2], nb[0] + nb[1] + nb[2]):
            assert b == pytest.approx(a, abs=1e-12, rel=1e-12)
        s_py, s_nb = py[1], nb[1]
    assert est.step(_scenario()[0][2]) == State(*cls.pure_step(est.P, H, tuple(_scenario()[0][2]),
                                                               (0.0,) * cls.state_size, True)[0])
