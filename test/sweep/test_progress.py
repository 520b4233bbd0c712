"""A sweep's time left knows each law's cost: after the fast laws' chunks, the slow law's runs left are priced at
the slow law's rate (the naive estimate, elapsed x runs left / runs done, said seconds where minutes were left);
slow laws come in small chunks and every law's first chunk comes early, so progress keeps moving."""
import io
import time
from types import SimpleNamespace

import pytest

from mwip_ros.cli import sweep as S
from mwip_ros.params.paths import default_params_file
from mwip_ros.sweep import engine
from mwip_ros.sweep.progress import Eta, describe_left
from mwip_ros.sweep.scenarios import expand
from mwip_ros.sweep.spec import parse_spec

pytestmark = pytest.mark.unit



class Chunk(SimpleNamespace):
    def __len__(self):
        return self.n


def fake_chunks():
    """4 chunks of 500 runs of a fast law (0.5 s each), 10 of 10 runs of a slow one (5 s each)."""
    return [Chunk(controller="fast", n=500, seconds=0.5) for _ in range(4)] + \
           [Chunk(controller="slow", n=10, seconds=5.0) for _ in range(10)]


def test_the_time_left_prices_each_laws_runs_at_that_laws_measured_cost():
    chunks = fake_chunks()
    eta = Eta(chunks)
    for c in chunks[:4]:                       # the fast law done
        eta.done(c.controller, len(c), c.seconds)
    left, untimed = eta.estimate(workers=1)
    assert untimed == ["slow"] and left == 0.0   # the slow law's cost is not known yet: said, not guessed
    assert describe_left(left, untimed) == "time left not known yet (slow not timed yet)"
    assert describe_left(12.4, ["slow"]) == "more than 12 s left (slow not timed yet)"
    eta.done("slow", 10, 5.0)
    left, untimed = eta.estimate(workers=1)
    assert untimed == [] and left == pytest.approx(9 * 5.0)
    elapsed, done, total = 4 * 0.5 + 5.0, 2010, 2100
    naive = elapsed * (total - done) / done     # the old estimate: 0.3 s
    assert naive < 1.0 and left > 40 * naive
    assert eta.estimate(workers=2)[0] == pytest.approx(9 * 5.0 / 2)


def test_a_laws_first_chunk_with_its_one_off_costs_is_left_out_once_a_second_is_timed():
    eta = Eta([Chunk(controller="a", n=100, seconds=0) for _ in range(4)])
    eta.done("a", 100, 12.0)                   # numba compiling the loop: 12 s for 100 runs of 0.01 s
    assert eta.cost("a") == pytest.approx(0.12)
    eta.done("a", 100, 1.0)
    assert eta.cost("a") == pytest.approx(0.01) and eta.estimate()[0] == pytest.approx(2.0)


def test_the_plain_progress_line_says_the_weighted_time_left(monkeypatch):
    chunks = fake_chunks()
    err = io.StringIO()
    monkeypatch.setattr(S.sys, "stderr", err)
    clock = [100.0]
    monkeypatch.setattr(S.time, "monotonic", lambda: clock[0])
    p = S._Progress(chunks, quiet=False)
    for c in chunks[:5]:                       # the fast law, then one slow chunk: 7 s of wall time
        clock[0] += c.seconds
        p.update(c, SimpleNamespace(steps=len(c) * 2000, seconds=c.seconds))
    line = err.getvalue().strip().splitlines()[-1]
    p.close()
    assert "2,010/2,100 runs (96 %)" in line and line.endswith("45 s left"), line


@pytest.mark.alone   # the lines' rhythm is on the wall clock
def test_a_plain_progress_line_comes_every_5_s_while_no_chunk_finishes(monkeypatch):
    """sweeps.md's promise: a line every 5 s, also while a chunk of a slow configuration runs for tens of seconds
    (laws_mass_mismatch_realistic.yaml said nothing for 27 s, then a line every 30 s). Here every 0.05 s."""
    err = io.StringIO()
    monkeypatch.setattr(S.sys, "stderr", err)
    monkeypatch.setattr(S._Progress, "EVERY_S", 0.05)
    chunks = fake_chunks()
    p = S._Progress(chunks, quiet=False)
    try:
        deadline = time.monotonic() + 3.0
        while err.getvalue().count("\n") < 3 and time.monotonic() < deadline:
            time.sleep(0.01)   # no chunk finishes meanwhile
        first = err.getvalue().splitlines()
        p.update(chunks[0], SimpleNamespace(steps=500 * 2000, seconds=0.5))
        while err.getvalue().count("500/2,100 runs") < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        p.close()
    lines = err.getvalue().splitlines()
    assert len(first) >= 3 and all("0/2,100 runs (0 %)" in line and "time left not known yet" in line
                                   for line in first[:3]), first
    after = lines[lines.index(next(ln for ln in lines if "500/2,100" in ln)):]
    assert sum("500/2,100 runs (24 %)" in line for line in after) >= 3 and "0/2,100 runs (0 %)" not in after, lines
    n = len(lines)
    time.sleep(0.2)
    assert len(err.getvalue().splitlines()) == n   # closed: silent


def test_a_law_the_batch_cannot_compile_comes_in_small_chunks_and_the_laws_take_turns():
    s = parse_spec({"base": str(default_params_file()), "duration_s": 1.0, "metrics_window_s": [0.5, 1.0],
                    "samples": 120, "vary": {"plant_sim.actual.m_b": {"scale": [0.9, 1.1]}},
                    "controllers": ["dsc", "mpc", "lqr_ndo"]}, "spec.yaml")
    chunks = engine.make_chunks(s, expand(s), chunk_size=100)
    assert [(c.controller, c.first, len(c)) for c in chunks] == [   # the slow law's first chunk first
        ("mpc", 0, engine.SLOW_CHUNK), ("dsc", 0, 100), ("lqr_ndo", 0, 100),
        ("mpc", 50, 50), ("dsc", 100, 20), ("lqr_ndo", 100, 20), ("mpc", 100, 20)]
    assert engine.chunk_size_for("mpc", 10) == 10 and engine.chunk_size_for("dsc", 10) == 10
    # an observer variant compiles as its base law does: large chunks
    assert [engine.chunk_size_for(n) for n in ("dscndo", "smc_ndo", "mpc_ndo")] == [engine.DEFAULT_CHUNK] * 2 + [50]


def test_a_chunk_result_says_how_long_it_took():
    s = parse_spec({"base": str(default_params_file()), "duration_s": 0.2, "metrics_window_s": [0.1, 0.2],
                    "samples": 2, "vary": {"plant_sim.actual.m_b": {"scale": [0.9, 1.1]}},
                    "controllers": ["lqr"]}, "spec.yaml")
    (c,) = engine.make_chunks(s, expand(s))
    assert engine.run_chunk(c).seconds > 0
