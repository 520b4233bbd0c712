"""Sizes a user can ask for are checked against the memory budget (mwip_ros.core.kernels.budget) before memory is spent.

samples, grid points, duration, the metrics window, delay queues and workers: a spec or a command beyond
the budget is refused with one line naming the key and the numbers (exit 2), in well under a second of
work; a chunk too large for one simulation batch runs as several, with the same results; the shipped
specs pass unchanged."""
from __future__ import annotations

import random
import time
from pathlib import Path

import numpy as np
import pytest

from mwip_ros.core.kernels import budget
from mwip_ros.sweep import engine
from mwip_ros.sweep.scenarios import expand
from mwip_ros.sweep.spec import SpecError, load_spec

from hostile import PAPER, REPO, assert_refused, measured  # noqa: E402  (test/hostile.py)

pytestmark = pytest.mark.unit


def spec_file(tmp_path: Path, body: str, base: str = None) -> Path:
    p = tmp_path / "spec.yaml"
    p.write_text(f"base: {base or PAPER}\ncontrollers: [dsc, dscndo]\n{body}")
    return p


def refused(path, key: str, *words):
    t0 = time.process_time()   # CPU, not wall: a loaded machine stretches the wall, not the work refused
    with pytest.raises(SpecError) as exc:
        load_spec(path)
    assert time.process_time() - t0 < 2.0
    assert exc.value.key == key, str(exc.value)
    for w in words:
        assert w in str(exc.value), str(exc.value)
    return str(exc.value)


@pytest.fixture(autouse=True)
def default_budget(monkeypatch):
    monkeypatch.delenv(budget.BUDGET_ENV, raising=False)


def test_the_shipped_specs_pass_the_checks():
    from mwip_ros.sweep.spec import SWEEP_BACKENDS
    for p in sorted((REPO / "config" / "sweeps").glob("*.yaml")):
        s = load_spec(p, backends=SWEEP_BACKENDS)   # as mwip_sweep reads them (terrain_slope: backend mujoco)
        assert budget.sweep_table_bytes(s.n_scenarios, len(s.axes), len(s.controllers)) < budget.DEFAULT_BUDGET / 10


def test_samples_at_the_old_maximum_are_refused_before_anything_is_built(tmp_path):
    text = refused(spec_file(tmp_path, "samples: 50000000\nvary:\n  plant_sim.actual.m_b: {scale: [0.7, 1.3]}\n"),
                   "samples", "50,000,000 scenarios x 2 law(s)", "GiB", "the memory budget is 2.0 GiB",
                   budget.BUDGET_ENV)
    assert "\n" not in text


def test_a_linspace_count_is_checked_without_listing_it(tmp_path, monkeypatch):
    from mwip_ros.sweep.spec import Axis

    def no_listing(self):
        raise AssertionError("load_spec listed a grid axis' values")

    monkeypatch.setattr(Axis, "grid_values", no_listing)   # a regression fails here, before a 1e9-entry list
    p = spec_file(tmp_path, "vary:\n  plant_sim.tau_ext1.amplitude: {linspace: [200, 400, 1000000000]}\n")
    refused(p, "vary", "1,000,000,000 scenarios")
    p = spec_file(tmp_path, "vary:\n  plant_sim.tau_ext1.amplitude: {linspace: [200.0, 400.0, 10000000]}\n")
    refused(p, "vary", "10,000,000 scenarios x 2 law(s)", "memory budget")   # under MAX_SCENARIOS, over the budget


def test_a_long_duration_is_refused_for_its_window(tmp_path):
    p = spec_file(tmp_path, "duration_s: 100000\nsamples: 10\nvary:\n  plant_sim.actual.m_b: {scale: [0.7, 1.3]}\n")
    refused(p, "duration_s", "10,000,001 samples", "512.0 MiB")
    p = spec_file(tmp_path, "duration_s: 100000\nmetrics_window_s: [0.0, 50000.0]\n")
    refused(p, "metrics_window_s", "[0, 50000] s at 200 Hz is 10,000,001 samples")
    # the same run with a short window fits: the window, not the duration, is what a batch keeps
    assert load_spec(spec_file(tmp_path, "duration_s: 100000\nmetrics_window_s: [99990.0, 100000.0]\n"))


def test_a_varied_control_rate_counts_at_its_fastest(tmp_path):
    p = spec_file(tmp_path, "duration_s: 10000\nmetrics_window_s: [0.0, 10000.0]\n"
                            "vary:\n  control_rate_hz: {grid: [100.0, 1000.0]}\n")
    refused(p, "metrics_window_s", "at 1000 Hz")


def test_the_budget_can_be_raised_or_lowered(tmp_path, monkeypatch):
    p = spec_file(tmp_path, "samples: 2000000\nvary:\n  plant_sim.actual.m_b: {scale: [0.7, 1.3]}\n")
    refused(p, "samples", "2,000,000 scenarios")
    monkeypatch.setenv(budget.BUDGET_ENV, "64G")
    assert load_spec(p).n_scenarios == 2_000_000
    monkeypatch.setenv(budget.BUDGET_ENV, "lots")
    refused(p, budget.BUDGET_ENV, "is not a size")


def test_a_chunk_beyond_the_batch_budget_runs_as_several_batches_with_the_same_results(tmp_path, monkeypatch):
    delay = tmp_path / "delay.yaml"
    delay.write_text("plant_sim:\n  ros__parameters:\n    sensors:\n      delay_periods: 100000\n")
    p = spec_file(tmp_path, "duration_s: 0.5\nmetrics_window_s: [0.0, 0.5]\nsamples: 12\nvary:\n"
                            "  plant_sim.actual.m_b: {scale: [0.7, 1.3]}\n", base=f"[{PAPER}, {delay}]")
    s = load_spec(p)
    sc = expand(s)
    chunk = engine.make_chunks(s, sc, chunk_size=100)[0]
    per, fixed = engine.scenario_cost(dict(s.base_values, **sc.overrides(0)), s.duration_s, s.window)
    import mwip_ros.core.kernels.batch as B
    sizes, real = [], B.simulate_batch
    monkeypatch.setattr(B, "simulate_batch", lambda loops, window, **k: (sizes.append(len(loops)),
                                                                         real(loops, window, **k))[1])
    whole = engine.run_chunk(chunk)
    assert sizes == [12]
    sizes.clear()
    split = engine.run_chunk(chunk, batch_bytes=fixed + 5 * per)
    assert sizes == [5, 5, 2] and all(n * per + fixed <= fixed + 5 * per for n in sizes)
    assert np.array_equal(whole.upright, split.upright) and whole.steps == split.steps
    for k in whole.metrics:
        assert np.array_equal(whole.metrics[k], split.metrics[k], equal_nan=True), k
    # a queue never holds more periods than the run has: a long delay on a short run costs little
    big = budget.scenario_batch_bytes(0, 100, 100_000, 0)
    assert big == budget.BATCH_SCENARIO + budget.BATCH_DELAY_PERIOD * 101


def test_the_window_is_found_without_listing_the_steps():
    rng = random.Random(3)
    for _ in range(3000):
        h = rng.choice([0.005, 1 / 300, 0.1, 1 / 7])
        n = rng.randint(0, 2000)
        a = rng.choice([0.0, rng.uniform(-1.0, n * h), round(rng.uniform(0, n * h) / h) * h])
        b = rng.choice([n * h, rng.uniform(a, n * h * 1.2), a])
        steps = [k for k in range(n + 1) if a - 1e-9 <= k * h <= b + 1e-9]   # what simulate_batch listed
        assert budget.window_samples(n, h, (a, b)) == ((steps[0] if steps else 0), len(steps))
    t0 = time.process_time()
    assert budget.window_samples(2 * 10 ** 9, 0.005, (5e6, 1e7)) == (10 ** 9, 10 ** 9 + 1)
    assert time.process_time() - t0 < 0.1


def test_workers_beyond_the_limit_are_refused():
    with pytest.raises(ValueError, match=r"--workers 100000: at most \d+ worker processes"):
        engine.Runner(100_000)
    with pytest.raises(ValueError, match=r"--dask local:N 100000: at most"):
        engine.Runner(1, dask="local:100000")
    assert engine.Runner(budget.max_workers()).workers == budget.max_workers()


def test_tune_refuses_a_search_beyond_the_budget(tmp_path):
    from mwip_ros.sweep.tune import check_memory, knobs_for
    p = spec_file(tmp_path, "samples: 200000\nvary:\n  plant_sim.actual.m_b: {scale: [0.7, 1.3]}\n")
    s = load_spec(p)
    knobs = knobs_for(["k1", "k2", "tau4", "X"], "dsc")
    with pytest.raises(SpecError, match=r"200,000 scenarios x 40 candidates per generation \(--popsize 8 x 5"):
        check_memory(s, knobs, 8)
    check_memory(s, knobs[:1], 1)
    check_memory(load_spec(REPO / "config" / "sweeps" / "tune_dscndo.yaml"), knobs, 8)


# --- the commands: exit 2, one line, fast, low memory -----------------------------------------------------

@pytest.mark.cli
def test_mwip_sweep_refuses_sizes_beyond_the_budget(tmp_path):
    out = tmp_path / "o"
    for body, words in [
        ("samples: 50000000\nvary:\n  plant_sim.actual.m_b: {scale: [0.7, 1.3]}\n", ("samples", "50,000,000")),
        ("vary:\n  plant_sim.tau_ext1.amplitude: {linspace: [200, 400, 1000000000]}\n", ("vary", "1,000,000,000")),
        ("duration_s: 100000\nsamples: 10\nvary:\n  plant_sim.actual.m_b: {scale: [0.7, 1.3]}\n", ("duration_s",)),
    ]:
        assert_refused(measured("mwip_ros.cli.sweep", [spec_file(tmp_path, body), "--out", out, "--workers", "1"]),
                       "mwip_sweep: error:", *words)
    assert not out.exists()


@pytest.mark.cli
def test_mwip_sim_refuses_a_duration_beyond_the_budget(tmp_path):
    assert_refused(measured("mwip_ros.cli.sim", ["--duration", "100000", "-q"]),
                   "mwip_sim: error: --duration 100000 s at 200 Hz is 20,000,001 rows", "memory budget is 2.0 GiB")
    long = tmp_path / "long.yaml"
    long.write_text("plant_sim:\n  ros__parameters:\n    duration_s: 1.0e+7\n    sensors:\n"
                    "      delay_periods: 100000\n")
    assert_refused(measured("mwip_ros.cli.sim", ["--params", PAPER, long, "-q", "--compare"]),
                   "plant_sim.duration_s 1e+07 s", "x 2 law(s)")


@pytest.mark.cli
def test_mwip_tune_refuses_a_search_beyond_the_budget(tmp_path):
    p = spec_file(tmp_path, "samples: 200000\nvary:\n  plant_sim.actual.m_b: {scale: [0.7, 1.3]}\n")
    assert_refused(measured("mwip_ros.cli.tune", [p, "--controller", "dscndo", "--tune", "k1", "k2", "tau4", "X",
                                                  "--out", tmp_path / "t.yaml", "--workers", "1"]),
                   "mwip_tune: error:", "samples", "candidates per generation")
    assert not (tmp_path / "t.yaml").exists()
