"""mwip_report on CSVs as a user runs it: the window follows the runs, falls are reported with their time,
metrics.json is valid JSON, the ratios to DSCNDO, and an --out that holds a report is refused.

The runs are synthetic trajectory tables of known formulas (theta_b = a sin(2 pi t), u = b cos(2 pi t), a ramp
for a fall), so every expected number below comes from the formula or from numpy on the columns, not from
the code under test.
"""
import json
import math

import numpy as np
import pytest

from mwip_ros.cli import report
from mwip_ros.core.closed_loop.trajectory import TRAJECTORY_COLUMNS, Trajectory
from mwip_ros.runs import write_csv

pytestmark = pytest.mark.unit

H = 0.01


def make_run(label, t_end, a=0.02, b=30.0, ramp=None):
    """theta_b = a sin(2 pi t), u = b cos(2 pi t) on [0, t_end]; ``ramp`` (rad/s): theta_b = ramp t instead."""
    t = np.arange(int(round(t_end / H)) + 1) * H
    cols = {c: np.full_like(t, np.nan) if c.startswith("tau_hat") else np.zeros_like(t) for c in TRAJECTORY_COLUMNS}
    cols.update(t=t, theta_b=a * np.sin(2 * np.pi * t) if ramp is None else ramp * t, u=b * np.cos(2 * np.pi * t),
                tau_d1=np.sin(t), tau_d2=np.cos(t))
    return Trajectory(label, cols, False, H)


def csvs(tmp_path, runs):
    paths = []
    for r in runs:
        paths.append(str(tmp_path / f"{r.label}.csv"))
        write_csv(r, paths[-1])
    return paths


def strict_json(path):
    def refuse(c):
        raise ValueError(f"bare {c} in {path}")
    return json.loads(path.read_text(), parse_constant=refuse)


def window_stats(run, w0, w1):
    sel = (run.t >= w0 - 1e-9) & (run.t <= w1 + 1e-9)
    th, u = run["theta_b"][sel], run["u"][sel]
    return np.ptp(th), np.sqrt(np.mean(th ** 2)), np.sqrt(np.mean(u ** 2))


def test_runs_shorter_than_the_default_window_use_their_second_half_and_say_so(tmp_path, capsys):
    runs = [make_run("dsc", 3.0, a=0.05), make_run("dscndo", 3.0, a=0.01)]
    out = tmp_path / "rep"
    assert report.main(csvs(tmp_path, runs) + ["--out", str(out), "--no-animation"]) == 0
    stdout = capsys.readouterr().out
    doc = strict_json(out / "metrics.json")
    assert doc["window"] == [1.5, 3.0]
    for r in runs:
        m = doc["runs"][r.label]
        p2p, rms, u_rms = window_stats(r, 1.5, 3.0)
        assert m["upright"] is True and m["covers_window"] is True and m["t_fall"] is None
        assert m["theta_b_p2p"] == pytest.approx(p2p, rel=1e-12) and m["u_rms"] == pytest.approx(u_rms, rel=1e-12)
        assert m["samples"] == 151
    md = (out / "metrics.md").read_text()
    assert "[5, 10] s" in md and "t in [1.5, 3] s" in md and "second half" in md
    assert "NOTE:" in stdout and "second half" in stdout and "run ends at t = 3.000 s" in stdout
    assert "FELL" not in stdout


def test_an_explicit_window_outside_the_runs_is_refused_with_one_line(tmp_path, capsys):
    paths = csvs(tmp_path, [make_run("dsc", 3.0)])
    out = tmp_path / "rep"
    assert report.main(paths + ["--out", str(out), "--window", "5", "10"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--window" in err[0] and "3.000 s" in err[0]
    assert not (out / "metrics.md").exists()
    assert report.main(paths + ["--out", str(out), "--window", "1", "2", "--no-animation"]) == 0   # inside: fine
    assert strict_json(out / "metrics.json")["window"] == [1.0, 2.0]


def test_a_fall_is_reported_with_its_time_and_upright_is_separate_from_covering_the_window(tmp_path, capsys):
    fa = report.FALL_ANGLE
    rate = 2.0                                              # theta_b = 2 t passes the fall angle at fa / 2
    first_over = math.floor(fa / rate / H + 1) * H          # the first sample with |theta_b| > fa
    runs = [make_run("dsc", 10.0), make_run("falls", 0.7, ramp=rate), make_run("short", 6.0)]
    out = tmp_path / "rep"
    assert report.main(csvs(tmp_path, runs) + ["--out", str(out), "--gif-fps", "10"]) == 0
    stdout = capsys.readouterr().out
    fell_lines = [line for line in stdout.splitlines() if line.startswith("FELL: ")]
    assert fell_lines == [f"FELL: falls at t = {first_over:.3f} s"]
    doc = strict_json(out / "metrics.json")
    assert doc["window"] == [5.0, 10.0]                     # the longest run covers the default window
    m = doc["runs"]
    assert m["falls"]["upright"] is False and m["falls"]["t_fall"] == pytest.approx(first_over, abs=1e-9)
    assert m["falls"]["theta_b_rms"] is None                # no sample in the window: null, not NaN
    assert doc["fallen"] == {"falls": pytest.approx(first_over, abs=1e-9)}
    # the 6 s run never fell: upright, though it does not cover the window (and it says so)
    assert m["short"]["upright"] is True and m["short"]["covers_window"] is False
    assert m["short"]["samples"] == 101
    md = (out / "metrics.md").read_text()
    assert f"FELL: falls at t = {first_over:.3f} s" in md
    row = next(line for line in md.splitlines() if line.startswith("| falls |"))
    assert "| NO |" in row and f"{first_over:.3f}" in row
    assert "short" in md and "ends before the window's end" in md
    assert "| falls | fell | fell | fell |" in md           # no ratio for a run that fell: said, not a number
    # write_report says which runs fell, for a script
    res = report.write_report(runs, tmp_path / "again", gif_fps=None)
    assert res["fallen"] == {"falls": pytest.approx(first_over, abs=1e-9)}
    assert [name for name, mm in res["named"] if not mm.upright] == ["falls"]


def test_metrics_json_has_no_bare_nan_even_without_estimates_or_samples(tmp_path):
    runs = [make_run("a", 2.0), make_run("b", 0.6, ramp=3.0)]       # no tau_hat at all; b falls at once
    out = tmp_path / "rep"
    assert report.main(csvs(tmp_path, runs) + ["--out", str(out), "--no-animation"]) == 0
    text = (out / "metrics.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    doc = strict_json(out / "metrics.json")
    assert doc["runs"]["a"]["tau_err1_rms"] is None and doc["runs"]["a"]["theta_b_rms"] is not None


def test_each_law_is_given_as_a_ratio_to_dscndo(tmp_path, capsys):
    amp = {"dsc": 0.06, "dscndo": 0.012, "lqr": 0.18, "lqr_ndo": 0.03}
    torque = {"dsc": 34.0, "dscndo": 22.0, "lqr": 48.0, "lqr_ndo": 26.0}
    runs = [make_run(k, 10.0, a=amp[k], b=torque[k]) for k in amp]
    out = tmp_path / "rep"
    assert report.main(csvs(tmp_path, runs) + ["--out", str(out), "--no-animation"]) == 0
    stdout = capsys.readouterr().out
    md = (out / "metrics.md").read_text()
    doc = strict_json(out / "metrics.json")
    assert doc["ratios"]["reference"] == "dscndo"
    assert "theta_b p2p / dscndo [x]" in md and "theta_b RMS / dscndo [x]" in md and "u RMS / dscndo [x]" in md
    for law in ("dsc", "lqr", "lqr_ndo"):
        want_th, want_u = amp[law] / amp["dscndo"], torque[law] / torque["dscndo"]   # sines: ratios of amplitudes
        got = doc["ratios"]["runs"][law]
        assert got["theta_b_p2p"] == pytest.approx(want_th, rel=1e-3)
        assert got["theta_b_rms"] == pytest.approx(want_th, rel=1e-3)
        assert got["u_rms"] == pytest.approx(want_u, rel=1e-3)
        row = next(line for line in md.splitlines() if line.startswith(f"| {law} |") and "x]" not in line
                   and line.count("|") == 5)
        assert row == f"| {law} | {want_th:.2f} | {want_th:.2f} | {want_u:.2f} |"
        assert any(line.split()[:2] == [law, f"{want_th:.2f}"] for line in stdout.splitlines())
    assert "dscndo" not in doc["ratios"]["runs"]


def test_without_a_dscndo_run_the_ratios_are_to_the_last_run_and_say_so(tmp_path):
    runs = [make_run("first", 10.0, a=0.04), make_run("second", 10.0, a=0.01)]
    out = tmp_path / "rep"
    assert report.main(csvs(tmp_path, runs) + ["--out", str(out), "--no-animation"]) == 0
    md = (out / "metrics.md").read_text()
    assert "no run is labelled dscndo" in md and "theta_b p2p / second [x]" in md
    assert strict_json(out / "metrics.json")["ratios"]["runs"]["first"]["theta_b_p2p"] == pytest.approx(4.0, rel=1e-3)
    # a bag directory's name ending in _dscndo is the DSCNDO run
    assert report.reference_run(["2026-11-22_101500_dsc", "2026-11-22_101500_dscndo", "x"])[0] == 1
    assert report.reference_run(["dsc", "lqr_ndo"])[0] == 1 and "no run is labelled" in report.reference_run(
        ["dsc", "lqr_ndo"])[1]


def test_an_out_holding_a_report_is_refused_unless_force_which_removes_stale_files(tmp_path, capsys):
    paths = csvs(tmp_path, [make_run("dsc", 1.0)])
    out = tmp_path / "rep"
    assert report.main(paths + ["--out", str(out), "--gif-fps", "10", "--window", "0.5", "1"]) == 0
    assert (out / "animation.gif").is_file()
    before = (out / "metrics.md").read_text()
    capsys.readouterr()
    assert report.main(paths + ["--out", str(out), "--no-animation", "--window", "0", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "already holds a report" in err[0] and "--force" in err[0]
    assert (out / "metrics.md").read_text() == before and (out / "animation.gif").is_file()
    (tmp_path / "only").mkdir()
    (tmp_path / "only" / "fig3.png").write_bytes(b"old")                # any one file of a report counts
    assert report.main(paths + ["--out", str(tmp_path / "only")]) == 2
    (out / "notes.txt").write_text("mine")
    assert report.main(paths + ["--out", str(out), "--no-animation", "--window", "0", "1", "--force"]) == 0
    assert not (out / "animation.gif").exists()                        # stale: this report has none
    assert "[0, 1] s" in (out / "metrics.md").read_text()
    assert (out / "notes.txt").read_text() == "mine"                    # not a report file: left alone


def test_no_ratio_is_given_when_the_dscndo_run_fell(tmp_path):
    # theta_b = 2 t passes the fall angle (1.0472 rad) at t = 0.52 s; the other run stays up
    runs = [make_run("dsc", 3.0, a=0.05), make_run("dscndo", 3.0, ramp=2.0)]
    out = tmp_path / "rep"
    assert report.main(csvs(tmp_path, runs) + ["--out", str(out), "--no-animation"]) == 0
    md = (out / "metrics.md").read_text()
    assert "| dsc | dscndo fell | dscndo fell | dscndo fell |" in md, md
    assert strict_json(out / "metrics.json")["ratios"]["runs"]["dsc"]["theta_b_p2p"] is None
