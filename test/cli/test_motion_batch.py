"""The batch tracks motion references too (theory 6.11): scenarios with motion.enabled run the compiled loop
(core.kernels.compiled_motion; test/core/kernels/test_compiled_motion.py compares it with the scalar loop for every
law), so a batch's numbers are mwip_sim's, and mwip_sweep and mwip_tune run a spec whose base turns motion on."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.kernels.batch import simulate_batch
from mwip_ros.core.closed_loop.sim import simulate

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[2]
FILES = [ROOT / "config/paper.yaml", ROOT / "config/motion.yaml"]


def test_a_batch_with_motion_equals_the_scalar_loop_per_scenario():
    base = P.merged_values(P.load_param_files(FILES))
    loops = [P.closed_loop(dict(base, **{"actual.m_b": m}), controller=c, duration=6.0)
             for m, c in ((250.0, "dscndo"), (310.6, "dscndo"), (360.0, "dscndo"))]
    assert all(lp.motion is not None for lp in loops)
    r = simulate_batch(loops, (2.0, 6.0))
    for i, lp in enumerate(loops):
        run = simulate(lp)
        assert float(np.abs(0.254 * run["dtheta_w"][-200:]).mean()) > 0.5   # it drove (1 m/s from 2 s)
        m = metrics.compute(run.columns, (2.0, 6.0), base["fall_angle"])
        assert r.metrics["theta_b_rms"][i] == pytest.approx(m.theta_b_rms, rel=1e-9)
        assert r.metrics["u_rms"][i] == pytest.approx(m.u_rms, rel=1e-9)
        mm = metrics.motion_metrics(run.columns, base["nominal.r"], base["fall_angle"])
        assert r.metrics["speed_rms"][i] == pytest.approx(mm["speed_rms"], rel=1e-9)
        assert bool(r.upright[i]) == m.upright


def _spec(tmp_path):
    f = tmp_path / "s.yaml"
    f.write_text(f"base: [{FILES[0]}, {FILES[1]}]\ncontrollers: [dscndo]\nduration_s: 4.0\n"
                 "metrics_window_s: [2.0, 4.0]\nseed: 1\nsamples: 2\n"
                 "vary:\n  plant_sim.actual.m_b: {scale: [0.9, 1.1]}\n")
    return f


@pytest.mark.cli
def test_mwip_sweep_and_mwip_tune_run_a_motion_spec(tmp_path):
    out = tmp_path / "sweep"
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sweep", str(_spec(tmp_path)), "--out", str(out)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "dscndo" in r.stdout and any(out.iterdir())
    from mwip_ros.sweep.results import read_results
    cols = read_results(out / "results.csv")   # the tracking metrics are columns of the table, one per run
    speed = np.array(cols["speed_rms"], dtype=float)
    assert len(speed) == 2 and np.all(np.isfinite(speed)) and np.all(speed > 0), cols
    assert np.all(np.array(cols["max_lean"], dtype=float) > 0)
    tuned = tmp_path / "tuned.yaml"
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.tune", str(_spec(tmp_path)), "--controller", "dscndo",
                        "--tune", "k1", "--maxiter", "1", "--popsize", "2", "--seed", "0", "--out", str(tuned)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert tuned.exists() and "k1" in tuned.read_text()
