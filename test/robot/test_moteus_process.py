"""mwip_moteus_emulator in its own process, MoteusBackend over its pty (mwip_ros.cli.moteus_emulator): the IMU on
ROS at its own rate, torque that moves the wheels, stops, the controllers' own watchdog when the driver is killed,
and a controller that stops answering or faults, named."""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("moteus")

from mwip_ros.robot import Command  # noqa: E402
from mwip_ros.robot.moteus_backend import MoteusBackend, MoteusConfig  # noqa: E402

from graphproc import Graph, wait_until  # noqa: E402

pytestmark = pytest.mark.graph

REPO = Path(__file__).resolve().parents[2]
AT_REST = ("plant_sim:\n  ros__parameters:\n    initial: {theta_w: 0.0, theta_b: 0.0, dtheta_w: 0.0, dtheta_b: 0.0}\n"
           "    tau_ext1: {amplitude: 0.0}\n    tau_ext2: {amplitude: 0.0}\n    actual: {D_w_variance: 0.0}\n")


def _emulator(g: Graph, tmp_path: Path, *options: str):
    """The emulator started as a user starts it (its IMU on the graph's domain), and its pty's path once it is up."""
    overlay = tmp_path / "at_rest.yaml"
    overlay.write_text(AT_REST)
    link = tmp_path / f"fdcanusb{len(g.procs)}"
    proc = g.start("mwip_moteus_emulator", params=None, as_given=True, label=link.name,
                   cmd=[sys.executable, "-m", "mwip_ros.cli.moteus_emulator", "--params", str(REPO / "config" /
                        "paper.yaml"), str(overlay), "--link", str(link), *options])
    assert proc.wait_for_output("fdcanusb: ", timeout=30), proc.output()
    return proc, str(link)


def _backend(path: str, **kw) -> MoteusBackend:
    """The backend with bounds that a loaded machine keeps (two cores shared by several test runs stall a process
    for 100 ms and more): what is judged here is what happens, not how fast (the 200 Hz figures are measured)."""
    args = dict(path=path, maximum_torque=20.0, watchdog_timeout=0.5, reply_timeout=0.02, silence_limit=0.3)
    args.update(kw)
    return MoteusBackend(MoteusConfig(**args))


def _drive(b: MoteusBackend, command, seconds: float, period: float = 0.005):
    end, t = time.monotonic() + seconds, time.monotonic()
    obs = b.step(command)
    while time.monotonic() < end:
        t += period
        time.sleep(max(0.0, t - time.monotonic()))
        obs = b.step(command)
    return obs


def _imu_messages(g: Graph, seconds: float):
    """The IMU messages a subscriber on the graph's domain receives over ``seconds`` (after the first one)."""
    import rclpy
    from sensor_msgs.msg import Imu

    from mwip_ros.msgs.qos import qos_for
    os.environ["ROS_DOMAIN_ID"] = g.env["ROS_DOMAIN_ID"]
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        node = rclpy.create_node("imu_probe", context=ctx)
        got = []
        node.create_subscription(Imu, "imu/data_raw", lambda m: got.append((time.monotonic(), m)),
                                 qos_for("realtime")[1])
        executor = rclpy.executors.SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        assert wait_until(lambda: got, 20.0, spin=lambda s: executor.spin_once(timeout_sec=s)), "no IMU message"
        start = len(got)
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            executor.spin_once(timeout_sec=0.01)
        node.destroy_node()
        return got[start:], time.monotonic() - t0
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.mark.alone
def test_the_imu_at_its_rate_torque_that_moves_the_wheels_a_stop_and_a_controller_unplugged(tmp_path):
    with Graph(tmp_path) as g:
        emu, path = _emulator(g, tmp_path)
        msgs, span = _imu_messages(g, 2.0)
        stamps = [x.header.stamp.sec + 1e-9 * x.header.stamp.nanosec for _, x in msgs]
        assert all(b > a for a, b in zip(stamps, stamps[1:]))   # each a new sample, stamped at its read
        rate = (len(stamps) - 1) / (stamps[-1] - stamps[0])
        assert rate == pytest.approx(400.0, rel=0.02)   # its own rate on its own clock, with nobody driving
        assert len(msgs) >= 0.8 * 400.0 * span           # and delivered (a loaded machine delays, drops a few)
        assert abs(time.time() - stamps[-1]) < 1.0
        m = msgs[-1][1]
        assert m.header.frame_id == "imu_link" and m.orientation_covariance[0] == -1.0
        acc = m.linear_acceleration
        assert (acc.x, acc.y, acc.z) == pytest.approx((0.0, 0.0, 9.81), abs=1e-6)   # at rest, upright (REP-145)
        with _backend(path) as b:
            assert b.reset().fault is None
            moving = _drive(b, Command(5.0, 5.0), 0.3)
            assert moving.fault is None
            assert moving.left.velocity > 0.05 and moving.right.velocity > 0.05   # forward, each with its sign
            assert moving.left.velocity == pytest.approx(moving.right.velocity, rel=0.02)
            assert moving.left.torque == pytest.approx(5.0, abs=1e-3) and moving.right.torque == pytest.approx(5.0,
                                                                                                                abs=1e-3)
            _drive(b, None, 0.03)
            stopped = b.step(None)
            assert stopped.fault is None and stopped.torque == 0.0
            _drive(b, Command(1.0, 1.0), 0.1)
            os.kill(emu.pid, signal.SIGUSR1)   # the right controller unplugged
            t0 = time.monotonic()
            assert wait_until(lambda: b.step(Command(1.0, 1.0)).fault is not None, 10.0, step=0.005)
            assert b.fault.startswith("moteus right wheel (CAN id 2): no answer for ") and "left" not in b.fault
            assert 0.3 <= time.monotonic() - t0 < 5.0   # silence_limit
            for _ in range(3):   # each cycle waits reply_timeout for the unplugged one
                left = b.step(Command(1.0, 1.0)).left
            assert left.torque == 0.0   # stops went to the left one: no torque
            # the unplugged one stops by its own watchdog
            assert emu.wait_for_output("CAN id 2: watchdog timeout (mode 11)", timeout=10.0), emu.output()
        assert emu.stop() == 0
        assert "watchdog trips 0 left 1 right" in emu.output()


DRIVER = """
import sys, time
from mwip_ros.robot import Command
from mwip_ros.robot.moteus_backend import MoteusBackend, MoteusConfig
b = MoteusBackend(MoteusConfig(path=sys.argv[1], maximum_torque=20.0, watchdog_timeout=float(sys.argv[2]),
                               reply_timeout=0.02, silence_limit=1.0))
b.reset()
t = time.monotonic()
for k in range(100000):
    obs = b.step(Command(2.0, 2.0))
    if k == 40:
        print("driving", obs.fault, flush=True)
    t += 0.005
    time.sleep(max(0.0, t - time.monotonic()))
"""


@pytest.mark.alone
def test_the_controllers_stop_by_their_watchdog_when_the_driver_is_killed(tmp_path):
    """SIGKILL of the driving process: no stop command, only silence; both controllers enter their timeout mode
    within watchdog_timeout of the kill and stop driving (--timeout-mode 0: no torque)."""
    watchdog = 0.3
    with Graph(tmp_path) as g:
        emu, path = _emulator(g, tmp_path, "--timeout-mode", "0")
        driver = subprocess.Popen([sys.executable, "-c", DRIVER, path, str(watchdog)], stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True, env=g.env)
        try:
            assert driver.stdout.readline().strip() == "driving None"
            os.kill(driver.pid, signal.SIGKILL)
            t_kill = time.monotonic()
            assert driver.wait(timeout=10) == -signal.SIGKILL
        finally:
            if driver.poll() is None:
                os.kill(driver.pid, signal.SIGKILL)
                driver.wait(timeout=10)
        with _backend(path, watchdog_timeout=0.3, reply_timeout=0.02, silence_limit=1.0) as b:
            first = b.observe()   # a query: no command, the watchdog is not fed
            assert first.fault is None and first.left.torque == pytest.approx(2.0, abs=1e-3)   # still driving
            assert wait_until(lambda: b.observe().fault is not None, 5.0, step=0.005)
            t_trip = time.monotonic()
            assert "left wheel (CAN id 1): watchdog timeout (mode 11)" in b.fault
            assert "right wheel (CAN id 2): watchdog timeout (mode 11)" in b.fault
            assert t_trip - t_kill < watchdog + 1.0   # on the wall clock: a loaded machine may be late to look
            b.observe()
            after = b.observe()
            assert after.left.torque == 0.0 and after.right.torque == 0.0
        assert emu.stop() == 0
        log = emu.output()
        assert "watchdog trips 1 left 1 right" in log
        for cid in (1, 2):   # on the emulator's own clock: at the first physics period (1 ms) after the deadline, or
            # at the first one it looks at without bytes of the host waiting (moteus_emu.serve), a few ms at most
            line = next(x for x in log.splitlines() if f"CAN id {cid}: watchdog timeout (mode 11), " in x)
            after_s = float(line.split("(mode 11), ")[1].split(" s after")[0])
            assert watchdog <= after_s <= watchdog + 0.005, line


@pytest.mark.alone
def test_an_over_temperature_is_a_fault_naming_the_wheel_and_no_torque_follows(tmp_path):
    with Graph(tmp_path) as g:
        emu, path = _emulator(g, tmp_path, "--overheat", "left", "--overheat-at", "0")
        with _backend(path) as b:
            b.reset()
            obs = b.step(Command(1.0, 1.0))
            if obs.fault is None:   # the stop of reset() answered before the command met the heat
                obs = b.step(Command(1.0, 1.0))
            assert obs.fault == "moteus left wheel (CAN id 1): fault 38 (over temperature)"
            _drive(b, Command(1.0, 1.0), 0.05)
            assert b.step(Command(1.0, 1.0)).torque == 0.0 and math.isfinite(b.observe().phi)
        assert emu.stop() == 0
