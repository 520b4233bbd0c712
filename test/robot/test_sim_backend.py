"""SimBackend (mwip_ros.robot.sim): the project's plants behind the robot's interface give the offline loop's
numbers."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest

from mwip_ros import params as P
from mwip_ros.core.plants.model import Sinusoid
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.robot import BackendError, Command
from mwip_ros.robot.sim import SimBackend

pytestmark = pytest.mark.unit

CONFIG = Path(__file__).resolve().parents[2] / "config"


def _values(*overlays, **over):
    v = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", *(CONFIG / o for o in overlays)]))
    v.update(over)
    return v


def _replay(run, cfg, wheels=None):
    """Feed a finished offline run's torques (the ``u`` that acted in each row) to a SimBackend of its plant: the
    reads, one per row."""
    sim = SimBackend(cfg)
    reads = [sim.observe()]
    for k in range(len(run) - 1):
        u = float(run["u"][k])
        reads.append(sim.step(Command.lumped(u) if wheels is None else wheels(u)))
    return reads


def test_the_rk4_plant_with_raw_sensors_reads_what_the_offline_loop_recorded_bit_for_bit():
    """DSCNDO's offline run (raw IMU and encoder with noise, bias walk and quantization): the same torques through
    the backend give every row's true state and raw sample exactly."""
    loop = P.closed_loop(_values("sensors_raw_realistic.yaml"), controller="dscndo", duration=1.0)
    run = simulate(loop)
    reads = _replay(run, loop.plant)
    c = run.columns
    assert len(reads) == len(run) > 100
    for k, obs in enumerate(reads):
        assert obs.time == c["t"][k]
        assert obs.truth == (c["theta_w"][k], c["theta_b"][k], c["dtheta_w"][k], c["dtheta_b"][k])
        assert obs.imu.angular_velocity == (0.0, c["gyro"][k], 0.0)
        assert obs.imu.linear_acceleration == (c["accel_x"][k], 0.0, c["accel_z"][k])
        assert obs.left == obs.right
        assert (obs.left.position, obs.left.velocity) == (c["encoder"][k], c["encoder_rate"][k])
        assert obs.torque == (c["u"][k - 1] if k else 0.0)   # both wheels: what acted over the previous period
        assert obs.fault is None


def test_a_file_without_raw_sensors_is_read_through_ideal_ones():
    """sensors.model state: the backend reads phi = theta_w - theta_b and its rate (the last difference), and the
    IMU at rest upright reads (0, 0, +g)."""
    v = _values()
    cfg = replace(P.plant_config(v), initial=(0.0, 0.0, 0.0, 0.0), tau_ext1=Sinusoid(), tau_ext2=Sinusoid())
    assert cfg.raw is None
    sim = SimBackend(cfg)
    first = sim.observe()
    assert first.imu.linear_acceleration == pytest.approx((0.0, 0.0, cfg.actual.g), abs=1e-12)
    assert first.imu.angular_velocity == (0.0, 0.0, 0.0)
    obs = sim.step(Command.lumped(1.0))
    x = obs.truth
    assert obs.phi == pytest.approx(x[0] - x[1], abs=1e-15)
    assert obs.phi_rate == pytest.approx((obs.phi - first.phi) / cfg.h, rel=1e-12)
    assert obs.time == pytest.approx(cfg.h, abs=1e-15)


def test_a_stop_opens_the_bridge_and_a_bad_command_faults_until_reset():
    cfg = replace(P.plant_config(_values()), initial=(0.0, 0.05, 0.0, 0.0))
    sim = SimBackend(cfg)
    pushed = sim.step(Command(2.0, 2.0))
    assert pushed.torque == 4.0   # each read reports the torque that acted over the period just integrated
    assert sim.step(None).torque == 0.0
    bad = sim.step(Command(math.nan, 1.0))
    assert bad.fault is not None and "bad_command" in bad.fault and bad.torque == 0.0
    after = sim.step(Command(1.0, 1.0))
    assert after.fault == bad.fault and after.torque == 0.0   # latched: no torque until reset
    fresh = sim.reset()
    assert fresh.fault is None and fresh.time == 0.0 and fresh.truth == tuple(cfg.initial)
    assert sim.step(Command(1.0, 1.0)).torque == 2.0


def test_the_mujoco_plant_reads_the_offline_loop_s_numbers_and_each_wheel_its_hinge():
    """The spatial plant: the wheels' pair (u/2, u/2) gives the offline loop's rows (which send u / 2 to each wheel)
    to 1e-12; each wheel reads its own hinge, and their mean is the raw encoder."""
    pytest.importorskip("mujoco")
    loop = P.closed_loop(_values("sensors_raw_realistic.yaml", backend="mujoco"), controller="dscndo", duration=0.5)
    run = simulate(loop)
    reads = _replay(run, loop.plant)
    c = run.columns
    for k, obs in enumerate(reads):
        assert obs.truth == pytest.approx((c["theta_w"][k], c["theta_b"][k], c["dtheta_w"][k], c["dtheta_b"][k]),
                                          abs=1e-12)
        assert obs.imu.angular_velocity[1] == pytest.approx(c["gyro"][k], abs=1e-12)
        assert obs.phi == pytest.approx(c["encoder"][k], abs=1e-12)
        left_hinge = c["wheel_left"][k] - c["theta_b"][k]
        right_hinge = c["wheel_right"][k] - c["theta_b"][k]
        assert obs.right.position - obs.left.position == pytest.approx(right_hinge - left_hinge, abs=1e-12)


def test_mujoco_wheels_turned_apart_read_apart_and_yaw_on_the_z_gyro():
    pytest.importorskip("mujoco")
    cfg = replace(P.plant_config(_values(backend="mujoco")), initial=(0.0, 0.0, 0.0, 0.0), tau_ext1=Sinusoid(),
                  tau_ext2=Sinusoid())
    sim = SimBackend(cfg)
    # the wheels' pair must pass the scrub of turning in place (theory 6.13: mu N w / 4 a wheel, 86 N m of u_psi on
    # the paper's robot): 60 N m each way turns it, 20 N m would not
    for _ in range(40):
        obs = sim.step(Command(-60.0, 60.0))
    assert obs.right.position - obs.left.position > 2e-3   # the right wheel forward, the left back (a heavy robot)
    assert obs.right.velocity > 5e-3 and obs.left.velocity < -5e-3
    assert obs.imu.angular_velocity[2] > 1e-3   # turning left (REP-103: +z) with the right wheel ahead
    assert abs(obs.truth[1]) < 1e-3   # no pitch: the two torques cancel on the body
    assert (obs.left.torque, obs.right.torque) == (-60.0, 60.0)


def test_a_diverged_simulation_is_a_backend_error():
    """MuJoCo's warning on a velocity beyond 1e10 (5e5 N m per wheel: plausible, so not a bad command)."""
    pytest.importorskip("mujoco")
    cfg = replace(P.plant_config(_values(backend="mujoco")), initial=(0.0, 0.0, 0.0, 0.0))
    sim = SimBackend(cfg)
    with pytest.raises(BackendError, match="sim: the simulation diverged at t = .*BADQVEL"):
        for _ in range(100):
            sim.step(Command(5e5, 5e5))
