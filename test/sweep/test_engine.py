"""The sweep engine: chunks give the same rows whoever runs them, and each row is that scenario's mwip_sim run."""
import math

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.closed_loop.sim import LAWS, simulate
from mwip_ros.params.paths import default_params_file
from mwip_ros.sweep import engine
from mwip_ros.sweep.results import METRICS
from mwip_ros.sweep.scenarios import expand, parameter_file
from mwip_ros.sweep.spec import parse_spec

VARY = {"plant_sim.actual.m_b": {"scale": [0.7, 1.3]}, "plant_sim.actual.l": {"scale": [0.7, 1.3]},
        "dscndo_controller.k1": {"uniform": [3.0, 9.0]},
        "plant_sim.initial.theta_b": {"grid": [-0.2, 0.9]},
        "plant_sim.torque_limit": {"values": [300.0]}}   # |u| <= 300 N m: from 0.9 rad it falls


def small_spec(samples=3, duration=1.5, controllers=("dsc", "dscndo")):
    return parse_spec({"base": str(default_params_file()), "duration_s": duration, "metrics_window_s": [0.5, 1.5],
                       "seed": 3, "samples": samples, "vary": VARY, "controllers": list(controllers)}, "spec.yaml")


def rows(runner):
    out = {}
    for chunk, res in runner:
        for j in range(len(chunk)):
            out[(chunk.first + j, chunk.controller)] = (bool(res.upright[j]), float(res.t_fall[j]),
                                                        *(float(res.metrics[m][j]) for m in METRICS.values()))
    return out


def same(a, b):
    return a.keys() == b.keys() and all(
        all(x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y)) for x, y in zip(a[k], b[k]))
        for k in a)


@pytest.mark.unit
def test_each_row_equals_the_scalar_simulator_on_that_scenarios_parameter_file(tmp_path):
    s = small_spec(controllers=("dsc", "dscndo", "lqr", "lqr_ndo"))
    sc = expand(s)
    got = rows(engine.run_local(engine.make_chunks(s, sc, chunk_size=4), workers=1))
    fell = 0
    for (i, ctrl), row in got.items():
        f = tmp_path / f"s{i}_{ctrl}.yaml"
        placed = {(a.section, a.name): sc.values[a.key][i] for a in s.axes}
        placed.update({("plant_sim", "seed"): sc.seeds[i], ("plant_sim", "duration_s"): s.duration_s,
                       ("dscndo_controller", "use_observer"): LAWS[ctrl][1],
                       ("dscndo_controller", "law"): LAWS[ctrl][0]})
        parameter_file(s.base_sections, placed, f)
        v = P.merged_values(P.load_param_file(f))
        run = simulate(P.closed_loop(v))                    # what mwip_sim --params f runs
        assert run.label == ctrl
        m = metrics.compute(run.columns, s.window, v["fall_angle"])
        assert row[0] == m.upright and row[0] == (not run.fallen)
        if run.fallen:
            fell += 1
            assert row[1] == pytest.approx(run.t[-1], abs=1e-12)
        else:
            assert math.isnan(row[1])
        want = [getattr(m, name) for name in METRICS.values()]
        np.testing.assert_allclose(row[2:], want, rtol=0, atol=1e-9, equal_nan=True)
    assert 0 < fell < len(got)   # the set has both outcomes


@pytest.mark.unit
def test_local_workers_and_one_process_give_identical_rows():
    s = small_spec(samples=4)
    sc = expand(s)
    chunks = engine.make_chunks(s, sc, chunk_size=5)
    assert same(rows(engine.run_local(chunks, workers=1)), rows(engine.run_local(chunks, workers=2)))


@pytest.mark.unit
def test_scenarios_with_another_control_period_or_delay_run_in_their_own_batch():
    s = parse_spec({"base": str(default_params_file()), "duration_s": 1.0, "metrics_window_s": [0.5, 1.0],
                    "vary": {"control_rate_hz": {"grid": [200.0, 100.0]}, "plant_sim.substeps": {"grid": [5, 2]},
                             "plant_sim.sensors.delay_periods": {"grid": [0, 2]},
                             "plant_sim.sensors.noise_std.dtheta_b": {"values": [0.01]}}},
                   "spec.yaml")
    sc = expand(s)
    got = rows(engine.run_local(engine.make_chunks(s, sc), workers=1))
    for (i, ctrl), row in got.items():
        v = dict(s.base_values, **sc.overrides(i))
        run = simulate(P.closed_loop(v, use_observer=ctrl == "dscndo", duration=1.0))
        m = metrics.compute(run.columns, s.window, v["fall_angle"])
        np.testing.assert_allclose(row[2:], [getattr(m, n) for n in METRICS.values()], rtol=0, atol=1e-9)


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.e2e
def test_a_real_dask_scheduler_and_worker_give_the_same_rows(tmp_path):
    """`dask scheduler` and `dask worker` as separate processes on localhost, as on a cluster."""
    import os
    import shutil
    import subprocess
    import sys
    pytest.importorskip("dask.distributed")
    dask = shutil.which("dask") or os.path.join(os.path.dirname(sys.executable), "dask")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = []
    try:
        procs.append(subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                       "--no-dashboard"], stdout=subprocess.DEVNULL,
                                      stderr=open(tmp_path / "s.log", "w")))
        procs.append(subprocess.Popen([dask, "worker", address, "--nworkers", "1", "--nthreads", "1",
                                       "--no-dashboard", "--local-directory", str(tmp_path / "w")],
                                      stdout=subprocess.DEVNULL, stderr=open(tmp_path / "w.log", "w")))
        from dask.distributed import Client
        with Client(address, timeout=60) as client:
            client.wait_for_workers(1, timeout=120)
        s = small_spec(samples=4)
        chunks = engine.make_chunks(s, expand(s), chunk_size=5)
        assert same(rows(engine.run_local(chunks, workers=1)), rows(engine.run_dask(chunks, address)))
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(10)
