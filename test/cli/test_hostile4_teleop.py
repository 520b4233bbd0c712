"""mwip_ctl drive against a hostile keyboard (issue 46 item 5), in this process through a pseudo-terminal: a burst of
keys neither delays nor multiplies the Twists (before: 200 keys 5 ms apart gave one Twist in the next 4 s, and the
robot stopped on its timeout while the screen showed vx 1.0), Ctrl-S does not stop the loop (before: flow control
stopped the output, the loop blocked in its write, no Twist and q did not quit), and a limit the controller refuses
is refused here too (before: motion.max_speed 1e300 was taken)."""
import os
import pty
import threading
import time
from types import SimpleNamespace

import pytest

from mwip_ros.cli.teleop import UP, drive, limits

pytestmark = pytest.mark.unit

RATE = 20.0


class _Pub:
    def __init__(self):
        self.times = []

    def publish(self, msg):
        self.times.append((time.monotonic(), msg.linear.x))


class _Ros:
    """What drive() needs of mwip_ctl's Ros: a node that makes the publisher, and a spin."""

    def __init__(self):
        self.pub = _Pub()
        self.node = SimpleNamespace(create_publisher=lambda *a, **k: self.pub)

    def until(self, cond, timeout):
        time.sleep(min(timeout, 0.001))
        return cond()


def _drive(keys, rate=RATE):
    """drive() on a pseudo-terminal in a thread, ``keys(master)`` typing; (the publications, the thread)."""
    master, slave = pty.openpty()
    ros = _Ros()
    args = SimpleNamespace(params=(), step_v=0.0, step_w=0.0, rate=rate)
    stdin, stdout = os.fdopen(slave, "r", closefd=False), os.fdopen(slave, "w", closefd=False)
    t = threading.Thread(target=drive, args=(ros, args, RuntimeError, stdin, stdout), daemon=True)

    def drain():   # the terminal's reader: what drive writes goes somewhere
        while True:
            try:
                if not os.read(master, 4096):
                    return
            except OSError:
                return
    threading.Thread(target=drain, daemon=True).start()
    t.start()
    try:
        keys(master)
        t.join(3.0)
        alive = t.is_alive()
    finally:
        os.write(master, b"\x11q")   # Ctrl-Q (resume output, for the old code) and quit
        t.join(3.0)
        os.close(slave)
        os.close(master)
    return ros.pub.times, alive


@pytest.mark.alone   # the twists' rate and the keys' timing are on the wall clock
def test_a_burst_of_keys_neither_delays_nor_multiplies_the_twists():
    marks = {}

    def keys(master):
        time.sleep(0.2)
        marks["burst"] = time.monotonic()
        for _ in range(200):   # 200 key presses 5 ms apart
            os.write(master, UP.encode())
            time.sleep(0.005)
        marks["after"] = time.monotonic()
        time.sleep(1.0)
        marks["end"] = time.monotonic()
        os.write(master, b"q")
    times, alive = _drive(keys)
    assert not alive
    during = [t for t, _ in times if marks["burst"] <= t < marks["after"]]
    after = [(t, v) for t, v in times if marks["after"] <= t < marks["end"]]
    burst_s = marks["after"] - marks["burst"]
    assert len(during) <= RATE * burst_s + 2, len(during)   # the rate, not one per key
    assert len(after) >= 0.7 * RATE, len(after)              # it goes on at the rate (before: none for seconds)
    assert after[-1][1] == pytest.approx(limits([]).max_speed)   # what the screen shows: vx at max_speed


@pytest.mark.alone   # the twists' rate and the keys' timing are on the wall clock
def test_ctrl_s_is_a_key_not_a_stop():
    def keys(master):
        time.sleep(0.2)
        os.write(master, b"\x13")   # Ctrl-S
        time.sleep(0.1)
        os.write(master, UP.encode() + b"q")
    t0 = time.monotonic()
    times, alive = _drive(keys)
    assert not alive, "drive still running 3 s after q (the output stopped by Ctrl-S)"
    assert len([t for t, _ in times if t > t0 + 0.2]) >= 2 and time.monotonic() - t0 < 6


def test_a_limit_the_controller_refuses_is_refused(tmp_path):
    f = tmp_path / "m.yaml"
    for value in ("1.0e+300", "1.0e+3"):   # the schema: motion.max_speed at most 100 m/s
        f.write_text(f"dscndo_controller:\n  ros__parameters:\n    motion:\n      max_speed: {value}\n")
        with pytest.raises(ValueError, match="'motion.max_speed'.*must be <= 100"):
            limits([f])
    f.write_text("dscndo_controller:\n  ros__parameters:\n    motion:\n      max_speed: 0.4\n")
    assert limits([f]).max_speed == 0.4


@pytest.mark.cli
@pytest.mark.parametrize("command", [["drive"], ["cmd", "--vx", "0.1"], ["push", "--wheel", "1"]])
def test_a_rate_that_would_flood_the_robot_is_a_usage_error(command):
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.ctl", *command, "--rate", "1e9"], capture_output=True,
                       text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert r.returncode == 2 and "--rate must be at most 1000 Hz" in r.stderr, r.stderr   # was: as fast as it could
