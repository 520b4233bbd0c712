"""The loop closed: identify a robot from its own identification run, within 3 % (true state)."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from mwip_ros import params as P
from mwip_ros.cli import identify
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.runs import write_csv

pytestmark = pytest.mark.unit

CONFIG = Path(__file__).resolve().parents[2] / "config"
ROBOT = {"actual.m_b": 250.0, "actual.I_b": 48.0, "actual.l": 0.28}   # not the paper's robot


def test_the_shipped_experiment_identifies_another_robot_within_3_percent(tmp_path):
    v = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "identify.yaml"]))
    v.update(ROBOT)
    run = simulate(P.closed_loop(v, controller="dscndo"))
    assert not run.fallen
    csv = tmp_path / "identify.csv"
    write_csv(run, csv)
    out = tmp_path / "identified.yaml"
    assert identify.main([str(csv), "--params", str(CONFIG / "paper.yaml"), "--out", str(out)]) == 0
    got = yaml.safe_load(out.read_text())["/**"]["ros__parameters"]["nominal"]
    for key in ("m_b", "I_b", "l"):
        truth = ROBOT[f"actual.{key}"]
        assert abs(got[key] - truth) <= 0.03 * truth, (key, got[key], truth)


def test_a_raw_sensor_log_is_fit_through_its_estimate_and_refused_naming_what_it_cannot_resolve(tmp_path, capsys):
    """With the realistic raw sensors the estimate (what the robot knows of itself) is the motion fit by default;
    its rate errors leave a parameter unresolved, and the tool says which, exit 2; the same log's true state
    identifies the robot (a simulator's check of the experiment)."""
    v = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "sensors_raw_realistic.yaml",
                                            CONFIG / "identify.yaml"]))
    run = simulate(P.closed_loop(v, controller="dscndo", duration=20.0))
    csv = tmp_path / "raw.csv"
    write_csv(run, csv)
    out = tmp_path / "identified.yaml"
    assert identify.main([str(csv), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "unresolved" in err or "unphysical" in err, err
    assert any(f"{k} = " in err for k in ("m_b", "I_b", "l")), err
    assert not out.exists()
    assert identify.main([str(csv), "--out", str(out), "--state", "true"]) == 0
    got = yaml.safe_load(out.read_text())["/**"]["ros__parameters"]["nominal"]
    assert abs(got["m_b"] - v["actual.m_b"]) <= 0.03 * v["actual.m_b"]
