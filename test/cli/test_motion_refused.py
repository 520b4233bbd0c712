"""Where motion.enabled cannot work yet (the batch: mwip_sweep, mwip_tune) it is refused in one line naming
``motion.enabled``, exit 2, before any work."""
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[2]


def _spec(tmp_path):
    f = tmp_path / "s.yaml"
    f.write_text(f"base: [{ROOT / 'config/paper.yaml'}, {ROOT / 'config/motion.yaml'}]\ncontrollers: [dscndo]\n"
                 "duration_s: 1.0\nmetrics_window_s: [0.0, 1.0]\nseed: 1\nsamples: 2\n"
                 "vary:\n  plant_sim.actual.m_b: {scale: [0.9, 1.1]}\n")
    return f


@pytest.mark.parametrize("tool, extra", [("sweep", ["--out", "OUT"]),
                                         ("tune", ["--controller", "dscndo", "--tune", "k1", "--out", "OUT.yaml"])])
def test_the_batch_refuses_motion_in_one_line(tmp_path, tool, extra):
    extra = [str(tmp_path / e) if e.startswith("OUT") else e for e in extra]
    r = subprocess.run([sys.executable, "-m", f"mwip_ros.cli.{tool}", str(_spec(tmp_path)), *extra],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "motion.enabled" in lines[0], r.stderr
    assert not (tmp_path / "OUT").exists() and not (tmp_path / "OUT.yaml").exists()
