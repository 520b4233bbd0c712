"""Every start-up mistake ends with exit 2 and one line naming the key or the file, never a traceback; every
node answers --help from the parameter schema without starting."""
import importlib
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from graphproc import PARAMS, Graph
from nodeharness import NodeHarness, node_class, refused
from mwip_ros import params as P
from mwip_ros.nodes.runtime.entry import NODES as NODE_MODULES
from mwip_ros.core.control.lqr import NO_DESIGN

NODES = ("plant_sim", "disturbance_observer", "dscndo_controller", "mcap_recorder", "bag_replay", "robot_markers",
         "foxglove_server", "state_estimator", "robot_state")

PAPER = PARAMS.read_text()


def _file(tmp_path, name, old, new):
    assert old in PAPER
    f = tmp_path / name
    f.write_text(PAPER.replace(old, new))
    return f


CASES = [  # (id, node, file maker or None, extra ros args, words the one line must hold)
    ("yaml syntax", "dscndo_controller", lambda d: _file(d, "bad.yaml", "k1: 6.0", "k1: [6.0"), (),
     ("bad.yaml", "not valid YAML at line")),
    ("missing file", "plant_sim", lambda d: d / "nope.yaml", (), ("'--params-file'", "no such file", "nope.yaml")),
    ("directory as file", "disturbance_observer", lambda d: d, (), ("'--params-file'", "is a directory")),
    ("integers in a double array", "disturbance_observer",
     lambda d: _file(d, "mixed.yaml", "X: [100.0, 0.0, 0.0, 100.0]", "X: [100.0, 0, 0, 100.0]"), (),
     ("'disturbance_observer.X'", "floating-point")),
    ("unparsable -p", "dscndo_controller", None, ("-p", "k1:=[1.0"), ("'k1'", "not YAML")),
    ("empty -p", "dscndo_controller", None, ("-p", "k1:="), ("'k1'", "gives no value")),
    ("overflowing duration", "plant_sim", lambda d: _file(d, "dur.yaml", "duration_s: 10.0", "duration_s: 1.0e+308"),
     (), ("'plant_sim.duration_s'", "must be <=")),
    ("vanishing rate", "plant_sim",
     lambda d: _file(d, "rate.yaml", "control_rate_hz: 200.0", "control_rate_hz: 1.0e-300"), (),
     ("'control_rate_hz'", "must be >= 0.001")),
    ("overflowing mass", "plant_sim", lambda d: _file(d, "mass.yaml", "m_b: 310.6", "m_b: 1.0e+308"), (),
     ("'plant_sim.actual.m_b'", "must be <=")),
    ("overflowing nominal mass", "dscndo_controller",
     lambda d: _file(d, "nom.yaml", "m_b: 210.6", "m_b: 1.0e+308"), (), ("'nominal.m_b'", "must be <=")),
    ("vanishing tau4", "dscndo_controller", None, ("-p", "tau4:=1e-300"), ("'tau4'", "must be >= 1e-06")),
    ("not a rule", "dscndo_controller", None, ("-p", "k1"), ("'k1'", "not a 'name:=value' rule")),
    # every law's design at start-up, whatever the law in use (old code: exit 1, an LqrDesignError traceback)
    ("mpc.Q negative", "dscndo_controller", None, ("-p", "mpc.Q:=[-1.0, 10.0, 1.0]"), ("'mpc.Q'", ">= 0")),
    ("mpc.Q zero", "dscndo_controller", None, ("-p", "mpc.Q:=[0.0, 0.0, 0.0]"), ("'mpc.Q'", NO_DESIGN)),
    ("mpc.Q huge", "dscndo_controller", None, ("-p", "mpc.Q:=[1.0e300, 10.0, 1.0]"), ("'mpc.Q'", "<= 1e+12")),
    # QoS overrides would be ignored (the nodes set their QoS): refused, not silently dropped
    ("qos override by -p", "dscndo_controller", None, ("-p", "qos_overrides./joint_states.subscription.depth:=10"),
     ("'qos_overrides./joint_states.subscription.depth'", "QoS overrides are not supported")),
    ("qos override in a file", "plant_sim",
     lambda d: _file(d, "qos.yaml", "    mode: lockstep",
                     "    mode: lockstep\n    qos_overrides:\n      /joint_states:\n"
                     "        publisher:\n          depth: 10"), (),
     ("'plant_sim.qos_overrides./joint_states.publisher.depth'", "QoS overrides are not supported")),
]


@pytest.mark.node
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_start_up_mistakes_are_refused_in_one_line_naming_the_key(tmp_path, case):
    """The node's own start-up (the harness runs it in this process): refused, one line, the key or file named."""
    _id, node, make_file, extra, words = case
    params = make_file(tmp_path) if make_file else PARAMS
    line = refused(node_class(node), *extra, params=params)
    assert "\n" not in line.strip(), line
    for w in words:
        assert w in line, (w, line)


@pytest.mark.graph
@pytest.mark.parametrize("case", [c for c in CASES if c[0] in ("yaml syntax", "unparsable -p")], ids=lambda c: c[0])
def test_a_refused_start_exits_2_with_one_line_and_no_traceback(tmp_path, case):
    """The process around a refusal (one file mistake, one command-line mistake): exit 2, that one line on stderr."""
    _id, node, make_file, extra, words = case
    params = make_file(tmp_path) if make_file else PARAMS
    with Graph(tmp_path) as g:
        p = g.start(node, *extra, params=params)
        code = p.wait(60)
    out = p.output()
    assert code == 2, out
    assert "Traceback" not in out and len(out.strip().splitlines()) == 1, out
    for w in words:
        assert w in out, (w, out)


@pytest.mark.graph
@pytest.mark.parametrize("node, plugins, words", [
    ("plant_sim", "no_such_law_module", ("cannot import the law module 'no_such_law_module'", "No module named")),
    ("dscndo_controller", "broken_plugin",
     ("the law module 'broken_plugin' raised while importing", "broken_plugin's own import error"))])
def test_a_law_plugin_that_fails_to_import_stops_the_node_in_one_line(tmp_path, node, plugins, words):
    """MWIP_ROS_LAWS naming a module that cannot be imported, or raises while importing: exit 2 at start-up (the
    plug-ins are imported with the package, so this needs a process of its own; every node starts through the same
    run_node)."""
    test_dir = str(Path(__file__).resolve().parents[1])
    with Graph(tmp_path) as g:
        g.env.update(MWIP_ROS_LAWS=plugins, PYTHONPATH=os.pathsep.join(
            p for p in (test_dir, g.env.get("PYTHONPATH", "")) if p))
        p = g.start(node)
        code = p.wait(60)
    out = p.output()
    assert code == 2, out
    assert "Traceback" not in out and len(out.strip().splitlines()) == 1, out
    assert f"MWIP_ROS_LAWS='{plugins}'" in out and all(w in out for w in words), out


@pytest.mark.node
@pytest.mark.parametrize("spelling, value", [("1e-1", 0.1), (".5", 0.5), ("5E-1", 0.5), ("+0.25", 0.25)])
def test_every_yaml_and_ros_double_spelling_is_accepted(tmp_path, spelling, value):
    f = _file(tmp_path, "spell.yaml", "tau4: 0.1", f"tau4: {spelling}")
    controller = node_class("dscndo_controller")
    with NodeHarness(controller, params=f) as from_file:
        assert from_file.node.v["tau4"] == value and f"tau4 = {value}" in from_file.logs()
    with NodeHarness(controller, "-p", f"tau4:={spelling}", "-r", "__node:=ctl_b", name="ctl_b") as from_cli:
        assert from_cli.node.v["tau4"] == value and f"tau4 = {value}" in from_cli.logs()


@pytest.mark.node
def test_a_namespaced_node_reads_its_plain_section(tmp_path):
    f = _file(tmp_path, "ns.yaml", "k1: 6.0", "k1: 7.5")
    controller = node_class("dscndo_controller")
    with NodeHarness(controller, "-r", "__ns:=/robot1", params=f) as p:
        assert p.node.get_namespace() == "/robot1" and p.node.v["k1"] == 7.5 and "k1 = 7.5" in p.logs()
    with NodeHarness(controller, "-r", "__ns:=/robot2", "-p", "k1:=8.5", params=f) as q:
        assert q.node.v["k1"] == 8.5   # -p dscndo_controller:k1:=8.5 (node_rules) wins over the file


@pytest.mark.node
def test_precedence_is_ros_2s_own_section_over_wildcard_then_the_later(tmp_path):
    """rclcpp/rclpy: a node's own values (its section, -p NODE:name:=v) win over the wildcard's (/**, -p name:=v),
    whatever the order; within one kind the later wins."""
    f = _file(tmp_path, "own.yaml", "k1: 6.0", "k1: 7.5")
    later = tmp_path / "later.yaml"
    later.write_text("dscndo_controller:\n  ros__parameters:\n    k1: 9.0\n")
    cases = {
        "wildcard_loses": (("-p", "k1:=8.5"), 7.5),
        "own_rule_wins": (("-p", "dscndo_controller:k1:=8.5"), 8.5),
        "later_file_wins": (("-p", "dscndo_controller:k1:=8.5", "--params-file", str(later)), 9.0),
        "later_rule_wins": (("--params-file", str(later), "-p", "dscndo_controller:k1:=8.5"), 8.5),
    }
    logs = {}
    for label, (args, k1) in cases.items():
        with NodeHarness(node_class("dscndo_controller"), *args, params=f, as_given=True) as h:
            assert h.node.v["k1"] == k1 and f"ready: k1 = {k1}" in h.logs(), (label, h.logs())
            logs[label] = h.logs()
    out = logs["wildcard_loses"]
    assert "-p k1:=8.5 is overridden by k1: 7.5 in this node's own section" in out and \
        "-p dscndo_controller:k1:=..." in out, out
    assert "overridden" not in logs["own_rule_wins"]


@pytest.mark.node
def test_a_shared_file_with_other_nodes_sections_and_a_renamed_nodes_own_section(tmp_path):
    """Sections of nodes that are not ours are left to them; a node renamed with __node:= reads its own section
    (checked: an unknown key in it stops the node, named)."""
    shared = PAPER + ("robot_state_publisher:\n  ros__parameters:\n    publish_frequency: 30.0\n"
                      "ctl_b:\n  ros__parameters:\n    k1: 7.5\n")
    good, bad = tmp_path / "shared.yaml", tmp_path / "bad.yaml"
    good.write_text(shared)
    bad.write_text(shared + "    k3: 1.0\n")
    controller = node_class("dscndo_controller")
    with NodeHarness(controller, params=good) as plain:
        assert plain.node.v["k1"] == 6.0
    with NodeHarness(controller, "-r", "__node:=ctl_b", params=good, name="ctl_b") as renamed:
        assert renamed.node.get_name() == "ctl_b" and renamed.node.v["k1"] == 7.5
    line = refused(controller, "-r", "__node:=ctl_b", params=bad, name="ctl_b")
    assert "'ctl_b.k3'" in line and "unknown parameter" in line and "\n" not in line, line


def _words(text):
    return " ".join(text.split())


def _help(node, flag, capsys):
    """``main([node, flag])`` in this process: (exit code, what it printed)."""
    code = importlib.import_module(NODE_MODULES[node]).main([node, flag])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.unit
@pytest.mark.parametrize("node", NODES)
def test_every_node_answers_help_from_the_schema(node, capsys):
    """``NODE --help``: the usage, what the node does, every parameter with its default and description, the exit
    codes (the process that prints it: test_help_as_typed_is_an_import_and_a_print)."""
    code, out, err = _help(node, "--help", capsys)
    assert code == 0 and err == "", out + err
    assert out.startswith(f"usage: {node} [--ros-args --params-file FILE -p {node}:NAME:=VALUE ...]"), out
    doc = importlib.import_module(NODE_MODULES[node]).__doc__
    assert _words(doc.split("\n\n")[0].replace("``", "")) in _words(out)
    for name, spec in P.specs_for(node).items():
        assert f"\n  {name}  ({spec.type}, default " in out, name
        assert _words(spec.description) in _words(out), name
    assert "exit code" in out.lower() and f"python -m pydoc {NODE_MODULES[node]}" in out


@pytest.mark.alone   # "at once" is timed on the wall clock
@pytest.mark.graph
def test_help_as_typed_is_an_import_and_a_print(tmp_path):
    """``plant_sim --help`` as typed (and as ``ros2 run mwip_ros plant_sim --help`` passes it): exit 0 at once, no
    rclpy log line (no node ran: a started one would wait for its peers). Every node prints its help through the
    same run_node (test_every_node_answers_help_from_the_schema)."""
    env = Graph(tmp_path).env
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", NODE_MODULES["plant_sim"], "--help"], env=env, capture_output=True,
                       text=True, timeout=30)
    took = time.monotonic() - t0
    assert r.returncode == 0 and r.stderr == "", r.stdout + r.stderr
    assert "[INFO]" not in r.stdout and "[WARN]" not in r.stdout
    assert took < 10, took   # an import and a print (a started node runs until its peers come or it is stopped)
    assert r.stdout.startswith("usage: plant_sim [--ros-args"), r.stdout


@pytest.mark.unit
def test_help_shows_defaults_ranges_topics_and_exit_codes(capsys):
    ctl, fox, plant = (_help(n, flag, capsys)[1]
                       for n, flag in (("dscndo_controller", "-h"), ("foxglove_server", "--help"), ("plant_sim", "-h")))
    assert "  tau4  (double, default 0.1, [1e-06, 1e+06], changeable at run time)" in ctl
    assert "  law  (string, default 'dsc', one of 'dsc', 'lqr', 'smc', 'mpc', changeable at run time)" in ctl
    assert "  publishes: wheel_torque_cmd, wheel_torques_cmd, controller_internals, /diagnostics" in ctl
    assert "  subscribes: joint_states, disturbance_estimate" in ctl
    assert "  port  (integer, default 8765, 1..65535)" in fox and "  topics  (string_array, default [])" in fox
    assert "  duration_s  (double, default 10.0, [0, 1e+07])" in plant and "  services: ~/reset" in plant
    assert "  use_sim_time  (bool, default false)" in plant
    assert "3 when\nthe robot fell" in plant   # the node's own exit codes


@pytest.mark.unit
def test_help_in_process_creates_no_ros_context(monkeypatch, capsys):
    """Every node's main(['NODE', '--help']) returns 0 with rclpy's init and Context unusable."""
    import rclpy

    def boom(*_a, **_k):
        raise AssertionError("--help created a ROS context")

    monkeypatch.setattr(rclpy, "init", boom)
    monkeypatch.setattr(rclpy, "Context", boom)
    for node in NODES:
        main = importlib.import_module(NODE_MODULES[node]).main
        # help wins over a file that would be refused, and over what follows --ros-args
        assert main([node, "-h", "--ros-args", "--params-file", "/no/such.yaml"]) == 0, node
        assert capsys.readouterr().out.startswith(f"usage: {node} "), node


OUTSIDE = [
    (["--bogus"], [], "'--bogus'"),
    (["--params-file", str(PARAMS)], [], "'--params-file'"),     # a ROS argument outside --ros-args: rcl ignores it
    ([], ["--", "extra"], "'extra'"),                             # after the --ros-args block ended
]


@pytest.mark.node
@pytest.mark.parametrize("before, after, word", OUTSIDE)
def test_an_argument_outside_ros_args_is_refused_naming_it(before, after, word):
    line = refused(node_class("plant_sim"), argv=["plant_sim", *before, "--ros-args", *after])
    assert f"unknown argument {word}" in line and "after --ros-args" in line and "plant_sim --help" in line, line


@pytest.mark.graph
def test_an_argument_outside_ros_args_exits_2_naming_it(tmp_path):
    before, after, word = OUTSIDE[0]
    with Graph(tmp_path) as g:
        p = g.start("plant_sim", *after, cmd=[sys.executable, "-m", "mwip_ros.nodes.loop.plant_sim", *before],
                    as_given=True)
        code = p.wait(60)
    out = p.output()
    assert code == 2, out
    assert "Traceback" not in out and len(out.strip().splitlines()) == 1, out
    assert f"unknown argument {word}" in out and "after --ros-args" in out and "plant_sim --help" in out, out


class _Fake:
    """Just enough of a node, a publisher and a subscription for the lockstep driver's graph wait."""

    def __init__(self):
        self.publishers = {}          # topic -> count
        self.subscriptions = 0        # matched on joint_states
        self.lines = []
        self.topic_name = "joint_states"

    # the node
    def count_publishers(self, topic):
        return self.publishers.get(topic, 0)

    def count_subscribers(self, _topic):
        return self.subscriptions

    def get_node_names_and_namespaces(self):
        return []

    def get_logger(self):
        return self

    def info(self, text):
        self.lines.append(("info", text))

    def warning(self, text):
        self.lines.append(("warning", text))

    # the state publisher and the command subscription
    def get_subscription_count(self):
        return self.subscriptions

    def get_publisher_count(self):
        return self.publishers.get("wheel_torque_cmd", 0)


def _driver(monkeypatch):
    from mwip_ros.nodes.runtime import lockstep
    now = [100.0]
    monkeypatch.setattr(lockstep.time, "monotonic", lambda: now[0])
    fake = _Fake()
    d = lockstep.LockstepDriver(fake, fake, None, fake, need_subs=2, timeout_s=10.0,
                                timeout_param="lockstep_timeout_s")

    def at(t):
        now[0] = 100.0 + t
        return d.wait_for_graph()
    return fake, d, at


@pytest.mark.unit
def test_a_normal_start_waits_for_the_graph_as_progress(monkeypatch):
    """The graph coming up within the grace: one plain line, nothing that reads like an error."""
    fake, _d, at = _driver(monkeypatch)
    assert at(0.0) is None and at(1.0) is None
    fake.publishers = {"wheel_torque_cmd": 1, "disturbance_estimate": 1}
    fake.subscriptions = 2
    assert at(1.5) is True
    assert fake.lines == [("info", "waiting for the graph to come up")]


@pytest.mark.unit
def test_a_graph_that_does_not_come_names_the_nodes_after_the_grace_then_times_out(monkeypatch):
    fake, d, at = _driver(monkeypatch)
    assert at(0.0) is None and at(1.9) is None
    assert fake.lines == [("info", "waiting for the graph to come up")]
    assert at(2.0) is None and at(3.0) is None and at(4.0) is None
    missing = ("info", "waiting for the graph: dscndo_controller, disturbance_observer (started? same ROS_DOMAIN_ID?); "
                       "2 subscribers on joint_states (matched: 0)")
    assert fake.lines[1:] == [missing, missing]
    fake.publishers = {"disturbance_estimate": 1}
    assert at(6.0) is None
    assert fake.lines[-1][1].startswith("waiting for the graph: dscndo_controller (started? same ROS_DOMAIN_ID?); 2 ")
    assert at(10.5) is False
    text = d.graph_timeout_text()   # the failure keeps saying why
    assert text.startswith("graph not ready after 10 s; waiting for: dscndo_controller (nothing publishes "
                           "wheel_torque_cmd); 2 subscribers on joint_states (matched: 0)"), text
