"""run_experiment.sh's plan (mwip_ros/cli/experiment.py): the laws it runs come from the registry and the user's
files, --duration takes what mwip_sim takes, and --sensors raw leaves the user's keys standing."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mwip_ros.cli import experiment
from mwip_ros.core import laws

REPO = Path(__file__).resolve().parents[2]
PAPER = str(REPO / "config" / "paper.yaml")
RAW = str(REPO / "config" / "sensors_raw_realistic.yaml")

pytestmark = pytest.mark.unit


def _file(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def _runs(lines):
    return [tuple(line.split()[1:]) for line in lines if line.startswith("run ")]


def test_every_registered_law_is_accepted_by_name():
    for name in laws.names():
        law = laws.get(name)
        assert _runs(experiment.plan(["--params", PAPER, "--laws", name])) == [
            (name, law.family, str(law.observer).lower())]
    assert _runs(experiment.plan(["--params", PAPER, "--laws", "smc,mpc_ndo,smc"])) == [
        ("smc", "smc", "false"), ("mpc_ndo", "mpc", "true")]


@pytest.mark.parametrize("spec", ["dsc,pid", "dsc,,lqr", ","])
def test_an_unknown_or_empty_law_is_one_line_naming_the_known_ones(spec):
    with pytest.raises(experiment.PlanError, match="--laws takes") as e:
        experiment.plan(["--params", PAPER, "--laws", spec])
    assert "mpc" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.cli
def test_a_plug_in_law_from_MWIP_ROS_LAWS_is_accepted():
    env = dict(os.environ, MWIP_ROS_LAWS="trivial_law",
               PYTHONPATH=os.pathsep.join([str(REPO / "test"), os.environ.get("PYTHONPATH", "")]))
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.experiment", "--params", PAPER, "--laws",
                        "trivial_ndo,dsc"], capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[-2:] == ["run trivial_ndo trivial true", "run dsc dsc false"]


def test_without_laws_the_files_law_runs_without_and_with_the_observer(tmp_path, capsys):
    assert _runs(experiment.plan(["--params", PAPER])) == [("dsc", "dsc", "false"), ("dscndo", "dsc", "true")]
    assert capsys.readouterr().err == ""   # the paper's default: nothing to say
    smc = _file(tmp_path, "smc.yaml", "dscndo_controller:\n  ros__parameters:\n    law: smc\n    use_observer: false\n")
    assert _runs(experiment.plan(["--params", PAPER, smc])) == [("smc", "smc", "false"), ("smc_ndo", "smc", "true")]
    assert "the parameter files' law 'smc'" in capsys.readouterr().err
    # --laws replaces the file's law, and says so
    assert _runs(experiment.plan(["--params", PAPER, smc, "--laws", "lqr"])) == [("lqr", "lqr", "false")]
    assert "--laws lqr runs in place of the parameter files' law 'smc'" in capsys.readouterr().err
    assert _runs(experiment.plan(["--params", PAPER, smc, "--laws", "smc_ndo"])) == [("smc_ndo", "smc", "true")]
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("text, seconds", [("10", 10.0), ("2.5", 2.5), ("1e3", 1000.0), ("5E-1", 0.5),
                                           ("1e7", 1e7), (" 3 ", 3.0)])
def test_duration_takes_what_mwip_sim_takes(text, seconds):
    lines = experiment.plan(["--params", PAPER, "--duration", text])
    assert lines[0] == f"duration {seconds!r}"
    assert "." in lines[0] or "e" in lines[0]   # the script passes it as ROS reads a double (60 is an integer)


@pytest.mark.parametrize("text", ["0", "-1", "inf", "nan", "1.1e7", "ten", ""])
def test_a_duration_mwip_sim_refuses_is_refused_with_its_message(text):
    with pytest.raises(experiment.PlanError, match="^--duration must be") as e:
        experiment.plan(["--params", PAPER, "--duration", text])
    from mwip_ros.cli.sim import duration_error
    try:
        assert str(e.value) == duration_error(float(text))   # mwip_sim's own line
    except ValueError:
        assert "number of seconds" in str(e.value)


def test_a_files_duration_0_is_refused_unless_duration_is_given(tmp_path):
    forever = _file(tmp_path, "forever.yaml", "plant_sim:\n  ros__parameters:\n    duration_s: 0.0\n")
    with pytest.raises(experiment.PlanError, match="plant_sim.duration_s is 0"):
        experiment.plan(["--params", PAPER, forever])
    assert experiment.plan(["--params", PAPER, forever, "--duration", "2"])[0] == "duration 2.0"


def test_the_raw_overlay_first_leaves_the_users_estimator_and_a_contradiction_is_refused(tmp_path):
    from mwip_ros import params as P
    mine = _file(tmp_path, "c.yaml", "state_estimator:\n  ros__parameters:\n    method: complementary\n")
    assert experiment.plan(["--params", RAW, PAPER, mine, "--sensors", "raw"])[0] == "model raw"
    merged = P.load_param_files([RAW, PAPER, mine])   # the order the script passes to every node
    assert merged.for_node("state_estimator")["method"] == "complementary"
    state = _file(tmp_path, "s.yaml", "plant_sim:\n  ros__parameters:\n    sensors:\n      model: state\n")
    with pytest.raises(experiment.PlanError, match="--sensors raw, but .* sensors.model: state"):
        experiment.plan(["--params", RAW, PAPER, state, "--sensors", "raw"])

