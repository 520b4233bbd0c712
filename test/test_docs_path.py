"""docs/laws.md "Driving a path": the square's and the figure eight's path tables of the eight laws are what the code
computes, to their printed digits (strings: an edited digit fails); docs/theory.md 6.13's other rows too."""
from __future__ import annotations

import pytest

from graphproc import REPO
from mwip_ros import params as P
from mwip_ros.core.mobile_base.path import path_rows, path_metrics
from mwip_ros.core.closed_loop.sim import simulate
from test_docs_numbers import table_after

pytestmark = pytest.mark.slow

pytest.importorskip("mujoco")

PAGE = REPO / "docs" / "laws.md"
LAWS = ["dsc", "dscndo", "lqr", "lqr_ndo", "smc", "smc_ndo", "mpc", "mpc_ndo"]


@pytest.mark.parametrize("scenario", ["square", "figure_eight"])
def test_the_path_tables_are_what_the_code_computes(scenario):
    from mwip_ros.core import laws
    head, rows = table_after(PAGE.read_text(), f"Driving a path, config/{scenario}.yaml")
    assert [r[0].split(" ")[0] for r in rows] == LAWS
    v = P.merged_values(P.load_param_files([REPO / "config" / "paper.yaml", REPO / "config" / f"{scenario}.yaml"]))
    assert v["backend"] == "mujoco" and v["motion.enabled"]
    for row in rows:
        law = row[0].split(" ")[0]
        if laws.unavailable(laws.get(law)):
            continue
        run = simulate(P.closed_loop(v, controller=law))
        label = law if not run.fallen else f"{law} (failed at {run.record['t_fall']:.3f} s)"
        assert row == path_rows([(label, path_metrics(run.columns, run.h))])[0], row


def test_the_raw_sensors_and_drive_path_table_is_what_the_code_computes():
    """docs/laws.md: DSCNDO on the square and the eight with the overlays of each row (raw sensors, the drive) on the
    paper's file; the first row is the ideal square's, as in the table above it."""
    head, rows = table_after(PAGE.read_text(), "Driving a path with raw sensors and the drive")
    assert len(rows) == 7 and rows[0][:3] == ["`config/square.yaml`", "dscndo", "0.2501"]
    for row in rows:
        files = [REPO / "config" / "paper.yaml", *(REPO / f for f in row[0].strip("`").split())]
        run = simulate(P.closed_loop(P.merged_values(P.load_param_files(files)), controller="dscndo"))
        label = "dscndo" if not run.fallen else f"dscndo (failed at {run.record['t_fall']:.3f} s)"
        assert row[1:] == path_rows([(label, path_metrics(run.columns, run.h))])[0], row


def test_the_odometry_drift_table_is_what_the_code_computes():
    """docs/real-robot.md: robot_state's integration (core.mobile_base.odometry.state_update) of the runs' states
    against the true pose, on both paths."""
    from mwip_ros.core.mobile_base.odometry import odometry_drift
    head, rows = table_after((REPO / "docs" / "real-robot.md").read_text(), "Odometry drift against the true pose")
    assert len(rows) == 4
    for row in rows:
        files = [REPO / "config" / "paper.yaml", REPO / row[0].split(" ")[0]]
        v = P.merged_values(P.load_param_files(files))
        run = simulate(P.closed_loop(v, controller=row[1]))
        assert not run.fallen
        d = odometry_drift(run.columns, v["actual.r"], v["actual.track_width"], v["sensors.model"])
        assert row[2:] == [f"{d['final_pos']:.4f}", f"{d['max_pos']:.4f}", f"{d['final_yaw']:.4f}"], row
