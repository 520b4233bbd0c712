"""One definition of a period (core.closed_loop.loop): every runner holds its stages in its order; the chain is data."""
from __future__ import annotations

import inspect
import re

import pytest

from mwip_ros.core.kernels import batch, compiled
from mwip_ros.core.closed_loop import loop
from mwip_ros.core.plants.plant import PLANTS, Plant, PlantSim, make_plant
from mwip_ros.nodes.loop import plant_runners, plant_sim
from mwip_ros.nodes.runtime import lockstep
from mwip_ros.nodes.tools import resim
from mwip_ros.params import file as param_file

from mathfixtures import exact_model_plant

pytestmark = pytest.mark.unit

STAGE = re.compile(r"# stage: (\w+)")


def _stages_in(fn) -> list:
    return STAGE.findall(inspect.getsource(fn))


def test_the_stages_are_the_contract_s_order():
    assert loop.STAGE_NAMES == ("sensors", "estimator", "observer", "law", "yaw", "drive", "plant")


@pytest.mark.parametrize("runner", [batch._simulate_numpy, compiled._loop], ids=["batch numpy", "compiled"])
def test_the_batch_runners_hold_every_stage_in_its_order(runner):
    """A stage added to STAGES and not to a runner fails here (the offline loop and the node share PlantSide)."""
    assert tuple(_stages_in(runner)) == loop.STAGE_NAMES


def test_the_offline_loop_and_the_plant_node_run_the_plant_s_stages_through_one_object():
    sim_src = "".join(inspect.getsource(f) for f in (loop.Period.run, loop.Period.sense_decide, loop.Period.actuate,
                                                       loop.Period.advance))
    assert "side.sense()" in sim_src and "side.act(" in sim_src and ".advance(" in sim_src
    node_src = inspect.getsource(plant_sim.PlantSimNode)
    assert "self.side.sense()" in node_src and "self.side.act(" in node_src and "self.side.advance(" in node_src
    assert "PlantSim(" not in node_src and "Sensors" not in node_src and "Actuator" not in node_src


def test_the_answering_stages_are_those_the_plant_does_not_run():
    chain = loop.answering()
    assert [(a.node, a.topic) for a in chain] == [("disturbance_observer", "disturbance_estimate"),
                                                  ("dscndo_controller", "wheel_torque_cmd")]
    with_estimator = loop.answering(estimator=True)
    assert [a.node for a in with_estimator] == ["state_estimator", "disturbance_observer", "dscndo_controller"]
    assert loop.loop_nodes() == ("plant_sim", "disturbance_observer", "dscndo_controller")


def test_the_driver_the_resim_and_the_parameter_merge_take_the_chain_from_the_stages():
    assert lockstep.CHAIN == loop.answering()
    assert resim.LOOP_NODES == ("disturbance_observer", "dscndo_controller")
    assert param_file.NODES_OF_THE_LOOP == ("dscndo_controller", "disturbance_observer", "state_estimator",
                                            "plant_sim")


class _Graph:
    """What the driver reads of the graph: publishers per topic, matched subscriptions of the state."""

    topic_name = "/joint_states"

    def __init__(self, publishers):
        self.publishers = publishers

    def count_publishers(self, topic):
        return self.publishers.get(topic, 0)

    def get_subscription_count(self):
        return 3


def test_an_extra_answering_stage_is_configuration_not_driver_code():
    """A chain with an estimator: the driver names it when nothing publishes its answer, with no new code."""
    chain = loop.answering(estimator=True)
    g = _Graph({"wheel_torque_cmd": 1, "disturbance_estimate": 1})
    assert lockstep.graph_missing(g, g, 3, chain) == ["state_estimator (nothing publishes joint_states)"]
    g.publishers["joint_states"] = 1
    assert lockstep.graph_missing(g, g, 3, chain) == []
    assert lockstep.graph_missing(_Graph({}), g, 3, chain)[0].startswith("dscndo_controller (nothing publishes "
                                                                         "wheel_torque_cmd)")


def test_the_plant_interface():
    cfg = exact_model_plant()
    p = make_plant(cfg)
    assert isinstance(p, PlantSim) and isinstance(p, Plant) and PLANTS["rk4"] is PlantSim
    with pytest.raises(ValueError, match="unknown plant backend 'bullet'; known: mujoco, rk4"):
        make_plant(cfg, "bullet")


def test_each_mode_is_a_runner():
    assert set(plant_runners.RUNNERS) == {"lockstep", "realtime"}
    src = inspect.getsource(plant_sim.PlantSimNode)
    assert 'self.mode == "' not in src and "self.mode ==" not in src   # no mode branches in the node


def test_a_driver_that_is_not_enabled_applies_no_torque_and_reports_none():
    """theory.md 6.8: disabled (require_enable, never enabled), the torque that acts is zero, and the observer is told
    zero; enabled, the command acts."""
    from dataclasses import replace

    from mwip_ros.core.closed_loop.loop import PlantSide

    cfg = exact_model_plant()
    side = PlantSide(replace(cfg, require_enable=True))
    assert side.safety.state == "disabled"
    u, _ = side.act(50.0)
    side.advance(u)
    assert u == 0.0 and side.sense()[1] == 0.0
    assert side.safety.enable(0.005).success
    u, _ = side.act(50.0)
    side.advance(u)
    assert u == 50.0 and side.sense()[1] == 50.0
