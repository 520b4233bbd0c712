"""mwip_moteus_emulator's command line without ROS (--imu-rate 0): --help, refusals in one line (exit 2), a short
run that serves its pty and leaves nothing behind."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parents[2]


def _run(*args, pre: str = "", timeout: float = 60.0):
    code = f"import sys\n{pre}\nfrom mwip_ros.cli.moteus_emulator import main\nsys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL, cwd=REPO)


@pytest.mark.cli
def test_help_names_the_faults_and_the_exit_codes():
    r = _run("--help")
    assert r.returncode == 0 and r.stdout.startswith("usage: mwip_moteus_emulator")
    for word in ("--latency", "--jitter", "--loss", "--silent", "SIGUSR1", "--overheat", "imu/data_raw", "exit codes"):
        assert word in r.stdout, word


@pytest.mark.parametrize("args, key", [
    (("--loss", "1.5"), "--loss"), (("--latency", "-0.001"), "--latency"), (("--physics-rate", "0"), "--physics-rate"),
    (("--silent-at", "1.0"), "--silent-at needs --silent"), (("--timeout-mode", "3"), "--timeout-mode"),
    (("--ids", "1", "1"), "distinct CAN ids"), (("--signs", "1", "2"), "sign must be +1 or -1"),
    (("--params", "/nonexistent.yaml"), "/nonexistent.yaml")])
@pytest.mark.cli
def test_a_bad_option_is_one_line_and_exit_2(args, key):
    r = _run(*args)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and key in r.stderr and r.stdout == ""


@pytest.mark.cli
def test_an_existing_link_is_never_replaced_unless_it_is_a_symlink_and_forced(tmp_path):
    mine = tmp_path / "mine"
    mine.write_text("keep")
    r = _run("--imu-rate", "0", "--link", mine, "--force")
    assert r.returncode == 2 and "not a symlink (never replaced)" in r.stderr and mine.read_text() == "keep"
    old = tmp_path / "old"
    old.symlink_to("/dev/null")
    r = _run("--imu-rate", "0", "--link", old)
    assert r.returncode == 2 and "--force replaces it" in r.stderr and os.readlink(old) == "/dev/null"


@pytest.mark.cli
def test_a_short_run_serves_its_link_and_removes_it(tmp_path):
    old = tmp_path / "old"
    old.symlink_to("/dev/null")
    r = _run("--imu-rate", "0", "--link", old, "--force", "--duration", "0.3")
    assert r.returncode == 0, r.stderr
    assert r.stdout == f"fdcanusb: {old}\n" and not os.path.lexists(old)   # made, served, removed at exit
    assert "0 frames" in r.stderr and "0 IMU messages" in r.stderr


@pytest.mark.cli
def test_without_the_moteus_package_it_says_so_in_one_line():
    r = _run("--imu-rate", "0", pre="sys.modules['moteus'] = None")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "needs the Python package moteus" in r.stderr and "python3-moteus-pip" in r.stderr
