"""mwip_tune with ``plant_sim.backend: mujoco`` (issue 32 item 4): every candidate runs the scalar loop on MuJoCo,
as mwip_sweep's scenarios do; a spec that varies ``plant_sim.backend`` runs each scenario on its own backend in
both tools, and one whose base file no mujoco model can be is refused at load in one line naming the axis."""
import subprocess
import sys

import pytest
import yaml

from mwip_ros import params as P
from mwip_ros.params.paths import default_params_file

pytestmark = pytest.mark.unit
pytest.importorskip("mujoco")


def _spec(tmp_path, backend="mujoco", vary=None, extra=None):
    over = tmp_path / "over.yaml"
    over.write_text(yaml.safe_dump({"plant_sim": {"ros__parameters": dict(
        {"backend": backend, "actual": {"D_w_variance": 0.0}}, **(extra or {}))}}))
    spec = tmp_path / "s.yaml"
    spec.write_text(yaml.safe_dump({
        "base": [str(default_params_file()), str(over)], "controllers": ["dscndo"], "duration_s": 1.0,
        "metrics_window_s": [0.5, 1.0],
        "vary": vary if vary is not None else {"plant_sim.actual.m_b": {"values": [280.0, 340.0]}}}))
    return spec


def _scalar_j(values, backend, weight=1e-4):
    """J of one scenario as the scalar loop on ``backend`` gives it (sweep/tune.py's definition)."""
    from mwip_ros.core.closed_loop import metrics
    from mwip_ros.core.closed_loop.sim import simulate
    loop = P.closed_loop(dict(values, backend=backend), duration=1.0, controller="dscndo")
    m = metrics.compute(simulate(loop).columns, (0.5, 1.0), loop.plant.fall_angle)
    return m.theta_b_rms + weight * m.u_rms


def test_the_objective_on_a_mujoco_base_is_mujocos_scalar_loop(tmp_path):
    from mwip_ros.sweep.spec import SWEEP_BACKENDS, load_spec
    from mwip_ros.sweep.tune import Objective, knobs_for
    spec = load_spec(_spec(tmp_path), backends=SWEEP_BACKENDS)
    ob = Objective(spec, "dscndo", knobs_for(["k1"], "dscndo"), 1e-4)
    j = ob.judge([6.0])["J"]
    per = [dict(spec.base_values, **ob.scenarios.overrides(i), k1=6.0) for i in range(2)]
    assert j == sum(_scalar_j(v, "mujoco") for v in per) / 2          # the very numbers of MuJoCo's scalar loop
    assert j != sum(_scalar_j(v, "rk4") for v in per) / 2             # not eq. (1)'s (they differ at 1e-7)


@pytest.mark.cli
def test_mwip_tune_tunes_on_mujoco_and_writes_the_overlay(tmp_path):
    out = tmp_path / "tuned.yaml"
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.tune", str(_spec(tmp_path)), "--controller", "dscndo",
                        "--tune", "k1", "--maxiter", "1", "--popsize", "2", "--workers", "1", "--out", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "held-out set of 2 scenarios" in r.stdout and "upright" in r.stdout
    assert "k1" in yaml.safe_load(out.read_text())["dscndo_controller"]["ros__parameters"]


def test_a_backend_axis_runs_each_scenario_on_its_backend(tmp_path):
    from mwip_ros.sweep.spec import SWEEP_BACKENDS, load_spec
    from mwip_ros.sweep.tune import Objective, knobs_for
    spec = load_spec(_spec(tmp_path, "rk4", {"plant_sim.backend": {"values": ["rk4", "mujoco"]}}),
                     backends=SWEEP_BACKENDS)
    ob = Objective(spec, "dscndo", knobs_for(["k1"], "dscndo"), 1e-4)
    assert [ob.scenarios.overrides(i)["backend"] for i in range(2)] == ["rk4", "mujoco"]
    cost = ob.per_scenario([[6.0]])[0]
    want = [_scalar_j(dict(spec.base_values, **ob.scenarios.overrides(i), k1=6.0), b)
            for i, b in enumerate(("rk4", "mujoco"))]
    assert cost[1] == want[1] and abs(cost[0] - want[0]) < 1e-9 and cost[0] != cost[1]


def test_a_backend_axis_is_refused_by_a_caller_that_runs_rk4_only(tmp_path):
    from mwip_ros.sweep.spec import SpecError, load_spec
    with pytest.raises(SpecError) as ei:
        load_spec(_spec(tmp_path, "rk4", {"plant_sim.backend": {"values": ["rk4", "mujoco"]}}))   # the envs' call
    assert ei.value.key == "vary.plant_sim.backend" and "mujoco" in str(ei.value) and "\n" not in str(ei.value)


@pytest.mark.cli
@pytest.mark.parametrize("tool", ["tune", "sweep"])
def test_a_backend_axis_whose_base_no_mujoco_model_can_be_is_one_line_exit_2(tmp_path, tool):
    """The base file runs on rk4, but its body (I_b_roll > I_b + I_b_yaw) is no rigid body: the axis's mujoco
    scenarios could not run, so the spec is refused before anything runs, naming the axis and the key."""
    spec = _spec(tmp_path, "rk4", {"plant_sim.backend": {"values": ["rk4", "mujoco"]}},
                 {"actual": {"D_w_variance": 0.0, "I_b_roll": 200.0}})
    args = ["--controller", "dscndo", "--tune", "k1", "--out", str(tmp_path / "t.yaml")] if tool == "tune" else \
        ["--out", str(tmp_path / "out"), "--no-figures"]
    r = subprocess.run([sys.executable, "-m", f"mwip_ros.cli.{tool}", str(spec), *args, "--workers", "1"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    err = r.stderr.strip()
    assert "\n" not in err and "vary.plant_sim.backend" in err and "actual.I_b_roll" in err, err
