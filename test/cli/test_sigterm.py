"""SIGTERM (timeout, kill, a batch scheduler) is handled like Ctrl-C by the long-running commands: finished work
kept, exit 143, and no process of the command's session (workers, multiprocessing's resource tracker) left
a few seconds later."""
import os
import signal
import subprocess
import sys
import time

import pytest
import yaml

from mwip_ros.sweep.results import read_results

from test_sweep import write_spec   # noqa: E402  (test/cli is on sys.path under pytest)

pytestmark = pytest.mark.e2e   # whole jobs signalled, their sessions checked for leftover workers


def session_processes(sid: int) -> list:
    out = subprocess.run(["ps", "-e", "-o", "pid=,sid="], capture_output=True, text=True).stdout
    return [int(p) for p, s in (line.split() for line in out.splitlines() if line.strip()) if int(s) == sid]


def start(module, *argv):
    """The command in a session of its own, as a batch scheduler starts a job."""
    return subprocess.Popen([sys.executable, "-m", module, *map(str, argv)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


def wait_for(cond, timeout, what):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def terminate_and_check(p, timeout=60):
    """SIGTERM to the command alone (not its group); its exit code, stderr; no process of its session left."""
    sid = p.pid   # start_new_session: the leader's pid is the session id
    try:
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=timeout)
        end = time.monotonic() + 5
        while session_processes(sid) and time.monotonic() < end:
            time.sleep(0.1)
        left = session_processes(sid)
    finally:
        for pid in session_processes(sid):   # whatever the assertion says: nothing of ours keeps running
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if p.poll() is None:
            p.kill()
            p.wait(10)
    assert not left, f"processes of the session left: {left}"
    return p.returncode, err


def test_sigterm_to_a_sweep_keeps_finished_rows_and_leaves_no_worker(tmp_path):
    spec = write_spec(tmp_path / "s.yaml", samples=400, duration_s=4.0, metrics_window_s=[2.0, 4.0])
    out = tmp_path / "out"
    p = start("mwip_ros.cli.sweep", spec, "--out", out, "--workers", "2", "--chunk", "50")
    csv = out / "results.csv"
    wait_for(lambda: csv.exists() and len(csv.read_text().splitlines()) > 1 or p.poll() is not None, 120,
             "the first finished chunk")
    assert p.poll() is None, p.stderr.read()
    assert len(session_processes(p.pid)) >= 3   # the sweep, its 2 workers (and the resource tracker)
    code, err = terminate_and_check(p)
    assert code == 143, err
    n = len(read_results(csv)["scenario"])
    assert 50 <= n < 4000 and n % 50 == 0
    assert f"interrupted (SIGTERM): {n:,} of 4,000 rows" in err and "Traceback" not in err


def test_sigterm_to_mwip_sim_keeps_the_finished_runs_csv(tmp_path):
    p = start("mwip_ros.cli.sim", "--compare", "dsc", "dscndo", "--duration", "600", "-q", "--csv", tmp_path / "r.csv")
    wait_for(lambda: (tmp_path / "r_dsc.csv").exists() or p.poll() is not None, 120, "the first run's CSV")
    code, err = terminate_and_check(p)
    assert code == 143 and "interrupted (SIGTERM) after 1 of 2 run(s); kept" in err, err
    assert len(err.strip().splitlines()) == 1
    assert sorted(f.name for f in tmp_path.iterdir()) == ["r_dsc.csv"]   # no half-written CSV of the second run


def test_sigterm_to_mwip_tune_writes_the_best_so_far_and_leaves_no_worker(tmp_path):
    out = tmp_path / "t.yaml"
    p = start("mwip_ros.cli.tune", write_spec(tmp_path / "s.yaml", samples=8), "--controller", "dscndo",
              "--tune", "k1", "k2", "--out", out, "--maxiter", "200", "--workers", "2", "--chunk", "10")
    lines = []

    def generation():
        line = p.stderr.readline()
        lines.append(line)
        return "generation 1/200" in line or not line

    wait_for(generation, 300, "the first generation")
    code, err = terminate_and_check(p)
    assert code == 143, "".join(lines) + err
    assert "interrupted: keeping the best so far" in err and "Traceback" not in err
    assert set(yaml.safe_load(out.read_text())["dscndo_controller"]["ros__parameters"]) == {"k1", "k2"}
