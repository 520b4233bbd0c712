"""mwip_ctl cmd and drive: cmd_vel (geometry_msgs/Twist) as a test subscriber receives it (cmd in this process, its
node a peer of the controller's: test/nodeharness.py); drive, a process on a pseudo-terminal, with key sequences,
the limits clipped, a zero Twist and the terminal restored at the end (also on Ctrl-C)."""
from __future__ import annotations

import os
import pty
import signal
import subprocess
import sys
import termios
import time
from pathlib import Path

import pytest
from geometry_msgs.msg import Twist
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from graphproc import fresh_domain_id, release_domain_id, ros_env
from injector import Injector
from mwip_ros.cli.teleop import DOWN, LEFT, RIGHT, UP, Limits, apply_key, limits, read_keys
from nodeharness import NodeHarness, node_class, run_ctl

MWIP_CTL = Path(sys.executable).with_name("mwip_ctl")
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.VOLATILE)


@pytest.mark.unit
def test_keys_step_and_clip_the_command():
    lim = Limits(0.25, 1.0)
    assert list(read_keys(UP + " q" + LEFT)) == [UP, " ", "q", LEFT]
    assert apply_key(UP, 0.0, 0.0, lim, 0.1, 0.5) == (0.1, 0.0)
    assert apply_key(DOWN, 0.0, 0.0, lim, 0.1, 0.5) == (-0.1, 0.0)
    assert apply_key(LEFT, 0.0, 0.0, lim, 0.1, 0.5) == (0.0, 0.5)     # left turns left: +wz (REP-103)
    assert apply_key(RIGHT, 0.0, 0.0, lim, 0.1, 0.5) == (0.0, -0.5)
    assert apply_key(UP, 0.2, 0.0, lim, 0.1, 0.5) == (0.25, 0.0)      # clipped at max_speed
    assert apply_key(LEFT, 0.0, 0.9, lim, 0.1, 0.5) == (0.0, 1.0)     # ... and max_yaw_rate
    assert apply_key(" ", 0.2, 0.9, lim, 0.1, 0.5) == (0.0, 0.0)
    assert apply_key("q", 0.2, 0.9, lim, 0.1, 0.5) is None
    assert apply_key("x", 0.2, 0.9, lim, 0.1, 0.5) == (0.2, 0.9)


@pytest.mark.unit
def test_limits_from_a_file_else_defaults(tmp_path):
    f = tmp_path / "m.yaml"
    f.write_text("dscndo_controller:\n  ros__parameters:\n    motion:\n      max_speed: 0.4\n      max_yaw_rate: 2.0\n")
    assert limits([f]) == Limits(0.4, 2.0)
    d = limits([])
    assert d.max_speed > 0 and d.max_yaw_rate > 0
    f.write_text("dscndo_controller:\n  ros__parameters:\n    motion:\n      max_speed: -1\n")
    with pytest.raises(ValueError, match="motion.max_speed"):
        limits([f])


@pytest.mark.cli
def test_drive_refuses_without_a_terminal():
    r = subprocess.run([str(MWIP_CTL), "drive"], stdin=subprocess.DEVNULL, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "terminal" in r.stderr


@pytest.fixture()
def reader():
    domain = fresh_domain_id()
    try:
        with Injector(domain) as inj:
            got = []
            inj.sub = inj.node.create_subscription(Twist, "cmd_vel", lambda m: got.append((time.monotonic(), m)),
                                                   QOS)
            inj.got, inj.env = got, ros_env(domain)
            yield inj
    finally:
        release_domain_id(domain)


@pytest.mark.alone   # it counts the Twists of 1 s of wall clock (6 of 10 came in a run beside the graph tests)
@pytest.mark.node
def test_cmd_publishes_the_twist_for_the_duration_then_zero():
    """In this process, beside a controller that follows cmd_vel (motion on): the reader a peer of both."""
    with NodeHarness(node_class("dscndo_controller"), "-p", "motion.enabled:=true") as h:
        got = []
        h.peer("reader").create_subscription(Twist, "/cmd_vel", lambda m: got.append((time.monotonic(), m)), QOS)
        code, out, err = run_ctl(h, "cmd", "--vx", "0.5", "--wz", "-0.2", "--duration", "1.0", "--rate", "10")
        assert code == 0, err
        assert h.spin(lambda: got and (got[-1][1].linear.x, got[-1][1].angular.z) == (0.0, 0.0), 5)
        # the controller took them too (its subscription keeps the newest: at least the moving one and the zero)
        assert h.node.motion.accepted >= 2 and not h.node.rejects.counts.get("cmd_vel"), h.logs()[-2000:]
    moving = [(t, m) for t, m in got if m.linear.x != 0.0]
    assert all((m.linear.x, m.angular.z) == (0.5, -0.2) for _, m in moving)
    assert 9 <= len(moving) <= 12                                   # 10 Hz for 1 s
    assert 0.8 <= moving[-1][0] - moving[0][0] <= 1.5
    last = got[-1][1]
    assert (last.linear.x, last.angular.z) == (0.0, 0.0)             # then a zero Twist
    assert "vx 0.5 m/s, wz -0.2 rad/s" in out


def _twist_is(reader, vx, wz, timeout=20):
    return reader.wait(lambda: reader.got and (round(reader.got[-1][1].linear.x, 9), round(reader.got[-1][1].angular.z,
                                                                                           9)) == (vx, wz), timeout)


def _default(name):
    """The schema's default of ``name`` (a dscndo_controller parameter)."""
    from mwip_ros.params.schema import NODE_SPECS
    return next(s.default for s in NODE_SPECS["dscndo_controller"] if s.name == name)


def _drained(fd) -> str:
    """Everything the terminal's master side has to read now."""
    import select
    out = b""
    while select.select([fd], [], [], 0.0)[0]:
        chunk = os.read(fd, 65536)
        if not chunk:
            break
        out += chunk
    return out.decode()


@pytest.mark.graph
def test_drive_through_a_pty(reader, tmp_path):
    f = tmp_path / "limits.yaml"
    f.write_text("dscndo_controller:\n  ros__parameters:\n    motion:\n      max_speed: 0.3\n      max_yaw_rate: 0.5\n")
    master, slave = pty.openpty()
    before = termios.tcgetattr(slave)
    p = subprocess.Popen([str(MWIP_CTL), "drive", "--params", str(f), "--rate", "50"], env=reader.env,
                         stdin=slave, stdout=slave, stderr=subprocess.PIPE)
    try:
        assert reader.wait(lambda: reader.sub.get_publisher_count() >= 1 and reader.got, 60), p.stderr
        assert _twist_is(reader, 0.0, 0.0)
        os.write(master, (UP + UP + LEFT).encode())                  # steps max/10: 0.03 m/s, 0.05 rad/s
        assert _twist_is(reader, 0.06, 0.05), reader.got[-1]
        os.write(master, (UP * 20 + RIGHT * 30).encode())            # clipped at the file's limits
        assert _twist_is(reader, 0.3, -0.5), reader.got[-1]
        os.write(master, b" ")
        assert _twist_is(reader, 0.0, 0.0)
        os.write(master, (UP + UP).encode())
        assert _twist_is(reader, 0.06, 0.0)
        os.write(master, b"q")
        assert reader.wait(lambda: p.poll() is not None, 20)
        reader.spin(0.3)
        assert p.returncode == 0, p.stderr.read()
        assert (reader.got[-1][1].linear.x, reader.got[-1][1].angular.z) == (0.0, 0.0)
        assert termios.tcgetattr(slave) == before                    # the terminal as it was
        screen = _drained(master)
        assert "max 0.3 m/s" in screen and "max 0.5 rad/s" in screen and "vx +0.060 m/s" in screen
        # the status line is drawn when it changes: at most the start, then once per key (2 + 1, 20 + 30 of which
        # the clipped ones change nothing, the stop, 2); not at every one of the hundreds of ticks
        assert screen.count("\rvx ") <= 1 + 3 + 50 + 1 + 2, screen.count("\rvx ")
        # Ctrl-C (SIGINT) while moving: a zero Twist, the terminal restored, exit 130
        p = subprocess.Popen([str(MWIP_CTL), "drive", "--rate", "50"], env=reader.env, stdin=slave, stdout=slave,
                             stderr=subprocess.PIPE)
        assert reader.wait(lambda: reader.sub.get_publisher_count() >= 1, 60)
        os.write(master, UP.encode())
        assert _twist_is(reader, round(_default("motion.max_speed") / 10, 9), 0.0)   # the schema's limit: a tenth
        p.send_signal(signal.SIGINT)
        assert reader.wait(lambda: p.poll() is not None, 20)
        reader.spin(0.3)
        assert p.returncode == 130
        assert (reader.got[-1][1].linear.x, reader.got[-1][1].angular.z) == (0.0, 0.0)
        assert termios.tcgetattr(slave) == before
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        os.close(master)
        os.close(slave)
