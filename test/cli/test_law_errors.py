"""A law plug-in's mistakes end in one line and exit 2, never a traceback (issue 30, item 8): a module that cannot be
imported or raises while importing (mwip_sim, mwip_sweep, mwip_tune, mwip_report, mwip_theorem, mwip_identify),
a law that raises in mwip_sim or inside a sweep (named with its scenario and its own error, not numpy's)."""
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from mwip_ros.params.paths import default_params_file
from mwip_ros.sweep.results import read_results

pytestmark = pytest.mark.unit

TEST_DIR = Path(__file__).resolve().parents[1]
T_BAD = 0.5   # test/bad_laws.py: AFTER = 100 periods of 5 ms


def _env(plugins):
    env = dict(os.environ, MWIP_ROS_LAWS=plugins)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(TEST_DIR), env.get("PYTHONPATH", "")) if p)
    return env


def _run(plugins, *args, timeout=300):
    return subprocess.run([sys.executable, "-m", *map(str, args)], env=_env(plugins), capture_output=True, text=True,
                          timeout=timeout)


def _spec(path, controllers, values=(-0.1, 0.0, 0.1)):
    path.write_text(yaml.safe_dump({"base": str(default_params_file()), "controllers": controllers,
                                    "duration_s": 1.0, "metrics_window_s": [0.2, 1.0], "seed": 5, "samples": 1,
                                    "vary": {"plant_sim.initial.theta_b": {"values": list(values)}}}))
    return path


def _one_line(r):
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    return r.stderr


@pytest.mark.parametrize("plugins, words", [
    ("no_such_law_module", ("MWIP_ROS_LAWS='no_such_law_module'", "cannot import the law module 'no_such_law_module'",
                            "No module named 'no_such_law_module'")),
    ("trivial_law:broken_plugin", ("the law module 'broken_plugin' raised while importing",
                                   "RuntimeError: broken_plugin's own import error"))])
@pytest.mark.cli
def test_a_plugin_that_fails_to_import_stops_every_tool_in_one_line(tmp_path, plugins, words):
    spec = _spec(tmp_path / "s.yaml", ["dscndo"])
    for prog, args in (("mwip_sim", ("mwip_ros.cli.sim", "--duration", "0.1", "-q")),
                       ("mwip_sweep", ("mwip_ros.cli.sweep", spec, "--out", tmp_path / "out")),
                       ("mwip_tune", ("mwip_ros.cli.tune", spec, "--controller", "dscndo", "--tune", "k1", "--out",
                                      tmp_path / "t.yaml")),
                       ("mwip_report", ("mwip_ros.cli.report", tmp_path / "none.csv", "--out", tmp_path / "rep")),
                       ("mwip_theorem", ("mwip_ros.cli.theorem",)),
                       ("mwip_identify", ("mwip_ros.cli.identify", tmp_path / "none.csv", "--out",
                                          tmp_path / "id.yaml"))):
        line = _one_line(_run(plugins, *args))
        assert line.startswith(f"{prog}: error: "), line
        for w in words:
            assert w in line, (prog, w, line)
    assert not (tmp_path / "out").exists() and not (tmp_path / "t.yaml").exists()


@pytest.mark.cli
def test_a_law_that_raises_in_mwip_sim_is_one_line_naming_it():
    line = _one_line(_run("bad_laws", "mwip_ros.cli.sim", "--controller", "raising", "--duration", "1", "-q"))
    assert line.strip() == (f"mwip_sim: error: the law 'raising' raised at t = {T_BAD:.3f} s: "
                            "RuntimeError: raising law's own error")


@pytest.mark.cli
def test_a_law_that_raises_inside_a_sweep_is_named_with_its_scenario_not_as_numpys_error(tmp_path):
    spec = _spec(tmp_path / "s.yaml", ["raising"])
    r = _run("bad_laws", "mwip_ros.cli.sweep", spec, "--out", tmp_path / "out", "--workers", "1", "--no-figures")
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and "truth value" not in r.stderr
    assert (f"mwip_sweep: error: the law 'raising' raised at t = {T_BAD:.3f} s in scenario 0: "
            "RuntimeError: raising law's own error") in r.stderr


@pytest.mark.cli
def test_a_sweep_never_scores_a_law_commanding_nan_or_1e300_upright(tmp_path):
    spec = _spec(tmp_path / "s.yaml", ["nan_cmd", "huge_cmd"])
    r = _run("bad_laws", "mwip_ros.cli.sweep", spec, "--out", tmp_path / "out", "--workers", "1", "--no-figures")
    assert r.returncode == 0, r.stderr
    cols = read_results(tmp_path / "out" / "results.csv")
    assert cols["upright"] == [False] * 6 and cols["t_fall"] == [T_BAD] * 6
    assert cols["failure"] == ["bad_command"] * 6
    md = (tmp_path / "out" / "summary.md").read_text()
    for law in ("nan_cmd", "huge_cmd"):
        assert f"| {law} | 0/3 (0.0 %; 3 bad_command) |" in md
