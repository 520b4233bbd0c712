"""Scenarios: the grid times the draws, reproducible, checked before anything runs; a scenario's parameter file."""
import pytest

from mwip_ros import params as P
from mwip_ros.params.paths import default_params_file
from mwip_ros.sweep.scenarios import expand, noise_seed, parameter_file
from mwip_ros.sweep.spec import SpecError, parse_spec

pytestmark = pytest.mark.unit


def spec(vary, samples=4, seed=7):
    return parse_spec({"base": str(default_params_file()), "duration_s": 1.0, "seed": seed, "samples": samples,
                       "vary": vary}, "spec.yaml")


def test_grid_points_times_draws_in_order_and_scale_multiplies_the_base():
    s = spec({"plant_sim.tau_ext1.amplitude": {"grid": [0.0, 30.0]}, "plant_sim.initial.theta_b": {"grid": [-0.1, 0.1]},
              "plant_sim.actual.m_b": {"scale": [0.5, 0.6]}})
    sc = expand(s)
    assert len(sc) == 2 * 2 * 4
    amp, th = sc.values["plant_sim.tau_ext1.amplitude"], sc.values["plant_sim.initial.theta_b"]
    assert amp == [0.0] * 8 + [30.0] * 8            # the first grid axis varies slowest
    assert th == ([-0.1] * 4 + [0.1] * 4) * 2        # then the next; draws innermost
    m = sc.values["plant_sim.actual.m_b"]
    base = s.base_values["actual.m_b"]
    assert all(0.5 * base <= v <= 0.6 * base for v in m) and len(set(m)) == len(m)
    assert sc.seeds == [noise_seed(7, i) for i in range(16)] and len(set(sc.seeds)) == 16
    assert sc.overrides(5) == {"tau_ext1.amplitude": 0.0, "initial.theta_b": 0.1, "actual.m_b": m[5],
                               "seed": sc.seeds[5]}


def test_the_same_spec_draws_the_same_scenarios_and_another_seed_others():
    v = {"dscndo_controller.k1": {"uniform": [2.0, 10.0]}}
    assert expand(spec(v)).values == expand(spec(v)).values
    assert expand(spec(v)).values != expand(spec(v, seed=8)).values


def test_a_varied_seed_is_the_noise_seed():
    sc = expand(spec({"plant_sim.seed": {"values": [3, 4]}}))
    assert sc.seeds == [3, 4]


def test_a_normal_draw_outside_the_range_is_refused_before_running():
    with pytest.raises(SpecError) as e:
        expand(spec({"dscndo_controller.k1": {"normal": [0.5, 2.0]}}, samples=200))
    assert (e.value.key == "vary.dscndo_controller.k1" and "must be > 0" in e.value.reason
            and "scenario" in e.value.reason)


def test_a_scenario_parameter_file_is_complete_and_reads_back(tmp_path):
    pf = P.load_param_file(default_params_file())
    out = tmp_path / "s.yaml"
    parameter_file(pf.sections, {("plant_sim", "actual.m_b"): 250.125, ("dscndo_controller", "k1"): 4.5,
                                 ("/**", "nominal.l"): 0.3, ("plant_sim", "seed"): 99,
                                 ("disturbance_observer", "X"): [50.0, 0.0, 0.0, 50.0]}, out, "# hello\n")
    text = out.read_text()
    assert text.startswith("# hello\n") and "X: [50.0, 0.0, 0.0, 50.0]" in text
    back = P.load_param_file(out)
    v = P.merged_values(back)
    assert (v["actual.m_b"], v["k1"], v["nominal.l"], v["seed"]) == (250.125, 4.5, 0.3, 99)
    for node in ("plant_sim", "disturbance_observer", "dscndo_controller"):   # every parameter written out, but an
        specs = P.specs_for(node)   # empty array (ROS reads [] as a byte array): left out, it is its default
        empty = {n for n, s in specs.items() if isinstance(s.default, (list, tuple)) and not s.default}
        names = set(specs) - {s.name for s in P.SHARED_SPECS} - empty
        assert names <= set(back.sections[node]), node
        assert not empty & set(back.sections[node]) and "[]" not in text, node
