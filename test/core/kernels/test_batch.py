"""The batch simulator equals the scalar loop scenario by scenario, noise included; a fall poisons nothing."""
import numpy as np
import pytest

from mathfixtures import FALL_ANGLE, P_FILE, assert_batch_equals_scalar
from mwip_ros import params as P
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.kernels.batch import simulate_batch
from mwip_ros.core.closed_loop.sim import simulate

pytestmark = pytest.mark.unit

BASE = P.merged_values(P.load_param_file(P_FILE))
WINDOW = (1.0, 2.0)


def _scenarios():
    rng = np.random.default_rng(7)
    out = []
    for i in range(12):
        v = dict(BASE)
        v.update({"seed": int(rng.integers(0, 1000)), "actual.m_b": BASE["actual.m_b"] * rng.uniform(0.7, 1.3),
                  "actual.I_b": BASE["actual.I_b"] * rng.uniform(0.7, 1.3),
                  "tau_ext1.amplitude": float(rng.uniform(0, 45)), "initial.theta_b": float(rng.uniform(-0.5, 0.5)),
                  "k1": float(rng.uniform(2, 10)), "use_observer": bool(i % 2),
                  "actual.D_w_variance": 0.0 if i == 3 else 0.2, "torque_limit": 400.0 if i == 5 else 0.0})
        out.append(v)
    fall = dict(BASE, **{"initial.theta_b": 0.9, "k1": 0.05, "k2": 0.05, "seed": 3})  # falls within 2 s
    diverge = dict(BASE, **{"initial.theta_b": 1.0, "tau_ext1.amplitude": 1e5, "seed": 4})
    return out + [fall, diverge]


@pytest.fixture(scope="module")
def runs():
    values = _scenarios()
    loops = [P.closed_loop(v, duration=2.0) for v in values]
    return loops, simulate_batch(loops, WINDOW, record=True), [simulate(lp) for lp in loops]


def test_every_batch_trajectory_equals_the_scalar_loop(runs):
    loops, batch, scalar = runs
    assert_batch_equals_scalar(loops, WINDOW, batch, scalar)


def test_falls_are_marked_and_poison_nothing(runs):
    loops, batch, scalar = runs
    assert batch.fallen.tolist() == [s.fallen for s in scalar]
    assert batch.fallen[-2] and batch.fallen[-1] and not batch.fallen[:-2].any()
    for i, s in enumerate(scalar):
        if s.fallen:
            assert batch.t_fall[i] == pytest.approx(s.t[-1])
        else:
            assert np.isnan(batch.t_fall[i]) and batch.upright[i]
    # the metrics are the single-run metrics of each trajectory
    for i, s in enumerate(scalar):
        m = metrics.compute(s.columns, WINDOW, FALL_ANGLE)
        for key, values in batch.metrics.items():
            assert values[i] == pytest.approx(getattr(m, key), rel=1e-9, abs=1e-12, nan_ok=True), (i, key)
        assert batch.upright[i] == m.upright


def test_scenarios_must_share_the_period():
    a = P.closed_loop(BASE, duration=0.1)
    b = P.closed_loop(dict(BASE, control_rate_hz=100.0), duration=0.1)
    with pytest.raises(ValueError, match="control period"):
        simulate_batch([a, b], WINDOW)


def test_the_lqr_baseline_in_a_batch_equals_the_scalar_loop():
    """lqr and lqr_ndo, scenarios with their own nominal model (so their own K) and weights."""
    rng = np.random.default_rng(11)
    values = [dict(BASE, law="lqr", use_observer=bool(i % 2), seed=i, **{
        "nominal.m_b": BASE["nominal.m_b"] * rng.uniform(0.9, 1.1), "lqr.R": float(rng.uniform(0.005, 0.05)),
        "initial.theta_b": float(rng.uniform(-0.3, 0.3))}) for i in range(6)]
    loops = [P.closed_loop(v, duration=2.0) for v in values]
    assert len({lp.params for lp in loops}) == 6   # each its own gain K (core.laws.lqr.LqrGain)
    batch, _ = assert_batch_equals_scalar(loops, WINDOW)
    assert [b.label for b in batch.trajectories] == ["lqr_ndo" if i % 2 else "lqr" for i in range(len(loops))]


def test_one_batch_runs_one_law():
    with pytest.raises(ValueError, match="the law"):
        simulate_batch([P.closed_loop(BASE, duration=0.1), P.closed_loop(BASE, duration=0.1, law="lqr")], WINDOW)


def test_sensing_and_actuation_in_a_batch_equal_the_scalar_loop():
    rng = np.random.default_rng(5)
    values = [dict(BASE, seed=i, use_observer=bool(i % 2), **{
        "sensors.noise_std.theta_b": float(rng.uniform(0, 0.004)),
        "sensors.noise_std.dtheta_w": float(rng.uniform(0, 0.4)),
        "sensors.noise_std.dtheta_b": 0.0 if i == 2 else 0.02, "sensors.encoder_counts_per_rev": 1024,
        "sensors.delay_periods": 1, "actuator.delay_periods": 2}) for i in range(5)]
    values[3] = dict(values[3], **{f"sensors.noise_std.{c}": 0.0
                                   for c in ("theta_w", "theta_b", "dtheta_w", "dtheta_b")})
    loops = [P.closed_loop(v, duration=2.0) for v in values]
    assert_batch_equals_scalar(loops, WINDOW)


def test_the_batch_math_namespace_computes_each_angle_once_and_never_goes_stale(monkeypatch):
    from mwip_ros.core.kernels import batch_numpy
    calls = []
    real_sin = np.sin
    monkeypatch.setattr(batch_numpy.np, "sin", lambda a: calls.append(a) or real_sin(a))
    trig = batch_numpy._Trig()
    a, b, c = (np.linspace(-1, 1, 7) + k for k in range(3))
    assert np.array_equal(trig.sin(a), real_sin(a)) and np.array_equal(trig.cos(a), np.cos(a))
    assert np.array_equal(trig.sin(b), real_sin(b)) and np.array_equal(trig.sin(a), real_sin(a))
    assert len(calls) == 2                               # a and b once each, however often asked
    d = a.copy()                                         # equal values, another array: computed, not guessed
    assert np.array_equal(trig.sin(c), real_sin(c)) and np.array_equal(trig.sin(d), real_sin(d))
    assert len(calls) == 4 and calls[-1] is d
    assert trig.sin(0.5) == real_sin(0.5) and trig.exp is np.exp and trig.floor is np.floor


@pytest.mark.parametrize("compiled", [True, False])
def test_the_metrics_without_a_record_equal_the_scalar_loop_in_either_form(runs, compiled):
    """Without ``record`` the batch runs compiled (core.kernels.compiled) by default, or over numpy arrays: the same
    falls, fall times, steps and metrics as each scenario's scalar run (these scenarios: noise, a torque limit,
    a fall, a divergence)."""
    loops, _, scalar = runs
    r = simulate_batch(loops, WINDOW, compiled=compiled)
    assert r.trajectories is None
    assert r.fallen.tolist() == [s.fallen for s in scalar]
    assert r.steps == sum(len(s) - 1 for s in scalar)
    for i, s in enumerate(scalar):
        m = metrics.compute(s.columns, WINDOW, FALL_ANGLE)
        assert r.t_fall[i] == pytest.approx(s.t[-1], abs=1e-9) if s.fallen else np.isnan(r.t_fall[i])
        assert r.upright[i] == m.upright
        for key, values in r.metrics.items():
            assert values[i] == pytest.approx(getattr(m, key), rel=1e-9, abs=1e-9, nan_ok=True), (i, key)


def test_the_compiled_form_is_the_default_and_the_switch_turns_it_off(monkeypatch):
    from mwip_ros.core.kernels import batch, compiled
    seen = []
    monkeypatch.setattr(batch, "_simulate_compiled", lambda *a: seen.append("compiled") or "c")
    monkeypatch.setattr(batch, "_simulate_numpy", lambda *a: seen.append("numpy") or "n")
    loops = [P.closed_loop(BASE, duration=0.1)]
    monkeypatch.delenv(batch.COMPILED_ENV, raising=False)
    assert simulate_batch(loops, WINDOW) == "c"
    assert simulate_batch(loops, WINDOW, record=True) == "n"   # a trajectory: the numpy form records it
    monkeypatch.setenv(batch.COMPILED_ENV, "0")
    assert simulate_batch(loops, WINDOW) == "n"
    assert simulate_batch(loops, WINDOW, compiled=True) == "c"
    assert compiled.kernel_for(type("NoPure", (), {})) is None


@pytest.mark.parametrize("compiled", [True, False])
def test_a_driver_nobody_enables_applies_no_torque_in_a_batch_as_in_the_scalar_loop(compiled):
    """require_enable: true offline (theory.md 6.8): the batch has no driver state machine of its own, so such
    scenarios run the scalar loop: no torque, the motor's back-EMF included (the wheel at 40 rad/s > V_max / K_t)."""
    v = dict(BASE, **{"require_enable": True, "motor.enabled": True, "initial.theta_b": 0.0,
                      "initial.dtheta_w": 40.0})
    loops = [P.closed_loop(v, duration=0.5)]
    r = simulate_batch(loops, (0.0, 0.5), compiled=compiled)
    assert r.metrics["u_rms"][0] == 0.0 and r.metrics["u_applied_rms"][0] == 0.0, r.metrics
