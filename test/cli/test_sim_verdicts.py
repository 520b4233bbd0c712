"""mwip_sim's verdicts (issue 29 item 10, issue 30 item 1): a fall exits 3 with its time, a law commanding NaN or
1e300 is a failure and never 'stayed upright', no ratio is printed from a run that fell, and a run shorter than
the metrics window says so; --help lists the exit codes."""
import pytest

from mwip_ros.cli import sim
from mwip_ros.params.paths import default_params_file

import bad_laws  # noqa: E402  registers nan_cmd, huge_cmd (test/bad_laws.py)

pytestmark = pytest.mark.unit

T_BAD = bad_laws.AFTER / 200.0   # the paper's 200 Hz


def _sim(capsys, *argv):
    code = sim.main([*argv, "-q"])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize("name", ["nan_cmd", "huge_cmd"])
def test_a_law_commanding_nan_or_1e300_fails_with_exit_3_and_its_time(capsys, name):
    code, out, _ = _sim(capsys, "--controller", name, "--duration", "1", "--window", "0.2", "1")
    assert code == 3
    assert f"{name}: FAILED at t = {T_BAD:.3f} s: the law's command is refused" in out
    assert "stayed upright" not in out and "nan rad" not in out
    assert out.split("\n")[2].split()[1] == "NO"   # the table's upright column


def _weak(tmp_path):
    f = tmp_path / "weak.yaml"   # gains that let both laws fall (as test_cli's fall)
    f.write_text(default_params_file().read_text().replace("k1: 6.0", "k1: 0.05").replace("k2: 6.0", "k2: 0.05"))
    return f


def test_both_runs_fallen_print_no_ratio_and_exit_3(capsys, tmp_path):
    code, out, _ = _sim(capsys, "--params", str(_weak(tmp_path)), "--compare", "--duration", "5")
    assert code == 3
    assert "DSCNDO / DSC theta_b peak-to-peak: no ratio, both fell" in out
    assert "nan" not in out.lower() and "x smaller" not in out
    assert "dsc: FELL at t = " in out and "dscndo: FELL at t = " in out


def test_a_run_shorter_than_the_window_says_so_and_qualifies_its_verdict(capsys):
    code, out, _ = _sim(capsys, "--duration", "0.001")
    assert code == 0
    assert "before the metrics window [5, 10] s ends: the metrics need t >= 10 s" in out
    assert "dscndo: stayed upright to the run's end at t = 0.000 s" in out and "needs t >= 10 s" in out
    code, out, _ = _sim(capsys, "--duration", "7")   # part of the window
    assert code == 0 and "the metrics need t >= 10 s (part of the window was simulated" in out
    code, out, _ = _sim(capsys, "--duration", "10")
    assert code == 0 and "note:" not in out and "dscndo: stayed upright (max |theta_b| = " in out


def test_help_lists_the_exit_codes(capsys):
    with pytest.raises(SystemExit):
        sim.main(["--help"])
    out = capsys.readouterr().out
    text = out[out.index("exit codes:"):]
    for code, words in (("0", "every run stayed upright"), ("2", "a mistake"), ("3", "a run fell or failed"),
                        ("130", "interrupted")):
        assert f"  {code:<5}{words}" in text


def test_a_failed_runs_csv_keeps_when_and_why_and_mwip_report_judges_it_failed(capsys, tmp_path):
    """The CSV of a run the law broke (its state fine, its command refused) says so; mwip_report reads it back
    and never calls the run upright."""
    from mwip_ros.cli import report
    from mwip_ros.runs import read_csv
    csv = tmp_path / "nan.csv"
    code, _, _ = _sim(capsys, "--controller", "nan_cmd", "--duration", "1", "--csv", str(csv))
    assert code == 3
    run = read_csv(csv)
    assert run.fallen and run.record == {"t_fall": T_BAD, "failure": "bad_command",
                                         "fall_text": f"FAILED at t = {T_BAD:.3f} s (bad_command)"}
    assert "t_fall" not in run.columns and "failure" not in run.columns
    assert report.main([str(csv), "--out", str(tmp_path / "rep"), "--no-animation", "--window", "0.2", "0.5"]) == 0
    md = (tmp_path / "rep" / "metrics.md").read_text()
    assert f"**FELL: nan at t = {T_BAD:.3f} s**" in md and "| nan | NO |" in md
