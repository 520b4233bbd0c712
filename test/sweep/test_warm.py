"""The batch loop compiled before a sweep needs it, said where the user looks (mwip_ros.sweep.warm): the loops a
sweep's chunks run that numba's cache lacks, each once; compiled first with a line and a line every 5 s; the
shipped loops set-up compiles; the cache's answer. Nothing here compiles a batch loop (a test compiles one trivial
function)."""
import importlib
import re
import sys
import threading
from types import SimpleNamespace

import pytest
from graphproc import REPO

from mwip_ros import params as P
from mwip_ros.core.kernels import jitcache
from mwip_ros.params.paths import default_params_file
from mwip_ros.sweep import warm
from mwip_ros.sweep.engine import Chunk

pytestmark = pytest.mark.unit

CONFIG = default_params_file().parent


def _values(*files):
    return P.merged_values(P.load_param_files([CONFIG / f for f in files], option="params"))


def test_the_loops_a_sweep_lacks_are_found_once_each_with_a_chunk_that_compiles_them(monkeypatch):
    monkeypatch.setattr(jitcache, "cached", lambda kernel: False)   # a fresh clone: nothing cached
    state, raw = _values("paper.yaml"), _values("paper.yaml", "sensors_raw_realistic.yaml")
    ov = ({"seed": 1, "plant_sim.actual.m_b": 250.0}, {"seed": 2})
    chunks = [Chunk(0, law, state, ov, 10.0, (5.0, 10.0)) for law in ("dsc", "dscndo", "lqr", "lqr_ndo", "mpc")]
    chunks.append(Chunk(0, "dscndo", raw, ov, 10.0, (5.0, 10.0)))
    cold = warm.cold_kernels(chunks)
    assert [label for label, _ in cold] == ["dsc", "lqr", "dsc with raw sensors (kalman)"]   # dscndo: dsc's loop
    for _, c in cold:   # one scenario of the sweep's, a few periods
        assert len(c) == 1 and c.overrides[0] == ov[0] and c.duration_s == pytest.approx(warm.WARM_S)
    monkeypatch.setattr(jitcache, "cached", lambda kernel: True)
    assert warm.cold_kernels(chunks) == []


def test_compiling_first_says_so_and_says_it_again_every_few_seconds(monkeypatch):
    """mwip_sweep's first run in a fresh clone said nothing for 90 s while numba compiled.  Each loop "compiles"
    until the heartbeat has spoken twice more (an event, not a sleep: a busy machine delays the beats, not the
    test's verdict)."""
    monkeypatch.setattr(warm, "EVERY_S", 0.05)
    base = _values("paper.yaml")
    monkeypatch.setattr(warm, "cold_kernels", lambda chunks: [
        ("dsc", Chunk(0, "dsc", base, ({"seed": 1},), 0.1, (0.0, 0.1))),
        ("lqr", Chunk(0, "lqr", base, ({"seed": 1},), 0.1, (0.0, 0.1)))])
    ran, lines, said = [], [], threading.Condition()

    def say(line):
        with said:
            lines.append(line)
            said.notify_all()

    def beats():
        return [line for line in lines if "still compiling" in line]

    def runner(chunks):   # compiling: the loops one after the other, each over two beats
        for c in chunks:
            with said:
                n = len(beats())
                assert said.wait_for(lambda: len(beats()) >= n + 2, timeout=60), lines
            ran.append(c.controller)
            yield c, None
    spent = warm.compile_first(runner, [], say, "mwip_sweep")
    assert ran == ["dsc", "lqr"] and spent >= 4 * warm.EVERY_S   # four beats, EVERY_S apart at least
    assert lines[0].startswith("mwip_sweep: compiling the batch loop for dsc, lqr (numba")
    assert len(beats()) >= 4 and "(dsc, lqr)" in beats()[0] and "(lqr)" in beats()[-1]
    assert lines[-1].startswith("mwip_sweep: compiled in ")


def test_nothing_is_said_when_every_loop_is_cached(monkeypatch):
    monkeypatch.setattr(warm, "cold_kernels", lambda chunks: [])
    lines = []
    assert warm.compile_first(lambda c: iter(()), [], lines.append, "mwip_sweep") == 0.0 and lines == []


def test_set_up_compiles_each_built_in_loop_with_state_and_raw_sensors():
    chunks = warm.shipped_chunks()
    laws = {c.controller for c in chunks}   # (and a test's plug-in law with a pure step, registered by another test)
    assert {"dsc", "lqr", "smc"} <= laws   # one per pure step: dscndo's is dsc's; mpc has none
    assert not {"dscndo", "lqr_ndo", "smc_ndo", "mpc", "mpc_ndo"} & laws
    models = {(c.base.get("sensors.model"), c.base.get("method")) for c in chunks}
    assert models == {("state", "kalman"), ("raw", "kalman"), ("raw", "complementary")}
    assert len(chunks) == 3 * len(laws)


def test_the_cache_says_whether_a_functions_machine_code_is_there(tmp_path, monkeypatch):
    (tmp_path / "warm_probe.py").write_text("def twice(x):\n    return 2.0 * x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    mod = importlib.import_module("warm_probe")
    try:
        f = jitcache.jit(mod.twice)
        assert jitcache.cached(f) is False        # never compiled
        assert f(1.5) == 3.0
        assert jitcache.cached(f) is True
        g = jitcache.jit(mod.twice)               # another process's view: from the cache on disk
        assert jitcache.cached(g) is True
        assert jitcache.cached(SimpleNamespace()) is None   # not a dispatcher: not known
    finally:
        sys.modules.pop("warm_probe", None)


def test_set_up_runs_the_compile_after_the_install_unless_its_caller_does_it():
    """The first sweep of a fresh clone at the speed of the next (issue 47 item 5: 99.9 s before, nothing said; 8.8 s
    after scripts/setup.sh at a load average of 4): setup.sh, which run_experiment.sh and test.sh run first, runs
    ``python -m mwip_ros.sweep.warm`` once the package is installed and before it stamps the environment up to date,
    except with MWIP_SETUP_WARM=0 (scripts/test.sh compiles them itself)."""
    script = (REPO / "scripts" / "setup.sh").read_text()
    code = [line.strip() for line in script.splitlines() if line.strip() and not line.strip().startswith("#")]
    warm_at = next(i for i, line in enumerate(code) if re.search(r"-m mwip_ros\.sweep\.warm( |$)", line))
    install_at = max(i for i, line in enumerate(code) if "pip_install" in line and "-e ." in line)
    stamp_at = next(i for i, line in enumerate(code) if line.startswith('echo "$WANT" > "$STAMP"'))
    assert install_at < warm_at < stamp_at
    assert 'if [ "${MWIP_SETUP_WARM:-1}" = "0" ]; then' in code[warm_at - 3:warm_at]
