"""scripts/bench_envs.py runs (a small N) and prints its six rows with their ratios to the batch simulator."""
import importlib.util
from pathlib import Path

import pytest

pytest.importorskip("gymnasium")

pytestmark = pytest.mark.unit

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "bench_envs.py"


def test_the_benchmark_prints_every_row_beside_the_batch(capsys):
    spec = importlib.util.spec_from_file_location("bench_envs", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--n", "64", "--steps", "20", "--repeat", "1"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ") and " M | " in line]
    assert len(rows) == 6, rows
    ratios = {r.split(" | ")[0][2:]: float(r.rstrip(" |").split(" | ")[-1]) for r in rows}
    assert ratios["simulate_batch, compiled, DSCNDO [scenario-steps/s]"] == 1.0
    assert all(v > 0 for v in ratios.values())
