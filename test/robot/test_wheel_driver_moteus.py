"""The wheel_driver node with the moteus backend over a pty to mwip_moteus_emulator, each its own process, in
realtime, driven by the test's own participant (a small constant wheel_torque_cmd, and the e-stop): the torque
reaches the controllers; the driver SIGKILLed, they stop by their own watchdog; a controller that stops answering
or overheats is a fault naming it and no torque follows; an e-stop stops both.  The bounds are those a loaded
two-core machine keeps (what is judged is what happens; the balance of the whole graph at 200 Hz is run by
test/test_run_experiment_robot.py and measured by scripts/bench_driver.py)."""
from __future__ import annotations

import json
import os
import signal
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("moteus")

from graphproc import Graph, wait_until  # noqa: E402

pytestmark = pytest.mark.graph

REPO = Path(__file__).resolve().parents[2]
ROBOT = [REPO / "config" / "paper.yaml", REPO / "config" / "upkie.yaml"]   # Upkie's rigid model behind the moteus
WATCHDOG = 0.5   # moteus.watchdog_timeout [s] here: a loaded machine stalls a process for 300 ms now and then
DRIVER = ("-p", "mode:=realtime", "-p", "backend:=moteus", "-p", "require_enable:=false", "-p", "watchdog_s:=1.0",
          "-p", f"moteus.watchdog_timeout:={WATCHDOG}", "-p", "moteus.reply_timeout:=0.02",
          "-p", "moteus.silence_limit:=1.0", "-p", "expected_subscribers:=2")
TORQUE = 0.1     # the test's command [N m], lumped: 0.05 N m a wheel


class Probe:
    """A participant of the test's on the graph's domain: what it hears on ``topics``, with its receipt time, and
    a publisher of the e-stop."""

    def __init__(self, g: Graph, topics):
        import rclpy
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Bool, Float64, String

        from mwip_ros.msgs.qos import BEST_EFFORT_INPUT_QOS, DRIVER_STATE_READER_QOS, REALTIME_INPUT_QOS
        os.environ["ROS_DOMAIN_ID"] = g.env["ROS_DOMAIN_ID"]
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        self.rclpy, self.ctx = rclpy, rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node("probe", context=self.ctx)
        self.got = {t: [] for t in topics}
        types = {"wheel_states": (JointState, REALTIME_INPUT_QOS), "wheel_encoder": (JointState, REALTIME_INPUT_QOS),
                 "driver_state": (String, DRIVER_STATE_READER_QOS)}
        for t in topics:
            cls, qos = types[t]
            self.node.create_subscription(cls, t, lambda m, t=t: self.got[t].append((time.monotonic(), m)), qos)
        self.estop = self.node.create_publisher(Bool, "emergency_stop", BEST_EFFORT_INPUT_QOS)
        from mwip_ros.msgs.qos import REALTIME_QOS
        cmd = self.node.create_publisher(Float64, "wheel_torque_cmd", REALTIME_QOS)   # the controller's place
        self.node.create_timer(0.01, lambda: cmd.publish(Float64(data=TORQUE)))
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)

    def spin(self, until, timeout: float) -> bool:
        return wait_until(until, timeout, spin=lambda s: self.executor.spin_once(timeout_sec=s))

    def faults(self):
        return [json.loads(m.data) for _, m in self.got.get("driver_state", []) if json.loads(m.data)["state"] ==
                "fault"]

    def reads_after(self, stamp_ns: int):
        """The wheel_states stamped after ``stamp_ns`` but the first: the first exchange after a transition writes
        the stop and reads the torque applied until then; every later read is of a stopped controller."""
        after = [m for _, m in self.got["wheel_states"]
                 if m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec > stamp_ns]
        return after[1:]

    def close(self):
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.ctx)


def _graph(g: Graph, tmp_path: Path, *emulator: str, driver=()):
    """The emulator (held until driven; --imu-rate 0: no IMU, no estimator here) and the driver; (emulator, driver,
    summary path) once the driver runs (the probe, made first, is its graph: the command and a wheel_encoder
    listener)."""
    link = tmp_path / "fdcanusb"
    emu = g.start("mwip_moteus_emulator", params=None, as_given=True, cmd=[
        sys.executable, "-m", "mwip_ros.cli.moteus_emulator", "--params", *map(str, ROBOT), "--link", str(link),
        "--hold", "--imu-rate", "0", *emulator])
    assert emu.wait_for_output("fdcanusb: ", timeout=60), emu.output()
    summary = tmp_path / "driver.json"
    drv = g.start("wheel_driver", *DRIVER, "-p", f"moteus.path:={link}", "-p", f"summary_json:={summary}", *driver,
                  params=ROBOT)
    assert drv.wait_for_output("starting realtime run", timeout=60), drv.output()
    return emu, drv, summary


@pytest.mark.alone
def test_the_torque_reaches_the_controllers_and_a_killed_driver_leaves_them_to_their_watchdog(tmp_path):
    with Graph(tmp_path) as g:
        probe = Probe(g, ("wheel_states", "wheel_encoder"))
        try:
            emu, drv, _ = _graph(g, tmp_path)
            assert probe.spin(lambda: len(probe.got["wheel_states"]) > 100, 60.0), drv.output()
            last = probe.got["wheel_states"][-1][1]
            # each controller applies its wheel's half of the command, in the wheel's forward sense (its sign)
            assert list(last.effort) == [pytest.approx(TORQUE / 2, abs=1e-3)] * 2
            assert "-> fault" not in drv.output() and drv.poll() is None
        finally:
            probe.close()
        os.kill(drv.pid, signal.SIGKILL)   # no stop command: only silence
        assert drv.wait(10) == -signal.SIGKILL
        assert emu.wait_for_output("CAN id 2: watchdog timeout (mode 11)", timeout=10), emu.output()
        assert emu.wait_for_output("CAN id 1: watchdog timeout (mode 11)", timeout=10), emu.output()
        assert emu.stop() == 0
        for cid in (1, 2):   # on the emulator's clock: at its first physics period (1 ms) past the deadline
            line = next(x for x in emu.output().splitlines() if f"CAN id {cid}: watchdog timeout (mode 11), " in x)
            after_s = float(line.split("(mode 11), ")[1].split(" s after")[0])
            assert WATCHDOG <= after_s <= WATCHDOG + 0.005, line
        assert "watchdog trips 1 left 1 right" in emu.output()   # none while the driver ran


@pytest.mark.parametrize("fault, named, answering", [
    (("--silent", "right", "--silent-at", "0.0"), "moteus right wheel (CAN id 2): no answer for ", (0,)),
    (("--overheat", "left", "--overheat-at", "0.0"), "moteus left wheel (CAN id 1): fault 38 (over temperature)",
     (0, 1)),
])
@pytest.mark.alone
def test_a_controller_that_stops_answering_or_faults_is_named_and_no_torque_follows(tmp_path, fault, named,
                                                                                    answering):
    """The injection is armed from the start; the robot is held until the first command, so the fault meets a
    driving driver."""
    with Graph(tmp_path) as g:
        probe = Probe(g, ("wheel_states", "wheel_encoder", "driver_state"))
        try:
            emu, drv, summary = _graph(g, tmp_path, *fault)
            assert probe.spin(lambda: probe.faults(), 60.0), drv.output()
            got = probe.faults()[0]
            assert got["reason"] == "device" and got["detail"].startswith(named), got
            assert probe.spin(lambda: len(probe.reads_after(got["stamp_ns"])) >= 20, 30.0), drv.output()
            after = probe.reads_after(got["stamp_ns"])
            # the controllers that answer report no torque: stopped (the silent one's read is its last answer)
            assert all(m.effort[i] == 0.0 for m in after for i in answering)
        finally:
            probe.close()
        drv.stop()
        s = json.loads(summary.read_text())
        assert s["fault_reason"] == "device" and s["fault_detail"].startswith(named)
        assert emu.stop() == 0


@pytest.mark.alone
def test_an_estop_stops_the_device(tmp_path):
    with Graph(tmp_path) as g:
        probe = Probe(g, ("wheel_states", "wheel_encoder", "driver_state"))
        try:
            emu, drv, summary = _graph(g, tmp_path)
            assert probe.spin(lambda: len(probe.got["wheel_states"]) > 100, 60.0), drv.output()
            assert probe.got["wheel_states"][-1][1].effort[0] == pytest.approx(TORQUE / 2, abs=1e-3)   # driving
            assert probe.spin(lambda: probe.estop.get_subscription_count() >= 1, 20.0)
            from std_msgs.msg import Bool
            probe.estop.publish(Bool(data=True))
            assert probe.spin(lambda: probe.faults(), 20.0), drv.output()
            got = probe.faults()[0]
            assert got["reason"] == "emergency_stop"
            assert probe.spin(lambda: len(probe.reads_after(got["stamp_ns"])) >= 20, 30.0), drv.output()
            after = probe.reads_after(got["stamp_ns"])
            assert all(m.effort[0] == 0.0 and m.effort[1] == 0.0 for m in after)   # both stopped
        finally:
            probe.close()
        drv.stop()
        s = json.loads(summary.read_text())
        assert s["fault_reason"] == "emergency_stop" and len(s["stop_after_s"]) == 1   # the first stop, timed
        assert emu.stop() == 0
        assert "watchdog trips 0 left 0 right" in emu.output()   # stopped by the stop command, not by a timeout

