"""mwip_report of a raw-sensor run: the estimation error metrics and the figure of true vs estimated pitch."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.cli import report
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.runs import write_csv

pytestmark = pytest.mark.unit

CONFIG = Path(__file__).resolve().parents[2] / "config"


def test_a_raw_run_is_judged_on_its_estimate_too(tmp_path):
    v = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "sensors_raw_realistic.yaml"]))
    run = simulate(P.closed_loop(v, controller="dscndo", duration=4.0))
    csv = tmp_path / "raw.csv"
    write_csv(run, csv)
    out = tmp_path / "report"
    assert report.main([str(csv), "--out", str(out), "--no-animation"]) == 0
    m = json.loads((out / "metrics.json").read_text())["runs"]["raw"]
    err = run["theta_b_hat"] - run["theta_b"]
    sel = run["t"] >= 2.0 - 1e-9   # the window of a 4 s run: its second half
    want = math.sqrt(float((err[sel] ** 2).mean()))
    assert m["theta_b_est_err_rms"] == pytest.approx(want, rel=1e-12)
    assert (out / "pitch_estimate.png").stat().st_size > 10_000
    # the table carries the raw samples, the estimate, the command and the torque that acted (no motor: equal)
    for c in ("gyro", "accel_x", "accel_z", "encoder", "encoder_rate", "theta_b_hat", "dtheta_b_hat", "theta_w_hat",
              "dtheta_w_hat", "u", "u_applied"):
        assert c in run.columns, c
    np.testing.assert_array_equal(run["u_applied"][:-1], run["u"][:-1])
    assert "pitch_estimate.png" in (out / "metrics.md").read_text()


def test_a_state_run_has_no_estimate_figure(tmp_path):
    run = simulate(P.closed_loop(P.merged_values(P.load_param_file(CONFIG / "paper.yaml")), controller="dscndo",
                                 duration=1.0))
    csv = tmp_path / "state.csv"
    write_csv(run, csv)
    assert report.main([str(csv), "--out", str(tmp_path / "r"), "--no-animation"]) == 0
    assert not (tmp_path / "r" / "pitch_estimate.png").exists()
    assert json.loads((tmp_path / "r" / "metrics.json").read_text())["runs"]["state"]["theta_b_est_err_rms"] is None
