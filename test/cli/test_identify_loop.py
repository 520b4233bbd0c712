"""The loop closed: identify a robot from its own identification run, within 3 % (true state)."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from mwip_ros import params as P
from mwip_ros.cli import identify
from mwip_ros.core.sim import simulate
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
