"""The emulator's protocol against mjbots' moteus library (mwip_ros.robot.moteus_emu): frames built by the library's
own Controller decoded, replies parsed back by the library's own parser, and the fdcanusb's lines both ways."""
from __future__ import annotations

import asyncio
import copy
import math

import pytest

moteus = pytest.importorskip("moteus")

from moteus import multiplex as mp  # noqa: E402
from moteus.fdcanusb_device import FdcanusbDevice, _append_checksum, _strip_and_validate_checksum  # noqa: E402
from moteus.protocol import Register as R, parse_message, parse_registers, scale_register  # noqa: E402
from moteus.transport_device import Frame  # noqa: E402

from mwip_ros.robot.moteus_emu import (MODE_POSITION, MODE_STOPPED, COMMAND_DEFAULTS, EmulatedRobot,  # noqa: E402
                                       Injection, Servo, ServoConfig, decode, scaled)
from mwip_ros.robot.mock import MockBackend, MockConfig  # noqa: E402

pytestmark = pytest.mark.unit

NAN = math.nan
RESOLUTIONS = (mp.INT8, mp.INT16, mp.INT32, mp.F32)


def _same(a, b, tol=0.0):
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return abs(a - b) <= tol


@pytest.mark.parametrize("register", sorted(set(COMMAND_DEFAULTS) | {R.MODE, R.POSITION, R.VELOCITY, R.TORQUE,
                                                                    R.VOLTAGE, R.TEMPERATURE, R.FAULT, R.UUID1}))
@pytest.mark.parametrize("resolution", RESOLUTIONS)
def test_the_cached_scales_are_the_library_s_mapping(register, resolution):
    for raw in (0, 1, -7, 100, (-128, -32768, -2147483648, 0.25)[resolution]):
        assert _same(scaled(register, resolution, raw), scale_register(register, resolution, raw))


def _position_frames(ctl):
    """Position commands as the library builds them: the backend's torque command, every field given, defaults."""
    yield ctl.make_position(position=NAN, velocity=0.0, kp_scale=0.0, kd_scale=0.0, feedforward_torque=-1.25,
                            maximum_torque=2.5, watchdog_timeout=0.05, query=True)
    yield ctl.make_position(position=0.3, velocity=-1.5, feedforward_torque=0.5, kp_scale=0.7, kd_scale=0.2,
                            maximum_torque=3.0, stop_position=1.0, watchdog_timeout=NAN, velocity_limit=2.0,
                            accel_limit=4.0, ilimit_scale=0.5, ignore_position_bounds=1.0)
    yield ctl.make_position(velocity=0.5)


def test_decode_reads_the_library_s_frames_as_the_library_does():
    """Every write and read of the library's own command frames (position, stop, query, custom query, at every
    resolution of a query override): the same registers and values as moteus.protocol.parse_registers."""
    ctl = moteus.Controller(id=3)
    frames = [*_position_frames(ctl), ctl.make_stop(), ctl.make_stop(query=True), ctl.make_query(),
              ctl.make_custom_query({R.MODE: mp.INT8, R.TEMPERATURE: mp.F32, R.UUID2: mp.INT32})]
    for res in RESOLUTIONS:
        qr = copy.deepcopy(moteus.QueryResolution())
        qr.position = qr.velocity = qr.torque = res
        qr.trajectory_complete = res
        frames.append(ctl.make_query(query_override=qr))
    for cmd in frames:
        writes, reads = decode(cmd.data)
        ref = parse_registers(cmd.data)
        assert reads == ref.query
        assert list(writes) == list(ref.command) and all(_same(writes[r], ref.command[r]) for r in writes)
    writes, _ = decode(next(_position_frames(ctl)).data)
    assert writes[R.MODE] == MODE_POSITION and math.isnan(writes[R.COMMAND_POSITION])
    assert (writes[R.COMMAND_FEEDFORWARD_TORQUE], writes[R.COMMAND_POSITION_MAX_TORQUE]) == (-1.25, 2.5)
    assert writes[R.COMMAND_TIMEOUT] == pytest.approx(0.05, rel=1e-7)   # an f32 on the wire


def _parse_reply(servo: Servo, payload: bytes):
    return parse_message(Frame(arbitration_id=(servo.cfg.can_id << 8), data=payload)).values


@pytest.mark.parametrize("resolution", RESOLUTIONS)
def test_a_reply_parses_back_as_the_controller_s_registers(resolution):
    """The controller's reply to the library's query, at each resolution, read by the library's own parser: each
    value to its resolution's step (moteus's register mappings), NaN where the register is NaN."""
    servo = Servo(ServoConfig(can_id=3, sign=-1))
    servo.measure(-2.0, 3.0)   # phi, phi' of the wheel: the shaft reads -sign...
    servo.torque = 0.37
    servo.overheat(True)
    qr = copy.deepcopy(moteus.QueryResolution())
    qr.position = qr.velocity = qr.torque = qr.voltage = qr.temperature = resolution
    ctl = moteus.Controller(id=3)
    values = _parse_reply(servo, servo.frame(ctl.make_query(query_override=qr).data, 0.0))
    step = {"position": (0.01, 1e-4, 1e-5, 1e-6), "velocity": (0.1, 2.5e-4, 1e-5, 1e-6),
            "torque": (0.5, 0.01, 1e-3, 1e-6), "voltage": (0.5, 0.1, 1e-3, 1e-6),
            "temperature": (1.0, 0.1, 1e-3, 1e-6)}
    expect = {R.POSITION: ("position", 2.0 / (2 * math.pi)), R.VELOCITY: ("velocity", -3.0 / (2 * math.pi)),
              R.TORQUE: ("torque", 0.37), R.VOLTAGE: ("voltage", 24.0), R.TEMPERATURE: ("temperature", 85.0)}
    for reg, (kind, want) in expect.items():
        limit = (127 * step[kind][0], 32767 * step[kind][1], math.inf, math.inf)[resolution]
        want_wire = max(-limit, min(limit, want))   # an int8 saturates (as the library's own writer does)
        assert values[reg] == pytest.approx(want_wire, abs=step[kind][resolution]), kind
    assert values[R.MODE] == MODE_STOPPED and values[R.FAULT] == 0


def test_a_register_it_does_not_have_is_a_read_error_and_the_rest_still_answers():
    servo = Servo(ServoConfig(can_id=1))
    ctl = moteus.Controller(id=1)
    payload = servo.frame(ctl.make_custom_query({R.MODE: mp.INT8, R.AUX1_GPIO_STATUS: mp.INT8}).data, 0.0)
    parsed = parse_registers(payload)
    assert parsed.response == {R.MODE: MODE_STOPPED}
    assert parsed.errors == [(R.AUX1_GPIO_STATUS, 1)]


# --- the register machine -----------------------------------------------------------------------------------

def _servo(**cfg):
    return Servo(ServoConfig(can_id=1, **cfg)), moteus.Controller(id=1)


def _torque_cmd(ctl, tau, **kw):
    args = dict(position=NAN, velocity=0.0, kp_scale=0.0, kd_scale=0.0, feedforward_torque=tau, maximum_torque=2.0,
                watchdog_timeout=0.05, query=True)
    args.update(kw)
    return ctl.make_position(**args).data


def test_position_mode_with_zero_scales_is_the_feedforward_torque_within_maximum_torque():
    servo, ctl = _servo(kp=10.0, kd=1.0, max_torque=5.0)
    servo.measure(1.0, 4.0)   # moving: no kd term may act with kd_scale 0
    servo.frame(_torque_cmd(ctl, 1.5), 0.0)
    assert servo.mode == MODE_POSITION and servo.update(0.001) == pytest.approx(1.5, rel=1e-6)
    servo.frame(_torque_cmd(ctl, -3.0), 0.01)
    assert servo.update(0.011) == pytest.approx(-2.0, rel=1e-6)   # clipped to maximum_torque
    servo.frame(_torque_cmd(ctl, 9.0, maximum_torque=NAN), 0.02)
    assert servo.update(0.021) == pytest.approx(5.0)              # NaN: the system's maximum
    assert servo.wheel_torque() == pytest.approx(5.0)


def test_the_kp_and_kd_terms_follow_their_scales_and_a_nan_position_drops_the_position_term():
    servo, ctl = _servo(kp=10.0, kd=1.0, max_torque=100.0, sign=-1)
    servo.measure(-2 * math.pi * 0.5, -2 * math.pi * 2.0)   # the shaft at +0.5 rev, +2 rev/s (sign -1)
    servo.frame(_torque_cmd(ctl, 0.25, position=1.0, velocity=1.0, kp_scale=0.5, kd_scale=0.25,
                            maximum_torque=NAN), 0.0)
    assert servo.update(0.0) == pytest.approx(0.25 + 0.25 * 1.0 * (1.0 - 2.0) + 0.5 * 10.0 * (1.0 - 0.5), rel=1e-6)
    assert servo.wheel_torque() == pytest.approx(-servo.torque)
    servo.frame(_torque_cmd(ctl, 0.25, position=NAN, velocity=1.0, kp_scale=0.5, kd_scale=0.25,
                            maximum_torque=NAN), 0.001)
    assert servo.update(0.001) == pytest.approx(0.25 + 0.25 * (1.0 - 2.0), rel=1e-6)
    servo.frame(ctl.make_position(position=NAN, velocity=0.0).data, 0.002)   # scales unwritten: 1
    assert servo.update(0.002) == pytest.approx(1.0 * (0.0 - 2.0), rel=1e-6)


def test_the_watchdog_stops_a_controller_at_watchdog_timeout_and_only_a_stop_brings_it_back():
    servo, ctl = _servo(timeout_mode=0)
    servo.frame(_torque_cmd(ctl, 1.0), 0.0)
    assert servo.update(0.0499) == pytest.approx(1.0) and servo.mode == MODE_POSITION
    assert servo.update(0.0500001) == 0.0 and servo.mode == 11 and servo.watchdog_trips == 1
    servo.frame(_torque_cmd(ctl, 1.0), 0.06)   # ignored: timeout is left only on a stop
    assert servo.update(0.061) == 0.0 and servo.mode == 11
    values = _parse_reply(servo, servo.frame(ctl.make_query().data, 0.062))
    assert values[R.MODE] == 11
    servo.frame(ctl.make_stop().data, 0.07)
    assert servo.mode == MODE_STOPPED
    servo.frame(_torque_cmd(ctl, 1.0), 0.08)
    assert servo.update(0.081) == pytest.approx(1.0)


def test_the_timeout_mode_12_damps_within_timeout_max_torque_and_unset_watchdogs_take_the_default():
    servo, ctl = _servo(kd=2.0, timeout_max_torque=1.0, default_timeout=0.1)
    servo.frame(ctl.make_position(position=NAN, feedforward_torque=1.0).data, 0.0)   # watchdog unset: 0.1 s
    assert servo.update(0.099) == pytest.approx(1.0)
    servo.measure(2 * math.pi * 0.2, 2 * math.pi * 0.3)   # the shaft at 0.3 rev/s
    assert servo.update(0.1) == pytest.approx(-0.6) and servo.mode == 11    # -kd v
    servo.measure(0.0, 2 * math.pi * 2.0)
    assert servo.update(0.2) == pytest.approx(-1.0)                          # within timeout_max_torque
    servo.frame(ctl.make_stop().data, 0.3)
    servo.frame(_torque_cmd(ctl, 1.0, watchdog_timeout=NAN), 0.3)            # NaN: no watchdog
    assert servo.update(100.0) == pytest.approx(1.0) and servo.mode == MODE_POSITION


def test_an_over_temperature_faults_a_driving_controller_with_code_38_until_a_stop_and_it_cools():
    servo, ctl = _servo()
    servo.frame(_torque_cmd(ctl, 1.0), 0.0)
    servo.overheat(True)
    assert servo.update(0.001) == 0.0 and servo.mode == 1
    values = _parse_reply(servo, servo.frame(ctl.make_query().data, 0.002))
    assert (values[R.MODE], values[R.FAULT]) == (1, 38) and values[R.TEMPERATURE] > 75.0
    servo.frame(_torque_cmd(ctl, 1.0), 0.003)
    assert servo.mode == 1   # only a stop leaves a fault
    servo.frame(ctl.make_stop().data, 0.004)
    assert (servo.mode, servo.fault) == (MODE_STOPPED, 0)
    servo.frame(_torque_cmd(ctl, 1.0), 0.005)
    assert (servo.mode, servo.fault) == (1, 38)   # still hot: it faults again on the command
    servo.overheat(False)
    servo.frame(ctl.make_stop().data, 0.006)
    servo.frame(_torque_cmd(ctl, 1.0), 0.007)
    assert servo.mode == MODE_POSITION and servo.update(0.008) == pytest.approx(1.0)


# --- the fdcanusb's lines ------------------------------------------------------------------------------------

class _Lines:
    """What FdcanusbDevice writes, without a serial port: its own line formatter."""

    def __init__(self):
        self.written = b""

    def write(self, data):
        self.written += data


def _host_line(frame, checksum: bool) -> bytes:
    dev = FdcanusbDevice.__new__(FdcanusbDevice)
    dev._serial, dev._disable_brs, dev._padding_hex, dev._debug_log = _Lines(), False, "50", None
    dev._checksum_active = checksum
    asyncio.run(dev._write_send_frame(frame))
    return dev._serial.written


def _robot(**inj):
    servos = [Servo(ServoConfig(can_id=1, sign=1)), Servo(ServoConfig(can_id=2, sign=-1))]
    robot = EmulatedRobot(MockBackend(MockConfig(h=0.001)), servos, Injection(**inj))
    robot.start(0.0)
    return robot


def _frame_of(ctl, cmd) -> Frame:
    arb = (cmd.destination if isinstance(cmd.destination, int) else 0) | (0x8000 if cmd.reply_required else 0)
    return Frame(arbitration_id=arb, data=cmd.data, is_fd=True, bitrate_switch=True)


@pytest.mark.parametrize("checksum", [True, False])
def test_the_fdcanusb_answers_ok_then_the_controller_s_frame_as_the_library_reads_it(checksum):
    robot = _robot()
    ctl = moteus.Controller(id=2)
    line = _host_line(_frame_of(ctl, ctl.make_position(position=NAN, feedforward_torque=0.5, query=True)), checksum)
    assert line.startswith(b"can send 8002 ") and line.endswith(b"\n")
    due, answers = robot.receive(line.rstrip(b"\n"), 0.0)
    assert due == 0.0 and answers[0].strip().startswith(b"OK") and len(answers) == 2
    rcv, had, valid = _strip_and_validate_checksum(answers[1].strip())
    assert had == checksum and (valid or not checksum)
    frame = FdcanusbDevice._parse_frame(None, rcv)
    assert frame.arbitration_id == 0x0200 and frame.is_fd and frame.bitrate_switch
    assert len(frame.data) in (8, 12, 16, 20, 24, 32, 48, 64)   # a CAN-FD length, padded with NOPs
    result = parse_message(frame)
    assert result.id == 2 and result.values[R.MODE] == MODE_POSITION
    assert robot.servos[1].command[R.COMMAND_FEEDFORWARD_TORQUE] == 0.5 and robot.servos[0].frames == 0


def test_a_bad_checksum_and_an_unknown_command_are_refused_and_change_nothing():
    robot = _robot()
    ctl = moteus.Controller(id=1)
    good = _host_line(_frame_of(ctl, ctl.make_position(feedforward_torque=1.0)), True).rstrip(b"\n")
    bad = good[:-2] + (b"00" if good[-2:] != b"00" else b"11")
    _, answers = robot.receive(bad, 0.0)
    assert answers == [_append_checksum(b"ERR checksum mismatch") + b"\n"]
    _, answers = robot.receive(b"can frobnicate 1", 0.0)
    assert answers[0].startswith(b"ERR unknown command")
    assert robot.servos[0].frames == 0 and robot.counters.errors == 2


def test_a_broadcast_reaches_both_and_a_frame_without_reply_wanted_gets_only_ok():
    robot = _robot()
    ctl = moteus.Controller(id=0x7f)
    _, answers = robot.receive(_host_line(_frame_of(ctl, ctl.make_stop(query=True)), False), 0.0)
    assert [a.split()[1] for a in answers[1:]] == [b"0100", b"0200"]
    _, answers = robot.receive(_host_line(_frame_of(ctl, ctl.make_stop()), False), 0.0)
    assert answers == [b"OK\n"]


def test_injected_latency_jitter_loss_and_silence():
    robot = _robot(latency=0.002, jitter=0.001, loss=0.25, seed=7, silent={2: 0.5})
    ctl = moteus.Controller(id=1)
    line = _host_line(_frame_of(ctl, ctl.make_query()), False)
    dues, replies = [], 0
    for k in range(400):
        due, answers = robot.receive(line, k * 1e-4)
        dues.append(due - k * 1e-4)
        replies += len(answers) - 1
        assert answers[0] == b"OK\n"   # the fdcanusb acknowledges a frame the bus then loses
    assert min(dues) >= 0.002 and max(dues) <= 0.003 + 1e-4   # in order: a late one holds back those after it
    assert robot.counters.lost == 400 - replies and 60 <= robot.counters.lost <= 140   # 25 % of 400, +-4.6 sd
    right = moteus.Controller(id=2)
    r_line = _host_line(_frame_of(right, right.make_query()), False)
    robot.injection.loss = 0.0
    assert len(robot.receive(r_line, 0.49)[1]) == 2
    assert len(robot.receive(r_line, 0.5)[1]) == 1 and robot.counters.unheard == 1   # unplugged from 0.5 s
    robot.silence(2, False)
    assert len(robot.receive(r_line, 0.6)[1]) == 2


def test_the_plant_refusing_a_torque_is_an_event_of_the_emulator():
    """A controller with no torque limit told 1e7 N m: the plant's own driver refuses it (bad_command), and the
    emulator says so once instead of going on silently without torque."""
    from dataclasses import replace
    from pathlib import Path

    from mwip_ros import params as P
    from mwip_ros.robot.sim import SimBackend
    v = P.merged_values(P.load_param_files([Path(__file__).resolve().parents[2] / "config" / "paper.yaml"]))
    robot = EmulatedRobot(SimBackend(replace(P.plant_config(v), h=0.001)),
                          [Servo(ServoConfig(can_id=1)), Servo(ServoConfig(can_id=2))], Injection())
    robot.start(0.0)
    ctl = moteus.Controller(id=1)
    robot.servos[0].frame(_torque_cmd(ctl, 1e7, maximum_torque=NAN), 0.0)
    robot.advance_to(0.0035)
    assert robot.events == ["the plant: sim: bad_command: |u| = 1e+07 N m > 1e+06 N m, implausible (no torque acts on "
                            "it from now on)"]
    assert robot.backend.plant.u_prev == 0.0


def test_only_a_command_waiting_in_the_line_holds_back_a_watchdog():
    """serve() takes the host's lines after the periods that ended before them: a controller those lines command is
    watched only up to the previous look, one they only query (or do not address) is watched throughout."""
    robot = _robot()
    c1, c2, everyone = moteus.Controller(id=1), moteus.Controller(id=2), moteus.Controller(id=0x7f)
    query = _host_line(_frame_of(c1, c1.make_query()), True)
    command = _host_line(_frame_of(c2, c2.make_position(position=NAN, feedforward_torque=0.1)), False)
    broadcast = _host_line(_frame_of(everyone, everyone.make_stop()), False)
    assert robot.commanded([query]) == set()
    assert robot.commanded([query, command]) == {2}
    assert robot.commanded([broadcast]) == {1, 2}
    for servo, ctl in zip(robot.servos, (c1, c2)):
        servo.frame(_torque_cmd(ctl, 1.0, watchdog_timeout=0.01), 0.0)
    robot.advance_to(0.02, watch_until=0.005, commanded={2})
    assert [s.mode for s in robot.servos] == [11, MODE_POSITION]   # 1 tripped at 0.010 s, 2 held back
    assert robot.servos[0].events[0].startswith("CAN id 1: watchdog timeout (mode 11), 0.0100 s after its last")
    robot.advance_to(0.03)
    assert robot.servos[1].mode == 11   # at the next look it is watched again
