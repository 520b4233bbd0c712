"""Parameter ranges and choices are data on the ParamSpec (``lo``, ``hi``, ``lo_open``, ``floor``, ``choices``):
the start-up and run-time check, the ROS parameter descriptor and the ``--help`` text are all derived from
them, and the derived inertia check is the model's (mwip_ros.core.plants.model), not a copy of eq. (2)."""
from __future__ import annotations

import math

import pytest

from mwip_ros import params as P
from mwip_ros.params import schema

pytestmark = pytest.mark.unit


def _every_spec():
    seen = {}
    for node in P.NODE_SPECS:
        for name, spec in P.specs_for(node).items():
            seen.setdefault((node if spec not in P.SHARED_SPECS else "/**", name), spec)
    return seen


SPECS = _every_spec()


def test_every_number_has_its_range_as_data_and_every_array_rule_its_words():
    for (node, name), spec in SPECS.items():
        if spec.type == "double":
            assert spec.lo is not None and spec.hi is not None and spec.lo < spec.hi, (node, name)
        elif spec.type == "integer":
            assert spec.lo is not None, (node, name)
        elif spec.rule is not None:
            assert spec.type.endswith("_array") and spec.words, (node, name)
        if spec.choices is not None:
            assert spec.type == "string" and spec.default in spec.choices, (node, name)
        assert spec.check(spec.default) is None, (node, name)       # every default is accepted


def test_the_check_follows_lo_hi_and_choices():
    for (node, name), spec in SPECS.items():
        lo, hi = spec.lo, spec.hi
        if spec.type == "double":
            above = math.nextafter(hi, math.inf)
            assert spec.check(hi) is None and spec.check(above) is not None, (node, name)
            assert (spec.check(lo) is None) == (not spec.lo_open and spec.floor is None), (node, name)
            assert spec.check(math.nextafter(lo, -math.inf)) is not None, (node, name)
            if spec.floor is not None:
                assert spec.check(spec.floor) is None and spec.check(math.nextafter(spec.floor, 0.0)) is not None
            with pytest.raises(P.ParamError, match=f"parameter '{name}': must be "):
                spec.validate(above, name)
        elif spec.type == "integer":
            assert spec.check(lo) is None and spec.check(lo - 1) is not None, (node, name)
            if hi is not None:
                assert spec.check(hi) is None and spec.check(hi + 1) is not None, (node, name)
        elif spec.choices is not None:
            assert all(spec.check(c) is None for c in spec.choices)
            assert spec.check("nothing of the kind") == (
                f"must be one of {', '.join(map(repr, spec.choices))}, got 'nothing of the kind'")


def test_the_wording_users_see():
    plant = P.specs_for("plant_sim")
    ctl = P.specs_for("dscndo_controller")
    assert plant["duration_s"].check(2e7) == "must be <= 1e+07 (far beyond any robot of this kind), got 20000000.0"
    assert ctl["k1"].check(0.0) == "must be > 0, got 0.0"
    assert ctl["tau4"].check(1e-9) == ("must be >= 1e-06 (a filter faster than a microsecond is no filter), "
                                       "got 1e-09")
    assert ctl["tau4"].check(2e6) == "must be <= 1e+06, got 2000000.0"
    assert plant["substeps"].check(0) == "must be >= 1, got 0"
    assert plant["sensors.delay_periods"].check(-1) == "must be a whole number from 0 to 100000, got -1"
    assert plant["realtime_priority"].check(100) == ("must be 0 (normal scheduling) or a SCHED_FIFO priority "
                                                     "1..99, got 100")
    assert P.specs_for("disturbance_observer")["X"].check([1.0]) == "must have 4 entries [c1, c2, c3, c4], got 1"


def test_descriptors_are_derived_from_the_data():
    from rcl_interfaces.msg import ParameterType

    from mwip_ros.nodes.runtime.params import _descriptor

    for (node, name), spec in SPECS.items():
        d = _descriptor(spec)
        assert d.description == spec.description and d.read_only == (not spec.dynamic), (node, name)
        if spec.type == "double":
            (r,) = d.floating_point_range
            assert (r.from_value, r.to_value, r.step) == (spec.lo, spec.hi, 0.0) and not d.integer_range
            assert d.type == ParameterType.PARAMETER_DOUBLE
        elif spec.type == "integer":
            (r,) = d.integer_range
            assert (r.from_value, r.to_value, r.step) == (spec.lo, schema.INT32_MAX if spec.hi is None else spec.hi, 1)
        else:
            assert not d.floating_point_range and not d.integer_range
        if spec.choices is not None:
            assert d.additional_constraints == f"must be one of {', '.join(map(repr, spec.choices))}"
    k1 = _descriptor(P.specs_for("dscndo_controller")["k1"])
    assert k1.additional_constraints == "must be > 0" and not k1.read_only and k1.dynamic_typing
    assert _descriptor(P.specs_for("plant_sim")["duration_s"]).additional_constraints == "must be >= 0"
    assert _descriptor(P.specs_for("plant_sim")["initial.theta_b"]).additional_constraints == ""


def test_help_ranges_are_derived_from_the_data():
    from mwip_ros.nodes.runtime.params import range_text

    plant, ctl = P.specs_for("plant_sim"), P.specs_for("dscndo_controller")
    assert range_text(plant["duration_s"]) == "[0, 1e+07]"
    assert range_text(plant["fall_angle"]) == "(0, 3.14159]"
    assert range_text(ctl["tau4"]) == "[1e-06, 1e+06]"          # the floor, not the open 0
    assert range_text(plant["sensors.delay_periods"]) == "0..100000"
    assert range_text(plant["substeps"]) == ">= 1"
    assert range_text(plant["realtime_priority"]) == "0 (normal scheduling) or a SCHED_FIFO priority 1..99"
    assert range_text(ctl["law"]) == f"one of {', '.join(map(repr, ctl['law'].choices))}"
    assert range_text(ctl["lqr.Q"]) == ctl["lqr.Q"].words and range_text(plant["csv"]) == ""


def test_the_derived_inertia_check_is_the_models(monkeypatch):
    from mwip_ros.core.plants import model

    base = P.defaults_for("plant_sim")
    P.check_derived(base)
    nominal = model.PhysicalParams(**{k: base[f"nominal.{k}"] for k in P.PAPER_NOMINAL})
    monkeypatch.setattr(model.PhysicalParams, "A_bar", property(lambda self: -1.0))
    with pytest.raises(P.ParamError, match="parameter 'nominal.m_b': the nominal model's inertia terms") as e:
        P.check_derived(base, "start-up value")
    assert (f"m11 = {nominal.m11:g}, m12 = {nominal.m12:g}, m22 = {nominal.m22:g}, A_bar = -1" in e.value.reason)
    monkeypatch.undo()
    flat = dict(base, **{"actual.m_b": 1e6, "actual.l": 1e6, "actual.r": 1e6, "actual.m_w": 1e-300,
                         "actual.I_w": 1e-300, "actual.I_b": 1e-300})   # each within its range; A_bar rounds to 0
    with pytest.raises(P.ParamError, match=r"parameter 'actual.m_b': .*A_bar = 0\)"):
        P.check_derived(flat)
