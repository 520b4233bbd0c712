"""scripts/run_experiment.sh --robot: the whole graph (state estimator, observer, controller, recorder) against a
robot's own interface through the wheel_driver, as a user runs it: the mock's wiring, Upkie in its own PyBullet, the
emulated moteus robot on a pty (its own process) in realtime; each writes the report with its period timing.  Kept
short (a few seconds of run each); the 60 s goals are scripts/bench_driver.py's."""
import subprocess
from pathlib import Path

import pytest

from graphproc import REPO, script_env

pytestmark = pytest.mark.e2e


def _run(tmp_path: Path, *args: str):
    r = subprocess.run(["bash", str(REPO / "scripts" / "run_experiment.sh"), "--out", str(tmp_path), "--laws",
                        "dscndo", *args], capture_output=True, text=True, timeout=600, env=script_env())
    report = next((p for p in tmp_path.iterdir() if p.name.endswith("_report")), None)
    metrics = (report / "metrics.md").read_text() if report is not None else ""
    return r, metrics


def _bag_topics(tmp_path: Path) -> dict:
    import yaml
    bag = next(p for p in tmp_path.iterdir() if p.name.endswith("_dscndo"))
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}


def test_the_mock_checks_the_wiring_in_lockstep(tmp_path):
    r, metrics = _run(tmp_path, "--robot", "mock", "--duration", "1")
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "## The robot side's period" in metrics and "- lockstep, backend mock, driver enabled" in metrics
    assert "- periods: 200 run, 0 missed" in metrics   # one period per command, states 0 to 200
    topics = _bag_topics(tmp_path)
    for topic in ("/wheel_encoder", "/wheel_states", "/imu/data_raw", "/joint_states", "/wheel_torque_cmd"):
        assert topics[topic] == 201, topic   # lockstep loses nothing
    assert topics.get("/true_joint_states", 0) == 0   # the mock has no truth


def test_upkie_in_its_own_pybullet_balances_through_the_graph(tmp_path):
    pytest.importorskip("upkie")
    r, metrics = _run(tmp_path, "--robot", "upkie-pybullet", "--duration", "2")
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "- lockstep, backend upkie, driver enabled" in metrics
    topics = _bag_topics(tmp_path)
    assert topics["/true_joint_states"] == topics["/true_pose"] == topics["/imu/data_raw"] == 401
    row = next(line for line in metrics.splitlines() if line.startswith("| dscndo | yes"))
    assert float(row.split("|")[4]) < 0.01   # theta_b RMS over the run's second half: the truth, upright


@pytest.mark.alone
def test_the_emulated_moteus_robot_balances_in_realtime(tmp_path):
    pytest.importorskip("moteus")
    r, metrics = _run(tmp_path, "--robot", "emulated-moteus", "--duration", "3", "--realtime-priority", "10")
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "- realtime, backend moteus, driver enabled" in metrics
    assert "watchdog trips 0 left 0 right" in r.stdout   # the emulator's counters, printed after the run
    logs = next(p for p in tmp_path.iterdir() if p.name.endswith("_logs"))
    assert "the newest IMU sample at each encoder sample" in (logs / "dscndo_state_estimator.log").read_text()
    assert not (logs / "dscndo_fdcanusb").exists()   # the emulator's link is gone with it


def test_what_a_robot_cannot_run_is_refused_before_anything_starts(tmp_path):
    r, _ = _run(tmp_path, "--robot", "emulated-moteus", "--mode", "lockstep")
    assert r.returncode == 2 and "--robot emulated-moteus runs on the wall clock" in r.stderr, r.stderr
    r, _ = _run(tmp_path, "--robot", "mock", "--no-record")
    assert r.returncode == 2 and "--robot needs the recording" in r.stderr, r.stderr
    assert not any(p.name.endswith("_logs") for p in tmp_path.iterdir())
