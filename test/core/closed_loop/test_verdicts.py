"""A run that fails is never scored upright (issue 30, item 1): a law commanding NaN or 1e300 (test/bad_laws.py), a
state that is not a number, and the model's own arithmetic failing end the run as a failure with its time and
cause, offline (core.closed_loop.sim), in the batch over numpy arrays and compiled (core.kernels.batch), and in the
metrics."""
import math

import numpy as np
import pytest

from mathfixtures import P_FILE, assert_batch_equals_scalar
from mwip_ros import params as P
from mwip_ros.core.kernels import batch as B
from mwip_ros.core.kernels import batch_numpy
from mwip_ros.core.closed_loop import loop, metrics
from mwip_ros.core.kernels.batch import simulate_batch
from mwip_ros.core.plants.plant import make_plant
from mwip_ros.core.closed_loop.sim import simulate

import bad_laws  # noqa: E402  registers nan_cmd, huge_cmd, raising

pytestmark = pytest.mark.unit

BASE = P.merged_values(P.load_param_file(P_FILE))
H = 1.0 / BASE["control_rate_hz"]
T_BAD = bad_laws.AFTER * H   # when the bad laws go wrong
WINDOW = (0.2, 1.0)          # covers T_BAD: the metrics see the rows before it


def _loop(name, **extra):
    return P.closed_loop(dict(BASE, **extra), controller=name, duration=1.0)


@pytest.mark.parametrize("name, said", [("nan_cmd", "u = nan is not finite"),
                                        ("huge_cmd", "|u| = 1e+300 N m > 1e+06 N m, implausible")])
def test_a_law_commanding_nan_or_1e300_fails_offline_at_that_period(name, said):
    run = simulate(_loop(name))
    assert run.fallen and len(run) == bad_laws.AFTER + 1            # row k = AFTER is the last
    assert run.record["t_fall"] == pytest.approx(T_BAD)
    assert run.record["fall_text"] == (f"FAILED at t = {T_BAD:.3f} s: the law's command is refused ({said})")
    assert run["u"][-1] == 0.0                                     # the driver refused it: no torque acted
    m = metrics.compute(run.columns, WINDOW, BASE["fall_angle"], run.record["t_fall"])
    assert not m.upright and m.t_fall == pytest.approx(T_BAD) and not m.covers_window


@pytest.mark.parametrize("name", ["nan_cmd", "huge_cmd"])
@pytest.mark.parametrize("compiled", [False, True])
def test_a_law_commanding_nan_or_1e300_fails_in_the_batch(name, compiled):
    loops = [_loop(name, seed=i) for i in range(3)]
    res = simulate_batch(loops, WINDOW, compiled=compiled)
    np.testing.assert_array_equal(res.fallen, [True] * 3)
    np.testing.assert_array_equal(res.upright, [False] * 3)
    np.testing.assert_allclose(res.t_fall, T_BAD)
    assert [B.FAILURES[c] for c in res.failure] == ["bad_command"] * 3
    # the rows before the failure are in the window, the refused one with zero torque, as offline
    scalar = metrics.compute(simulate(loops[0]).columns, WINDOW, BASE["fall_angle"], T_BAD)
    assert res.metrics["u_rms"][0] == pytest.approx(scalar.u_rms, rel=1e-9)
    assert np.isfinite(res.metrics["u_rms"][0])


@pytest.mark.parametrize("name", ["nan_cmd", "huge_cmd"])
def test_the_recorded_batch_of_a_bad_law_equals_the_scalar_loop_and_says_why(name):
    batch, _ = assert_batch_equals_scalar([_loop(name), _loop(name, seed=3)], WINDOW)
    assert [t.record for t in batch.trajectories] == [{"t_fall": pytest.approx(T_BAD), "failure": "bad_command"}] * 2


def test_the_models_arithmetic_failing_is_a_diverged_run_not_a_traceback(monkeypatch):
    """With the driver's limit lifted, 1e300 reaches eq. (1): offline its math fails (math domain error), the batch
    gets NaN; both end the run, diverged, at the same t."""
    monkeypatch.setattr(loop, "PLAUSIBLE_TORQUE", 0.0)        # 0: only a non-finite command is refused
    monkeypatch.setattr(batch_numpy, "PLAUSIBLE_TORQUE", math.inf)   # the numpy form's driver gate
    lp = _loop("huge_cmd", torque_limit=0.0)
    run = simulate(lp)
    assert run.fallen and run.record["t_fall"] == pytest.approx(T_BAD + H)
    assert "the state diverged" in run.record["fall_text"]
    res = simulate_batch([lp], WINDOW, compiled=False)
    assert B.FAILURES[res.failure[0]] == "diverged" and res.t_fall[0] == pytest.approx(T_BAD + H)
    assert not res.upright[0]


def test_a_state_that_is_not_a_number_has_fallen():
    plant = make_plant(P.plant_config(BASE))
    for x in ((0.0, math.nan, 0.0, 0.0), (0.0, 0.0, math.inf, 0.0), (math.nan, 0.0, 0.0, 0.0)):
        plant.x = type(plant.x)(*x)
        assert plant.fallen, x
    t = np.array([0.0, 0.005, 0.01])
    assert metrics.fall_time(t, [0.0, math.nan, 0.0], 0.5) == 0.005
    assert metrics.fall_time(t, [0.0, 0.1, math.inf], 0.5) == 0.01
    assert metrics.fall_time(t, [0.0, 0.1, -0.2], 0.5) is None
    m = metrics.compute({"t": t, "theta_b": np.array([0.0, math.nan, math.nan]), "u": np.zeros(3)}, (0.0, 0.01), 0.5)
    assert not m.upright and m.t_fall == 0.005


def test_the_torque_limit_never_turns_a_command_that_is_not_a_number_into_torque():
    from mwip_ros.core.plants.plant import saturate
    assert math.isnan(saturate(math.nan, 120.0)) and math.isnan(saturate(math.nan, 0.0))   # was +120 N m
    assert saturate(1e300, 120.0) == 120.0 and saturate(-math.inf, 120.0) == -120.0
    assert saturate(50.0, 120.0) == 50.0 and saturate(-130.0, 120.0) == -120.0 and saturate(7.0, 0.0) == 7.0


@pytest.mark.parametrize("bad", [(0.0, math.nan, 0.0, 0.0), (0.0, 0.05, math.inf, 0.0)])
def test_a_state_that_is_not_a_number_ends_the_run_diverged_alike_offline_and_in_both_batches(bad):
    """The state is checked before anything reads it: no row, diverged at that t (not a fall of a NaN angle, not the
    law's NaN command the state would make)."""
    from dataclasses import replace
    good = _loop("dscndo")
    lp = replace(good, plant=replace(good.plant, initial=type(good.plant.initial)(*bad)))
    run = simulate(lp)
    assert len(run) == 0 and run.fallen and run.record["failure"] == "diverged" and run.record["t_fall"] == 0.0
    for compiled in (False, True):
        res = simulate_batch([lp, good], WINDOW, compiled=compiled)
        assert [B.FAILURES[c] for c in res.failure] == ["diverged", ""], compiled
        assert res.t_fall[0] == 0.0 and list(res.upright) == [False, True], compiled
