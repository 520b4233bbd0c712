"""MoteusBackend (mwip_ros.robot.moteus_backend) through mjbots' moteus library over a pty to the emulated robot,
served by a thread of this process (the emulator's own process: test_moteus_process.py).  Timing is not judged here
(the two share an interpreter): what goes over the line and what comes back is."""
from __future__ import annotations

import math
import os
import threading
import time
import tty
from dataclasses import replace
from pathlib import Path

import pytest

pytest.importorskip("moteus")

from mwip_ros import params as P  # noqa: E402
from mwip_ros.core.plants.model import Sinusoid  # noqa: E402
from mwip_ros.robot import Backend, BackendError, Command  # noqa: E402
from mwip_ros.robot.moteus_backend import MoteusBackend, MoteusConfig  # noqa: E402
from mwip_ros.robot.moteus_emu import EmulatedRobot, Injection, Servo, ServoConfig, serve  # noqa: E402
from mwip_ros.robot.sim import SimBackend  # noqa: E402

from graphproc import wait_until  # noqa: E402

# alone: the backend's timeouts (silence_limit, a write's bound) and the emulator's watchdog are on the wall clock,
# and the tests bound them there (scripts/test.sh runs them without other work of their class beside them)
pytestmark = [pytest.mark.unit, pytest.mark.alone]

CONFIG = Path(__file__).resolve().parents[2] / "config"
WATCHDOG = 1.0   # a machine loaded 7 times over its cores stalls this process for 300 ms and more


@pytest.fixture
def emulated():
    """(the emulated robot, its pty's path): two controllers (ids 1, 2; signs +1, -1) over the paper's robot, no
    disturbance, upright; served until the test ends."""
    v = P.merged_values(P.load_param_files([CONFIG / "paper.yaml"]))
    cfg = replace(P.plant_config(v), h=0.002, substeps=1, initial=(0.0, 0.0, 0.0, 0.0), tau_ext1=Sinusoid(),
                  tau_ext2=Sinusoid())
    servos = [Servo(ServoConfig(can_id=1, sign=1, timeout_mode=0)), Servo(ServoConfig(can_id=2, sign=-1,
                                                                                     timeout_mode=0))]
    robot = EmulatedRobot(SimBackend(cfg), servos, Injection())
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    running = threading.Event()
    running.set()
    server = threading.Thread(target=serve, args=(robot, master, running.is_set), daemon=True)
    server.start()

    def stop_serving():   # the fdcanusb stops reading (its pty stays open)
        running.clear()
        server.join(timeout=5)

    robot.stop_serving = stop_serving
    try:
        yield robot, os.ttyname(slave)
    finally:
        running.clear()
        server.join(timeout=5)
        os.close(master)
        os.close(slave)


def _backend(path, **kw) -> MoteusBackend:
    args = dict(path=path, maximum_torque=3.0, watchdog_timeout=WATCHDOG, reply_timeout=0.2, silence_limit=1.0)
    args.update(kw)
    return MoteusBackend(MoteusConfig(**args))


def _run(backend, command, seconds: float, period: float = 0.005):
    """Step ``command`` for ``seconds``; the last read.  :data:`SENT` holds when the last step began."""
    end = time.monotonic() + seconds
    SENT[0] = time.monotonic()
    obs = backend.step(command)
    while time.monotonic() < end:
        time.sleep(period)
        SENT[0] = time.monotonic()
        obs = backend.step(command)
    return obs


SENT = [0.0]


def _modes(robot, *want) -> bool:
    """The controllers reach these modes (a frame the exchange's bound cut short is still on its way)."""
    return wait_until(lambda: [s.mode for s in robot.servos] == list(want), 2.0, step=0.002)


def test_torque_commands_move_the_wheels_forward_with_each_wheel_s_sign_and_a_stop_stops(emulated):
    robot, path = emulated
    with _backend(path) as b:
        assert isinstance(b, Backend) and not b.simulated
        first = b.reset()
        assert first.fault is None and first.imu is None and first.truth is None
        assert (first.left.position, first.right.position) == (0.0, 0.0)
        obs = _run(b, Command(2.0, 2.0), 0.3)
        assert obs.fault is None
        assert _modes(robot, 10, 10)
        assert (robot.servos[0].torque, robot.servos[1].torque) == pytest.approx((2.0, -2.0), abs=1e-3)
        x = robot.obs.truth
        assert x[2] - x[3] > 0.1   # the wheels turn forward relative to the body
        assert obs.left.velocity > 0.1 and obs.right.velocity > 0.1 and obs.phi > 0.0
        assert obs.left.velocity == pytest.approx(obs.right.velocity, rel=1e-3)   # both read in the forward sense
        assert obs.left.torque == pytest.approx(2.0, abs=1e-3) and obs.right.torque == pytest.approx(2.0, abs=1e-3)
        clipped = b.step(Command(9.0, -9.0))   # the right one: -9 forward on sign -1, +9 on its shaft
        assert clipped.fault is None   # each within maximum_torque 3, from the next physics period:
        assert wait_until(lambda: [round(s.torque, 3) for s in robot.servos] == [3.0, 3.0], 1.0, step=0.002)
        stopped = b.step(None)
        assert stopped.fault is None and _modes(robot, 0, 0)
        assert b.step(None).torque == 0.0
    assert b.closed and _modes(robot, 0, 0)
    b.close()   # idempotent
    with pytest.raises(BackendError, match="moteus: the backend is closed"):
        b.observe()


def test_the_watchdog_stops_the_controllers_when_the_commands_stop(emulated):
    robot, path = emulated
    with _backend(path) as b:
        b.reset()
        _run(b, Command(1.0, 1.0), 0.1)
        t_last = SENT[0]   # the last command left after this
        assert wait_until(lambda: all(s.mode == 11 for s in robot.servos), 2.0, step=0.002)
        assert time.monotonic() - t_last >= WATCHDOG   # not before watchdog_timeout
        assert [s.torque for s in robot.servos] == [0.0, 0.0] and [s.watchdog_trips for s in robot.servos] == [1, 1]
        obs = b.observe()
        assert "moteus left wheel (CAN id 1): watchdog timeout (mode 11)" in obs.fault
        assert "moteus right wheel (CAN id 2): watchdog timeout" in obs.fault
        b.step(Command(1.0, 1.0))   # latched: stops go out instead, and the stop leaves the timeout mode
        assert _modes(robot, 0, 0)
        fresh = b.reset()
        assert fresh.fault is None
        assert b.step(Command(1.0, 1.0)).fault is None and _modes(robot, 10, 10)


def test_a_controller_that_stops_answering_is_named_alone_and_no_torque_follows(emulated):
    robot, path = emulated
    with _backend(path) as b:
        b.reset()
        _run(b, Command(1.0, 1.0), 0.05)
        assert not b.step(Command(1.0, 1.0)).stale   # both answered: a read of now
        robot.silence(2, True)
        t0 = time.monotonic()
        obs = b.step(Command(1.0, 1.0))
        assert obs.stale   # the right wheel's last answer: no read of now (the driver does not publish it)
        while obs.fault is None and time.monotonic() - t0 < 4.0:
            obs = b.step(Command(1.0, 1.0))
        assert obs.fault is not None and obs.fault.startswith("moteus right wheel (CAN id 2): no answer for ")
        assert "left" not in obs.fault and time.monotonic() - t0 >= 1.0   # silence_limit
        assert b.missed[1] >= 1
        assert obs.right == b._last[1] and math.isfinite(obs.right.position)   # its last answer, kept
        b.step(Command(1.0, 1.0))
        assert wait_until(lambda: robot.servos[0].mode == 0, 2.0, step=0.002)   # stopped; the right one stops
        # by its own watchdog
        assert wait_until(lambda: robot.servos[1].mode == 11, 3.0, step=0.002)
        robot.silence(2, False)
        assert b.reset().fault is None and _modes(robot, 0, 0)


def test_a_controller_s_over_temperature_fault_is_named_with_its_code(emulated):
    robot, path = emulated
    with _backend(path) as b:
        b.reset()
        _run(b, Command(0.5, 0.5), 0.05)
        robot.servos[0].overheat(True)
        assert wait_until(lambda: b.step(Command(0.5, 0.5)).fault is not None, 5.0, step=0.005)
        assert b.fault == "moteus left wheel (CAN id 1): fault 38 (over temperature)"
        b.step(Command(0.5, 0.5))
        assert _modes(robot, 0, 0)   # stops to both after the fault
        assert b.reset().fault is None   # the stop clears moteus's fault; the next command meets the heat again
        assert wait_until(lambda: b.step(Command(0.5, 0.5)).fault is not None, 5.0, step=0.005)
        assert "fault 38" in b.fault


def _fill(fd: int) -> int:
    """Write to the non-blocking ``fd`` until it takes not one byte more; the bytes written."""
    n = 0
    for size in (4096, 64, 1):
        try:
            while True:
                n += os.write(fd, b"x" * size)
        except BlockingIOError:
            pass
    return n


def test_a_device_that_stops_reading_is_a_fault_not_a_hang(emulated):
    """pyserial, as the library opens it, would wait without a bound for the port to take a write: an fdcanusb that
    stops reading, its buffer full, costs one write of silence_limit, then nothing goes out until reset."""
    robot, path = emulated
    with _backend(path, silence_limit=0.5) as b:
        b.reset()
        robot.stop_serving()
        jam = os.open(path, os.O_WRONLY | os.O_NOCTTY | os.O_NONBLOCK)   # fill what the pty holds, to the byte
        try:
            # the kernel moves what was written into the reader's buffer later (a worker thread): fill again until
            # 0.1 s after the last fill nothing more goes in
            while _fill(jam):
                time.sleep(0.1)
        finally:
            os.close(jam)
        t0 = time.monotonic()
        obs = b.step(Command(0.5, 0.5))
        assert time.monotonic() - t0 < 0.5 + 0.2 + 0.5   # the write's bound, the replies' bound, slack
        assert obs.fault.startswith(f"moteus: the fdcanusb at {path!r} failed: it did not take a write within "
                                    "silence_limit 500 ms (it stopped reading, or this system is that late)")
        t1 = time.monotonic()
        for _ in range(5):
            assert b.step(Command(0.5, 0.5)).fault == obs.fault
        assert b.observe().fault == obs.fault
        assert time.monotonic() - t1 < 0.05   # no traffic: the latched read at once


def test_a_serial_path_that_does_not_open_is_one_line_naming_it():
    with pytest.raises(BackendError, match="moteus: cannot open the fdcanusb at '/nonexistent/fdcanusb': ") as err:
        MoteusBackend(MoteusConfig(path="/nonexistent/fdcanusb", maximum_torque=1.0))
    assert "\n" not in str(err.value)


def test_a_non_finite_command_stops_both_and_latches(emulated):
    robot, path = emulated
    with _backend(path) as b:
        b.reset()
        b.step(Command(1.0, 1.0))
        obs = b.step(Command(1.0, math.inf))
        assert "the command for the right wheel is not finite" in obs.fault
        assert _modes(robot, 0, 0)


@pytest.mark.parametrize("bad, key", [
    (dict(path=""), "path"), (dict(maximum_torque=0.0), "maximum_torque"), (dict(maximum_torque=math.nan),
                                                                           "maximum_torque"),
    (dict(ids=(1, 1)), "ids"), (dict(ids=(0, 2)), "ids"), (dict(signs=(1, 0)), "signs"),
    (dict(watchdog_timeout=-1.0), "watchdog_timeout"), (dict(reply_timeout=math.inf), "reply_timeout"),
    (dict(reply_timeout=0.03, watchdog_timeout=0.05), "reply_timeout")])
def test_a_bad_setting_is_refused_naming_it(bad, key):
    args = dict(path="/dev/fdcanusb", maximum_torque=1.0)
    args.update(bad)
    with pytest.raises(ValueError, match=f"moteus: {key}: "):
        MoteusConfig(**args)
