"""A law that fails is never scored upright nor tuned as good, and a law that raises is named (issue 30, items 1
and 8): the sweep engine's rows, the tuner's objective (test/bad_laws.py's laws)."""
import math

import numpy as np
import pytest

from mwip_ros.core import laws
from mwip_ros.core.kernels import batch as B
from mwip_ros.params.paths import default_params_file
from mwip_ros.sweep import engine
from mwip_ros.sweep.scenarios import expand
from mwip_ros.sweep.spec import parse_spec
from mwip_ros.sweep.tune import FALL_PENALTY, INADMISSIBLE, Objective, knobs_for

import bad_laws  # noqa: E402  registers nan_cmd, huge_cmd, raising

pytestmark = pytest.mark.unit

T_BAD = bad_laws.AFTER / 200.0


def spec(**over):
    doc = {"base": str(default_params_file()), "duration_s": 1.0, "metrics_window_s": [0.2, 1.0], "seed": 2,
           "samples": 1, "vary": {"plant_sim.initial.theta_b": {"values": [-0.1, 0.0, 0.1]}}}
    doc.update(over)
    return parse_spec(doc, "spec.yaml")


def _chunk(law, first=0):
    s = spec()
    sc = expand(s)
    return engine.Chunk(first, law, s.base_values, tuple(sc.overrides(i) for i in range(len(sc))), s.duration_s,
                        s.window)


@pytest.mark.parametrize("law", ["nan_cmd", "huge_cmd"])
def test_a_sweep_row_of_a_law_commanding_nan_or_1e300_is_a_failure_with_its_time_and_cause(law):
    res = engine.run_chunk(_chunk(law))
    assert not res.upright.any()
    np.testing.assert_allclose(res.t_fall, T_BAD)
    assert [B.FAILURES[c] for c in res.failure] == ["bad_command"] * 3


def test_a_law_that_raises_in_a_sweep_is_named_with_its_scenario_and_its_own_error():
    """Over the batch's arrays the law's ``if`` raised numpy's ValueError (an ambiguous truth value) instead."""
    with pytest.raises(laws.LawError) as e:
        engine.run_chunk(_chunk("raising", first=10))
    assert e.value.law == "raising" and e.value.scenario == 10 and e.value.t == pytest.approx(T_BAD)
    assert str(e.value) == (f"the law 'raising' raised at t = {T_BAD:.3f} s in scenario 10: "
                            "RuntimeError: raising law's own error")


@pytest.mark.parametrize("law", ["nan_cmd", "huge_cmd"])
def test_the_tuner_scores_a_failing_law_as_falls_never_as_good(law):
    obj = Objective(spec(), law, knobs_for(["k1"], "dsc"), weight=1e-3)
    good = Objective(spec(), "dscndo", knobs_for(["k1"], "dsc"), weight=1e-3)
    cost = obj.per_scenario(np.array([[6.0]]))
    assert (cost == FALL_PENALTY).all()
    assert good.per_scenario(np.array([[6.0]])).max() < FALL_PENALTY
    judged = obj.judge([6.0])
    assert judged["upright_share"] == 0.0 and math.isnan(judged["theta_b_rms_median"])


def test_a_stability_margin_of_nan_is_inadmissible(monkeypatch):
    obj = Objective(spec(), "dscndo", knobs_for(["k1"], "dsc"), weight=0.0)
    monkeypatch.setattr(laws.get("dscndo"), "stability_margin", classmethod(lambda cls, *a, **k: math.nan))
    assert obj.admissibility([6.0]) == -INADMISSIBLE
    assert (obj.per_scenario(np.array([[6.0]])) > INADMISSIBLE).all() and obj.steps == 0
