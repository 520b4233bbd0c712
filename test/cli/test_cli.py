"""mwip_sim and mwip_theorem as a user runs them."""
import csv
import subprocess
import sys

import pytest

from mwip_ros.params.paths import default_params_file
from mwip_ros.runs import read_csv
from mwip_ros.core.control.lqr import NO_DESIGN

pytestmark = pytest.mark.unit

REQUIRED = ["t", "theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_hat1", "tau_hat2", "tau_d1", "tau_d2"]


def run(*args):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, timeout=300)


@pytest.mark.cli
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


@pytest.mark.cli
def test_mwip_sim_bad_param_file_names_the_key(tmp_path):
    bad = default_params_file().read_text().replace("tau4: 0.1", "tau4: -0.1")
    f = tmp_path / "bad.yaml"
    f.write_text(bad)
    r = run("mwip_ros.cli.sim", "--params", str(f), "--duration", "0.1")
    assert r.returncode == 2
    assert "dscndo_controller.tau4" in r.stderr and "> 0" in r.stderr


@pytest.mark.cli
def test_mwip_sim_reports_a_fall(tmp_path):
    text = default_params_file().read_text().replace("k1: 6.0", "k1: 0.05").replace("k2: 6.0", "k2: 0.05")
    f = tmp_path / "weak.yaml"
    f.write_text(text)
    r = run("mwip_ros.cli.sim", "--params", str(f), "--controller", "dsc", "--duration", "5")
    assert r.returncode == 3 and "dsc: FELL at t = " in r.stdout   # 3: a fall, as plant_sim and run_experiment.sh
    assert "VIOLATED" in r.stderr


@pytest.mark.cli
def test_mwip_theorem_table():
    r = run("mwip_ros.cli.theorem")
    assert r.returncode == 0
    for k in ("a1", "a2", "a3", "a4", "a5", "gamma"):
        assert k in r.stdout
    assert "hold" in r.stdout


@pytest.mark.cli
def test_help_texts():
    for mod in ("mwip_ros.cli.sim", "mwip_ros.cli.theorem"):
        r = run(mod, "--help")
        assert r.returncode == 0 and "usage" in r.stdout


@pytest.mark.cli
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


def _one_error_line(r, *words):
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.splitlines()) == 1, r.stderr
    for w in words:
        assert w in r.stderr, (w, r.stderr)


@pytest.mark.cli
@pytest.mark.parametrize("mod, prog", [("mwip_ros.cli.sim", "mwip_sim"), ("mwip_ros.cli.theorem", "mwip_theorem")])
def test_a_missing_or_directory_params_file_names_the_option_the_user_typed(tmp_path, mod, prog):
    r = run(mod, "--params", str(tmp_path / "missing.yaml"))
    _one_error_line(r, f"{prog}: error: parameter '--params': no such file", "missing.yaml")
    assert "--params-file" not in r.stderr     # that is the nodes' option, not this tool's
    r = run(mod, "--params", str(default_params_file()), str(tmp_path))
    _one_error_line(r, "'--params'", "is a directory")


@pytest.mark.cli
@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e9", "0", "-1"])
def test_mwip_sim_refuses_a_duration_outside_the_parameter_files_range(tmp_path, value):
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", f"--duration={value}", "-q", "--csv",
                        str(tmp_path / "r.csv")], capture_output=True, text=True, timeout=60)
    _one_error_line(r, "--duration must be > 0 and <= 1e+07 s")
    assert not (tmp_path / "r.csv").exists()


@pytest.mark.cli
def test_mwip_sim_checks_its_outputs_before_simulating_and_overwrites_only_with_force(tmp_path):
    old_csv, old_png = tmp_path / "old.csv", tmp_path / "old.png"
    old_csv.write_text("mine\n")
    old_png.write_text("mine\n")
    (tmp_path / "afile").write_text("a file\n")
    short = ("--duration", "0.5", "--window", "0", "0.5", "-q")
    for args, words in ((("--csv", old_csv), f"--csv {old_csv} exists; choose another name or add --force"),
                        (("--plot", old_png), f"--plot {old_png} exists"),
                        (("--csv", tmp_path), "is a directory"),
                        (("--plot", tmp_path / "afile" / "f.png"), "is not a directory"),
                        (("--csv", tmp_path / "nodir" / "r.csv"), "does not exist")):
        _one_error_line(run("mwip_ros.cli.sim", *short, *map(str, args)), words)
    # --compare: each suffixed file is checked before the first run, so none is written
    (tmp_path / "c_dscndo.csv").write_text("mine\n")
    _one_error_line(run("mwip_ros.cli.sim", "--compare", *short, "--csv", str(tmp_path / "c.csv")),
                    f"--csv {tmp_path / 'c_dscndo.csv'} exists")
    assert not (tmp_path / "c_dsc.csv").exists()
    assert old_csv.read_text() == old_png.read_text() == (tmp_path / "c_dscndo.csv").read_text() == "mine\n"
    r = run("mwip_ros.cli.sim", *short, "--csv", str(old_csv), "--force")
    assert r.returncode == 0, r.stderr
    assert len(read_csv(old_csv)) == 101


@pytest.mark.parametrize("Q, words", [("[-1.0, 10.0, 1.0]", ">= 0"), ("[0.0, 0.0, 0.0]", NO_DESIGN),
                                      ("[1.0e300, 10.0, 1.0]", "<= 1e+12")])
@pytest.mark.cli
def test_a_bad_mpc_state_weight_is_one_line_naming_the_key_and_exit_2_whatever_the_law(tmp_path, Q, words):
    """mpc.Q is checked at start-up by every registered law's design (as lqr.Q is), not when MPC first steps:
    old code ended in exit 1 with an LqrDesignError traceback (--controller mpc) or ran on (--controller dsc)."""
    f = tmp_path / "q.yaml"
    f.write_text(default_params_file().read_text().replace("      Q: [100.0, 10.0, 1.0]  # weights on theta_b, "
                                                           "theta_b', theta_w' (the diagonal, >= 0), as lqr.Q",
                                                           f"      Q: {Q}"))
    assert Q in f.read_text()
    for law in ("mpc", "dsc"):
        r = run("mwip_ros.cli.sim", "--params", str(f), "--controller", law, "--duration", "0.1", "-q")
        _one_error_line(r, "'mpc.Q'", words)


@pytest.mark.parametrize("section, key, value, law, warned", [
    ("dscndo_controller", "mpc", "{u_max: 1.0}", "mpc", True),
    ("dscndo_controller", "mpc", "{u_max: 20.0}", "mpc_ndo", True),
    ("dscndo_controller", "mpc", "{u_max: 20.0}", "dscndo", False),   # not the law that runs: its limit says nothing
    ("dscndo_controller", "mpc", "{u_max: 120.0}", "mpc", False),
    ("plant_sim", "torque_limit", "20.0", "dscndo", True)])
@pytest.mark.cli
def test_a_torque_limit_too_weak_for_the_initial_tilt_is_warned_of_as_the_motor_is(tmp_path, section, key, value, law,
                                                                                   warned):
    """mpc.u_max and torque_limit below the torque that holds the body at the initial tilt: the run falls, and
    mwip_sim says so first with the motor overlay's figures (core.plants.drive.limit_warning); old code: no warning."""
    f = tmp_path / "w.yaml"
    f.write_text(f"{section}:\n  ros__parameters:\n    {key}: {value}\n")
    r = run("mwip_ros.cli.sim", "--params", str(default_params_file()), str(f), "--controller", law,
            "--duration", "1.0", "-q")
    lines = [ln for ln in r.stderr.splitlines() if "warning" in ln]
    name = "mpc.u_max" if key == "mpc" else key
    if warned:
        assert len(lines) == 1 and f"warning: {name} = " in lines[0] and "initial tilt" in lines[0], r.stderr
        assert "80.08 N m that holds the body" in lines[0] and "cannot turn the body back" in lines[0]
    else:
        assert lines == [], r.stderr
