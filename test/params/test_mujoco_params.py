"""The keys of ``plant_sim.backend: mujoco`` (docs/theory.md 6.10): out of range, or a body no rigid body can be,
or wheels that overlap, or the package missing, is one line naming the key; mwip_sim runs the backend and a
diverging run ends as a fault, not as a trajectory; a caller that runs rk4 only refuses the backend in one line."""
import subprocess
import sys

import pytest

from mwip_ros import params as P
from mwip_ros.params.paths import default_params_file

pytestmark = pytest.mark.unit

BASE = P.merged_values(P.load_param_file(default_params_file()))


def _file(tmp_path, lines, name="mj.yaml"):
    f = tmp_path / name
    f.write_text("plant_sim:\n  ros__parameters:\n" + "".join(f"    {line}\n" for line in lines))
    return f


def _sim(*args):
    return subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", *args], capture_output=True, text=True,
                          timeout=300)


@pytest.mark.parametrize("line, key", [
    ("backend: bullet", "plant_sim.backend"),
    ("actual: {track_width: 0.0}", "plant_sim.actual.track_width"),
    ("actual: {I_b_roll: -1.0}", "plant_sim.actual.I_b_roll"),
    ("actual: {I_b_yaw: 2.0e6}", "plant_sim.actual.I_b_yaw"),
    ("ground: {friction: 0.0}", "plant_sim.ground.friction"),
    ("mujoco: {timestep: 1.0e-7}", "plant_sim.mujoco.timestep"),
])
def test_an_out_of_range_key_is_one_line_naming_it(tmp_path, line, key):
    with pytest.raises(P.ParamError) as ei:
        P.load_param_files([default_params_file(), _file(tmp_path, [line])])
    assert key in str(ei.value) and "\n" not in str(ei.value)


@pytest.mark.parametrize("over, key", [
    ({"actual.I_b_roll": 200.0}, "actual.I_b_roll"),     # 200 > 65 + 20: no rigid body
    ({"actual.I_b_yaw": 1.0, "actual.I_b_roll": 10.0}, "actual.I_b"),
    ({"actual.track_width": 0.05}, "actual.track_width"),   # two wheels r / 5 wide each: they overlap
])
def test_a_3d_model_no_robot_can_be_is_refused_naming_the_key(over, key):
    v = dict(BASE, backend="mujoco", **over)
    with pytest.raises(P.ParamError) as ei:
        P.check_derived(v, "p.yaml")
    assert ei.value.key == key
    P.check_derived(dict(v, backend="rk4"))              # the rk4 backend uses none of them: not its business


def test_a_missing_mujoco_is_one_line_naming_the_package(monkeypatch):
    import sys
    monkeypatch.setitem(sys.modules, "mujoco", None)   # import mujoco raises ImportError
    with pytest.raises(P.ParamError) as ei:
        P.check_derived(dict(BASE, backend="mujoco"))
    text = str(ei.value)
    assert ei.value.key == "backend" and "mujoco" in text and "python3-mujoco-pip" in text and "\n" not in text


@pytest.mark.cli
def test_mwip_sim_runs_the_mujoco_backend(tmp_path):
    pytest.importorskip("mujoco")
    r = _sim("--params", str(default_params_file()), str(_file(tmp_path, ["backend: mujoco"])), "--compare",
             "--duration", "2", "-q")
    assert r.returncode == 0, r.stderr
    assert "dscndo" in r.stdout and "stayed upright" in r.stdout
    assert not list(tmp_path.glob("MUJOCO_LOG.TXT"))


def test_mwip_sim_ends_a_diverging_run_as_a_fault_naming_the_law_and_time(monkeypatch, capsys):
    from mwip_ros.cli import sim
    from mwip_ros.core.plants.plant import PlantDiverged

    def diverging(loop, label="", progress=None, on_period=None):
        raise PlantDiverged("the MuJoCo simulation diverged in [1.2, 1.205] s: mjWARN_BADQACC (...)")

    monkeypatch.setattr(sim, "simulate", diverging)
    assert sim._main(["--controller", "dscndo", "--duration", "2", "-q"]) == 1
    out = capsys.readouterr()
    assert "mwip_sim: dscndo: the MuJoCo simulation diverged in [1.2, 1.205] s: mjWARN_BADQACC" in out.err
    assert "metrics" not in out.out and "upright" not in out.out


def _mujoco_spec(tmp_path, vary="{}"):
    base = _file(tmp_path, ["backend: mujoco", "actual: {D_w_variance: 0.0}"])   # no per-scenario noise seed
    spec = tmp_path / "s.yaml"
    spec.write_text(f"base: [{default_params_file()}, {base}]\ncontrollers: [dscndo]\nduration_s: 1.0\n"
                    f"metrics_window_s: [0.5, 1.0]\nvary: {vary}\n")
    return spec


def test_an_rk4_only_caller_refuses_the_mujoco_backend_in_one_line(tmp_path):
    from mwip_ros.sweep.spec import SpecError, load_spec
    with pytest.raises(SpecError) as ei:
        load_spec(_mujoco_spec(tmp_path))   # the environments' call: rk4 only (mwip_sweep, mwip_tune run mujoco)
    assert "backend: mujoco" in str(ei.value) and "mwip_tune" in str(ei.value) and "\n" not in str(ei.value)


def test_the_batch_runs_the_mujoco_backend_scenario_by_scenario_as_mwip_sim_and_a_divergence_is_a_failure():
    """A mujoco scenario runs the scalar loop (mwip_sim's numbers); one that diverges is that scenario's
    ``diverged`` failure (not an error of the batch), scored neither upright nor from NaN."""
    pytest.importorskip("mujoco")
    from mwip_ros.core.closed_loop import metrics
    from mwip_ros.core.kernels.batch import simulate_batch
    from mwip_ros.core.closed_loop.sim import simulate
    from mwip_ros.core.closed_loop.trajectory import FAILURES
    good = P.closed_loop(dict(BASE, backend="mujoco"), duration=1.0, controller="dscndo")
    bad = P.closed_loop(dict(BASE, backend="mujoco", **{"actual.I_w": 1e-6, "actual.D_b": 1e6,   # diverges at 1 ms
                                                        "mujoco.timestep": 0.001}), duration=1.0, controller="dscndo")
    r = simulate_batch([good, bad], (0.5, 1.0))
    want = metrics.compute(simulate(good).columns, (0.5, 1.0), good.plant.fall_angle)
    assert r.metrics["theta_b_rms"][0] == want.theta_b_rms and r.metrics["u_rms"][0] == want.u_rms
    assert list(r.upright) == [True, False] and FAILURES[r.failure[1]] == "diverged" and r.t_fall[1] == 0.0
    assert not r.fallen[0] and r.fallen[1]


@pytest.mark.cli
def test_mwip_sweep_runs_the_mujoco_backend(tmp_path):
    pytest.importorskip("mujoco")
    from mwip_ros.sweep.results import read_results
    spec = _mujoco_spec(tmp_path, "{plant_sim.actual.m_b: {values: [280.0, 340.0]}}")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sweep", str(spec), "--out", str(out), "--workers", "1",
                        "--no-figures"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    cols = read_results(out / "results.csv")
    assert len(cols["scenario"]) == 2 and all(float(u) == 1.0 for u in cols["upright"]), cols
    from mwip_ros.core.closed_loop import metrics
    from mwip_ros.core.closed_loop.sim import simulate
    loop = P.closed_loop(dict(BASE, backend="mujoco", **{"actual.m_b": 340.0, "actual.D_w_variance": 0.0}),
                         duration=1.0, controller="dscndo")
    want = metrics.compute(simulate(loop).columns, (0.5, 1.0), loop.plant.fall_angle)
    assert abs(cols["theta_b_rms"][1] - want.theta_b_rms) < 1e-12
