"""One check of every output the tools write (mwip_ros.cli.outputs), and mwip_sweep's outputs and
--write-params on hostile places and hostile results: one line and exit 2, never a traceback, nothing
left behind, /dev/null never removed."""
import csv
import json
import os
import subprocess
import sys

import pytest

from mwip_ros.cli import outputs

from test_sweep import write_spec   # noqa: E402  (test/cli is on sys.path under pytest)

pytestmark = pytest.mark.unit


def sweep(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "mwip_ros.cli.sweep", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout)


def one_line(r, *words):
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    for w in words:
        assert w in r.stderr, (w, r.stderr)


# --- the helper ---------------------------------------------------------------------------------

def test_a_file_output_is_refused_for_what_cannot_be_a_file(tmp_path):
    (tmp_path / "f").write_text("x")
    (tmp_path / "old.csv").write_text("x")
    os.mkfifo(tmp_path / "fifo")
    cases = {tmp_path: "is a directory", tmp_path / "f" / "x.csv": "is not a directory",
             tmp_path / "f" / "a" / "x.csv": f"{tmp_path / 'f'} is not a directory",
             tmp_path / "none" / "x.csv": "does not exist", "/dev/null": "is a device, not a regular file",
             tmp_path / "fifo": "is a FIFO", "/proc/x.csv": "cannot create a file in /proc",
             tmp_path / "old.csv": "exists; choose another name or add --force"}
    for path, words in cases.items():
        reason = outputs.refuse_existing(path, False, "--csv")
        assert reason and reason.startswith(f"--csv {path}") and words in reason, (path, reason)
    assert outputs.refuse_existing(tmp_path / "old.csv", True, "--csv") is None
    assert outputs.refuse_existing("/dev/null", True, "--csv")           # --force never writes through a device
    assert outputs.refuse_existing(tmp_path / "new.csv", False, "--csv") is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f", "fifo", "old.csv"]   # the probe left nothing


def test_a_directory_output_is_refused_for_what_cannot_hold_it_and_force_removes_only_its_files(tmp_path):
    (tmp_path / "f").write_text("x")
    names = ("a.csv", "b.png")
    for path, words in {"/dev/null": "is a device, not a directory", tmp_path / "f": "is a file, not a directory",
                        tmp_path / "f" / "sub": f"{tmp_path / 'f'} is not a directory",
                        "/proc/x": "cannot create it in /proc", "/proc/x/y": "cannot create it in /proc"}.items():
        reason = outputs.refuse_directory(path, names, True, "--out")
        assert reason and reason.startswith(f"--out {path}") and words in reason, (path, reason)
    out = tmp_path / "out"
    assert outputs.refuse_directory(out / "deep", names, False, "--out") is None and not out.exists()
    out.mkdir()
    (out / "a.csv").write_text("old")
    (out / "mine.txt").write_text("mine")
    reason = outputs.refuse_directory(out, names, False, "--out", "a report")
    assert "already holds a report (a.csv)" in reason and "--force" in reason
    assert outputs.refuse_directory(out, names, True, "--out") is None
    assert outputs.remove_stale(out, names) is None
    assert sorted(p.name for p in out.iterdir()) == ["mine.txt"]
    (out / "b.png").mkdir()
    assert "--force removes only regular files" in outputs.refuse_directory(out, names, True, "--out")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only directory")
def test_an_unwritable_directory_is_refused(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        assert "not writable" in outputs.refuse_existing(ro / "x.csv", True, "--csv")
        assert "cannot write into it" in outputs.refuse_directory(ro, ("a",), True, "--out")
    finally:
        ro.chmod(0o700)


# --- mwip_sweep --out ----------------------------------------------------------------------------

@pytest.mark.parametrize("out, words", [
    ("/dev/null", "--out /dev/null is a device, not a directory"),
    ("FILE/sub", "FILE is not a directory"),
    ("FILE", "is a file, not a directory"),
    ("/proc/x", "--out /proc/x: cannot create it in /proc"),
])
@pytest.mark.cli
def test_mwip_sweep_out_where_no_directory_can_be_is_one_line(tmp_path, out, words):
    spec = write_spec(tmp_path / "s.yaml", samples=1, vary={})
    (tmp_path / "FILE").write_text("a file\n")
    target = out if out.startswith("/") else tmp_path / out
    one_line(sweep(spec, "--out", target, "--workers", "1", "--force"), words)
    assert (tmp_path / "FILE").read_text() == "a file\n" and os.path.exists("/dev/null")


# --- mwip_sweep --write-params on a results directory edited by hand ----------------------------------

@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    d = tmp_path_factory.mktemp("sw")
    spec = write_spec(d / "s.yaml", samples=1, duration_s=1.0, metrics_window_s=[0.5, 1.0],
                      vary={"plant_sim.actual.m_b": {"scale": [0.7, 1.3]}, "dscndo_controller.k1": {"grid": [4.0]}})
    r = sweep(spec, "--out", d / "out", "--workers", "1", "--no-figures", "-q")
    assert r.returncode == 0, r.stderr
    return d / "out"


def _edit(src, dst, header=None, cell=None, info=None):
    import shutil
    shutil.copytree(src, dst)
    with open(dst / "results.csv", newline="") as f:
        table = list(csv.reader(f))
    if header is not None:
        table[0] = header(table[0])
    if cell is not None:
        col, value = cell
        table[1][table[0].index(col)] = value
    with open(dst / "results.csv", "w", newline="") as f:
        csv.writer(f).writerows(table)
    if info is not None:
        doc = json.loads((dst / "sweep.json").read_text())
        info(doc)
        (dst / "sweep.json").write_text(json.dumps(doc))
    return dst


M_B = "plant_sim.actual.m_b"


@pytest.mark.parametrize("name, edit, words", [
    ("cut_header", dict(header=lambda h: h[:4]), "the header has no 'upright'"),
    ("no_controller", dict(header=lambda h: [x if x != "controller" else "law" for x in h]),
     "the header has no 'controller' column"),
    ("huge", dict(cell=(M_B, "1e308")), "parameter 'plant_sim.actual.m_b': must be <="),
    ("list", dict(cell=(M_B, "[1.0, 2.0]")), "parameter 'plant_sim.actual.m_b': expected a floating-point number"),
    ("field", dict(cell=(M_B, "1" * 200_000)), "field larger than field limit"),
    ("no_axes", dict(info=lambda d: d.pop("axes")), "sweep.json has no 'axes'"),
    ("bad_axes", dict(info=lambda d: d.update(axes=[{"key": 3}])), "'axes' must be a list of"),
    ("no_column", dict(info=lambda d: d["axes"].append({"key": "plant_sim.actual.l", "section": "plant_sim",
                                                         "name": "actual.l", "type": "double"})),
     "has no column 'plant_sim.actual.l'"),
    ("long_duration", dict(info=lambda d: d.update(duration_s=1e308)), "plant_sim.duration_s"),
])
@pytest.mark.cli
def test_write_params_on_an_edited_results_directory_is_one_line(finished, tmp_path, name, edit, words):
    d = _edit(finished, tmp_path / name, **edit)
    f = tmp_path / "s0.yaml"
    r = sweep("--results", d, "--scenario", 0, "--controller", "dsc", "--write-params", f)
    one_line(r, words)
    assert not f.exists() and not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.cli
def test_write_params_never_removes_or_writes_dev_null(finished):
    r = sweep("--results", finished, "--scenario", 0, "--write-params", "/dev/null", "--force")
    one_line(r, "--write-params /dev/null is a device, not a regular file")
    assert os.path.exists("/dev/null") and not os.path.isfile("/dev/null")
