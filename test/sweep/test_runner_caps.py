"""Where chunks run, bounded: --workers capped by the cores (unless --oversubscribe) and, when the runner starts,
by the chunks; --dask local:0 refused (it was accepted and never finished)."""
import argparse
import subprocess
import sys

import pytest

from mwip_ros.cli import sweep as S
from mwip_ros.params.paths import default_params_file
from mwip_ros.sweep import engine
from mwip_ros.sweep.scenarios import expand
from mwip_ros.sweep.spec import parse_spec

pytestmark = pytest.mark.unit


def args(*argv):
    ap = argparse.ArgumentParser()
    S.add_runner_arguments(ap)
    ap.add_argument("-q", "--quiet", action="store_true")
    return ap.parse_args(list(argv))


def test_workers_are_capped_by_the_cores_unless_oversubscribed(capsys):
    cores = S.cores()
    r = S.runner_from(args("--workers", "10000", "--chunk", "1"))
    assert r.workers == cores and r.dask is None
    assert f"--workers 10000 capped at {cores}" in capsys.readouterr().err
    assert S.runner_from(args("--workers", str(cores), "-q")).workers == cores
    assert capsys.readouterr().err == ""
    assert S.runner_from(args("--workers", str(cores + 1), "--oversubscribe")).workers == cores + 1
    assert S.runner_from(args("--dask", "local:10000", "-q")).dask == f"local:{cores}"


@pytest.mark.parametrize("dask, words", [("local:0", "N >= 1"), ("local:-1", "a whole number"),
                                         ("local:x", "a whole number"), ("local:", "a whole number"),
                                         ("  ", "needs an address")])
def test_a_local_dask_cluster_of_no_workers_is_refused(dask, words):
    with pytest.raises(ValueError, match=words):
        S.runner_from(args("--dask", dask))


@pytest.mark.cli
def test_mwip_sweep_refuses_dask_local_0_in_one_line(tmp_path):
    spec = tmp_path / "s.yaml"
    spec.write_text(f"base: {default_params_file()}\nduration_s: 1.0\nmetrics_window_s: [0.5, 1.0]\n")
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sweep", str(spec), "--out", str(tmp_path / "o"),
                        "--dask", "local:0"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.strip() == \
        "mwip_sweep: error: --dask local:N needs N >= 1 workers, got 'local:0'", r.stderr
    assert not (tmp_path / "o").exists()


def test_the_runner_starts_no_more_workers_than_chunks():
    s = parse_spec({"base": str(default_params_file()), "duration_s": 0.2, "metrics_window_s": [0.1, 0.2],
                    "controllers": ["dsc"], "vary": {"dscndo_controller.k1": {"grid": [4.0, 6.0]}}}, "spec.yaml")
    chunks = engine.make_chunks(s, expand(s), chunk_size=1)
    assert len(chunks) == 2
    with engine.Runner(2) as one:                 # one chunk: this process, nothing spawned
        list(one(chunks[:1]))
        assert one.started == 0 and one._pool is None
    with engine.Runner(2) as r:
        assert r.describe(len(chunks)) == "2 worker processes" and r.describe(1) == "this process"
        assert len(list(r(chunks))) == 2 and r.started == 2
