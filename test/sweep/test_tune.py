"""The tuner's objective, constraint and bounds."""
import math

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.params.paths import default_params_file
from mwip_ros.sweep.spec import SpecError, parse_spec
from mwip_ros.sweep.tune import FALL_PENALTY, INADMISSIBLE, Objective, Tuner, apply, knobs_for, parse_bounds

pytestmark = pytest.mark.unit


def spec(**over):
    doc = {"base": str(default_params_file()), "duration_s": 2.0, "metrics_window_s": [1.0, 2.0], "seed": 2,
           "samples": 3, "vary": {"plant_sim.actual.m_b": {"scale": [0.8, 1.2]},
                                  "plant_sim.initial.theta_b": {"values": [-0.2, 0.95]},
                                  "plant_sim.torque_limit": {"values": [300.0]}}}
    doc.update(over)
    return parse_spec(doc, "spec.yaml")


def test_the_objective_is_the_mean_cost_of_each_scenarios_own_run():
    s = spec()
    knobs = knobs_for(["k1", "X"], "dsc")
    obj = Objective(s, "dscndo", knobs, weight=1e-3)
    x = np.array([[5.0, 150.0, 120.0], [4.0, 90.0, 110.0]])
    cost = obj.per_scenario(x)
    assert cost.shape == (2, 6)
    for j in range(2):
        for i in range(6):
            v = dict(s.base_values, **obj.scenarios.overrides(i), **apply(knobs, x[j], s.base_values))
            run = simulate(P.closed_loop(v, use_observer=True, duration=2.0))
            m = metrics.compute(run.columns, s.window, v["fall_angle"])
            want = m.theta_b_rms + 1e-3 * m.u_rms if m.upright else FALL_PENALTY
            assert cost[j, i] == pytest.approx(want, rel=1e-9), (j, i)
    assert (cost == FALL_PENALTY).any() and (cost < FALL_PENALTY).any()   # 0.95 rad with |u| <= 300 falls
    np.testing.assert_allclose(obj(x), cost.mean(axis=1))
    assert obj.best[0] == cost.mean(axis=1).min()


def test_a_candidate_breaking_theorem_2_is_not_simulated_and_costs_more_than_any_fall():
    s = spec()
    obj = Objective(s, "dscndo", knobs_for(["k1", "tau4"], "dsc"), weight=0.0)
    bad = np.array([[20.0, 0.5]])   # a3 = 1/tau4 - 3 k1 / 2 - ... < 0
    cost = obj.per_scenario(bad)
    assert obj.steps == 0 and (cost > INADMISSIBLE).all() and INADMISSIBLE > FALL_PENALTY
    # LQR has no such constraint
    lqr = Objective(s, "lqr", knobs_for(["lqr.R"], "lqr"), weight=0.0)
    assert lqr.admissibility([0.05]) == 0.0


@pytest.mark.parametrize("names, law, words", [
    (["tau5"], "dsc", "did you mean 'tau4'"), (["k1"], "lqr", "DSC gain"), (["lqr.R"], "dsc", "lqr laws")])
def test_unknown_or_foreign_knobs_are_refused(names, law, words):
    with pytest.raises(SpecError) as e:
        knobs_for(names, law)
    assert words in e.value.reason


@pytest.mark.parametrize("given, words", [
    (["k1=5:2"], "empty"), (["k1=0:5"], "> 0"), (["k1=-1:5"], "> 0"), (["k9=1:2"], "not tuned"),
    (["k1=1"], "name=low:high"), (["k1=a:b"], "numbers"),
    (["k1=2e6:3e6"], "low = 2e+06 is outside the parameter's range: k1 must be <= 1e+06"),   # the schema's (0, 1e6]
    (["k2=1:1e7"], "high = 1e+07 is outside")])
def test_bad_bounds_are_refused(given, words):
    with pytest.raises(SpecError) as e:
        parse_bounds(knobs_for(["k1", "k2"], "dsc"), given)
    assert e.value.key == "--bounds" and words in e.value.reason


def test_the_search_is_seeded_and_keeps_the_best_it_saw():
    s = spec(samples=2)
    runs = []
    for _ in range(2):
        obj = Objective(s, "dscndo", knobs_for(["k1"], "dsc"), weight=1e-4)
        x, j, gens = Tuner(obj, [(2.0, 6.0)], seed=3, maxiter=2, popsize=3).run()
        runs.append((x.tolist(), j))
        assert 2.0 <= x[0] <= 6.0 and j == obj.best[0] and gens >= 1
    assert runs[0] == runs[1]
    assert math.isfinite(runs[0][1])


def test_the_state_estimator_is_tunable_like_any_other_knob():
    """A raw-sensor loop's estimator parameter: a knob of the state_estimator section, set in the merged values
    and written to the overlay under state_estimator."""
    from mwip_ros.sweep.tune import overlay
    (k,) = knobs_for(["kalman.bias_walk"], "dscndo")
    assert (k.section, k.param) == ("state_estimator", "kalman.bias_walk")
    base = P.merged_values(P.load_param_file(default_params_file()))
    assert apply([k], [0.002], base) == {"kalman.bias_walk": 0.002}
    assert overlay([k], [0.002], base) == {("state_estimator", "kalman.bias_walk"): 0.002}
