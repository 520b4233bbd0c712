"""The compiled batch loop with the stages beyond the state-measuring plant: the raw sensors and their estimator, the
motor and the excitation (``core.kernels.compiled._loop``) equal the scalar loop (:func:`.sim.simulate`) scenario by
scenario, every metric to 1e-9, falls included; with the SIMD lanes and without (``MWIP_BATCH_SIMD=0``, in a process of
its own: the lane width is fixed at import)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.kernels import batch, compiled
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.kernels.batch import simulate_batch
from mwip_ros.core.closed_loop.sim import simulate

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "config"
WINDOW = (0.5, 2.0)
PAPER = P.merged_values(P.load_param_file(CONFIG / "paper.yaml"))
RAW = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "sensors_raw_realistic.yaml"]))
CHIRP = {"excitation.type": "chirp", "excitation.amplitude": 20.0, "excitation.f0": 0.5, "excitation.f1": 5.0,
         "excitation.duration_s": 1.5}
MOTOR = {"motor.enabled": True, "motor.current_limit": 50.0}   # 100 N m at most: the drive saturates at times

CASES = {   # name -> (base values, overrides of every scenario)
    "raw_kalman": (RAW, {}),
    "raw_complementary": (RAW, {"method": "complementary"}),
    "raw_delay": (RAW, {"sensors.delay_periods": 2, "actuator.delay_periods": 1}),
    "motor": (PAPER, MOTOR),
    "chirp": (PAPER, CHIRP),
    "raw_motor_chirp": (RAW, {**MOTOR, **CHIRP}),
}


def _values(base, over, shared_tau: bool, seed=11):
    """Eight scenarios of their own masses and seeds, one that falls at once and one that falls later."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(8):
        v = dict(base, **over)
        v.update({"seed": int(rng.integers(0, 1000)), "actual.m_b": base["actual.m_b"] * rng.uniform(0.7, 1.3),
                  "actual.I_b": base["actual.I_b"] * rng.uniform(0.7, 1.3),
                  "initial.theta_b": float(rng.uniform(-0.2, 0.2))})
        if i == 3:
            v["actual.D_w_variance"] = 0.0
        if not shared_tau:
            v["tau_ext1.amplitude"] = float(rng.uniform(0, 45))
        out.append(v)
    out.append(dict(out[0], **{"initial.theta_b": 1.2, "seed": 3}))                     # beyond the fall angle
    out.append(dict(out[1], **{"torque_limit": 20.0, "tau_ext2.amplitude": 40.0, "tau_ext2.omega": 1.0,
                               "tau_ext2.phase": 0.0, "seed": 4}))   # too weak a drive: falls in the window
    return out


def _stage_keys(loop) -> set:
    keys = set()
    if loop.plant.raw is not None:
        keys |= {"theta_b_est_err_rms", "dtheta_b_est_err_rms"}
    if loop.plant.motor.enabled:
        keys |= {"u_applied_rms", "saturated_s"}
    return keys


def check_case(name: str, shared_tau: bool = True, controller: str = "dscndo") -> dict:
    """The batch of case ``name`` run compiled (never the scalar fallback) against the scalar loop: fall, its time,
    the steps and every metric of :func:`.metrics.compute` to 1e-9 (relative above 1). Returns facts to check."""
    base, over = CASES[name]
    loops = [P.closed_loop(v, duration=2.0, controller=controller) for v in _values(base, over, shared_tau)]

    def refused(*a, **k):
        raise AssertionError("the batch fell back to the scalar loop")
    each, batch._simulate_each = batch._simulate_each, refused
    try:
        r = simulate_batch(loops, WINDOW, compiled=True)
    finally:
        batch._simulate_each = each
    worst, stepped, sat = 0.0, 0, 0.0
    assert set(r.metrics) >= set().union(*(_stage_keys(lp) for lp in loops))
    for i, lp in enumerate(loops):
        s = simulate(lp)
        m = metrics.compute(s.columns, WINDOW, lp.plant.fall_angle)
        assert bool(r.fallen[i]) == s.fallen, (name, i)
        if s.fallen:
            assert abs(r.t_fall[i] - s.t[-1]) <= 1e-9, (name, i)
        for key, values in r.metrics.items():
            want, got = getattr(m, key), values[i]
            if np.isnan(want) or np.isnan(got):
                assert np.isnan(want) and np.isnan(got), (name, i, key, got, want)
                continue
            err = abs(got - want) / max(1.0, abs(want))
            assert err <= 1e-9, (name, i, key, got, want)
            worst = max(worst, err)
        for key in _stage_keys(lp):
            assert key in r.metrics
        if lp.plant.motor.enabled:
            sat = max(sat, m.saturated_s)
        stepped += len(s) - 1
    assert r.steps == stepped
    return {"fallen": [bool(v) for v in r.fallen], "worst": worst, "saturated": sat}


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_compiled_stages_equal_the_scalar_loop(name):
    for shared in (True, False):
        facts = check_case(name, shared)
        assert facts["fallen"][8] and facts["fallen"][9] and facts["fallen"][:8].count(False) >= 5, (name, facts)
        if "motor" in name:
            assert facts["saturated"] > 0.0   # the drive did saturate


def test_a_law_without_the_observer_and_lqr_run_the_stages_compiled():
    check_case("raw_motor_chirp", True, "dsc")
    check_case("raw_kalman", False, "lqr_ndo")


def test_the_kernel_calls_the_estimators_and_the_raw_sensors_own_code():
    from mwip_ros.core.plants import drive, raw_sensors
    from mwip_ros.core import laws
    from mwip_ros.core.estimators import complementary, kalman
    law = laws.get("dscndo")
    k = compiled.kernel_for(law, kalman.KalmanFilter)
    assert k is compiled.kernel_for(law, kalman.KalmanFilter) is not compiled.kernel_for(law)
    assert k is not compiled.kernel_for(law, complementary.ComplementaryFilter)
    g = k.py_func.__globals__
    assert k.py_func.__code__ is compiled._loop.__code__
    # the stages sensors and estimator: core.kernels.compiled.sense_raw, which the vector env runs too (envs.kernels)
    assert g["sense_raw"].py_func.__code__ is compiled.sense_raw.__code__
    g = g["sense_raw"].py_func.__globals__
    assert g["est_step"].py_func.__code__ is kalman.kalman_step.__code__
    assert g["raw_sample"].py_func.__code__ is raw_sensors.raw_sample.__code__
    assert g["motor_torque"].py_func.__code__ is drive.motor_torque.__code__
    g = k.py_func.__globals__
    assert g["rk4_driven"] is compiled._rk4_driven


def test_mixed_estimators_or_raw_and_state_fall_back_to_the_scalar_loop():
    a = P.closed_loop(dict(RAW, seed=1), duration=0.2, controller="dscndo")
    b = P.closed_loop(dict(RAW, seed=2, method="complementary"), duration=0.2, controller="dscndo")
    c = P.closed_loop(dict(PAPER, seed=3), duration=0.2, controller="dscndo")
    assert batch._raw_stage([a, b]) is None and batch._raw_stage([a, c]) is None
    r = simulate_batch([a, b, c], (0.1, 0.2))
    for i, lp in enumerate((a, b, c)):
        m = metrics.compute(simulate(lp).columns, (0.1, 0.2), lp.plant.fall_angle)
        assert r.metrics["u_rms"][i] == m.u_rms


@pytest.mark.slow
def test_without_simd_lanes_too():
    """Every case again with ``MWIP_BATCH_SIMD=0`` (one scenario after another), in a process of its own."""
    code = ("import importlib.util, sys\n"
            f"spec = importlib.util.spec_from_file_location('stages', {str(Path(__file__))!r})\n"
            "mod = importlib.util.module_from_spec(spec); spec.loader.exec_module(mod)\n"
            "from mwip_ros.core.kernels import simd\n"
            "assert simd.WIDTH == 0\n"
            "for name in sorted(mod.CASES):\n"
            "    for shared in (True, False):\n"
            "        f = mod.check_case(name, shared)\n"
            "        assert f['fallen'][8] and f['fallen'][9] and f['fallen'][:8].count(False) >= 5, (name, f)\n"
            "print('ok')\n")
    env = dict(os.environ, MWIP_BATCH_SIMD="0")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=1200)
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-3000:]
