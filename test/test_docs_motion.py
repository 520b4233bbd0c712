"""docs/laws.md "Driving: cmd_vel": the motion table of the eight laws and the roll-away against the position hold are
what the code computes, to their printed digits (strings: an edited digit fails)."""
from __future__ import annotations

import pytest

from graphproc import REPO
from mwip_ros import params as P
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.closed_loop.sim import simulate
from test_docs_numbers import table_after

pytestmark = pytest.mark.slow   # the documentation's tables recomputed (MuJoCo runs): heavy, not a unit of code

PAGE = REPO / "docs" / "laws.md"
FILES = [REPO / "config" / "paper.yaml", REPO / "config" / "motion.yaml"]
REAL = [FILES[0], *(REPO / "config" / f for f in ("sensors_raw_realistic.yaml", "motor_realistic.yaml")), FILES[1]]


@pytest.mark.parametrize("caption, files", [
    ("Motion tracking, config/motion.yaml (ideal sensing):", FILES),
    ("Motion tracking, config/motion.yaml with config/sensors_raw_realistic.yaml and config/motor_realistic.yaml:",
     REAL)])
def test_the_motion_tables_are_what_the_code_computes(caption, files):
    head, rows = table_after(PAGE.read_text(), caption)
    assert [r[0] for r in rows] == ["dsc", "dscndo", "lqr", "lqr_ndo", "smc", "smc_ndo", "mpc", "mpc_ndo"]
    v = P.merged_values(P.load_param_files(files))
    for row in rows:
        run = simulate(P.closed_loop(v, controller=row[0]))
        m = metrics.motion_metrics(run.columns, v["nominal.r"], v["fall_angle"], run.record.get("t_fall"))
        assert row == metrics.motion_rows([(row[0], m)])[0], row
        assert m["upright"]


def _travel(v):
    run = simulate(P.closed_loop(v, controller="dscndo"))
    t, tw = run["t"], run["theta_w"]
    sel = (t >= 5.0 - 1e-9) & (t <= 10.0 + 1e-9)
    d = v["nominal.r"] * (tw[sel][-1] - tw[sel][0])
    return [f"{d:.4f}", f"{d / 5.0:.4f}"]


def test_roll_away_against_position_hold():
    _, rows = table_after(PAGE.read_text(), "Roll-away against position hold, DSCNDO, t in [5, 10] s:")
    paper = P.merged_values(P.load_param_files(FILES[:1]))
    hold = dict(P.merged_values(P.load_param_files(FILES)), **{"motion.profile": [0.0, 0.0], "duration_s": 10.0})
    assert rows[0][1:] == _travel(paper)
    assert rows[1][1:] == _travel(hold)
    assert abs(float(rows[1][2])) < abs(float(rows[0][2])) / 5   # holding, not rolling away


def test_the_lean_gain_table_of_theory_6_11():
    text = (REPO / "docs" / "theory.md").read_text()
    _, rows = table_after(text, "| k_x [rad s/rad] | speed err RMS [m/s] | upright |")
    base = P.merged_values(P.load_param_files(FILES))
    for row in rows:
        kx = float(row[0].split()[0])
        v = dict(base, **{"motion.lean_gain": kx})
        run = simulate(P.closed_loop(v, controller="dscndo"))
        m = metrics.motion_metrics(run.columns, v["nominal.r"], v["fall_angle"], run.record.get("t_fall"))
        if m["upright"]:
            assert row[1:] == [f"{m['speed_rms']:.4f}", "yes"], row
        else:
            assert row[1:] == ["-", f"NO (fell at {run.record['t_fall']:.3f} s)"], row
