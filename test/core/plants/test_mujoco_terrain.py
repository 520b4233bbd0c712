"""The ground of the MuJoCo plant (``ground.slope``, ``ground.bumps``; params.ground, docs/theory.md 6.10): a slope
the robot starts on, standing, and rolls down with no torque; a step that stops a slow wheel; flat ground that is the
model without them, to the bit; out-of-range values one line naming the key, exit 2."""
import math
import subprocess
import sys

import pytest

pytest.importorskip("mujoco")

from mwip_ros import params as P  # noqa: E402
from mwip_ros.core.plants.mujoco_plant import mjcf  # noqa: E402
from mwip_ros.core.plants.plant import make_plant  # noqa: E402
from mwip_ros.params.paths import default_params_file  # noqa: E402

pytestmark = pytest.mark.unit

PAPER = P.merged_values(P.load_param_file(default_params_file()))
QUIET = {"initial.theta_b": 0.0, "actual.D_w_variance": 0.0, "tau_ext1.amplitude": 0.0, "tau_ext2.amplitude": 0.0}


def _plant(**over):
    v = dict(PAPER, backend="mujoco", **QUIET)
    v.update({k.replace("__", "."): x for k, x in over.items()})
    P.check_derived(v)
    return make_plant(P.plant_config(v))


def _run(p, periods, u=0.0):
    xs = []
    for _ in range(periods):
        p.step(u)
        xs.append(p.pose.x)
    return xs


@pytest.mark.parametrize("slope", [0.1, -0.1])
def test_on_a_slope_the_robot_starts_standing_on_the_ground_and_rolls_down_with_no_torque(slope):
    p = _plant(ground__slope=slope)
    r = PAPER["actual.r"]
    # standing: upright, at rest, the wheel's centre a radius (less the contact's sink, 4.0e-5 m at the default
    # physics step: test_mujoco_plant) off the plane
    normal = -p.pose.x * math.sin(slope) + p.pose.z * math.cos(slope)
    assert p.x[1] == 0.0 and p.x[2] == 0.0 and abs(normal - r) < 5e-5
    assert abs(p.pose.x * math.cos(slope) + p.pose.z * math.sin(slope)) < 1e-12   # at x = 0 along the slope
    x0 = p.pose.x
    _run(p, 60)   # 0.3 s
    down = -math.copysign(1.0, slope)   # uphill ahead for slope > 0: down is -x
    assert down * (p.pose.x - x0) > 0.02 and down * p.x[2] > 0.5   # it rolls down, the wheel turning that way
    flat = _plant()
    _run(flat, 60)
    assert abs(flat.pose.x) < 1e-3 and abs(flat.x[2]) < 1e-2       # on flat ground it stays (an equilibrium)


def test_a_step_stops_a_slow_wheel_where_its_edge_meets_the_wheel():
    r, h, at = PAPER["actual.r"], 0.1, 0.6
    v0 = {"initial.dtheta_w": 0.3 / r, "actual.D_w_mean": 0.0}
    free = max(_run(_plant(**{k.replace(".", "__"): x for k, x in v0.items()}), 300))
    stopped = max(_run(_plant(ground__bumps=[at, h], **{k.replace(".", "__"): x for k, x in v0.items()}), 300))
    edge = at - math.sqrt(r * r - (r - h) ** 2)   # the wheel's centre when its rim touches the step's edge
    assert free > edge + 0.02                       # with no step it rolls past there
    assert edge - 0.01 < stopped < edge + 0.005     # with the step it stops there (and rolls back)


def test_flat_ground_is_the_model_without_ground_keys_to_the_bit_and_a_far_step_changes_nothing():
    v = dict(PAPER, backend="mujoco")
    base = mjcf(P.plant_config(v))
    assert mjcf(P.plant_config(dict(v, **{"ground.slope": 0.0, "ground.bumps": [5.0, 0.0]}))) == base
    assert "quat" not in base.split('name="ground"')[1].split("/>")[0] and "box" not in base
    a, b = _plant(), _plant(ground__bumps=[40.0, 0.2])
    assert "step_0" in mjcf(b.cfg)
    for _ in range(200):
        a.step(5.0)
        b.step(5.0)
        assert tuple(a.x) == tuple(b.x) and tuple(a.pose) == tuple(b.pose)


@pytest.mark.parametrize("line", [
    "ground: {slope: 0.6}",
    "ground: {bumps: [1.0]}",
    "ground: {bumps: [1.0, 0.1, 0.5, 0.0]}",    # positions not increasing
    "ground: {bumps: [1.0, -0.1]}",
    "ground: {bumps: [1.0, 1.5]}",
])
def test_an_out_of_range_ground_is_one_line_naming_the_key(tmp_path, line):
    f = tmp_path / "g.yaml"
    f.write_text(f"plant_sim:\n  ros__parameters:\n    {line}\n")
    with pytest.raises(P.ParamError) as ei:
        P.load_param_files([default_params_file(), f])
    key = "plant_sim.ground." + line.split("{")[1].split(":")[0]
    assert key in str(ei.value) and "\n" not in str(ei.value)


def test_a_step_under_the_starting_wheel_is_refused_naming_ground_bumps():
    v = dict(PAPER, backend="mujoco", **{"ground.bumps": [0.1, 0.05]})   # closer than r = 0.254 m
    with pytest.raises(P.ParamError) as ei:
        P.check_derived(v, "p.yaml")
    assert ei.value.key == "ground.bumps" and "\n" not in str(ei.value)
    P.check_derived(dict(v, **{"ground.bumps": [0.1, 0.0, 0.3, 0.05]}))   # a zero step is flat; 0.3 m is clear


@pytest.mark.cli
def test_mwip_sim_exits_2_on_a_bad_slope_naming_the_key(tmp_path):
    f = tmp_path / "g.yaml"
    f.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n    ground: {slope: 1.0}\n")
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", "--params", str(default_params_file()), str(f),
                        "--duration", "0.1", "-q"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "plant_sim.ground.slope" in r.stderr and len(r.stderr.strip().splitlines()) == 1
