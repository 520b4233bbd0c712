"""MockBackend (mwip_ros.robot.mock): commands mirrored into states as ros2_control's GenericSystem does."""
from __future__ import annotations

import math

import pytest

from mwip_ros.robot import Backend, Command
from mwip_ros.robot.mock import MockBackend, MockConfig

pytestmark = pytest.mark.unit


def test_each_wheel_s_torque_state_is_its_own_last_command_and_nothing_moves():
    mock = MockBackend(MockConfig(h=0.01, position=(0.5, -0.25), velocity=(0.0, 0.1)))
    assert isinstance(mock, Backend) and mock.simulated
    first = mock.observe()
    assert (first.time, first.torque) == (0.0, 0.0)
    obs = mock.step(Command(1.5, -0.5))
    assert (obs.left.torque, obs.right.torque) == (1.5, -0.5)   # per wheel, with its sign
    assert (obs.left.position, obs.right.position) == (0.5, -0.25)
    assert (obs.left.velocity, obs.right.velocity) == (0.0, 0.1)
    assert obs.time == pytest.approx(0.01, abs=1e-15) and obs.truth is None and obs.fault is None
    assert mock.observe() == obs   # a read changes nothing
    for _ in range(99):
        obs = mock.step(Command(2.0, 3.0))
    assert obs.time == pytest.approx(1.0, abs=1e-12)
    assert (obs.left.position, obs.right.velocity) == (0.5, 0.1)


def test_a_nan_command_leaves_the_state_a_stop_zeroes_it_and_reset_restarts():
    mock = MockBackend()
    mock.step(Command(1.0, 2.0))
    obs = mock.step(Command(math.nan, math.inf))
    assert (obs.left.torque, obs.right.torque) == (1.0, 2.0)   # GenericSystem skips a NaN command
    obs = mock.step(Command(math.nan, -1.0))
    assert (obs.left.torque, obs.right.torque) == (1.0, -1.0)
    assert mock.step(None).torque == 0.0
    mock.step(Command(1.0, 1.0))
    fresh = mock.reset()
    assert (fresh.time, fresh.torque) == (0.0, 0.0)


def test_disabled_commands_mirror_nothing():
    mock = MockBackend(MockConfig(disable_commands=True))
    assert mock.step(Command(1.0, 1.0)).torque == 0.0


def test_the_imu_reads_a_robot_at_rest_upright_or_is_absent():
    with_imu = MockBackend(MockConfig(g=9.80665)).observe().imu
    assert with_imu.angular_velocity == (0.0, 0.0, 0.0)
    assert with_imu.linear_acceleration == (0.0, 0.0, 9.80665)   # REP-145: +g on z at rest
    assert MockBackend(MockConfig(imu=False)).observe().imu is None


@pytest.mark.parametrize("bad, key", [(dict(h=0.0), "h"), (dict(h=math.nan), "h"), (dict(position=(0.0,)), "position"),
                                      (dict(velocity=(0.0, math.inf)), "velocity")])
def test_a_bad_setting_is_refused_naming_it(bad, key):
    with pytest.raises(ValueError, match=f"mock: {key}"):
        MockConfig(**bad)
