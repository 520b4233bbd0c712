"""mwip_identify against hostile logs and options (issue 46 item 8): a value no robot reads is refused naming its
column (before: "not excited"), --validate on a log that does not move or whose times do not advance is one line
(before: exit 0 reporting an error, or a ZeroDivisionError traceback), and --retune's population is checked
against the memory budget before anything is built (before: an allocation traceback)."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.identification.identify_validate import prediction_errors

pytestmark = pytest.mark.unit

CONFIG = Path(__file__).resolve().parents[2] / "config"


def _csv(path: Path, rows: int = 400, **override) -> Path:
    t = np.arange(rows) * 0.005
    cols = {"t": t, "theta_w": np.sin(t), "theta_b": 0.05 * np.sin(3 * t), "dtheta_w": np.cos(t),
            "dtheta_b": 0.15 * np.cos(3 * t), "u": 20 * np.sin(7 * t)}
    for k, (row, v) in override.items():
        cols[k] = cols[k].copy()
        cols[k][row] = v
    path.write_text(",".join(cols) + "\n" + "\n".join(",".join(repr(float(cols[c][i])) for c in cols)
                                                        for i in range(rows)) + "\n")
    return path


@pytest.mark.cli
def test_a_value_no_robot_reads_is_refused_naming_its_column(tmp_path):
    log = _csv(tmp_path / "log.csv", dtheta_b=(99, 1e300))
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.identify", str(log), "--params", str(CONFIG / "paper.yaml"),
                        "--out", str(tmp_path / "out.yaml")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2, r.stderr
    assert "column dtheta_b: 1e+300 at t = 0.495 s" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_validation_needs_a_log_that_moves_and_whose_times_advance():
    p = P.physical(P.merged_values(P.load_param_files([CONFIG / "paper.yaml"])), "actual")
    t = np.arange(400) * 0.005
    z = np.zeros_like(t)
    with pytest.raises(ValueError, match="pitch does not move"):   # an all-zero log: "0 deg" said nothing
        prediction_errors(t, z, z, z, z, z, p, 0.5, 0.1)
    with pytest.raises(ValueError, match="times do not advance"):  # was ZeroDivisionError
        prediction_errors(z, z, 0.05 * np.sin(3 * t), z, z, z, p, 0.5, 0.1)
    got = prediction_errors(t, np.sin(t), 0.05 * np.sin(3 * t), np.cos(t), 0.15 * np.cos(3 * t), 20 * np.sin(7 * t),
                            p, 0.5, 0.1)
    assert got.windows == 2 and np.isfinite(got.rms)


def test_retune_refuses_a_population_beyond_the_memory_budget_before_building_it():
    from mwip_ros.cli.identify_retune import retune
    from mwip_ros.sweep.spec import SpecError
    values = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "identify.yaml"]))
    with pytest.raises(SpecError, match="--popsize.*memory budget"):
        retune([CONFIG / "paper.yaml", CONFIG / "identify.yaml"], P.physical(values, "actual"), "dscndo", 1,
               100_000_000)
