"""The tables of docs/real-robot.md and the rival laws' of docs/laws.md are what the code computes, to their digits.

The rival laws (ideal, and with the realistic raw sensors and drive), the estimators, the drive and the
identification, each found by its header on the one page that has it (test_docs_numbers.page_with): each row is
simulated offline as ``mwip_sim --params ...`` would, every printed cell compared with the computed value formatted
with the cell's own number of decimals (strings: an edited digit fails).
"""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from graphproc import REPO
from mwip_ros import params as P
from mwip_ros.cli import identify
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.runs import write_csv
from test_docs_numbers import page_with, table_after

pytestmark = pytest.mark.slow   # the documentation's tables recomputed (MuJoCo runs): heavy, not a unit of code

CONFIG = REPO / "config"
PAPER, RAW, MOTOR, IDENT = (CONFIG / f for f in ("paper.yaml", "sensors_raw_realistic.yaml", "motor_realistic.yaml",
                                                  "identify.yaml"))
LAWS = {"DSC": "dsc", "DSCNDO": "dscndo", "LQR": "lqr", "LQR+NDO": "lqr_ndo", "SMC": "smc", "SMC+NDO": "smc_ndo",
        "MPC": "mpc", "MPC+NDO": "mpc_ndo"}
_cache: dict = {}


def run(files, law, **over):
    """The metrics over t in [5, 10] s of ``law`` with the parameter files ``files`` and ``over`` (merged values)."""
    key = (tuple(map(str, files)), law, tuple(sorted(over.items())))
    if key not in _cache:
        v = P.merged_values(P.load_param_files(list(files)))
        v.update(over)
        r = simulate(P.closed_loop(v, controller=law))
        _cache[key] = metrics.compute(r.columns, metrics.WINDOW, v["fall_angle"])
    return _cache[key]


def _same(printed: str, value) -> bool:
    if printed == "-":
        return value is None or value != value
    decimals = len(printed.split(".")[1]) if "." in printed else 0
    return printed == f"{value:.{decimals}f}"


def _check(header_start: str, rows_expected, cell):
    """Every cell of the table whose header starts with ``header_start``: ``cell(row label, column) -> value``."""
    page = page_with(header_start)
    head, rows = table_after(page.read_text(), header_start)
    assert sorted(r[0] for r in rows) == sorted(rows_expected), [r[0] for r in rows]
    bad = [(r[0], col, printed, cell(r[0], col)) for r in rows for col, printed in zip(head[1:], r[1:])
           if not _same(printed, cell(r[0], col))]
    assert not bad, f"{page.name} differs from what the code computes: " + "; ".join(
        f"{row} / {col}: printed {p!r}, computed {w!r}" for row, col, p, w in bad)


def test_the_rival_laws_table():
    def cell(label, col):
        files = [PAPER, RAW, MOTOR] if "raw sensors + drive" in col else [PAPER]
        m = run(files, LAWS[label])
        return m.theta_b_rms if col.startswith("theta_b RMS") else m.u_rms
    _check("| law | theta_b RMS [rad] | u RMS [N m] | theta_b RMS, raw sensors", LAWS, cell)


ESTIMATORS = {"the true state": ([PAPER], {}),
              "complementary, tau 1 s, bias unknown": ([PAPER, RAW], {"method": "complementary",
                                                                       "complementary.tau": 1.0}),
              "complementary, tau 1 s, bias told": ([PAPER, RAW], {"method": "complementary", "complementary.tau": 1.0,
                                                                    "complementary.gyro_bias": 0.01}),
              "kalman, bias unknown": ([PAPER, RAW], {})}


def test_the_estimators_table():
    assert P.merged_values(P.load_param_file(RAW))["sensors.imu.gyro_bias"] == 0.01   # the "told" row's value

    def cell(label, col):
        files, over = ESTIMATORS[label]
        if col.startswith("LQR+NDO"):
            return run(files, "lqr_ndo", **over).theta_b_rms
        m = run(files, "dscndo", **over)
        return {"pitch error RMS [rad]": m.theta_b_est_err_rms, "pitch rate error RMS [rad/s]": m.dtheta_b_est_err_rms,
                "DSCNDO theta_b RMS [rad]": m.theta_b_rms}[col]
    _check("| estimator | pitch error RMS", ESTIMATORS, cell)


def test_the_drive_table():
    def cell(label, col):
        if col.startswith("theta_b RMS, ideal"):
            return run([PAPER], LAWS[label]).theta_b_rms
        m = run([PAPER, MOTOR], LAWS[label])
        return m.theta_b_rms if col.startswith("theta_b RMS") else m.saturated_s
    _check("| law | theta_b RMS, ideal torque", ("DSC", "DSCNDO", "LQR", "LQR+NDO"), cell)


def test_the_identification_table(tmp_path):
    """The shipped experiment, identified by mwip_identify, then the paper's scenario with each nominal model."""
    v = P.merged_values(P.load_param_files([PAPER, IDENT]))
    csv = tmp_path / "identify.csv"
    write_csv(simulate(P.closed_loop(v, controller="dscndo")), csv)
    out = tmp_path / "identified.yaml"
    assert identify.main([str(csv), "--params", str(PAPER), "--out", str(out)]) == 0
    got = yaml.safe_load(out.read_text())["/**"]["ros__parameters"]["nominal"]
    base = P.merged_values(P.load_param_file(PAPER))
    models = {"the paper's": {k: base[f"nominal.{k}"] for k in ("m_b", "I_b", "l")}, "identified": got,
              "the true robot": {k: base[f"actual.{k}"] for k in ("m_b", "I_b", "l")}}
    for k in ("m_b", "I_b", "l"):
        assert abs(got[k] - base[f"actual.{k}"]) <= 0.001 * base[f"actual.{k}"]   # "to 0.1 %"

    def cell(label, col):
        model = models[label]
        key = col.split(" [")[0]
        if key in model:
            return float(f"{model[key]:.6g}")
        law = {"DSC": "dsc", "DSCNDO": "dscndo", "LQR+NDO": "lqr_ndo"}[col.split(" theta_b")[0]]
        return run([PAPER], law, **{f"nominal.{k}": val for k, val in model.items()}).theta_b_rms
    _check("| nominal model | m_b [kg]", models, cell)


def test_an_edited_cell_is_caught(monkeypatch):
    """Not vacuous: one digit changed in the estimators table is a mismatch."""
    text = page_with("| estimator | pitch error RMS").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("| kalman, bias unknown |"))
    edited = line.replace("0.00035", "0.00036")
    assert edited != line
    read = Path.read_text
    monkeypatch.setattr(Path, "read_text", lambda self, *a, **k: read(self, *a, **k).replace(line, edited))
    with pytest.raises(AssertionError, match="kalman, bias unknown / pitch error RMS"):
        test_the_estimators_table()


def test_the_drive_identification_table():
    """config/identify_drive.yaml under DSCNDO with the realistic motor, fitted by core.identification.drive_identify
    (what mwip_identify --drive prints)."""
    from mwip_ros.core.identification.drive_identify import identify_drive
    files = [PAPER, MOTOR, CONFIG / "identify_drive.yaml"]
    v = P.merged_values(P.load_param_files(files))
    r = simulate(P.closed_loop(v, controller="dscndo"))
    c = r.columns
    d = identify_drive(c["u"], c["u_applied"], c["dtheta_w"], c["dtheta_b"], v["motor.voltage_limit"])
    for k in ("torque_constant", "resistance", "current_limit"):
        assert getattr(d, k) == pytest.approx(v[f"motor.{k}"], rel=1e-4)   # "to 1e-5 of each" (measured)
    cells = {"K_t [N m/A]": d.torque_constant, "R [ohm]": d.resistance, "I_max [A]": d.current_limit,
             "periods on the current limit": d.periods[1], "periods on the voltage limit": d.periods[2]}
    _check("| drive identified", ["config/motor_realistic.yaml"], lambda label, col: cells[col])


UNSEEN = {"m_b": 250.0, "I_b": 48.0, "l": 0.28}   # the retune table's robot, never seen by the tool


def test_the_raw_bag_table(tmp_path):
    """mwip_identify --raw on mwip_sim's CSV of 15 s of the chirp on a 280 / 58 / 0.29 robot (the lockstep graph's bag
    of the same run gives the same fit to the bit: test/cli/test_identify_bag.py)."""
    from mwip_ros.core.identification.identify_raw import identify_raw
    v = P.merged_values(P.load_param_files([PAPER, RAW, IDENT]))
    v.update({"actual.m_b": 280.0, "actual.I_b": 58.0, "actual.l": 0.29, "duration_s": 15.0,
              "excitation.duration_s": 15.0})
    csv = tmp_path / "raw.csv"
    write_csv(simulate(P.closed_loop(v, controller="dscndo")), csv)
    cols, _ = identify._load_raw(identify._parser().parse_args([str(csv), "--raw", "--out", "x.yaml"]))
    known = P.physical(P.merged_values(P.load_param_file(PAPER)), "nominal")
    got = identify_raw(cols["t"], *(cols[k] for k in identify.RAW), known=known, start=known, imu_offset=0.3).values
    _check("| raw log of 15 s of the chirp", ["mwip_sim's CSV, and the lockstep graph's bag of the same run"],
           lambda label, col: got[col.split(" [")[0]])


@pytest.mark.slow
def test_the_retune_table(tmp_path):
    """mwip_identify --retune (the default search) on the shipped experiment's log of the unseen robot, the same
    search on the true model, and the paper's scenario on that robot with each row's nominal model and gains."""
    from dataclasses import replace
    from mwip_ros.cli.identify_retune import retune
    v = P.merged_values(P.load_param_files([PAPER, IDENT]))
    v.update({f"actual.{k}": x for k, x in UNSEEN.items()})
    csv = tmp_path / "identify.csv"
    write_csv(simulate(P.closed_loop(v, controller="dscndo")), csv)
    out = tmp_path / "gains.yaml"
    assert identify.main([str(csv), "--params", str(PAPER), "--retune", "--out", str(out)]) == 0
    base = P.merged_values(P.load_param_file(PAPER))
    true = retune([PAPER], replace(P.physical(base, "nominal"), **UNSEEN), "dscndo", 30, 8)
    rows = {"the paper's gains and model": base, "tuned on the identified model":
            P.merged_values(P.load_param_files([PAPER, out])),
            "tuned on the true model": dict(base, **{f"nominal.{k}": x for k, x in UNSEEN.items()},
                                            **{p: x for (_s, p), x in true.placed.items()})}
    rms = {}

    def cell(label, col):
        values = rows[label]
        key = col.split(" [")[0]
        if key.startswith("nominal "):
            return values[f"nominal.{key.split()[1]}"]
        if key in ("X.c1", "X.c4"):
            return values["X"][0 if key == "X.c1" else 3]
        if key in ("k1", "k2", "tau4"):
            return values[key]
        if label not in rms:
            w = dict(values, **{f"actual.{k}": x for k, x in UNSEEN.items()})
            r = simulate(P.closed_loop(w, controller="dscndo"))
            rms[label] = metrics.compute(r.columns, metrics.WINDOW, w["fall_angle"]).theta_b_rms
        return rms[label]
    _check("| DSCNDO on the unseen robot", rows, cell)
