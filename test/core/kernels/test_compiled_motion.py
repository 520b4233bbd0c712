"""The compiled batch loop tracking motion references (``core.kernels.compiled_motion``, docs/theory.md 6.11) equals the
scalar loop (:func:`.sim.simulate` with its :class:`.motion.Shaper`) scenario by scenario, for every law the compiled
loop runs, with the state measured (ideal, realistic sensing) and with the raw sensors, kalman and the motor: every
window metric and :func:`.metrics.motion_metrics`' speed and hold numbers to 1e-9, falls included; and it
runs compiled, from the Shaper's and the laws' own functions."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.kernels import batch, compiled, jitcache
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.control import motion
from mwip_ros.core.kernels.batch import simulate_batch
from mwip_ros.core.kernels.compiled_motion import MOTION_METRICS
from mwip_ros.core.laws import get as law
from mwip_ros.core.closed_loop.sim import simulate

pytestmark = pytest.mark.unit

CONFIG = Path(__file__).resolve().parents[3] / "config"
MOTION = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "motion.yaml"]))
REALISTIC = {k: v for k, v in P.merged_values(P.load_param_file(CONFIG / "sensing_realistic.yaml")).items()
             if k.startswith(("sensors.", "actuator."))}
RAW_MOTOR = dict(P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "sensors_raw_realistic.yaml",
                                                     CONFIG / "motion.yaml"])),
                 **{"motor.enabled": True})   # raw IMU and encoder, kalman, the drive (docs/theory.md 6.7)
BASES = {"off": MOTION, "realistic": dict(MOTION, **REALISTIC), "raw_motor": RAW_MOTOR}
WINDOW = (1.0, 20.0)
DURATION = 22.0   # the hold of config/motion.yaml's profile: v* = 0 from 18 s, hold from 20 s (HOLD_SETTLE_S)
COMPILED_LAWS = ["dsc", "dscndo", "lqr", "lqr_ndo", "smc", "smc_ndo"]


def _values(base: dict, seed=5):
    """Four scenarios of their own masses, seeds and start, tracking config/motion.yaml's profile; one with a profile
    of its own that never stops (no hold: NaN drift), one without motion, one that falls at once."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(4):
        v = dict(base)
        v.update({"seed": int(rng.integers(0, 1000)), "actual.m_b": base["actual.m_b"] * rng.uniform(0.8, 1.2),
                  "actual.I_b": base["actual.I_b"] * rng.uniform(0.8, 1.2),
                  "initial.theta_b": float(rng.uniform(-0.15, 0.15)),
                  "initial.theta_w": float(rng.uniform(-1.0, 1.0))})
        out.append(v)
    out.append(dict(out[0], **{"motion.profile": [0.0, 0.0, 1.0, 0.4, 5.0, -0.3], "motion.max_accel": 0.8,
                               "motion.position_gain": 0.3, "seed": 9}))
    out.append(dict(out[1], **{"motion.enabled": False, "seed": 10}))
    out.append(dict(out[2], **{"initial.theta_b": 1.2, "seed": 11}))   # beyond the fall angle
    return out


def _close(got, want):
    return (np.isnan(want) and np.isnan(got)) or abs(got - want) <= 1e-9 * max(1.0, abs(want))


def _check_equal(loops, r, runs=None):
    """Each scenario of ``r`` against the scalar loop (``runs``: the scalar runs by loop, filled as they are made)."""
    runs = {} if runs is None else runs
    for i, lp in enumerate(loops):
        s = runs[id(lp)] = runs[id(lp)] if id(lp) in runs else simulate(lp)
        assert bool(r.fallen[i]) == s.fallen, i
        m = metrics.compute(s.columns, WINDOW, lp.plant.fall_angle)
        mm = (metrics.motion_metrics(s.columns, lp.motion.r, lp.plant.fall_angle) if lp.motion is not None
              else dict.fromkeys(MOTION_METRICS, np.nan))
        for key, values in r.metrics.items():
            want = mm[key] if key in MOTION_METRICS else getattr(m, key)
            assert _close(values[i], want), (i, key, values[i], want)
        if lp.motion is not None and not s.fallen:   # the run tracked the profile (the numbers compared mean it;
            assert mm["speed_rms"] < 0.55, mm          # LQR's worst of these scenarios: 0.513 m/s)
    assert set(MOTION_METRICS) <= set(r.metrics)


def check_law(controller: str, sensing: str) -> None:
    """The batch of :func:`_values` run compiled (never the scalar fallback), mixed (a scenario without motion: the
    law scenario by scenario) and every one with motion (the law on the SIMD lanes), against the scalar loop."""
    loops = [P.closed_loop(v, duration=DURATION, controller=controller) for v in _values(BASES[sensing])]
    assert compiled.kernel_for(law(controller)) is not None

    def scalar(*args, **kwargs):
        raise AssertionError("the motion batch ran the scalar loop")
    moving = [lp for lp in loops if lp.motion is not None]
    each, batch._simulate_each = batch._simulate_each, scalar
    try:
        r, r_moving = simulate_batch(loops, WINDOW, compiled=True), simulate_batch(moving, WINDOW, compiled=True)
    finally:
        batch._simulate_each = each
    runs = {}
    _check_equal(loops, r, runs)
    _check_equal(moving, r_moving, runs)
    assert r.fallen[-1] and (sensing == "raw_motor" or not r.fallen[:-1].any())   # raw + the drive: some laws fall
    assert not r.fallen[:4].all()
    assert np.isnan(r.metrics["hold_drift"][4]) and np.isfinite(r.metrics["hold_drift"][:4][~r.fallen[:4]]).all()
    assert np.isnan(r.metrics["speed_rms"][5])   # no motion: no tracking numbers


# two cases in the fast loop (unit), the rest of every law and sensing in the slow tier: the scalar reference runs
# of 6 scenarios x 22 s are a second or two a case
FAST_CASES = {("dscndo", "off"), ("lqr_ndo", "raw_motor")}


@pytest.mark.parametrize("controller, sensing", [
    pytest.param(c, s, marks=() if (c, s) in FAST_CASES else pytest.mark.slow)
    for c in COMPILED_LAWS for s in sorted(BASES)])
def test_the_compiled_batch_tracks_the_profile_as_the_scalar_loop(controller, sensing):
    check_law(controller, sensing)


@pytest.mark.slow
def test_without_simd_lanes_too():
    """DSCNDO and LQR again with ``MWIP_BATCH_SIMD=0`` (one scenario after another), in a process of its own."""
    import os
    import subprocess
    import sys
    code = ("import importlib.util\n"
            f"spec = importlib.util.spec_from_file_location('motion_oracle', {str(Path(__file__))!r})\n"
            "mod = importlib.util.module_from_spec(spec); spec.loader.exec_module(mod)\n"
            "from mwip_ros.core.kernels import simd\n"
            "assert simd.WIDTH == 0\n"
            "mod.check_law('dscndo', 'off')\n"
            "mod.check_law('lqr', 'off')\n"
            "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=CONFIG.parent, env=dict(os.environ, MWIP_BATCH_SIMD="0"),
                         capture_output=True, text=True, timeout=1200)
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-3000:]


def test_without_the_compiled_loop_a_motion_batch_runs_the_scalar_loop_with_the_same_metrics():
    """The numpy form has no references: ``compiled=False`` (and a law without a pure form, mpc) runs the scalar loop,
    whose metrics (the motion ones included) the compiled loop's equal."""
    loops = [P.closed_loop(v, duration=DURATION, controller="lqr_ndo") for v in _values(MOTION)]
    a, b = simulate_batch(loops, WINDOW, compiled=True), simulate_batch(loops, WINDOW, compiled=False)
    assert set(a.metrics) == set(b.metrics) and a.steps == b.steps
    for key in a.metrics:
        assert all(_close(x, y) for x, y in zip(a.metrics[key], b.metrics[key])), key


def test_the_kernel_tracks_with_the_shapers_and_the_laws_own_functions():
    """No second copy: the compiled loop's references are motion.py's functions and the laws' tracking their own
    (DSC's outer loop; the others' pure_step on the error state), and the cache stamp covers their files."""
    from mwip_ros.core.kernels import compiled_motion
    from mwip_ros.core.laws import dsc, lqr
    g = compiled.kernel_for(law("dscndo")).py_func.__globals__
    track = g["law_track"].py_func
    assert track.__code__ is compiled_motion.law_track.__code__
    assert track.__globals__["track_step"].py_func.__code__ is dsc.dsc_track_step.__code__
    shaper = track.__globals__["motion_reference"].py_func.__globals__
    for name, fn in (("profile_at", motion.profile_at), ("speed_start", motion.speed_start),
                     ("speed_step", motion.speed_step)):
        assert shaper[name].py_func.__code__ is fn.__code__, name
    if compiled.SIMD:   # the same tracking on lanes (DSC: pure_lanes)
        lanes = g["law_track_lanes"].py_func.__globals__
        assert lanes["track_lanes"].py_func.__code__ is dsc.dsc_track_step.__code__
        assert lanes["motion_reference"] is track.__globals__["motion_reference"]
    assert g["motion_row"].py_func.__code__ is compiled_motion.motion_row.__code__
    files, _ = jitcache.made_of(compiled.kernel_for(law("dsc")).py_func)
    for f in (motion.__file__, compiled_motion.__file__, dsc.__file__):
        assert str(Path(f)) in files, f
    lq = compiled.kernel_for(law("lqr")).py_func.__globals__["law_track"].py_func.__globals__["track_step"].py_func
    assert lq.__code__ is compiled_motion.tracked_step.__code__
    assert lq.__globals__["law_step"].py_func.__code__ is lqr.lqr_step.__code__
    assert lq.__globals__["error_state"].py_func.__code__ is motion.error_state.__code__


def test_the_shaper_steps_with_the_pure_functions(monkeypatch):
    """The scalar Shaper forms v*, theta_w'*, theta_w* with the functions the compiled loop runs."""
    calls = []
    real = motion.speed_step

    def spy(*a):
        calls.append(a)
        return real(*a)
    monkeypatch.setattr(motion, "speed_step", spy)
    sh = motion.Shaper(motion.MotionConfig(profile=((0.0, 1.0),)), 0.01)
    sh.reference(0, 0.5)
    ref = sh.reference(3)
    assert len(calls) == 3 and ref.v == pytest.approx(4 * 0.5 * 0.01)
    assert ref.theta_w == pytest.approx(0.5 + 0.01 * (1 + 2 + 3) * 0.005 / 0.254)


_MOTION_CHECK = """
from mwip_ros import params as P
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.kernels.batch import simulate_batch
from mwip_ros.core.closed_loop.sim import simulate
loop = P.closed_loop(P.merged_values(P.load_param_files({files!r})), duration=4.0, controller="dsc")
r = simulate_batch([loop], (1.0, 4.0), compiled=True)
m = metrics.motion_metrics(simulate(loop).columns, loop.motion.r, loop.plant.fall_angle)
print(repr(m["speed_rms"]), repr(float(r.metrics["speed_rms"][0])))
"""


@pytest.mark.slow
def test_an_edit_to_the_shaper_is_compiled_afresh_in_the_batch_loop(tmp_path):
    """The compiled loop's cache stamp covers core/control/motion.py (neither the loop's file nor
    core/kernels/compiled_motion.py): an edit to the Shaper's speed step reaches the next process's compiled loop, which
    still equals the scalar one."""
    import os
    import shutil
    import subprocess
    import sys

    pkg = Path(compiled.__file__).resolve().parents[2]
    shutil.copytree(pkg, tmp_path / "mwip_ros", ignore=shutil.ignore_patterns("__pycache__"))
    env = dict(os.environ, PYTHONPATH=str(tmp_path), NUMBA_CACHE_DIR=str(tmp_path / "numba_cache"))
    script = _MOTION_CHECK.format(files=[str(CONFIG / "paper.yaml"), str(CONFIG / "motion.yaml")])

    def run():
        out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600,
                             cwd=tmp_path)
        assert out.returncode == 0, out.stderr
        scalar, batch = (float(v) for v in out.stdout.split())
        assert batch == pytest.approx(scalar, rel=1e-9)   # the compiled loop runs the code as it is now
        return batch

    first = run()
    motion_py = tmp_path / "mwip_ros" / "core" / "control" / "motion.py"
    text = motion_py.read_text()
    edit = "v = _toward(v, v_target, max_accel * h)"
    assert edit in text
    motion_py.write_text(text.replace(edit, "v = _toward(v, v_target, 0.5 * max_accel * h)"))
    assert run() != pytest.approx(first, rel=1e-3)   # half the acceleration: another speed error
