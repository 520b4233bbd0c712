"""docs/getting-started.md "Drive it", end to end: the documented command (scripts/run_experiment.sh in realtime with
config/drive.yaml and robot_state), shortened to 20 s, and `mwip_ctl cmd --vx 0.5 --wz 0.3 --duration 5` from
another process on the domain it printed: the bag shows the robot driving forward and turning, upright."""
import os
import re
import signal
import subprocess
import threading

import numpy as np
import pytest

from graphproc import REPO, script_env, wait_until

pytest.importorskip("mujoco")
pytest.importorskip("rosbags.highlevel")

DOC = REPO / "docs" / "getting-started.md"
DURATION = "20"


def _documented_commands():
    """The page's run_experiment.sh line and its mwip_ctl cmd line (the test runs what the page says)."""
    text = DOC.read_text().split("## Drive it", 1)[1].split("\n## ", 1)[0]
    run = next(ln for ln in text.splitlines() if ln.startswith("scripts/run_experiment.sh"))
    cmd = next(ln.split("#")[0].split() for ln in text.splitlines() if ln.startswith("mwip_ctl cmd"))
    return run.split(), cmd


def _session_pids(sid: int) -> list:
    out = subprocess.run(["ps", "-e", "-o", "pid=,sid="], capture_output=True, text=True).stdout
    return [int(p) for p, s in (line.split() for line in out.splitlines()) if int(s) == sid]


@pytest.mark.alone
@pytest.mark.e2e
def test_the_documented_drive_command_drives_forward_and_turns_upright(tmp_path):
    run, cmd = _documented_commands()
    assert run[run.index("--duration") + 1] == "300" and "config/drive.yaml" in run and "--robot-state" in run
    assert cmd[:2] == ["mwip_ctl", "cmd"]
    run[run.index("--duration") + 1] = DURATION
    p = subprocess.Popen(["bash", str(REPO / run[0]), *run[1:], "--out", str(tmp_path), "--name", "drive"],
                         cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         start_new_session=True, env=script_env())
    lines = []
    reader = threading.Thread(target=lambda: lines.extend(iter(p.stdout.readline, "")), daemon=True)
    reader.start()
    try:
        def seen(pattern):
            return next((m for m in (re.search(pattern, ln) for ln in list(lines)) if m), None)
        assert wait_until(lambda: seen(r"realtime run, ROS_DOMAIN_ID=(\d+)") or p.poll() is not None, 300), lines
        domain = seen(r"realtime run, ROS_DOMAIN_ID=(\d+)").group(1)
        # the plant is running (its progress line), then the command, as a user in another shell sends it
        assert wait_until(lambda: seen(r" s simulated") or p.poll() is not None, 120), "".join(lines)[-3000:]
        assert p.poll() is None, "".join(lines)[-3000:]
        env = dict(script_env(), ROS_DOMAIN_ID=domain, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
        sent = subprocess.run([*cmd, "--timeout", "30"], cwd=REPO, capture_output=True, text=True, timeout=120,
                              env=env)
        assert sent.returncode == 0, sent.stdout + sent.stderr
        assert p.wait(180) == 0, "".join(lines)[-3000:]
    finally:
        if p.poll() is None:
            os.kill(p.pid, signal.SIGINT)   # the script stops every node it started, by PID
            try:
                p.wait(60)
            except subprocess.TimeoutExpired:
                pass
        for pid in _session_pids(p.pid):
            os.kill(pid, signal.SIGKILL)
        if p.poll() is None:
            p.wait(10)
    assert wait_until(lambda: _session_pids(p.pid) == [], 10), _session_pids(p.pid)
    from mwip_ros.runs import load_run
    bag = tmp_path / "drive_dscndo"
    r = load_run(bag)
    c = r.columns
    yaw = np.unwrap(c["yaw"])
    forward = np.sum(np.diff(c["x"]) * np.cos(yaw[:-1]) + np.diff(c["y"]) * np.sin(yaw[:-1]))
    assert yaw.max() - yaw[0] > 0.6, (yaw.max(), yaw[0])    # 0.3 rad/s for 5 s less the ramps: about 1.4 rad
    moving = np.abs(np.gradient(yaw, c["t"])) > 0.1          # while it turned, it drove forward
    assert forward > 1.0 and moving.sum() > 200, (forward, moving.sum())
    assert np.abs(c["theta_b"][c["t"] > 2.0]).max() < 0.3    # upright (the paper's initial tilt settled)
    assert c["t"][-1] > float(DURATION) - 1.0
