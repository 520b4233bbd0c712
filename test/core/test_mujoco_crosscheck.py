"""The cross-check of the MuJoCo backend in full (issue 32): every law, the paper's 10 s scenario, flat ground and
no yaw: theta_b within 1e-3 rad of the rk4 backend's at every step, its RMS over [5, 10] s within 1 %, the yaw ~0.
(test/core/test_mujoco_plant.py runs the first second of each law and DSC / DSCNDO in full in the unit tier.)"""
import numpy as np
import pytest

pytest.importorskip("mujoco")

from mwip_ros.core import metrics  # noqa: E402

from test_mujoco_plant import LAWS, PAPER, _pair  # noqa: E402

pytestmark = pytest.mark.e2e


@pytest.mark.parametrize("law", LAWS)
def test_every_law_agrees_with_rk4_over_the_paper_run(law):
    a, b, yaw = _pair(law, 10.0)
    assert len(a) == len(b) == 2001 and not a.fallen and not b.fallen
    assert np.max(np.abs(a["theta_b"] - b["theta_b"])) < 1e-3
    ma, mb = (metrics.compute(r.columns, (5.0, 10.0), PAPER["fall_angle"]) for r in (a, b))
    assert mb.theta_b_rms == pytest.approx(ma.theta_b_rms, rel=0.01)
    assert np.max(np.abs(yaw)) < 1e-9
