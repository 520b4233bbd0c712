"""mwip_report on a run of the MuJoCo plant (its pose columns): the 3D pose at the end, as docs/recording.md shows."""
from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mwip_ros.cli import report
from mwip_ros.core.closed_loop.trajectory import Trajectory

pytestmark = pytest.mark.unit
REPO = Path(__file__).resolve().parents[2]


def _run(**pose):
    t = np.array([0.0, 0.005, 0.010])
    cols = {"t": t, "theta_b": np.zeros(3), "theta_w": np.zeros(3), "dtheta_b": np.zeros(3), "dtheta_w": np.zeros(3),
            "u": np.zeros(3)}
    cols.update({k: np.asarray(v, dtype=float) for k, v in pose.items()})
    return Trajectory("r", cols, False, 0.005)


def test_the_pose_summary_is_relative_to_the_start_and_none_without_a_pose_or_from_nan():
    run = _run(x=[1.0, 1.5, 2.25], y=[-1.0, -1.0, -0.5], yaw=[0.0, 0.1, 0.3], roll=[0.0, -0.02, 0.01],
               wheel_left=[5.0, 6.0, 7.5], wheel_right=[5.0, 6.0, 6.5])
    assert report.pose_summary(run) == {"t_s": 0.01, "x_m": 1.25, "y_m": 0.5, "yaw_rad": 0.3, "roll_max_abs_rad": 0.02,
                                        "wheel_left_rad": 2.5, "wheel_right_rad": 1.5}
    assert report.pose_summary(_run()) is None   # a planar run (rk4): no pose columns
    nan = _run(x=[0.0, 1.0, math.nan], y=[0.0] * 3, yaw=[0.0] * 3, roll=[0.0] * 3, wheel_left=[0.0] * 3,
               wheel_right=[0.0] * 3)
    assert report.pose_summary(nan) is None   # never a figure from NaN


@pytest.mark.cli
def test_the_docs_pose_note_is_what_mwip_report_prints_for_a_mujoco_run(tmp_path):
    pytest.importorskip("mujoco")
    text = " ".join((REPO / "docs" / "recording.md").read_text().split())
    said = re.search(r"`(3D pose at t = [^`]*)`", text).group(1)
    over = tmp_path / "mujoco.yaml"
    over.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n")
    csv = tmp_path / "mj.csv"
    sim = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", "--params", str(REPO / "config" / "paper.yaml"),
                          str(over), "--controller", "dscndo", "--duration", "3", "--csv", str(csv), "-q"],
                         capture_output=True, text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.report", str(csv), "--out", str(tmp_path / "rep"),
                        "--no-animation"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert f"mj: {said}" in r.stdout.splitlines(), r.stdout
