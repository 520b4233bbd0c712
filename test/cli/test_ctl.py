"""mwip_ctl, the live actions of docs/graph.md without a ros2 CLI, against a realtime graph as a user runs them."""
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from graphproc import REPO, Graph

MWIP_CTL = Path(sys.executable).with_name("mwip_ctl")   # the console script setup.py installs


# mwip_ctl's own wait for the node (discovery of a new process): 30 s here, not its 5 s default, which a loaded
# machine has exceeded; the tests of the timeout give theirs
DISCOVERY = ("--timeout", "30")


def ctl(graph, *args, timeout=60):
    t0 = time.monotonic()
    args = args if "--timeout" in args else (*args, *DISCOVERY)
    r = subprocess.run([str(MWIP_CTL), *args], capture_output=True, text=True, env=graph.env, timeout=timeout)
    r.seconds = time.monotonic() - t0
    print(f"{r.seconds:5.2f} s  mwip_ctl {' '.join(args)}")
    return r


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    """Observer, controller and a realtime plant that runs until stopped (upright start: nothing falls)."""
    workdir = tmp_path_factory.mktemp("ctl")
    with Graph(workdir) as g:
        g.obs = g.start("disturbance_observer", "-p", "mode:=realtime")
        g.ctl = g.start("dscndo_controller", "-p", "mode:=realtime")
        g.plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", "-p", "initial.theta_b:=0.0")
        for p, text in ((g.obs, "ready"), (g.ctl, "ready"), (g.plant, "starting realtime run")):
            assert p.wait_for_output(text, 60), p.output()[-2000:]
        yield g


@pytest.mark.graph
def test_param_set_converts_a_whole_number_for_a_double_get_reads_it_back_and_the_node_logs_it(graph):
    r = ctl(graph, "param", "set", "dscndo_controller", "k1", "8")
    assert r.returncode == 0 and r.stdout.strip() == "dscndo_controller: k1 = 8.0", (r.stdout, r.stderr)
    assert graph.ctl.wait_for_output("parameters changed: k1: 6.0 -> 8.0", 10), graph.ctl.output()[-2000:]
    r = ctl(graph, "param", "get", "dscndo_controller", "k1")
    assert r.returncode == 0 and r.stdout.strip() == "8.0", (r.stdout, r.stderr)
    r = ctl(graph, "param", "list", "dscndo_controller")
    assert r.returncode == 0 and {"k1", "law", "use_observer", "lqr.Q"} <= set(r.stdout.split()), r.stdout


@pytest.mark.graph
def test_param_set_prints_the_nodes_warning_where_the_user_looks(graph):
    """k1 = 7 breaks Theorem 2 (a3 = -0.7167): the warning was only in the controller's log; mwip_ctl prints it
    (stderr, exit 0: the change is made), and nothing for gains that keep it."""
    r = ctl(graph, "param", "set", "dscndo_controller", "k1", "7")
    assert r.returncode == 0 and r.stdout.strip() == "dscndo_controller: k1 = 7.0", (r.stdout, r.stderr)
    line, = r.stderr.strip().splitlines()
    assert line.startswith("dscndo_controller: warning: gains break Theorem 2") and "a3 = -0.7167" in line, line
    assert graph.ctl.wait_for_output("a3 = -0.7167", 10)   # the node's own log says the same
    r = ctl(graph, "param", "set", "dscndo_controller", "k1", "6")   # the paper's: a3 = 0.7833 > 0
    assert r.returncode == 0 and r.stderr == "", (r.stdout, r.stderr)


@pytest.mark.graph
def test_a_value_the_schema_refuses_exits_1_with_the_nodes_reason_and_changes_nothing(graph):
    before = ctl(graph, "param", "get", "dscndo_controller", "k1").stdout
    # k1 must be > 0 (ParamSpec _positive): 0 is sent as the double 0.0, so the refusal is the range, not the type
    r = ctl(graph, "param", "set", "dscndo_controller", "k1", "0")
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert "dscndo_controller refused k1 = 0.0" in r.stderr and "parameter 'k1': must be > 0" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    r = ctl(graph, "param", "set", "dscndo_controller", "law", "pid")
    assert r.returncode == 1 and "must be one of 'dsc', 'lqr'" in r.stderr, r.stderr
    assert ctl(graph, "param", "get", "dscndo_controller", "k1").stdout == before != ""


@pytest.mark.graph
def test_reset_restarts_the_plant_and_the_loop_follows(graph):
    r = ctl(graph, "reset")
    assert r.returncode == 0 and r.stdout.startswith("plant_sim: reset #1 at t = "), (r.stdout, r.stderr)
    assert graph.plant.wait_for_output("reset #1 at t = ", 10)
    for p in (graph.obs, graph.ctl):   # realtime: they see the stamps go back (to the run's first) at once
        assert p.wait_for_output("joint_states restarted at t = ", 10), p.output()[-2000:]


@pytest.mark.graph
def test_push_reaches_the_plant_with_its_torques_and_ends_with_a_zero_wrench(graph):
    r = ctl(graph, "push", "--wheel", "50", "--duration", "0.2")
    assert r.returncode == 0, (r.stdout, r.stderr)
    assert "tau_ext1 += 50, tau_ext2 += 50 N m" in r.stdout and "then a zero wrench" in r.stdout
    # the plant logs the torques it parsed from each external_wrench it took, and the zero one that ends it
    assert graph.plant.wait_for_output("external wrench cleared", 10), graph.plant.output()[-2000:]
    out = graph.plant.output()
    pushed = out.split("external wrench: tau_ext1 += 50, tau_ext2 += 50 N m")
    assert len(pushed) >= 3 and "external wrench cleared" in pushed[-1]   # 10 Hz for 0.2 s: 3 sent, >= 2 taken
    # the body row alone: torque.y only (eq. 1's body row carries tau_ext2 - tau_ext1)
    r = ctl(graph, "push", "--body", "20", "--duration", "0.1", "--rate", "0")
    assert r.returncode == 0 and graph.plant.wait_for_output("tau_ext1 += 0, tau_ext2 += 20 N m", 10)
    r = ctl(graph, "push", "--lateral", "300", "--yaw", "5", "--duration", "0.1", "--rate", "0")   # mujoco's
    assert r.returncode == 0 and "force.y 300 N, torque.z 5 N m" in r.stdout, (r.stdout, r.stderr)
    assert graph.plant.wait_for_output("force.y 300 N, torque.z 5 N m", 10), graph.plant.output()[-2000:]
    assert graph.plant.poll() is None, graph.plant.output()[-2000:]   # pushed, not fallen


@pytest.mark.graph
def test_ctrl_c_ends_a_push_with_a_zero_wrench_and_exits_130_quietly(graph):
    p = subprocess.Popen([str(MWIP_CTL), "push", "--wheel", "5", "--duration", "60", *DISCOVERY],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=graph.env)
    try:
        assert graph.plant.wait_for_output("external wrench: tau_ext1 += 5, tau_ext2 += 5 N m", 20)
        cleared = graph.plant.output().count("external wrench cleared")
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=10)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130 and out == err == "", (p.returncode, out, err)
    end = time.monotonic() + 10
    while graph.plant.output().count("external wrench cleared") == cleared and time.monotonic() < end:
        time.sleep(0.05)
    assert graph.plant.output().count("external wrench cleared") > cleared


@pytest.mark.graph
def test_estop_holds_the_level_reset_is_refused_until_release_then_disable_and_enable(tmp_path):
    """estop publishes true once and exits; the plant holds the e-stop: reset is refused (exit 1, one line naming
    it) until estop --release; then reset clears the fault, and disable and enable switch the driver.  A plant of
    its own, at rest and upright with nothing to push it (no controller: a long watchdog), stays up in fault."""
    with Graph(tmp_path) as graph:
        graph.plant = graph.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", "-p",
                                  "initial.theta_b:=0.0", "-p", "tau_ext1.amplitude:=0.0", "-p",
                                  "tau_ext2.amplitude:=0.0", "-p", "actual.D_w_variance:=0.0", "-p",
                                  "lockstep_timeout_s:=0.5", "-p", "watchdog_s:=1000.0", "-p", "exit_on_fall:=false")
        assert graph.plant.wait_for_output("starting realtime run", 60), graph.plant.output()[-2000:]
        _estop_sequence(graph)


@pytest.mark.graph
def test_the_estop_sequence_on_the_drive_graph_the_robot_falls_then_reset_picks_it_up(tmp_path):
    """docs/real-robot.md's sequence on the drive graph (config/drive.yaml: MuJoCo, motion from cmd_vel,
    exit_on_fall: false): the e-stop cuts the torque and the balancing robot falls, the plant stays up (before,
    exit_on_fall ended the run and every later call found no node); reset is refused while the e-stop is asserted;
    released, reset clears the fault and puts the robot back at its initial state, and the loop balances it."""
    pytest.importorskip("mujoco")
    files = [REPO / "config" / "paper.yaml", REPO / "config" / "drive.yaml"]
    with Graph(tmp_path) as graph:
        obs = graph.start("disturbance_observer", "-p", "mode:=realtime", params=files)
        ctl_node = graph.start("dscndo_controller", "-p", "mode:=realtime", params=files)
        graph.plant = plant = graph.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", "-p",
                                          f"summary_json:={tmp_path / 'summary.json'}", params=files)
        for p, text in ((obs, "ready"), (ctl_node, "ready"), (plant, "starting realtime run")):
            assert p.wait_for_output(text, 60), p.output()[-2000:]
        r = ctl(graph, "estop")
        assert r.returncode == 0, (r.stdout, r.stderr)
        assert plant.wait_for_output("-> fault (emergency_stop", 10), plant.output()[-2000:]
        assert plant.wait_for_output("FALLEN at t = ", 20), plant.output()[-2000:]   # no torque: it falls
        assert "the robot lies where it fell" in plant.output() and plant.poll() is None
        r = ctl(graph, "reset")
        assert r.returncode == 1 and "emergency stop is still asserted" in r.stderr, (r.stdout, r.stderr)
        r = ctl(graph, "estop", "--release")
        assert r.returncode == 0, (r.stdout, r.stderr)
        assert plant.wait_for_output("emergency stop released", 10), plant.output()[-2000:]
        r = ctl(graph, "reset")
        assert r.returncode == 0 and "fault cleared (emergency_stop" in r.stdout, (r.stdout, r.stderr)
        assert plant.wait_for_output("reset #2", 10), plant.output()[-2000:]   # (#1: the refused call's, no torque)
        time.sleep(3.0)   # the loop catches the robot from its initial tilt (it recovers within 2 s)
        assert plant.poll() is None, plant.output()[-2000:]
        plant.stop(signal.SIGINT, timeout=30)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["resets"] == 2 and not summary["fallen"] and summary["driver_state"] == "enabled", summary
    assert summary["metrics"]["theta_b_max_abs"] < 0.2, summary["metrics"]   # upright again after the reset


def _estop_sequence(graph):
    plant = graph.plant
    r = ctl(graph, "estop")
    assert r.returncode == 0 and "emergency stop asserted" in r.stdout, (r.stdout, r.stderr)
    assert plant.wait_for_output("-> fault (emergency_stop", 10), plant.output()[-2000:]
    r = ctl(graph, "reset")
    assert r.returncode == 1 and r.stdout == "", (r.stdout, r.stderr)
    line, = r.stderr.strip().splitlines()
    assert "refused reset" in line and "emergency stop is still asserted" in line, line
    r = ctl(graph, "enable")
    assert r.returncode == 1 and "call ~/reset first" in r.stderr, (r.stdout, r.stderr)
    r = ctl(graph, "estop", "--release")
    assert r.returncode == 0 and "emergency stop released" in r.stdout, (r.stdout, r.stderr)
    assert plant.wait_for_output("emergency stop released; the fault stays latched", 10), plant.output()[-2000:]
    r = ctl(graph, "reset")
    assert r.returncode == 0 and "fault cleared (emergency_stop" in r.stdout, (r.stdout, r.stderr)
    r = ctl(graph, "disable")
    assert r.returncode == 0 and r.stdout.strip() == "plant_sim: disabled", (r.stdout, r.stderr)
    r = ctl(graph, "enable")
    assert r.returncode == 0 and r.stdout.strip() == "plant_sim: enabled", (r.stdout, r.stderr)
    assert plant.poll() is None


@pytest.mark.graph
@pytest.mark.parametrize("args,service", [
    (["param", "get", "no_such_node", "k1"], "no_such_node/get_parameters"),
    (["reset", "--node", "no_such_plant"], "no_such_plant/reset"),
    (["push", "--node", "no_such_plant", "--wheel", "1"], "no_such_plant subscribes /external_wrench"),
    (["enable", "--node", "no_such_plant"], "no_such_plant/enable"),
    (["disable", "--node", "no_such_plant"], "no_such_plant/disable"),
    (["estop", "--node", "no_such_plant"], "no_such_plant subscribes /emergency_stop"),
    (["estop", "--release", "--node", "no_such_plant"], "no_such_plant subscribes /emergency_stop"),
])
def test_nothing_answering_exits_1_within_the_timeout_naming_the_node_and_the_domain(graph, args, service):
    r = ctl(graph, *args, "--timeout", "1")
    assert r.returncode == 1, (r.stdout, r.stderr)
    line, = r.stderr.strip().splitlines()
    assert service in line and f"ROS_DOMAIN_ID={graph.domain_id}" in line, line
    assert r.seconds < 15


@pytest.mark.unit
def test_help_of_every_subcommand_exits_0_without_ros_and_usage_errors_exit_2_in_one_line():
    script = ("import sys, contextlib, io\n"
              "from mwip_ros.cli.ctl import main\n"
              "for argv in ([], ['param'], ['param', 'set'], ['param', 'get'], ['param', 'list'], ['reset'],\n"
              "             ['push'], ['enable'], ['disable'], ['estop']):\n"
              "    with contextlib.redirect_stdout(io.StringIO()) as out:\n"
              "        code = main(argv + ['--help'])\n"
              "    assert code == 0 and 'usage: mwip_ctl' in out.getvalue(), (argv, code)\n"
              "print('rclpy' in sys.modules)\n")
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == "False", (r.stdout, r.stderr)
    for args in (["param", "set", "dscndo_controller", "k1"], ["param", "set", "dscndo_controller", "k1", "{a: 1}"],
                 ["push", "--wheel", "nan"], ["push", "--wheel", "2e6"], ["push", "--duration", "0"], ["jump"],
                 ["push", "--lateral", "nan"], ["push", "--lateral", "2e6"], ["push", "--yaw", "2e6"]):
        r = subprocess.run([str(MWIP_CTL), *args], capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, (args, r.stderr)
