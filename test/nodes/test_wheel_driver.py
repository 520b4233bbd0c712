"""The wheel_driver node in this process (test/nodeharness.py): its refusals, the lockstep graph over the rk4 plant
equal to plant_sim's bit for bit, and the realtime period on a clock the test moves: what it publishes and stamps,
the commands it writes, the state machine on the device (enable, read-only, the e-stop, a device's fault, the
watchdog, a fall on the estimate), missed periods, and the timing it reports."""
from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path

import pytest
from std_srvs.srv import Trigger

from graphproc import PARAMS
from nodeharness import Loop, NodeHarness, Wire, node_class, refused
from mwip_ros.msgs import layouts as L
from mwip_ros.nodes.loop import wheel_driver as W
from mwip_ros.robot import Command
from mwip_ros.robot.mock import MockBackend, MockConfig

pytestmark = pytest.mark.node

REPO = Path(__file__).resolve().parents[2]
RAW = [PARAMS, REPO / "config" / "sensors_raw_realistic.yaml"]
H_NS = 5_000_000


class Recording(MockBackend):
    """The mock as a device (read once per wake, its reads at ``time.monotonic()``), keeping every command written;
    its reads carry ``fault`` from the ``fault_from``-th step on."""

    simulated = False

    def __init__(self, fault_from=None, fault="moteus right wheel (CAN id 2): no answer for 53 ms"):
        self.written, self.fault_from, self.fault_line = [], fault_from, fault
        super().__init__(MockConfig())

    def _read(self, obs):
        return obs if self.simulated else replace(obs, time=time.monotonic())

    def reset(self):
        return self._read(super().reset())

    def step(self, command):
        self.written.append(command)
        obs = self._read(super().step(command))
        return replace(obs, fault=self.fault_line) if (self.fault_from is not None
                                                       and len(self.written) >= self.fault_from) else obs


class SimulatedRecording(Recording):
    """The mock as it is: a simulator (every period due is stepped, its reads on the run's grid)."""

    simulated = True


def _driver(monkeypatch, backend, *args, params=RAW) -> NodeHarness:
    monkeypatch.setattr(W, "open_backend", lambda values, robot: backend)
    return NodeHarness(W.WheelDriverNode, *args, params=params)


class Clock:
    """The node's clock made the test's: ``node._now_ns`` reads it; :meth:`tick` moves it on and wakes the node."""

    def __init__(self, h: NodeHarness, start_ns: int = 1_000_000_000_000):
        self.h, self.now = h, start_ns
        h.node._now_ns = lambda: self.now
        h.node._start("the test's clock")   # period 0 due now: its wake at once

    def tick(self, periods: int = 1, late_ns: int = 100_000) -> None:
        deadline = self.h.node.schedule.due(self.h.node.schedule.k + periods)
        self.now = deadline + late_ns
        self.h.node._tick()


def _transitions(h: NodeHarness) -> list:
    return [json.loads(m.data) for m in h.messages("driver_state", W.String)]


@pytest.mark.parametrize("args, words", [
    (("-p", "mode:=lockstep", "-p", "backend:=moteus"), ("'mode'", "lockstep needs a simulated backend")),
    (("-p", "backend:=moteus"), ("'moteus.path'", "fdcanusb")),
    (("-p", "backend:=moteus", "-p", "moteus.path:=/no/such/fdcanusb", "-p", "wheel_torque_limit:=0.9"),
     ("'moteus.path'", "cannot open the fdcanusb at '/no/such/fdcanusb'")),
    (("-p", "backend:=moteus", "-p", "moteus.path:=/dev/null"), ("'wheel_torque_limit'", "needs a torque limit")),
    (("-p", "backend:=moteus", "-p", "moteus.path:=/dev/null", "-p", "wheel_torque_limit:=0.9", "-p",
      "moteus.reply_timeout:=0.03"), ("'moteus.reply_timeout'", "more than half of watchdog_timeout")),
    (("-p", "backend:=moteus", "-p", "moteus.path:=/dev/null", "-p", "wheel_torque_limit:=0.9", "-p",
      "moteus.right_id:=1"), ("'moteus.left_id'", "two distinct CAN ids")),
    (("-p", "mode:=lockstep", "-p", "mock.imu:=false"), ("'mock.imu'", "lockstep needs the backend's IMU")),
    (("-p", "wheel_torque_limit:=-1.0"), ("'wheel_torque_limit'", "out of range")),
    (("-p", "backend:=odrive"), ("'backend'", "must be one of 'mock', 'rk4', 'mujoco', 'upkie', 'moteus'")),
])
def test_a_driver_that_cannot_run_refuses_in_one_line_naming_the_key(args, words):
    line = refused(W.WheelDriverNode, *args, params=RAW)
    assert "\n" not in line and all(w in line for w in words), line


def test_a_wheel_limit_above_plant_sims_share_refuses_in_one_line_naming_both_keys(tmp_path):
    robot = tmp_path / "robot.yaml"   # plant_sim gives each wheel torque_limit / 2 = 0.9 N m
    robot.write_text("plant_sim:\n  ros__parameters:\n    torque_limit: 1.8\n")
    line = refused(W.WheelDriverNode, "-p", "wheel_torque_limit:=1.0", params=[*RAW, robot])
    assert "\n" not in line and "'wheel_torque_limit'" in line and "plant_sim's torque_limit" in line, line


def test_help_lists_its_parameters_topics_and_exit_codes(capsys):
    from mwip_ros import params as P
    assert W.main(["wheel_driver", "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: wheel_driver [--ros-args")
    for name in P.specs_for("wheel_driver"):
        assert f"\n  {name}  (" in out, name
    assert "publishes: imu/data_raw, wheel_encoder, wheel_states" in out
    assert "subscribes: wheel_torque_cmd, wheel_torques_cmd, emergency_stop, /diagnostics" in out
    assert "services: ~/enable, ~/disable, ~/reset" in out and "3 the robot fell" in out


def test_lockstep_over_the_rk4_plant_is_plant_sims_run_bit_for_bit():
    """The driver with backend rk4 (SimBackend: the plant's stages) in the lockstep graph gives plant_sim's raw run:
    the same true states (noise, bias walk, quantized encoder), the same commands, the same estimates."""
    chain = {n: NodeHarness(node_class(n), params=RAW) for n in ("state_estimator", "disturbance_observer",
                                                                 "dscndo_controller")}
    drv = NodeHarness(W.WheelDriverNode, "-p", "mode:=lockstep", "-p", "backend:=rk4", "-p", "require_enable:=false",
                      "-p", "duration_s:=1.0", params=RAW)
    try:
        wire = Wire(*chain.values(), drv)
        drv.node._start("wired")
        wire.pump()
        assert drv.node.done and drv.node.exit_code == 0
        ours = {t: list(chain[n].sent(t) if n else drv.sent(t)) for n, t in (
            (None, "true_joint_states"), ("dscndo_controller", "wheel_torque_cmd"),
            ("state_estimator", "joint_states"))}
    finally:
        for h in (*chain.values(), drv):
            h.close()
    with Loop("-p", "duration_s:=1.0", params=RAW) as loop:
        loop.start()
        assert loop.run()
        theirs = {t: list(loop[n].sent(t)) for n, t in (
            ("plant_sim", "true_joint_states"), ("dscndo_controller", "wheel_torque_cmd"),
            ("state_estimator", "joint_states"))}
    assert len(ours["true_joint_states"]) == 201
    for topic in ours:
        assert len(ours[topic]) == len(theirs[topic]) and ours[topic] == theirs[topic], topic


def test_realtime_period_publishes_the_read_stamped_at_it_and_writes_the_newest_command(monkeypatch):
    backend = SimulatedRecording()
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false")
    try:
        clock = Clock(h)
        t0 = h.node.stamp0
        assert backend.written == []   # state 0 is the reset's read
        h.feed("wheel_torque_cmd", L.encode_command(0.6))
        clock.tick()
        h.feed("wheel_torques_cmd", L.encode_wheel_torques(0, 0.3, -0.1))
        clock.tick()
        assert backend.written == [Command(0.3, 0.3), Command(0.3, -0.1)]
        enc = [L.parse_encoder(m) for m in h.sent("wheel_encoder")]
        assert [e[0] - t0 for e in enc] == [0, H_NS, 2 * H_NS]   # a simulator's reads on the run's grid
        assert [e[3] for e in enc] == [0.0, pytest.approx(0.6), pytest.approx(0.2)]   # u_L + u_R as the servos report
        wheels = [L.parse_wheel_states(m) for m in h.sent("wheel_states")]
        assert [w[0] for w in wheels] == [e[0] for e in enc]
        imu = [L.parse_imu(m) for m in h.sent("imu/data_raw")]
        assert [i[0] for i in imu] == [e[0] for e in enc] and imu[-1][1:] == (0.0, 0.0, 9.81)
        from sensor_msgs.msg import JointState
        last = h.messages("wheel_states", JointState)[-1]
        assert list(last.name) == ["wheel_left_joint", "wheel_right_joint"] and list(last.effort) == [0.3, -0.1]
    finally:
        h.close()


def test_a_read_in_which_a_device_did_not_answer_is_no_sample_for_the_estimator(monkeypatch):
    """A device's exchange that lost a reply (Observation.stale: the wheel holds its last answer) is no sample for
    the estimator (no wheel_encoder, no imu/data_raw; wheel_states only): stamped now, that answer would tell the
    estimator the wheels stood still since it came (issue 49: the emulated moteus robot's estimator diverged on such
    reads). The next answer is published, its stamp spanning the gap; the count is on /diagnostics and in the
    summary."""
    backend = Recording()
    stale_steps = {2, 3}   # the 2nd and 3rd exchanges lose a reply
    step = backend.step
    backend.step = lambda command: replace(step(command), stale=len(backend.written) in stale_steps)
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false")
    try:
        clock = Clock(h)
        for _ in range(4):
            clock.tick()
        assert len(backend.written) == 5   # every period an exchange, the command written
        stamps = [L.parse_encoder(m)[0] for m in h.sent("wheel_encoder")]
        assert len(stamps) == 3 and len(h.sent("imu/data_raw")) == 3
        assert len(h.sent("wheel_states")) == 5   # each wheel's read goes out still (the answering wheels')
        gaps = [round((b - a) / H_NS) for a, b in zip(stamps, stamps[1:])]
        assert gaps == [3, 1]   # the read after the two lost ones spans them
        assert h.node.stale_reads == 2
        _level, _text, values = h.node.diagnostic_status()
        assert values["stale_reads"] == 2
    finally:
        h.close()


def test_a_device_is_read_once_a_wake_stamped_at_its_read_and_missed_periods_are_counted(monkeypatch):
    backend = Recording()
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false")
    try:
        clock = Clock(h)
        assert len(backend.written) == 1   # a device: period 0 is an exchange
        clock.tick(periods=4)               # a wake three periods late: the newest period, once
        assert len(backend.written) == 2 and h.node.timing.missed == 3
        stamps = [L.parse_encoder(m)[0] for m in h.sent("wheel_encoder")]
        # a device's read is stamped on the node's clock at its exchange (the test's clock stood at the wake; the
        # exchange came microseconds before the stamp was taken)
        assert 0 <= clock.now - stamps[-1] < 50_000_000 and stamps[0] < stamps[-1]
    finally:
        h.close()


def test_a_simulator_catches_up_every_period_that_came_due(monkeypatch):
    backend = SimulatedRecording()
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false")
    try:
        clock = Clock(h)
        clock.tick(periods=4)
        assert len(backend.written) == 4 and len(h.sent("wheel_encoder")) == 2   # run 4, published the newest
        assert L.parse_encoder(h.sent("wheel_encoder")[-1])[0] == h.node.stamp0 + 4 * H_NS
    finally:
        h.close()


def test_a_driver_that_requires_enable_writes_stops_until_enabled(monkeypatch):
    backend = SimulatedRecording()
    h = _driver(monkeypatch, backend)   # require_enable: true, the schema's default
    try:
        clock = Clock(h)
        h.feed("wheel_torque_cmd", L.encode_command(0.4))
        clock.tick()
        assert backend.written == [None]
        response = h.call("~/enable", Trigger.Request())
        assert response.success
        clock.tick()
        assert backend.written == [None, Command(0.2, 0.2)]
        assert h.call("~/disable", Trigger.Request()).success
        clock.tick()
        assert backend.written[-1] is None and [r["reason"] for r in _transitions(h)] == ["start", "enable", "disable"]
    finally:
        h.close()


def test_read_only_reads_and_publishes_and_never_writes_torque(monkeypatch):
    backend = SimulatedRecording()
    h = _driver(monkeypatch, backend, "-p", "read_only:=true", "-p", "require_enable:=false")
    try:
        clock = Clock(h)
        for u in (0.5, -0.5, 1.0):
            h.feed("wheel_torque_cmd", L.encode_command(u))
            clock.tick()
        assert backend.written == [None, None, None] and len(h.sent("wheel_encoder")) == 4
        assert h.node.driver.safety.state == "enabled" and h.node.driver.torque_writes == 0
    finally:
        h.close()


def test_an_estop_stops_the_next_period_and_holds_until_released_and_reset(monkeypatch):
    backend = SimulatedRecording()
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false")
    try:
        clock = Clock(h)
        h.feed("wheel_torque_cmd", L.encode_command(0.4))
        clock.tick()
        h.feed("emergency_stop", _bool(True))
        h.feed("wheel_torque_cmd", L.encode_command(0.4))
        clock.tick()
        assert backend.written == [Command(0.2, 0.2), None]   # the period after the e-stop: a stop
        assert len(h.node.driver.stop_after) == 1
        refused_reset = h.call("~/reset", Trigger.Request())
        assert not refused_reset.success and "emergency stop is still asserted" in refused_reset.message
        h.feed("emergency_stop", _bool(False))
        assert h.call("~/reset", Trigger.Request()).success
        clock.tick()   # the reset at a period boundary: the backend reset, its first read published
        assert len(backend.written) == 2 and h.node.resets == 1
        h.feed("wheel_torque_cmd", L.encode_command(0.4))   # a command after the reset (the old one is dropped)
        clock.tick()
        assert backend.written[-1] == Command(0.2, 0.2)
        assert [(r["reason"], r["state"]) for r in _transitions(h)][1:] == [("emergency_stop", "fault"),
                                                                           ("reset", "enabled")]
    finally:
        h.close()


def _bool(value: bool) -> bytes:
    return bytes([0, 1, 0, 0, 1 if value else 0])


def test_a_device_fault_is_latched_named_on_diagnostics_and_no_torque_follows(monkeypatch, tmp_path):
    backend = Recording(fault_from=3)
    summary = tmp_path / "driver.json"
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false", "-p", f"summary_json:={summary}")
    try:
        clock = Clock(h)
        for _ in range(5):
            h.feed("wheel_torque_cmd", L.encode_command(0.4))
            clock.tick()
        assert backend.written == [None, Command(0.2, 0.2), Command(0.2, 0.2), None, None, None]
        faults = [r for r in _transitions(h) if r["state"] == "fault"]
        assert len(faults) == 1 and faults[0]["reason"] == "device"
        assert faults[0]["detail"] == "moteus right wheel (CAN id 2): no answer for 53 ms"
        level, message, values = h.node.diagnostic_status()
        assert level == 2 and "device: moteus right wheel (CAN id 2): no answer for 53 ms" in message
        assert "driver: t = " in h.logs("ERROR")
    finally:
        h.close()
    s = json.loads(summary.read_text())
    assert (s["exit_code"], s["fault_reason"], s["torque_writes"], s["stop_writes"]) == (0, "device", 2, 4)
    assert s["timing"]["periods"] == 6


def test_the_watchdog_stops_a_device_whose_controller_went_silent(monkeypatch):
    backend = Recording()
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false", "-p", "watchdog_s:=0.1")
    try:
        clock = Clock(h)
        h.feed("wheel_torque_cmd", L.encode_command(0.4))
        clock.tick()
        h.node.driver.watchdog.last -= 0.2   # the last command 0.2 s ago (the core's arithmetic: test/core)
        clock.tick()
        assert backend.written[-2:] == [Command(0.2, 0.2), None]
        fault = [r for r in _transitions(h) if r["state"] == "fault"][0]
        assert fault["reason"] == "watchdog" and "> watchdog_s = 100 ms" in fault["detail"]
    finally:
        h.close()


def test_no_command_at_all_within_the_start_up_bound_is_a_watchdog_fault_naming_the_silent_stage(monkeypatch):
    backend = Recording()
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false", "-p", "watchdog_s:=0.1", "-p",
                "lockstep_timeout_s:=2.0")
    try:
        clock = Clock(h)
        h.node._no_command_since -= 1.9   # the first state 1.9 s ago: within the bound, stops written, no fault
        clock.tick()
        assert not h.node.driver.safety.faulted and backend.written == [None, None]
        h.node._no_command_since -= 0.2
        clock.tick()
        fault = [r for r in _transitions(h) if r["state"] == "fault"][0]
        assert fault["reason"] == "watchdog"
        assert fault["detail"].startswith("no wheel_torque_cmd within lockstep_timeout_s = 2 s of the first state; "
                                          "the stage that did not answer: estimator (state_estimator: ")
    finally:
        h.close()


def test_without_a_truth_a_fall_is_judged_on_the_estimate_and_ends_the_run(monkeypatch):
    backend = Recording()
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false")
    try:
        clock = Clock(h)
        h.feed("joint_states", L.encode_state(0, (0.0, 0.3, 0.0, 0.0), 0.0))
        clock.tick()
        assert not h.node.done
        h.feed("joint_states", L.encode_state(0, (0.0, -1.2, 0.0, 0.0), 0.0))
        clock.tick()
        assert h.node.done and h.node.exit_code == 3 and "FALLEN at t = " in h.node.failure
        assert "> fall_angle 1.0472" in h.node.failure   # the robot's (paper.yaml's plant_sim) fall_angle
    finally:
        h.close()


def test_bad_commands_fault_the_driver_and_a_push_is_refused_by_a_backend_that_has_none(monkeypatch):
    backend = SimulatedRecording()
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false")
    try:
        clock = Clock(h)
        from mwip_ros.msgs import cdr
        h.feed("wheel_torques_cmd", cdr.JointStateEncoder(L.WHEEL_TORQUE_JOINTS)(0, (), (), (math.nan, 0.2)))
        clock.tick()
        assert backend.written == [None]
        assert [r["reason"] for r in _transitions(h)][1:] == ["bad_command"]
        h.feed("external_wrench", L.encode_external_wrench(0.0, 0.0))
        assert h.node.rejects.counts == {"wheel_torques_cmd": 1, "external_wrench": 1}
    finally:
        h.close()


def test_timing_goes_to_diagnostics_and_the_summary(monkeypatch, tmp_path):
    backend = Recording()
    summary = tmp_path / "s.json"
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false", "-p", f"summary_json:={summary}")
    try:
        clock = Clock(h)
        for _ in range(20):
            h.feed("wheel_torque_cmd", L.encode_command(0.1))
            clock.tick()
        clock.tick(periods=3)
        _level, _message, values = h.node.diagnostic_status()
        for f in W.TIMING_FIELDS:
            assert float(values[f"{f}_ms_p99"]) >= 0.0 and float(values[f"{f}_ms_max"]) >= float(values[f"{f}_ms_p99"])
        assert values["missed_periods"] == 2 and values["periods"] == 22
    finally:
        h.close()
    t = json.loads(summary.read_text())["timing"]
    assert t["periods"] == 22 and t["missed"] == 2
    # 22 exchanges: period 0 (no command yet: a stop, no age), 20 with a fresh command, 1 late with the held one
    assert t["exchange_count"] == 22 and t["command_age_count"] == 21 and t["wake_latency_count"] == 22
    assert t["wake_latency_ms_max"] == pytest.approx(0.1)   # every wake 0.1 ms after its deadline (the test's clock)


@pytest.mark.parametrize("backend_class", [SimulatedRecording, Recording])
def test_a_realtime_run_ends_at_its_planned_duration_with_exit_0(monkeypatch, tmp_path, backend_class):
    # the run's own end (duration_s) is exit 0 in its summary too, a simulator's (every period stepped) as a device's
    # (read once a wake, a late wake's periods missed); bench_driver judges each law on this exit
    backend = backend_class()
    summary = tmp_path / "s.json"
    h = _driver(monkeypatch, backend, "-p", "require_enable:=false", "-p", "duration_s:=0.05", "-p",
                f"summary_json:={summary}")
    try:
        clock = Clock(h)
        for i in range(12):
            if h.node.done:
                break
            h.feed("wheel_torque_cmd", L.encode_command(0.1))
            clock.tick(periods=2 if i == 3 else 1)
        assert h.node.done and h.node.exit_code == 0 and h.node.failure is None
        assert h.node.driver.safety.state == "enabled"
    finally:
        h.close()
    s = json.loads(summary.read_text())
    assert s["exit_code"] == 0 and s["fault_reason"] is None and s["fell_at"] is None
    # a simulator: periods 1 to 10 stepped (state 0 is the reset's); a device: exchanges at periods 0 to 10 but 4
    device = backend_class is Recording
    assert s["timing"]["periods"] == 10 and s["timing"]["missed"] == (1 if device else 0)
