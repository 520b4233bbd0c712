"""The yaw stage in the graph (docs/theory.md 6.13): with the MuJoCo plant and motion on, the controller answers with
the two wheels' torques on wheel_torques_cmd, and the lockstep graph equals mwip_sim to 1e-9, the turn included."""
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from graphproc import PARAMS, run_lockstep  # noqa: E402
from mwip_ros import params as P  # noqa: E402
from mwip_ros.core.sim import simulate  # noqa: E402
from mwip_ros.core.trajectory import POSE_COLUMNS  # noqa: E402
from mwip_ros.runs import read_csv  # noqa: E402

pytestmark = pytest.mark.graph

MOTION = Path(__file__).resolve().parents[2] / "config" / "motion.yaml"
STATE = ["theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_d1", "tau_d2"]


@pytest.mark.parametrize("controller", ["dscndo", "lqr"])
def test_lockstep_mujoco_graph_with_the_yaw_stage_equals_mwip_sim(tmp_path, controller):
    from mwip_ros.core import laws
    turn = tmp_path / "turn.yaml"
    turn.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n"
                    "dscndo_controller:\n  ros__parameters:\n"
                    "    motion: {profile: [0.0, 0.0, 0.5, 0.3], yaw_profile: [0.0, 0.0, 0.25, 0.5]}\n")
    files = [PARAMS, MOTION, turn]
    cls = laws.get(controller)
    code, csv_path, logs = run_lockstep(tmp_path, cls.observer, "-p", "duration_s:=2.0", params=files,
                                        law=cls.family)
    assert code == 0, logs["plant_sim"].output()
    offline = simulate(P.closed_loop(P.merged_values(P.load_param_files(files)), controller=controller,
                                     duration=2.0))
    graph = read_csv(csv_path)
    assert len(graph) == len(offline) == 401
    assert np.max(np.abs(offline["u_psi"])) > 10.0 and offline["yaw"][-1] > 0.2   # it turned
    for c in STATE + POSE_COLUMNS:
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)
