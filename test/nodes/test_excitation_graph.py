"""The controller's excitation (identification) in the graph: the lockstep graph equals mwip_sim with it on (and with
the drive's model on); the two graphs run at once."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from graphproc import PARAMS, run_lockstep
from loopgraph import concurrently
from mwip_ros import params as P
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.runs import load_run

pytestmark = pytest.mark.graph

IDENTIFY = Path(__file__).resolve().parents[2] / "config" / "identify.yaml"


def _merge(a: dict, b: dict) -> dict:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _overlaid_for_2_s(tmp_path, overlay: Path) -> Path:
    """The paper's file with ``overlay`` over it and the plant's duration 2 s, as one file (a node takes one)."""
    merged = _merge(yaml.safe_load(PARAMS.read_text()), yaml.safe_load(overlay.read_text()))
    merged["plant_sim"]["ros__parameters"]["duration_s"] = 2.0
    params = tmp_path / f"{overlay.stem}_2s.yaml"
    params.write_text(yaml.safe_dump(merged))
    return params


MOTOR = Path(__file__).resolve().parents[2] / "config" / "motor_realistic.yaml"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """{overlay: (its parameter file, the plant's exit code, its csv, the logs)}: the chirp's and the drive's lockstep
    graphs at once (graphproc.run_lockstep, each a domain of its own)."""
    work = tmp_path_factory.mktemp("excitation")

    def run(overlay):
        d = work / overlay.stem
        d.mkdir()
        params = _overlaid_for_2_s(d, overlay)
        return (params, *run_lockstep(d, True, params=params))
    return dict(zip((IDENTIFY, MOTOR), concurrently(lambda: run(IDENTIFY), lambda: run(MOTOR))))


def test_lockstep_graph_with_a_chirp_equals_offline(runs):
    params, code, csv_path, logs = runs[IDENTIFY]
    assert code == 0, logs["plant_sim"].output()
    graph = load_run(csv_path)
    loop = P.closed_loop(P.merged_values(P.load_param_file(params)), controller="dscndo")
    assert loop.excitation is not None and loop.excitation.type == "chirp"
    offline = simulate(loop)
    assert len(graph) == len(offline) == 401
    assert np.max(np.abs(offline["excitation"])) > 10.0   # the chirp is in the command
    for c in ("theta_w", "theta_b", "dtheta_w", "dtheta_b", "u"):
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)


def test_lockstep_graph_with_the_drive_equals_offline_and_records_the_torque_that_acted(runs):
    """The motor model on (config/motor_realistic.yaml): the plant's csv equals mwip_sim's to 1e-9, u_applied (the
    torque that acted) beside the command u, and the drive saturates in the first periods, so the two differ."""
    params, code, csv_path, logs = runs[MOTOR]
    assert code == 0, logs["plant_sim"].output()
    assert "motor: K_t = 2 N m/A" in logs["plant_sim"].output()
    graph = load_run(csv_path)
    offline = simulate(P.closed_loop(P.merged_values(P.load_param_file(params)), controller="dscndo"))
    assert len(graph) == len(offline) == 401
    for c in ("theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "u_applied", "drive_saturation"):
        np.testing.assert_allclose(graph[c][:-1], offline[c][:-1], rtol=0, atol=1e-9, err_msg=c)
    assert np.max(np.abs(graph["u"][:-1] - graph["u_applied"][:-1])) > 10.0
