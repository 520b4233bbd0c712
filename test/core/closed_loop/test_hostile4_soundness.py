"""The code review's soundness findings (issue 46 item 10), each at its cause:

* a fallen robot lies still in MuJoCo too (``Plant.lie``): before, plant_sim zeroed the planar rates and left
  MuJoCo's velocities (``true_wheel_states`` read 0.089 rad/s) and the raw accelerometer used stale torques;
* the terrain scan's push is the offline loop's external wrench (``Period``'s ``wrench``): before, a private plant
  class duplicated it, was put into the global plant registry and raised TypeError with the yaw stage on;
* ``odometry_drift`` of a run whose first row is not finite: one line (was IndexError);
* one implementation of each constant and clip (``ABSURD_SPEED``, ``_clip``, ``SEED_RANGE``).
"""
import math
from pathlib import Path

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.closed_loop.loop import PlantSide

pytestmark = pytest.mark.unit

CONFIG = Path(__file__).resolve().parents[3] / "config"


def _mujoco_side(**changes):
    v = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "drive.yaml"]))
    v.update(changes)
    return PlantSide(P.closed_loop(v).plant)


def test_a_fallen_mujoco_robot_lies_still_wheels_and_body():
    side = _mujoco_side(**{"initial.theta_b": 1.0})
    p = side.plant
    side.act(0.0, wheels=(40.0, -40.0))   # a pair commanded, then the fall
    while not p.fallen:
        side.advance(0.0)
    assert max(abs(w) for w in p.wheel_rates) > 0.01   # it was still moving
    k = p.k
    p.lie()
    assert p.k == k + 1
    assert p.x[2] == 0.0 and p.x[3] == 0.0
    assert p.wheel_rates == (0.0, 0.0) and p.yaw_rate == 0.0   # MuJoCo's own velocities: true_wheel_states reads them
    assert p.u_prev == 0.0 and p.wheels_prev in (None, (0.0, 0.0)) and p.extra_prev == (0.0,) * len(p.extra_prev)
    # what a raw sample at t_k+1^- sees is the body at rest, no torque: the same as a fresh plant in this pose
    a1 = p.sample_accel()
    p.u_prev, p.wheels_prev = 50.0, (25.0, 25.0)
    assert p.sample_accel() != a1   # (the torques that acted are what sample_accel reads)


def test_a_fallen_planar_robot_lies_still():
    side = PlantSide(P.closed_loop(P.merged_values(P.load_param_files([CONFIG / "paper.yaml"]))).plant)
    p = side.plant
    side.advance(100.0, (5.0, 0.0))
    p.lie()
    assert p.x[2] == p.x[3] == 0.0 and p.u_prev == 0.0 and p.extra_prev == (0.0, 0.0) and not p.enabled_prev


def test_the_terrain_push_is_the_offline_wrench_with_the_yaw_stage_on_and_registers_no_plant():
    from mwip_ros.core.plants.plant import PLANTS
    from mwip_ros.sweep import terrain
    before = dict(PLANTS)
    base = terrain.base_values()
    driving = dict(base, **{"motion.enabled": True, "motion.profile": [0.0, 0.0]})   # the yaw stage runs
    out = terrain.push_run(driving, "dscndo", 1000.0)          # was TypeError (a plant without ``wheels``)
    assert out.ok and 0.0 < out.value < terrain.ROLL_LIMIT
    assert PLANTS == before                                     # was: a private backend added to the registry


def test_the_push_acts_over_its_window_only():
    from mwip_ros.sweep.terrain import _push_wrench
    w = _push_wrench(5.0, 0.1, 3000.0)
    assert w(4.995) == (0.0, 0.0, 0.0, 0.0) and w(5.0) == (0.0, 0.0, 3000.0, 0.0)
    assert w(5.095) == (0.0, 0.0, 3000.0, 0.0) and w(5.1) == (0.0, 0.0, 0.0, 0.0)


def test_odometry_drift_of_a_run_whose_first_row_is_not_finite_is_one_line():
    from mwip_ros.core.mobile_base.odometry import odometry_drift
    n = 5
    cols = {c: np.zeros(n) for c in ("dtheta_w", "theta_b", "gyro_z", "x", "y", "yaw")}
    cols["t"] = np.arange(n) * 0.005
    assert odometry_drift(cols, 0.254, 0.5)["final_pos"] == 0.0
    cols["dtheta_w"][0] = math.nan
    with pytest.raises(ValueError, match="first row is not finite"):   # was IndexError
        odometry_drift(cols, 0.254, 0.5)
    cols["dtheta_w"][0], cols["x"][0] = 0.0, math.nan
    with pytest.raises(ValueError, match="first row is not finite"):
        odometry_drift(cols, 0.254, 0.5)


def test_one_implementation_of_each_limit_and_clip():
    from mwip_ros.cli import teleop
    from mwip_ros.core.control import motion, yaw
    from mwip_ros.core.plants import plant
    from mwip_ros.envs import common, scalar
    from mwip_ros.params import motion as params_motion
    assert params_motion.ABSURD_SPEED is motion.ABSURD_SPEED
    assert motion._clip is plant.saturate
    assert not hasattr(yaw, "_clip") and not hasattr(teleop, "_clip")
    assert scalar.SEED_RANGE is common.SEED_RANGE
    assert yaw.wheel_torques(10.0, 4.0, 8.0) == (3.0, 4.0)   # each wheel within torque_limit / 2 (saturate's)


@pytest.mark.parametrize("args, words", [
    (["--laws", "bogus", "dsc"], "--laws: bogus is not a registered law"),
    (["--only", "push", "--figure", "f.png"], "--figure draws the slope and step")])
@pytest.mark.cli
def test_the_terrain_cli_refuses_before_any_scan(tmp_path, args, words):
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-m", "mwip_ros.sweep.terrain", *args], capture_output=True, text=True,
                       timeout=60, cwd=tmp_path)   # was: a KeyError traceback, or a failure after every scan
    assert r.returncode == 2 and words in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "f.png").exists()
