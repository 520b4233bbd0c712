"""Killed and paused peers, a second controller in the domain: the plant names the node at fault; absurd commands and
cut wrenches change nothing; two namespaced graphs in one domain do not hear each other.

A killed observer and a paused (SIGSTOPped) controller are processes; a silent state estimator (its publisher still
in the plant's graph, as a killed process's stays there for a while), a second controller's publisher and hostile
inputs are fed to a plant in this process (test/nodeharness.py); the namespaces' isolation is a graph of processes.
"""
import math
import os
import signal
import struct

import pytest
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import Imu, JointState

from graphproc import PARAMS, Graph, wait_until
from injector import plant_rejected
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import qos_for
from mwip_ros.msgs.topics import SYSTEM_TOPICS
from nodeharness import Loop, NodeHarness, node_class, realtime_tick

RAW = (PARAMS, PARAMS.parent / "sensors_raw_realistic.yaml")
# lockstep_timeout_s is the wait for the graph at the start as for each command (the default is 10 s): the peers are
# up ("ready") before the plant starts, and a newcomer finds a running node within a quarter second
# (mwip_ros.nodes.runtime.discovery), so 4 s is the wait for a state's answer from a killed or paused peer
LOCKSTEP = ("-p", "duration_s:=0.0", "-p", "lockstep_timeout_s:=4.0")


def _ready(*procs) -> None:
    """Each node has started (its "ready" line): the plant's lockstep_timeout_s then counts discovery only, not a
    loaded machine's start-up of the peers."""
    for p in procs:
        assert p.wait_for_output("ready", 60), p.output()


def _lockstep_graph(g, *controllers):
    obs = g.start("disturbance_observer")
    ctls = [g.start("dscndo_controller", *args, label=label) for label, args in controllers]
    _ready(obs, *ctls)
    return obs, ctls


@pytest.mark.graph
def test_a_killed_observer_is_named_not_the_controller(tmp_path):
    with Graph(tmp_path) as g:
        obs, (ctl,) = _lockstep_graph(g, ("dscndo_controller", ()))
        plant = g.start("plant_sim", *LOCKSTEP)
        assert plant.wait_for_output("starting lockstep run", 60), plant.output()   # running
        os.kill(obs.pid, signal.SIGKILL)
        code = plant.wait(60)
        out = plant.output()
    assert code == 1, out
    failure = out.split("lockstep timeout:")[1]
    assert "disturbance_observer (it did not answer state k = " in failure, failure
    assert "the controller is running but did not answer" not in failure


@pytest.mark.node
def test_a_silent_state_estimator_is_named():
    """Raw sensors, the loop in this process: the chain is estimator, observer, controller; the estimator stops
    answering while its publisher stays in the plant's graph (a killed process keeps its place there for a while):
    the lockstep timeout names it, not the observer nor the controller."""
    with Loop(*LOCKSTEP[:2], "-p", "lockstep_timeout_s:=1.0", params=RAW) as loop:
        plant, node = loop.plant, loop.plant.node
        # the chain as the plant's graph lists it: the estimator's and the observer's publishers, the estimator's
        # subscription on the plant's first topic (the plant counts it before its first state)
        for topic, kind, who in (("joint_states", JointState, "state_estimator"),
                                 ("disturbance_estimate", WrenchStamped, "disturbance_observer")):
            plant.publisher(topic, kind, name=who)
        plant.peer("state_estimator").create_subscription(Imu, "imu/data_raw", lambda _m: None, qos_for("lockstep")[1])
        loop.start()
        assert loop.run(lambda: node.plant.k >= 50)
        loop.wire.cut(loop["state_estimator"])   # it answers nothing from now on, state 50 included
        loop.run(lambda: node.done)              # state 50 resent (the driver listens to the answers then): nothing
        # the plant's own loop (runner.watch: resends, then the timeout) until lockstep_timeout_s has passed
        assert wait_until(lambda: (node.runner.watch({}), loop.wire.pump(), node.done)[-1], 5), plant.logs()[-2000:]
        assert node.exit_code == 1
    failure = plant.logs().split("lockstep timeout:")[1]
    assert "state_estimator (it did not answer state k = 50" in failure, failure
    assert "disturbance_observer (it did not answer" not in failure and "controller is running" not in failure


@pytest.mark.alone
@pytest.mark.graph
def test_a_paused_controller_is_named(tmp_path):
    with Graph(tmp_path) as g:
        obs, (ctl,) = _lockstep_graph(g, ("dscndo_controller", ()))
        plant = g.start("plant_sim", *LOCKSTEP)
        assert plant.wait_for_output("starting lockstep run", 60), plant.output()   # running
        os.kill(ctl.pid, signal.SIGSTOP)
        try:
            code = plant.wait(60)
        finally:
            os.kill(ctl.pid, signal.SIGCONT)
        out = plant.output()
    assert code == 1, out
    failure = out.split("lockstep timeout:")[1]
    assert "the controller is running but did not answer" in failure and "disturbance_observer" not in failure


@pytest.mark.node
def test_lockstep_refuses_two_controllers_and_names_them():
    """Two publishers on wheel_torque_cmd in the plant's graph: the lockstep run ends (exit 1) naming both; a
    controller whose inputs have one publisher each says nothing (a second plant on joint_states it names)."""
    with NodeHarness(node_class("plant_sim"), "-p", "duration_s:=20.0") as h:
        for who in ("dscndo_controller", "dscndo_controller_b"):
            h.publisher("wheel_torque_cmd", name=who)
        h.node._start("test")
        h.node.runner.watch(h.node.watch.check())   # the plant's loop, between callbacks
        assert h.node.done and h.node.exit_code == 1
    out = h.logs()
    assert "lockstep refuses mixed streams" in out
    assert "/dscndo_controller, /dscndo_controller_b" in out and "wheel_torque_cmd" in out
    with NodeHarness(node_class("dscndo_controller")) as c:
        c.publisher("joint_states", name="plant_sim")
        c.publisher("disturbance_estimate", name="disturbance_observer")
        assert c.node.watch.check() == {} and "publishers on" not in c.logs()   # the observer alone on its topic
        c.publisher("joint_states", name="plant_sim_b")
        c.node.watch._next = 0.0   # due now (it looks once a second)
        assert c.node.watch.check() == {"joint_states": ["/plant_sim", "/plant_sim_b"]}


@pytest.mark.node
def test_the_plant_rejects_absurd_commands_and_cut_wrenches_and_keeps_running():
    """A realtime plant in this process, upright at rest, its tick called directly: absurd commands and cut or
    absurd wrenches are rejected and counted, nothing of them acts, and the run goes on."""
    at_rest = ("mode:=realtime", "duration_s:=0.0", "initial.theta_b:=0.0", "actual.D_w_variance:=0.0",
               "tau_ext1.amplitude:=0.0", "tau_ext2.amplitude:=0.0")
    with NodeHarness(node_class("plant_sim"), *(x for r in at_rest for x in ("-p", r))) as h:
        node = h.node
        node._start("test")
        for _ in range(20):
            realtime_tick(node)
        for n, u in enumerate((1e300, -1e7, math.inf, math.nan), start=1):
            h.feed("wheel_torque_cmd", L.encode_command(u))
            assert node.rejects.counts["wheel_torque_cmd"] == n, u
        full = L.encode_external_wrench(25.0, -3.0)
        for n, data in enumerate((full[:-12],                                      # cut inside torque.y: refused
                                  L.encode_external_wrench(1e9, 0.0),              # absurd
                                  b"\x00\x01\x00\x00" + struct.pack("<5d", 1, 2, 3, 4, 5)),   # one double short
                                 start=1):
            h.feed("external_wrench", data)
            assert node.rejects.counts["external_wrench"] == n
        assert node.extra == (0.0, 0.0)
        n = len(h.sent("joint_states"))
        for _ in range(100):
            realtime_tick(node)
        assert len(h.sent("joint_states")) == n + 100 and not node.done   # still stepping
        last = L.parse_joint_state(h.sent("joint_states")[-1])[1]
    out = h.logs()
    assert all(math.isfinite(v) for v in last) and abs(last.theta_b) < 0.5  # nothing absurd was applied
    rejected = plant_rejected(out)
    assert rejected["wheel_torque_cmd"] == 4 and rejected["external_wrench"] == 3, rejected
    assert "implausible command" in out and "not a geometry_msgs/Wrench: message ends at byte" in out
    assert "external wrench: tau_ext1" not in out  # nothing was applied as a push


@pytest.mark.graph
def test_two_namespaced_graphs_in_one_domain_do_not_hear_each_other(tmp_path):
    """Each graph under its namespace, /clock remapped into it (docs/graph.md, Namespaces): both runs equal the
    offline simulator, each recorder records its own graph only."""
    import numpy as np

    from bagcheck import decoded_messages
    from graphproc import PARAMS
    from mwip_ros import params as P
    from mwip_ros.core.closed_loop.sim import simulate
    from mwip_ros.runs import load_run

    offline = simulate(P.closed_loop(P.merged_values(P.load_param_file(PARAMS)), duration=2.0))
    with Graph(tmp_path) as g:
        plants = {}
        for ns in ("a", "b"):
            remap = ("-r", f"__ns:=/{ns}", "-r", f"/clock:=/{ns}/clock")
            g.start("mcap_recorder", *remap, "-p", f"output:={tmp_path / ('bag_' + ns)}", "-p", "use_sim_time:=true",
                    label=f"rec_{ns}")
            g.start("disturbance_observer", *remap, "-p", f"csv:={tmp_path / (ns + '_est.csv')}", label=f"obs_{ns}")
            g.start("dscndo_controller", *remap, label=f"ctl_{ns}")
        for ns in ("a", "b"):
            # expected_subscribers 3: the plant starts once its recorder listens too (else, under load, a
            # recorder that discovers the plant late records nothing of a 2 s run)
            plants[ns] = g.start("plant_sim", "-r", f"__ns:=/{ns}", "-r", f"/clock:=/{ns}/clock",
                                 "-p", "duration_s:=2.0", "-p", "expected_subscribers:=3",
                                 "-p", f"csv:={tmp_path / (ns + '.csv')}", label=f"plant_{ns}")
        for ns, plant in plants.items():
            assert plant.wait(120) == 0, plant.output()
            assert "publishers on" not in plant.output()
    for ns in ("a", "b"):
        run = load_run(tmp_path / f"{ns}.csv", estimates=tmp_path / f"{ns}_est.csv")
        for c in ("theta_b", "u", "tau_hat1", "tau_d1"):
            np.testing.assert_allclose(run[c], offline[c], rtol=0, atol=1e-9, err_msg=(ns, c))
        topics, stamps = {}, {}
        for topic, _type, _t, msg in decoded_messages(tmp_path / f"bag_{ns}"):
            topics[topic] = topics.get(topic, 0) + 1
            stamp = getattr(msg, "clock", None) or getattr(getattr(msg, "header", None), "stamp", None)
            if stamp is not None:
                stamps.setdefault(topic, set()).add((stamp.sec, stamp.nanosec))
        # every state once (a state the plant resent before its graph answered is recorded twice, read once)
        assert len(stamps[f"/{ns}/clock"]) == 401 and len(stamps[f"/{ns}/joint_states"]) == 401, topics
        assert all(t.startswith(f"/{ns}/") for t in topics if t not in SYSTEM_TOPICS), topics   # ROS's own are global
