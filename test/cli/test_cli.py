"""mwip_sim and mwip_theorem as a user runs them."""
import csv
import subprocess
import sys

import pytest

from mwip_ros.params.paths import default_params_file
from mwip_ros.runs import read_csv

REQUIRED = ["t", "theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_hat1", "tau_hat2", "tau_d1", "tau_d2"]


def run(*args):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, timeout=300)


def test_mwip_sim_compare_writes_csv_plot_and_metrics(tmp_path):
    r = run("mwip_ros.cli.sim", "--compare", "--csv", str(tmp_path / "run.csv"), "--plot", str(tmp_path / "f.png"))
    assert r.returncode == 0, r.stderr
    for label in ("dsc", "dscndo"):
        f = tmp_path / f"run_{label}.csv"
        with open(f) as fh:
            header = next(csv.reader(fh))
        assert header[:len(REQUIRED)] == REQUIRED
        res = read_csv(f)
        assert len(res) == 2001 and res.t[-1] == pytest.approx(10.0)
    assert (tmp_path / "f.png").stat().st_size > 10_000
    assert "dsc " in r.stdout and "dscndo" in r.stdout and "x smaller" in r.stdout
    assert "stayed upright" in r.stdout and "Theorem 2" in r.stderr


def test_mwip_sim_bad_param_file_names_the_key(tmp_path):
    bad = default_params_file().read_text().replace("tau4: 0.1", "tau4: -0.1")
    f = tmp_path / "bad.yaml"
    f.write_text(bad)
    r = run("mwip_ros.cli.sim", "--params", str(f), "--duration", "0.1")
    assert r.returncode == 2
    assert "dscndo_controller.tau4" in r.stderr and "> 0" in r.stderr


def test_mwip_sim_reports_a_fall(tmp_path):
    text = default_params_file().read_text().replace("k1: 6.0", "k1: 0.05").replace("k2: 6.0", "k2: 0.05")
    f = tmp_path / "weak.yaml"
    f.write_text(text)
    r = run("mwip_ros.cli.sim", "--params", str(f), "--controller", "dsc", "--duration", "5")
    assert r.returncode == 1 and "FELL" in r.stdout
    assert "VIOLATED" in r.stderr


def test_mwip_theorem_table():
    r = run("mwip_ros.cli.theorem")
    assert r.returncode == 0
    for k in ("a1", "a2", "a3", "a4", "a5", "gamma"):
        assert k in r.stdout
    assert "hold" in r.stdout


def test_help_texts():
    for mod in ("mwip_ros.cli.sim", "mwip_ros.cli.theorem"):
        r = run(mod, "--help")
        assert r.returncode == 0 and "usage" in r.stdout


def test_mwip_sim_compares_the_four_laws_and_prints_the_lqr_gain(tmp_path):
    r = run("mwip_ros.cli.sim", "--compare", "dsc", "dscndo", "lqr", "lqr_ndo", "--duration", "6", "--window", "3", "6",
            "--csv", str(tmp_path / "r.csv"))
    assert r.returncode == 0, r.stderr
    rows = {line.split()[0]: line.split() for line in r.stdout.splitlines() if line.split()[:1] and
            line.split()[0] in ("dsc", "dscndo", "lqr", "lqr_ndo") and "yes" in line}
    assert set(rows) == {"dsc", "dscndo", "lqr", "lqr_ndo"}
    assert "LQR gain K = [" in r.stderr and "lqr.R = 0.01" in r.stderr
    p2p = {k: float(v[2]) for k, v in rows.items()}
    assert p2p["lqr_ndo"] < p2p["lqr"] and p2p["dscndo"] < p2p["dsc"]   # the observer term helps both laws
    assert all((tmp_path / f"r_{k}.csv").is_file() for k in rows)
    bad = tmp_path / "bad.yaml"
    bad.write_text(default_params_file().read_text().replace("Q: [100.0, 10.0, 1.0]", "Q: [100.0, 10.0, 0.0]"))
    r = run("mwip_ros.cli.sim", "--params", str(bad), "--controller", "lqr")
    assert r.returncode == 2 and "lqr.Q" in r.stderr and "Traceback" not in r.stderr
