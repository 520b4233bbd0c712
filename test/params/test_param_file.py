"""The parameter file loader refuses each kind of bad input with a message naming the key."""
import copy

import pytest
import yaml

from mwip_ros import params as P
from mwip_ros.params.paths import default_params_file
from mwip_ros.core.control.lqr import NO_DESIGN

pytestmark = pytest.mark.unit

BASE = yaml.safe_load(default_params_file().read_text())


def _load(tmp_path, doc):
    f = tmp_path / "p.yaml"
    f.write_text(yaml.safe_dump(doc))
    return P.load_param_file(f)


def _mutate(path, value):
    doc = copy.deepcopy(BASE)
    node = doc
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return doc


def test_paper_file_loads_with_spec_values(tmp_path):
    pf = P.load_param_file(default_params_file())
    v = pf.for_node("plant_sim")
    assert v["actual.m_b"] == 310.6 and v["nominal.m_b"] == 210.6 and v["control_rate_hz"] == 200.0
    assert pf.for_node("disturbance_observer")["X"] == [100.0, 0.0, 0.0, 100.0]
    c = pf.for_node("dscndo_controller")
    assert (c["k1"], c["k2"], c["tau4"], c["use_observer"]) == (6.0, 6.0, 0.1, True)


@pytest.mark.parametrize("path,value,key,words", [
    (("plant_sim", "ros__parameters", "actual", "m_b"), -310.6, "plant_sim.actual.m_b", "> 0"),
    (("plant_sim", "ros__parameters", "actual", "m_b"), 0.0, "plant_sim.actual.m_b", "> 0"),
    (("/**", "ros__parameters", "nominal", "I_b"), -1.0, "nominal.I_b", "> 0"),
    (("/**", "ros__parameters", "nominal", "l"), 0.0, "nominal.l", "> 0"),
    (("/**", "ros__parameters", "control_rate_hz"), 0.0, "control_rate_hz", "> 0"),
    (("/**", "ros__parameters", "control_rate_hz"), 200, "control_rate_hz", "200.0"),
    (("dscndo_controller", "ros__parameters", "tau4"), 0.0, "dscndo_controller.tau4", "> 0"),
    (("dscndo_controller", "ros__parameters", "k1"), "six", "dscndo_controller.k1", "floating-point"),
    (("dscndo_controller", "ros__parameters", "use_observer"), "yes please", "dscndo_controller.use_observer",
     "true or false"),
    (("plant_sim", "ros__parameters", "actual", "D_w_variance"), -0.2, "plant_sim.actual.D_w_variance", ">= 0"),
    (("plant_sim", "ros__parameters", "substeps"), 5.0, "plant_sim.substeps", "integer"),
    (("plant_sim", "ros__parameters", "substeps"), 0, "plant_sim.substeps", ">= 1"),
    (("plant_sim", "ros__parameters", "mode"), "fast", "plant_sim.mode", "lockstep"),
    (("disturbance_observer", "ros__parameters", "X"), [100.0, 0.0, 100.0], "disturbance_observer.X", "4 entries"),
    (("disturbance_observer", "ros__parameters", "X"), [100, 0, 0, 100], "disturbance_observer.X", "floating-point"),
    (("plant_sim", "ros__parameters", "fall_angle"), float("nan"), "plant_sim.fall_angle", "finite"),
    (("dscndo_controller", "ros__parameters", "law"), "pid", "dscndo_controller.law", "one of 'dsc', 'lqr'"),
    (("plant_sim", "ros__parameters", "sensors"), {"delay_periods": 1.5}, "plant_sim.sensors.delay_periods",
     "integer"),
    (("plant_sim", "ros__parameters", "actuator"), {"delay_periods": -1}, "plant_sim.actuator.delay_periods",
     "from 0"),
    (("plant_sim", "ros__parameters", "sensors"), {"noise_std": {"theta_b": -0.1}},
     "plant_sim.sensors.noise_std.theta_b", ">= 0"),
    (("dscndo_controller", "ros__parameters", "lqr"), {"Q": [1.0, 1.0], "R": 0.01}, "dscndo_controller.lqr.Q",
     "3 entries"),
    (("dscndo_controller", "ros__parameters", "lqr"), {"Q": [1.0, 1.0, 1.0], "R": 0.0}, "dscndo_controller.lqr.R",
     "> 0"),
])
def test_bad_values_are_refused_naming_the_key(tmp_path, path, value, key, words):
    with pytest.raises(P.ParamError) as ei:
        _load(tmp_path, _mutate(path, value))
    assert ei.value.key == key
    assert f"'{key}'" in str(ei.value) and words in str(ei.value)
    assert "p.yaml" in str(ei.value)


@pytest.mark.parametrize("Q, words", [([100.0, 10.0, 0.0], NO_DESIGN), ([-1.0, 1.0, 1.0], "semidefinite")])
def test_lqr_weights_without_a_design_are_refused_naming_lqr_q(tmp_path, Q, words):
    """Checked whatever the law: a switch to lqr at run time must not be the first to fail."""
    pf = _load(tmp_path, _mutate(("dscndo_controller", "ros__parameters", "lqr"), {"Q": Q, "R": 0.01}))
    with pytest.raises(P.ParamError) as ei:
        P.merged_values(pf)
    assert ei.value.key == "lqr.Q" and words in ei.value.reason and "p.yaml" in str(ei.value)


def test_unknown_and_misspelled_keys(tmp_path):
    doc = _mutate(("dscndo_controller", "ros__parameters", "k3"), 1.0)
    with pytest.raises(P.ParamError, match="'dscndo_controller.k3'.*unknown parameter"):
        _load(tmp_path, doc)
    doc = copy.deepcopy(BASE)
    doc["plant_sim"]["ros__parameters"]["actual"]["m_bb"] = doc["plant_sim"]["ros__parameters"]["actual"].pop("m_b")
    with pytest.raises(P.ParamError, match="plant_sim.actual.m_bb.*did you mean 'actual.m_b'"):
        _load(tmp_path, doc)
    # a key in the wrong node's section says where it belongs
    doc = _mutate(("plant_sim", "ros__parameters", "k1"), 6.0)
    with pytest.raises(P.ParamError, match="'plant_sim.k1'.*belongs under dscndo_controller"):
        _load(tmp_path, doc)
    doc = copy.deepcopy(BASE)
    doc["dscndo_controler"] = doc.pop("dscndo_controller")
    with pytest.raises(P.ParamError, match="dscndo_controler.*unknown node name.*did you mean 'dscndo_controller'"):
        _load(tmp_path, doc)
    doc = copy.deepcopy(BASE)
    doc["plant_sim"] = {"ros_parameters": {}}
    with pytest.raises(P.ParamError, match="ros__parameters"):
        _load(tmp_path, doc)


def test_a_shared_file_may_configure_other_nodes_and_a_renamed_node_reads_its_own_section(tmp_path):
    doc = copy.deepcopy(BASE)
    doc["robot_state_publisher"] = {"ros__parameters": {"publish_frequency": 30.0, "robot_description": "<urdf/>"}}
    doc["/teleop/joy_node"] = {"ros__parameters": {"deadzone": 0.1}}
    doc["ctl_b"] = {"ros__parameters": {"k1": 7.5, "lqr": {"R": 0.02}}}
    pf = _load(tmp_path, doc)
    assert P.merged_values(pf) == P.merged_values(P.load_param_file(default_params_file()))   # ours unchanged
    assert set(pf.others) == {"robot_state_publisher", "joy_node", "ctl_b"}
    assert pf.section_for("dscndo_controller", "ctl_b") == {"k1": 7.5, "lqr.R": 0.02}
    doc["ctl_b"]["ros__parameters"]["k3"] = 1.0   # inside the node's own section, an unknown key is still refused
    with pytest.raises(P.ParamError, match="'ctl_b.k3'.*unknown parameter"):
        _load(tmp_path, doc).section_for("dscndo_controller", "ctl_b")


def test_ros_own_parameters_and_namespaced_sections_are_accepted(tmp_path):
    doc = copy.deepcopy(BASE)
    doc["/**"]["ros__parameters"]["use_sim_time"] = True
    doc["/robot1/plant_sim"] = doc.pop("plant_sim")
    pf = _load(tmp_path, doc)
    assert pf.for_node("plant_sim")["actual.m_b"] == 310.6
    doc["/**"]["ros__parameters"]["use_sim_time"] = "yes"
    with pytest.raises(P.ParamError, match="use_sim_time"):
        _load(tmp_path, doc)


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(P.ParamError, match="no such file"):
        P.load_param_file(tmp_path / "nope.yaml")
    f = tmp_path / "bad.yaml"
    f.write_text("plant_sim: [unclosed\n")
    with pytest.raises(P.ParamError, match="not valid YAML"):
        P.load_param_file(f)


def test_overrides_are_checked_the_same_way():
    pf = P.load_param_file(default_params_file())
    assert pf.for_node("dscndo_controller", {"k1": 7.0})["k1"] == 7.0
    with pytest.raises(P.ParamError, match="'k1'.*> 0"):
        pf.for_node("dscndo_controller", {"k1": -7.0})
    with pytest.raises(P.ParamError, match="'k1'.*7.0"):
        pf.for_node("dscndo_controller", {"k1": 7})
    with pytest.raises(P.ParamError, match="'k9'.*unknown"):
        pf.for_node("dscndo_controller", {"k9": 1.0})


def test_every_spec_default_passes_its_own_check():
    for node in P.NODE_SPECS:
        for name, spec in P.specs_for(node).items():
            spec.validate(spec.default)


@pytest.mark.parametrize("doc, said", [
    ({"/**": {"ros__parameters": {"control_rate_hertz": 100.0}}},
     "unknown parameter in the shared /** section (did you mean 'control_rate_hz'?)"),
    ({"/**": {"ros__parameters": {"k_1": 7.0}}},   # a node's key misspelt in the shared section: its node named
     "unknown parameter in the shared /** section (did you mean 'k1' under dscndo_controller:?)"),
    ({"dscndo_controller": {"ros__parameter": {"k1": 7.0}}},
     "exactly 'ros__parameters:': got 'ros__parameter' (did you mean 'ros__parameters'?)"),
    ({"dscndo_controller": {"ros__parameters": {"k_1": 7.0}}},
     "unknown parameter for dscndo_controller (did you mean 'k1'?)"),
])
def test_a_misspelt_key_anywhere_in_a_file_gets_a_did_you_mean(doc, said):
    """The same "did you mean" as a sweep spec's (params.schema.spelling_hint); the shared section had none."""
    with pytest.raises(P.ParamError) as err:
        P.parse_param_dict(doc, "typo.yaml")
    assert said in str(err.value), err.value
