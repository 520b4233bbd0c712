"""mwip_robot (mwip_ros/cli/robot.py): its help, its refusals in one line with exit 2, and a short run on Upkie's
PyBullet that writes its CSV and JSON (in this process: the CLI's main)."""
from __future__ import annotations

import json

import pytest

from mwip_ros.cli.robot import main
from mwip_ros.params.paths import default_params_file
from mwip_ros.runs import read_csv

pytestmark = pytest.mark.unit

CONFIG = default_params_file().parent
UPKIE = [str(CONFIG / "paper.yaml"), str(CONFIG / "upkie.yaml")]


def test_help_names_the_robots_and_the_exit_codes(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "upkie-pybullet" in out and "upkie-spine" in out and "exit codes:" in out and "--realtime" in out


def test_raw_measure_without_raw_sensors_is_refused(capsys):
    assert main(["--robot", "upkie-pybullet", "--params", str(CONFIG / "paper.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mwip_robot: error: --measure raw needs sensors.model: raw") and "\n" not in err


def test_existing_outputs_and_bad_durations_are_refused_before_any_run(tmp_path, capsys):
    out = tmp_path / "run.csv"
    out.write_text("keep me\n")
    assert main(["--robot", "upkie-pybullet", "--params", *UPKIE, "--csv", str(out)]) == 2
    assert "--csv" in capsys.readouterr().err and out.read_text() == "keep me\n"
    assert main(["--robot", "upkie-pybullet", "--params", *UPKIE, "--duration", "0"]) == 2
    assert "--duration 0" in capsys.readouterr().err
    assert main(["--robot", "upkie-pybullet", "--params", *UPKIE, "--duration", "3", "--window", "5", "10"]) == 2
    assert "--window 5 10: give 0 <= T0 < T1 <= the run's 3 s" in capsys.readouterr().err


def test_a_bad_upkie_parameter_names_its_key(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("plant_sim:\n  ros__parameters:\n    upkie:\n      leg_kp_scale: -1.0\n")
    assert main(["--robot", "upkie-pybullet", "--params", *UPKIE, str(bad)]) == 2
    assert "upkie.leg_kp_scale" in capsys.readouterr().err


def test_a_short_run_writes_its_csv_and_numbers(tmp_path, capsys):
    pytest.importorskip("pybullet")
    csv, js = tmp_path / "run.csv", tmp_path / "run.json"
    assert main(["--robot", "upkie-pybullet", "--params", *UPKIE, "--duration", "0.5", "--window", "0.3", "0.5",
                 "--csv", str(csv), "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("upkie-pybullet, dscndo, measured raw: upright")
    numbers = json.loads(js.read_text())
    assert numbers["upright"] and numbers["window"] == [0.3, 0.5] and numbers["theta_b_rms"] < 0.03
    run = read_csv(csv)
    assert len(run) == 101 and {"gyro", "accel_x", "encoder", "u_applied", "theta_b_hat", "x"} <= set(run.columns)
