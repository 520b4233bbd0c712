"""Optional packages (mwip_ros/optional.py) fail only the feature that needs them, in one line naming the package
and how to install it; every one is declared in package.xml.  Each child process runs without the package
(test/without.py)."""
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

from without import env_without

from mwip_ros.optional import OPTIONAL, MissingPackage, required

REPO = Path(__file__).resolve().parents[1]


def run(tmp_path, hidden, *args, timeout=120):
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, timeout=timeout,
                          env=env_without(tmp_path, *hidden), cwd=tmp_path)


def one_line_naming(text: str, pip: str, key: str) -> None:
    lines = text.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in text, text
    assert f"pip install '{pip}'" in lines[0] and key in lines[0], text


@pytest.mark.cli
def test_mwip_sim_runs_dsc_and_dscndo_without_daqp(tmp_path):
    r = run(tmp_path, ["daqp"], "-m", "mwip_ros.cli.sim", "--compare", "dsc", "dscndo", "--duration", "1",
            "--window", "0.5", "1", "-q")
    assert r.returncode == 0, r.stderr
    assert "dsc: stayed upright" in r.stdout and "dscndo: stayed upright" in r.stdout, r.stdout


@pytest.mark.cli
@pytest.mark.parametrize("args", [["--controller", "mpc"], ["--compare", "dsc", "mpc_ndo"]])
def test_mwip_sim_refuses_mpc_without_daqp_in_one_line_exit_2(tmp_path, args):
    r = run(tmp_path, ["daqp"], "-m", "mwip_ros.cli.sim", *args, "--duration", "1", "-q")
    assert r.returncode == 2, r.stderr
    one_line_naming(r.stderr, "daqp", "python3-daqp-pip")
    assert "mwip_sim: error: the law mpc" in r.stderr and r.stdout == "", r.stdout


@pytest.mark.cli
def test_the_controllers_laws_are_built_without_daqp_but_mpc(tmp_path):
    """What dscndo_controller builds at start-up (core.laws.instances): every family but mpc, whose refusal
    names daqp."""
    code = (
        "from mwip_ros import params as P\n"
        "from mwip_ros.core import laws\n"
        "from mwip_ros.params.paths import default_params_file\n"
        "v = P.merged_values(P.load_param_files([default_params_file()]))\n"
        "built = laws.instances(v, P.physical(v, 'nominal'), P.period(v))\n"
        "print(sorted(built)); print(sorted(f for f in laws.families() if laws.lookup(f, False)))\n"
        "print(laws.unavailable(laws.get('mpc_ndo')))\n"
        "print(built['dsc'].step((0.0, 0.1, 0.0, 0.0), None)[0])\n")
    r = run(tmp_path, ["daqp"], "-c", code)
    assert r.returncode == 0, r.stderr
    built, every, refusal, u = r.stdout.splitlines()
    assert eval(built) == [f for f in eval(every) if f != "mpc"] and "dsc" in eval(built), r.stdout
    assert "the law mpc_ndo needs the Python package daqp" in refusal and "python3-daqp-pip" in refusal
    assert float(u) != 0.0


@pytest.mark.cli
def test_mwip_sweep_runs_without_numba_and_says_so(tmp_path):
    from mwip_ros.params.paths import default_params_file
    spec = tmp_path / "s.yaml"
    spec.write_text(yaml.safe_dump({"base": str(default_params_file()), "controllers": ["dsc", "dscndo"],
                                    "duration_s": 1.0, "metrics_window_s": [0.5, 1.0], "seed": 3, "samples": 3,
                                    "vary": {"plant_sim.actual.m_b": {"scale": [0.9, 1.1]}}}))
    r = run(tmp_path, ["numba"], "-m", "mwip_ros.cli.sweep", spec, "--out", tmp_path / "out", "--workers", "1",
            "--no-figures")
    assert r.returncode == 0, r.stderr
    warning = [line for line in r.stderr.splitlines() if "warning" in line]
    assert len(warning) == 1 and "numba" in warning[0] and "python3-numba" in warning[0], r.stderr
    rows = (tmp_path / "out" / "results.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 6, rows


@pytest.mark.parametrize("hidden, args, pip, key", [
    ("daqp", [], "daqp", "python3-daqp-pip"),
    ("dask", ["--dask", "local:1"], "dask[distributed]", "python3-dask-pip")])
@pytest.mark.cli
def test_mwip_sweep_refuses_a_missing_package_before_any_work(tmp_path, hidden, args, pip, key):
    from mwip_ros.params.paths import default_params_file
    spec = tmp_path / "s.yaml"
    spec.write_text(yaml.safe_dump({"base": str(default_params_file()), "controllers": ["dsc", "mpc"],
                                    "duration_s": 1.0, "metrics_window_s": [0.5, 1.0], "samples": 2,
                                    "vary": {"plant_sim.actual.m_b": {"scale": [0.9, 1.1]}}}))
    r = run(tmp_path, [hidden], "-m", "mwip_ros.cli.sweep", spec, "--out", tmp_path / "out", *args)
    assert r.returncode == 2, r.stderr
    one_line_naming(r.stderr, pip, key)
    assert not (tmp_path / "out" / "results.csv").exists()


@pytest.mark.unit
def test_required_names_the_package_the_feature_and_the_rosdep_key(monkeypatch):
    monkeypatch.setitem(sys.modules, "foxglove", None)
    with pytest.raises(MissingPackage) as err:
        with required("foxglove", "the live view"):
            import foxglove.websocket  # noqa: F401
    one_line_naming(str(err.value), "foxglove-sdk", "python3-foxglove-sdk-pip")
    assert str(err.value).startswith("the live view needs the Python package foxglove-sdk")
    with required("math"):
        import math
    assert math.sqrt(4.0) == 2.0


@pytest.mark.unit
def test_every_optional_package_is_declared_and_every_pip_key_is_defined_for_rosdep():
    root = ET.parse(REPO / "package.xml").getroot()
    declared = {e.text.strip() for e in root if e.tag in ("depend", "exec_depend")}
    defined = yaml.safe_load((REPO / "rosdep" / "mwip_ros.yaml").read_text())
    for module, pkg in OPTIONAL.items():
        assert pkg.rosdep in declared, (module, pkg.rosdep)
    for key in sorted(k for k in declared if k.endswith("-pip")):
        assert key in defined and defined[key]["ubuntu"]["pip"]["packages"], key


@pytest.mark.cli
def test_mwip_tune_refuses_mpc_without_daqp_in_one_line(tmp_path):
    r = run(tmp_path, ["daqp"], "-m", "mwip_ros.cli.tune", REPO / "config" / "sweeps" / "tune_dscndo.yaml",
            "--controller", "mpc", "--tune", "mpc.R", "--out", tmp_path / "t.yaml")
    assert r.returncode == 2, r.stderr
    one_line_naming(r.stderr, "daqp", "python3-daqp-pip")
    assert not (tmp_path / "t.yaml").exists()
