"""The law ``policy`` in the ROS graph (MWIP_ROS_LAWS=mwip_ros.policy_law, ``law: policy``, ``policy.file``): the
lockstep graph's trajectory is MwipEnv's episode of the same policy file bit for bit (the env computed here, in
process; the law is registered only in the node processes)."""
import os

import numpy as np
import pytest

from graphproc import PARAMS, Graph, loop_chain
from mwip_ros.runs import load_run

pytestmark = pytest.mark.graph

gym = pytest.importorskip("gymnasium")


def test_the_controller_node_runs_a_learned_policy_equal_to_the_env(tmp_path, monkeypatch):
    from mwip_ros.envs import MwipEnv
    from mwip_ros.policy import LinearPolicy
    policy = LinearPolicy((9.609, 1.246, -0.0438), 256.0)
    policy.save(tmp_path / "p.json")
    monkeypatch.setenv("MWIP_ROS_LAWS", "mwip_ros.policy_law")   # the node processes register the law
    csv_path = tmp_path / "graph.csv"
    controller = ("-p", "use_observer:=false", "-p", "law:=policy", "-p", f"policy.file:={tmp_path / 'p.json'}")
    with Graph(tmp_path) as g:   # as graphproc.run_lockstep, the controller given the policy's file
        procs = [g.start(a.node, "-p", "use_sim_time:=true", *(controller if a.node == "dscndo_controller" else ()),
                         params=PARAMS) for a in loop_chain(PARAMS)]
        plant = g.start("plant_sim", "-p", f"csv:={csv_path}", "-p", "duration_s:=2.0", params=PARAMS)
        code = plant.wait(180.0)
        logs = {p.name: p.output() for p in (*procs, plant)}
    assert code == 0, logs
    assert "policy ready: w = (9.609, 1.246, -0.0438), S = 256 N m" in logs["dscndo_controller"], logs
    graph = load_run(csv_path)
    env = MwipEnv(PARAMS, duration=2.0)
    obs, info = env.reset(seed=0)
    xs, us = [info["state"]], []
    while True:
        obs, _, terminated, truncated, info = env.step(policy(obs[None, :])[0])
        us.append(info["u"])
        if terminated or truncated:
            break
        xs.append(np.array(env.unwrapped._period.side.plant.x))
    xs = np.array(xs)
    assert truncated and len(graph) == len(us) + 1 == 401
    for j, c in enumerate(("theta_w", "theta_b", "dtheta_w", "dtheta_b")):
        np.testing.assert_array_equal(graph[c][:-1], xs[:, j], err_msg=c)
    np.testing.assert_array_equal(graph["u"][:-1], us)
    assert os.environ["MWIP_ROS_LAWS"] == "mwip_ros.policy_law"
