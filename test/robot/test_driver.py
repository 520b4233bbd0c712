"""The wheel driver's period without ROS (mwip_ros.robot.driver): the command that acts (gated by the state machine,
read-only, clipped per wheel), one exchange per period, a device's fault latched and named, a fall on the truth or on
the estimate, the stop's latency after leaving enabled."""
from __future__ import annotations

import math
from dataclasses import replace

import pytest

from mwip_ros.core.control.safety import DISABLED, ENABLED, FAULT
from mwip_ros.robot import Command
from mwip_ros.robot.driver import DriverConfig, WheelDriver, timing_lines
from mwip_ros.robot.mock import MockBackend, MockConfig

pytestmark = pytest.mark.unit

H = 0.005


class Recording(MockBackend):
    """The mock, keeping what each step wrote; a fault line and a truth from given periods on."""

    def __init__(self, fault_from=None, fault="moteus right wheel (CAN id 2): fault 38 (over temperature)",
                 truth=None):
        self.written, self.fault_from, self.fault_line, self.truth = [], fault_from, fault, truth
        super().__init__(MockConfig(h=H))

    def step(self, command):
        self.written.append(command)
        obs = super().step(command)
        if self.fault_from is not None and len(self.written) >= self.fault_from:
            obs = replace(obs, fault=self.fault_line)
        if self.truth is not None:
            obs = replace(obs, truth=self.truth(len(self.written)))
        return obs


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def _driver(backend=None, **cfg) -> WheelDriver:
    clock = Clock()
    d = WheelDriver(backend or Recording(), DriverConfig(h=H, **{"require_enable": False, **cfg}), clock=clock)
    d.start()
    return d


def test_the_newest_command_is_written_with_the_read_each_period_and_its_age():
    d = _driver()
    obs, age, trs = d.period(0.0)
    assert d.backend.written == [None] and age is None and trs == []   # no command yet: a stop
    d.take_command(Command(0.3, -0.1), 0.0)
    d.take_command(Command(0.4, 0.2), 0.0)   # the newest one wins
    d.clock.t += 0.0031
    obs, age, _ = d.period(H)
    assert d.backend.written[-1] == Command(0.4, 0.2)
    assert (obs.left.torque, obs.right.torque) == (0.4, 0.2)   # the mock mirrors what was written
    assert age == pytest.approx(0.0031, abs=1e-12)


def test_each_wheel_is_clipped_to_its_limit():
    d = _driver(wheel_torque_limit=0.9)
    d.take_command(Command.lumped(2.5), 0.0)   # 1.25 a wheel
    d.period(0.0)
    d.take_command(Command(-3.0, 0.5), 0.0)
    d.period(H)
    assert d.backend.written == [Command(0.9, 0.9), Command(-0.9, 0.5)]


def test_disabled_read_only_and_faulted_drivers_write_stops():
    d = _driver(require_enable=True)
    d.take_command(Command(0.2, 0.2), 0.0)
    d.period(0.0)
    assert d.safety.state == DISABLED and d.backend.written[-1] is None
    assert d.enable(0.0).success
    d.period(H)
    assert d.backend.written[-1] == Command(0.2, 0.2)
    ro = _driver(read_only=True)
    for k in range(5):
        ro.take_command(Command(1.0, 1.0), 0.0)
        ro.period(k * H)
    assert ro.safety.state == ENABLED and ro.backend.written == [None] * 5 and ro.torque_writes == 0


def test_a_device_fault_is_latched_with_its_line_and_no_torque_follows():
    d = _driver(backend=Recording(fault_from=3))
    d.take_command(Command(0.5, 0.5), 0.0)
    trs = [d.period(k * H)[2] for k in range(6)]
    assert trs[0] == trs[1] == [] and len(trs[2]) == 1
    tr = trs[2][0]
    assert (tr.to_state, tr.reason) == (FAULT, "device")
    assert tr.detail == "moteus right wheel (CAN id 2): fault 38 (over temperature)"
    assert d.backend.written[:3] == [Command(0.5, 0.5)] * 3   # the read that showed it came with the third write
    assert d.backend.written[3:] == [None] * 3                 # and every later period is a stop
    d.take_command(Command(0.5, 0.5), 0.0)
    d.period(6 * H)
    assert d.backend.written[-1] is None and trs[3:] == [[], [], []]   # latched: one transition


def test_a_fall_is_judged_on_the_truth_or_else_on_the_estimate():
    truth = Recording(truth=lambda k: (0.0, 0.2 * k, 0.0, 0.0))   # theta_b grows by 0.2 rad a period
    d = _driver(backend=truth, fall_angle=0.5)
    falls = [tr for k in range(4) for tr in d.period(k * H)[2]]
    assert d.fell_at == pytest.approx(2 * H) and [tr.reason for tr in falls] == ["fall"]   # 0.6 > 0.5 at period 3
    blind = _driver(fall_angle=0.5)   # the mock has no truth: the estimate is judged
    blind.period(0.0)
    assert blind.fell_at is None
    blind.estimate(-0.7)
    trs = blind.period(H)[2]
    assert blind.fell_at == H and trs[0].reason == "fall" and blind.safety.faulted


def test_a_fall_during_another_fault_still_ends_the_run():
    d = _driver(fall_angle=0.5)
    d.set_level(0.0, "emergency_stop", True, "pressed")
    d.estimate(1.0)
    assert d.period(0.0)[2] == [] and d.fell_at == 0.0   # latched on the e-stop, the fall still seen
    assert d.safety.fault_reason == "emergency_stop"


def test_bad_commands_are_a_fault_and_never_kept():
    d = _driver()
    d.take_command(Command(0.2, 0.2), 0.0)
    tr = d.take_command(Command(0.1, math.nan), 0.0)
    assert tr.reason == "bad_command" and d.command == Command(0.2, 0.2)
    assert d.take_command(Command(math.inf, 0.0), 0.0) is None   # already in fault: refused, no second transition
    assert d.command == Command(0.2, 0.2)
    d.period(0.0)
    assert d.backend.written == [None]


def test_the_first_stop_after_leaving_enabled_is_timed():
    d = _driver()
    d.take_command(Command(0.2, 0.2), 0.0)
    d.period(0.0)
    d.clock.t += 0.001
    d.set_level(0.001, "emergency_stop", True, "pressed")
    d.clock.t += 0.0035
    d.period(H)
    d.period(2 * H)
    assert d.stop_after == [pytest.approx(0.0035)]   # one entry: the first stop after the transition


def test_the_watchdog_faults_once_the_commands_stop():
    d = _driver(watchdog_s=0.1)
    d.watchdog.arm(d.clock())
    d.clock.t += 0.05
    assert d.check_watchdog(d.clock(), 0.05) is None
    d.take_command(Command(0.1, 0.1), 0.05)
    d.clock.t += 0.099
    assert d.check_watchdog(d.clock(), 0.149) is None
    d.clock.t += 0.002
    tr = d.check_watchdog(d.clock(), 0.151)
    assert tr.reason == "watchdog" and "no wheel_torque_cmd for 101.0 ms > watchdog_s = 100 ms" in tr.detail
    assert d.gated() is None


def test_timing_lines_say_none_for_an_empty_series():
    rep = {"periods": 3, "missed": 1, "periods_due": 4}
    for f in ("exchange", "read_to_publish", "command_age", "wake_latency"):
        rep.update({f"{f}_ms_p50": 1.0, f"{f}_ms_p99": 2.0, f"{f}_ms_max": 3.0})
    rep["command_age_ms_p50"] = None
    lines = timing_lines(rep, H)
    assert lines[0] == "periods: 3 run of 4 due, 1 missed (deadline passed with no wake; h = 5 ms)"
    assert "command's age when written: none" in lines
    assert "read to publish: p50 1.000, p99 2.000, max 3.000 ms" in lines
