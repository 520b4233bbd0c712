"""mwip_ctl, the live actions of docs/graph.md without a ros2 CLI.

* in this process: ``mwip_ctl``'s ``main`` with its ROS node made in the context of a node under test
  (test/nodeharness.py: a peer of the plant or the controller, no discovery), so every request, answer and message
  goes through the middleware within that one participant: each command's output, exit code and effect on the node
  (parameters converted, set, read back and refused; reset; push; the e-stop's level held, refused resets, release,
  disable and enable; nothing answering within the timeout);
* a realtime graph of processes, one for the module, against the console script as a user types it: a parameter
  set and read back by two processes, a reset that the observer and the controller follow, a push the plant takes,
  and Ctrl-C ending a push with a zero wrench and exit 130.
"""
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import nodeharness
from graphproc import REPO, Graph
from nodeharness import NodeHarness, node_class
from mwip_ros.cli import ctl as CTL
from mwip_ros.msgs import layouts as L

MWIP_CTL = Path(sys.executable).with_name("mwip_ctl")   # the console script setup.py installs


# --- in this process ------------------------------------------------------------------------------------------
@pytest.fixture
def run_ctl():
    """``run_ctl(h, *argv)``: ``mwip_ctl argv`` in this process against harness ``h`` (nodeharness.run_ctl): (exit
    code, stdout, stderr)."""
    return nodeharness.run_ctl


def _plant(*rules):
    return NodeHarness(node_class("plant_sim"), *(x for r in ("duration_s:=0.0", *rules) for x in ("-p", r)))


@pytest.mark.node
def test_param_set_converts_a_whole_number_for_a_double_get_reads_it_back_and_the_node_logs_it(run_ctl):
    with NodeHarness(node_class("dscndo_controller")) as h:
        code, out, err = run_ctl(h, "param", "set", "dscndo_controller", "k1", "8")
        assert code == 0 and out.strip() == "dscndo_controller: k1 = 8.0", (out, err)
        assert h.node.v["k1"] == 8.0 and "parameters changed: k1: 6.0 -> 8.0" in h.logs(), h.logs()[-2000:]
        code, out, err = run_ctl(h, "param", "get", "dscndo_controller", "k1")
        assert code == 0 and out.strip() == "8.0", (out, err)
        code, out, err = run_ctl(h, "param", "list", "dscndo_controller")
        assert code == 0 and {"k1", "law", "use_observer", "lqr.Q"} <= set(out.split()), out
        code, out, err = run_ctl(h, "param", "get", "dscndo_controller", "k7")
        assert code == 1 and "dscndo_controller has no parameter 'k7'" in err and len(err.splitlines()) == 1, err


@pytest.mark.node
def test_param_set_prints_the_nodes_warning_where_the_user_looks(run_ctl):
    """k1 = 7 breaks Theorem 2 (a3 = -0.7167): the warning was only in the controller's log; mwip_ctl prints it
    (stderr, exit 0: the change is made), and nothing for gains that keep it."""
    with NodeHarness(node_class("dscndo_controller")) as h:
        code, out, err = run_ctl(h, "param", "set", "dscndo_controller", "k1", "7")
        assert code == 0 and out.strip() == "dscndo_controller: k1 = 7.0", (out, err)
        line, = err.strip().splitlines()
        assert line.startswith("dscndo_controller: warning: gains break Theorem 2") and "a3 = -0.7167" in line, line
        assert "a3 = -0.7167" in h.logs()   # the node's own log says the same
        code, out, err = run_ctl(h, "param", "set", "dscndo_controller", "k1", "6")   # the paper's: a3 = 0.7833 > 0
        assert code == 0 and err == "", (out, err)


@pytest.mark.node
def test_a_value_the_schema_refuses_exits_1_with_the_nodes_reason_and_changes_nothing(run_ctl):
    with NodeHarness(node_class("dscndo_controller")) as h:
        before = dict(h.node.v)
        # k1 must be > 0 (ParamSpec _positive): 0 is sent as the double 0.0, so the refusal is the range, not the type
        code, out, err = run_ctl(h, "param", "set", "dscndo_controller", "k1", "0")
        assert code == 1 and out == "", (out, err)
        assert "dscndo_controller refused k1 = 0.0" in err and "parameter 'k1': must be > 0" in err, err
        assert len(err.strip().splitlines()) == 1
        code, out, err = run_ctl(h, "param", "set", "dscndo_controller", "law", "pid")
        assert code == 1 and "must be one of 'dsc', 'lqr'" in err, err
        assert dict(h.node.v) == before
        assert run_ctl(h, "param", "get", "dscndo_controller", "k1")[1].strip() == "6.0"


@pytest.mark.node
def test_reset_answers_with_the_plants_reset(run_ctl):
    with _plant() as h:
        h.node._start("test")
        for _ in range(10):
            h.feed("wheel_torque_cmd", L.encode_command(0.0))
        code, out, err = run_ctl(h, "reset")
        assert code == 0 and out.startswith("plant_sim: reset #1 at t = 0.050 s"), (out, err)
        h.feed("wheel_torque_cmd", L.encode_command(0.0))   # the state in flight answered: the reset happens
        assert h.node.resets == 1 and h.node.plant.k == 0 and "reset #1 at t = 0.050 s" in h.logs()


@pytest.mark.node
def test_push_reaches_the_plant_with_its_torques_and_ends_with_a_zero_wrench(run_ctl):
    with _plant() as h:
        code, out, err = run_ctl(h, "push", "--wheel", "50", "--duration", "0.2")
        assert code == 0, (out, err)
        assert "tau_ext1 += 50, tau_ext2 += 50 N m" in out and "then a zero wrench" in out
        # the plant logs the torques it parsed from each external_wrench it took, and the zero one that ends it
        assert h.spin(lambda: "external wrench cleared" in h.logs(), 5), h.logs()[-2000:]
        pushed = h.logs().split("external wrench: tau_ext1 += 50, tau_ext2 += 50 N m")
        # 10 Hz for 0.2 s: 3 sent; the plant says a wrench when it changes (issue 46: a flood of one was a line each)
        assert len(pushed) == 2 and "external wrench cleared" in pushed[-1]
        # the body row alone: torque.y only (eq. 1's body row carries tau_ext2 - tau_ext1)
        code, out, err = run_ctl(h, "push", "--body", "20", "--duration", "0.1", "--rate", "0")
        assert code == 0 and h.spin(lambda: h.logs().count("external wrench cleared") == 2, 5), (out, err)
        assert "tau_ext1 += 0, tau_ext2 += 20 N m" in h.logs()
        code, out, err = run_ctl(h, "push", "--lateral", "300", "--yaw", "5", "--duration", "0.1", "--rate", "0")
        assert code == 0 and "force.y 300 N, torque.z 5 N m" in out, (out, err)   # mujoco's
        assert h.spin(lambda: h.logs().count("external wrench cleared") == 3, 5), h.logs()[-2000:]
        assert "force.y 300 N, torque.z 5 N m" in h.logs() and h.node.extra == (0.0, 0.0, 0.0, 0.0)


@pytest.mark.node
def test_estop_holds_the_level_reset_is_refused_until_release_then_disable_and_enable(run_ctl):
    """estop publishes true once and returns; the plant holds the e-stop: reset is refused (exit 1, one line naming
    it) until estop --release; then reset clears the fault, and disable and enable switch the driver."""
    with _plant() as h:
        code, out, err = run_ctl(h, "estop")
        assert code == 0 and "emergency stop asserted" in out, (out, err)
        assert h.spin(lambda: h.node.safety.faulted, 5) and "-> fault (emergency_stop" in h.logs()
        code, out, err = run_ctl(h, "reset")
        assert code == 1 and out == "", (out, err)
        line, = err.strip().splitlines()
        assert "refused reset" in line and "emergency stop is still asserted" in line, line
        code, out, err = run_ctl(h, "enable")
        assert code == 1 and "call ~/reset first" in err, (out, err)
        code, out, err = run_ctl(h, "estop", "--release")
        assert code == 0 and "emergency stop released" in out, (out, err)
        assert h.spin(lambda: "emergency stop released; the fault stays latched" in h.logs(), 5), h.logs()[-2000:]
        code, out, err = run_ctl(h, "reset")
        assert code == 0 and "fault cleared (emergency_stop" in out, (out, err)
        code, out, err = run_ctl(h, "disable")
        assert code == 0 and out.strip() == "plant_sim: disabled", (out, err)
        code, out, err = run_ctl(h, "enable")
        assert code == 0 and out.strip() == "plant_sim: enabled", (out, err)
        assert h.node.safety.state == "enabled" and not h.node.done


@pytest.fixture(scope="module")
def lone():
    """A plant in a private context: the one node anything can find there."""
    with _plant() as h:
        yield h


@pytest.mark.node
@pytest.mark.parametrize("args,service", [
    (["param", "get", "no_such_node", "k1"], "no_such_node/get_parameters"),
    (["reset", "--node", "no_such_plant"], "no_such_plant/reset"),
    (["push", "--node", "no_such_plant", "--wheel", "1"], "no_such_plant subscribes /external_wrench"),
    (["enable", "--node", "no_such_plant"], "no_such_plant/enable"),
    (["disable", "--node", "no_such_plant"], "no_such_plant/disable"),
    (["estop", "--node", "no_such_plant"], "no_such_plant subscribes /emergency_stop"),
    (["estop", "--release", "--node", "no_such_plant"], "no_such_plant subscribes /emergency_stop"),
])
def test_nothing_answering_exits_1_within_the_timeout_naming_the_node_and_the_domain(run_ctl, lone, monkeypatch,
                                                                                     args, service):
    monkeypatch.setenv("ROS_DOMAIN_ID", "57")   # what the line names (the harness's context has no discovery)
    t0 = time.monotonic()
    code, out, err = run_ctl(lone, *args, "--timeout", "0.3")
    took = time.monotonic() - t0
    assert code == 1 and out == "", (out, err)
    line, = err.strip().splitlines()
    assert service in line and "ROS_DOMAIN_ID=57" in line and "0.3 s" in line, line
    assert 0.3 <= took < 5, took


@pytest.mark.cli
def test_help_of_every_subcommand_exits_0_without_ros_and_usage_errors_exit_2_in_one_line(capsys):
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
    # the usage errors, refused before any ROS: main() as the console script calls it ...
    for args in (["param", "set", "dscndo_controller", "k1"], ["param", "set", "dscndo_controller", "k1", "{a: 1}"],
                 ["push", "--wheel", "nan"], ["push", "--wheel", "2e6"], ["push", "--duration", "0"], ["jump"],
                 ["push", "--lateral", "nan"], ["push", "--lateral", "2e6"], ["push", "--yaw", "2e6"]):
        code = CTL.main(args)
        err = capsys.readouterr().err
        assert code == 2 and len(err.strip().splitlines()) == 1 and err.startswith("mwip_ctl"), (args, err)
    # ... and the console script itself
    r = subprocess.run([str(MWIP_CTL), "push", "--wheel", "nan"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "'nan' is not finite" in r.stderr, r


# --- a graph of processes, as a user runs the console script -----------------------------------------------------
def ctl(graph, *args, timeout=60):
    t0 = time.monotonic()
    r = subprocess.run([str(MWIP_CTL), *args], capture_output=True, text=True, env=graph.env, timeout=timeout)
    r.seconds = time.monotonic() - t0
    print(f"{r.seconds:5.2f} s  mwip_ctl {' '.join(args)}")
    return r


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    """Observer, controller and a realtime plant that runs until stopped, upright at rest with no disturbance: a
    controller the loaded machine starves past watchdog_s leaves it at zero torque, exactly upright, and the plant
    stays up (exit_on_fall: false)."""
    workdir = tmp_path_factory.mktemp("ctl")
    at_rest = ("initial.theta_b:=0.0", "tau_ext1.amplitude:=0.0", "tau_ext2.amplitude:=0.0",
               "actual.D_w_variance:=0.0", "exit_on_fall:=false", "mode:=realtime", "duration_s:=0.0")
    with Graph(workdir) as g:
        g.obs = g.start("disturbance_observer", "-p", "mode:=realtime")
        g.ctl = g.start("dscndo_controller", "-p", "mode:=realtime")
        g.plant = g.start("plant_sim", *(x for r in at_rest for x in ("-p", r)))
        for p, text in ((g.obs, "ready"), (g.ctl, "ready"), (g.plant, "starting realtime run")):
            assert p.wait_for_output(text, 60), p.output()[-2000:]
        yield g


@pytest.mark.alone
@pytest.mark.graph
def test_the_console_script_sets_a_parameter_another_reads_back_and_the_node_logs_it(graph):
    r = ctl(graph, "param", "set", "dscndo_controller", "k1", "8")
    assert r.returncode == 0 and r.stdout.strip() == "dscndo_controller: k1 = 8.0", (r.stdout, r.stderr)
    assert graph.ctl.wait_for_output("parameters changed: k1: 6.0 -> 8.0", 10), graph.ctl.output()[-2000:]
    r = ctl(graph, "param", "get", "dscndo_controller", "k1")
    assert r.returncode == 0 and r.stdout.strip() == "8.0", (r.stdout, r.stderr)


@pytest.mark.alone
@pytest.mark.graph
def test_reset_restarts_the_plant_and_the_loop_follows(graph):
    r = ctl(graph, "reset")
    assert r.returncode == 0 and r.stdout.startswith("plant_sim: reset #1 at t = "), (r.stdout, r.stderr)
    assert graph.plant.wait_for_output("reset #1 at t = ", 10)
    for p in (graph.obs, graph.ctl):   # realtime: they see the stamps go back (to the run's first) at once
        assert p.wait_for_output("joint_states restarted at t = ", 10), p.output()[-2000:]


@pytest.mark.alone
@pytest.mark.graph
def test_push_reaches_the_plant_process_and_ends_with_a_zero_wrench(graph):
    r = ctl(graph, "push", "--wheel", "50", "--duration", "0.2")
    assert r.returncode == 0, (r.stdout, r.stderr)
    assert "tau_ext1 += 50, tau_ext2 += 50 N m" in r.stdout and "then a zero wrench" in r.stdout
    assert graph.plant.wait_for_output("external wrench cleared", 10), graph.plant.output()[-2000:]
    pushed = graph.plant.output().split("external wrench: tau_ext1 += 50, tau_ext2 += 50 N m")
    assert len(pushed) == 2 and "external wrench cleared" in pushed[-1]   # said once, when it changed
    assert graph.plant.poll() is None, graph.plant.output()[-2000:]


@pytest.mark.alone
@pytest.mark.graph
def test_ctrl_c_ends_a_push_with_a_zero_wrench_and_exits_130_quietly(graph):
    p = subprocess.Popen([str(MWIP_CTL), "push", "--wheel", "5", "--duration", "60"],
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


@pytest.mark.alone
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
        plant = graph.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", "-p",
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
        time.sleep(3.0)   # 3 s of the loop after the reset: what is observed is that nothing ends it (it recovers in 2)
        assert plant.poll() is None, plant.output()[-2000:]
        plant.stop(signal.SIGINT, timeout=30)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["resets"] == 2 and not summary["fallen"] and summary["driver_state"] == "enabled", summary
    assert summary["metrics"]["theta_b_max_abs"] < 0.2, summary["metrics"]   # upright again after the reset
