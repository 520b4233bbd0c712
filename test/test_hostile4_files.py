"""Every file a node or tool reads is a regular file, read with a size bound (issue 46 item 3), and a policy file is
a linear policy or one line naming policy.file (item 8): mwip_ros.yamlio's open_regular / read_bytes, the one way a
file is opened.  Before, opening a FIFO waited for a writer for ever (mwip_sim hung; set at run time, the
controller's executor blocked, its watchdog faulted and the robot fell) and /dev/zero was read until MemoryError."""
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from mwip_ros.params.paths import default_params_file
from mwip_ros.policy import LinearPolicy
from mwip_ros.yamlio import FileTooLarge, NotRegularFile, YamlRefused, load_yaml, open_regular, read_bytes

pytestmark = pytest.mark.unit

PAPER = default_params_file()


@pytest.fixture()
def fifo(tmp_path):
    path = tmp_path / "pipe.json"
    os.mkfifo(path)
    yield path
    # a reader that blocked on it (the old code) is let go: a writer opens it and closes at once
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
    except OSError:
        pass


def _within(seconds, call):
    """``call()``'s result or exception, or AssertionError if it does not return within ``seconds`` (a blocked
    open: the thread is left to the fixture that unblocks it)."""
    out = {}

    def run():
        try:
            out["value"] = call()
        except BaseException as exc:   # noqa: BLE001 - handed to the test
            out["error"] = exc
    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(seconds)
    assert not t.is_alive(), f"still reading after {seconds} s"
    if "error" in out:
        raise out["error"]
    return out["value"]


@pytest.mark.parametrize("reader", ["open_regular", "read_bytes", "load_yaml"])
def test_a_fifo_and_a_device_are_refused_unread(fifo, reader):
    calls = {"open_regular": lambda p: open_regular(p, "file").close(),
             "read_bytes": lambda p: read_bytes(p, 1024, "file"),
             "load_yaml": lambda p: load_yaml(Path(p), "parameter file")}
    for path, kind in ((fifo, "a FIFO"), ("/dev/zero", "a character device"), (fifo.parent, "a directory")):
        with pytest.raises(NotRegularFile, match=kind):
            _within(2.0, lambda: calls[reader](path))


def test_read_bytes_bounds_a_regular_file(tmp_path):
    f = tmp_path / "big"
    f.write_bytes(b"x" * 2000)
    assert read_bytes(f, 2000) == b"x" * 2000
    with pytest.raises(FileTooLarge, match="at most"):
        read_bytes(f, 1999)
    y = tmp_path / "big.yaml"
    y.write_bytes(b"#" * (4 * 1024 * 1024 + 1))
    with pytest.raises(YamlRefused, match="at most 4.0 MiB"):   # the YAML reader's bound, through the same opener
        load_yaml(y)


def _policy(tmp_path, doc) -> Path:
    p = tmp_path / "p.json"
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return p


GOOD = {"policy": "linear", "features": ["theta_b", "dtheta_b", "dtheta_w"], "w": [9.6, 1.2, -0.04], "scale": 256.0}


@pytest.mark.parametrize("change, words", [
    ({"w": "123"}, "w must be a list of three finite numbers"),              # was taken as (1, 2, 3)
    ({"w": [1, 2, True]}, "w must be a list"),
    ({"w": [1e300, 0, 0]}, "beyond"),
    ({"features": ["dtheta_w", "theta_b", "dtheta_b"]}, "features must be"),  # was ignored
    ({"scale": 1e7}, "scale must be"),
    ({"scale": "256"}, "scale must be"),
    ({"policy": "mlp"}, "policy must be 'linear'"),
])
def test_a_policy_file_that_is_not_a_linear_policy_is_refused_naming_policy_file(tmp_path, change, words):
    with pytest.raises(ValueError, match="policy.file") as exc:
        LinearPolicy.load(_policy(tmp_path, {**GOOD, **change}))
    assert words in str(exc.value) and "\n" not in str(exc.value)


def test_a_deeply_nested_or_large_policy_file_is_one_line(tmp_path):
    with pytest.raises(ValueError, match="policy.file"):   # was RecursionError
        LinearPolicy.load(_policy(tmp_path, "[" * 30000 + "]" * 30000))
    with pytest.raises(ValueError, match="at most 64.0 KiB|at most 65,536 bytes"):
        LinearPolicy.load(_policy(tmp_path, " " * 70000 + json.dumps(GOOD)))


def test_a_policy_with_a_scale_no_drive_gives_is_said(tmp_path):
    p = LinearPolicy.load(_policy(tmp_path, {**GOOD, "scale": 1e5}))   # was silent: 100,000 N m
    assert p.scale == 1e5 and "scale = 100000 N m" in p.warnings()[0]
    assert LinearPolicy.load(_policy(tmp_path, GOOD)).warnings() == []


def _mwip_sim(tmp_path, *args, timeout=60):
    env = dict(os.environ, MWIP_ROS_LAWS="mwip_ros.policy_law")
    return subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, env=env, cwd=tmp_path)


@pytest.mark.alone   # "at once" is on the wall clock: not beside other work of its class
@pytest.mark.cli
@pytest.mark.parametrize("target", ["fifo", "/dev/zero"])
def test_mwip_sim_refuses_a_policy_file_that_is_not_a_regular_file_at_once(tmp_path, fifo, target):
    path = fifo if target == "fifo" else target
    overlay = tmp_path / "policy.yaml"
    overlay.write_text(f"dscndo_controller:\n  ros__parameters:\n    law: policy\n    use_observer: false\n"
                       f"    policy:\n      file: {path}\n")
    t0 = time.monotonic()
    r = _mwip_sim(tmp_path, "--params", PAPER, overlay, "--duration", "0.1", "-q", timeout=30)
    assert r.returncode == 2 and "policy.file" in r.stderr and "not a regular file" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert time.monotonic() - t0 < 25


@pytest.mark.cli
def test_a_parameter_file_that_is_a_fifo_is_refused_in_one_line(tmp_path, fifo):
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", "--params", str(fifo), "--duration", "0.1", "-q"],
                       capture_output=True, text=True, timeout=30, cwd=tmp_path)
    assert r.returncode == 2 and "not a regular file" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_a_csv_that_is_a_fifo_is_refused(fifo):
    from mwip_ros.runs import read_csv
    with pytest.raises(ValueError, match="not a regular file"):
        _within(2.0, lambda: read_csv(fifo))


@pytest.mark.cli
@pytest.mark.parametrize("cli", ["bag_repair", "report"])
def test_a_bag_with_a_fifo_for_a_file_is_refused_in_one_line(tmp_path, cli):
    bag = tmp_path / "bag"
    bag.mkdir()
    os.mkfifo(bag / "bag_0.mcap")
    try:
        args = [str(bag)] + (["--out", str(tmp_path / "out")] if cli == "report" else [])
        r = subprocess.run([sys.executable, "-m", f"mwip_ros.cli.{cli}", *args], capture_output=True, text=True,
                           timeout=60, cwd=tmp_path)
    finally:
        try:
            os.close(os.open(bag / "bag_0.mcap", os.O_WRONLY | os.O_NONBLOCK))
        except OSError:
            pass
    assert r.returncode == 2 and "not a regular file" in r.stderr, (r.returncode, r.stderr)
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
