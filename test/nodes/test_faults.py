"""Killed and paused peers, a second controller in the domain: the plant names the node at fault."""
import os
import signal

import pytest

from graphproc import Graph
from mwip_ros.msgs.topics import SYSTEM_TOPICS

pytestmark = pytest.mark.graph

# lockstep_timeout_s is the wait for the graph at the start as for each command: 8 s, as a loaded machine's
# discovery has taken more than 3 s to match the readers of state 0 (the default is 10 s)
LOCKSTEP = ("-p", "duration_s:=0.0", "-p", "lockstep_timeout_s:=8.0")


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


def test_a_killed_observer_is_named_not_the_controller(tmp_path):
    with Graph(tmp_path) as g:
        obs, (ctl,) = _lockstep_graph(g, ("dscndo_controller", ()))
        plant = g.start("plant_sim", *LOCKSTEP)
        assert plant.wait_for_output("steps/s", 60), plant.output()  # running (progress every 2 s)
        os.kill(obs.pid, signal.SIGKILL)
        code = plant.wait(60)
        out = plant.output()
    assert code == 1, out
    failure = out.split("lockstep timeout:")[1]
    assert "disturbance_observer (it did not answer state k = " in failure, failure
    assert "the controller is running but did not answer" not in failure


def test_a_killed_state_estimator_is_named(tmp_path):
    """Raw sensors: the chain is estimator, observer, controller; the first that stops answering is named."""
    from graphproc import PARAMS
    raw = (PARAMS, PARAMS.parent / "sensors_raw_realistic.yaml")
    with Graph(tmp_path) as g:
        est = g.start("state_estimator", params=raw)
        _ready(est, g.start("disturbance_observer", params=raw), g.start("dscndo_controller", params=raw))
        plant = g.start("plant_sim", *LOCKSTEP, params=raw)
        assert plant.wait_for_output("steps/s", 60), plant.output()  # running (progress every 2 s)
        os.kill(est.pid, signal.SIGKILL)
        code = plant.wait(60)
        out = plant.output()
    assert code == 1, out
    failure = out.split("lockstep timeout:")[1]
    assert "state_estimator" in failure, failure
    assert "disturbance_observer (it did not answer" not in failure and "controller is running" not in failure


def test_a_paused_controller_is_named(tmp_path):
    with Graph(tmp_path) as g:
        obs, (ctl,) = _lockstep_graph(g, ("dscndo_controller", ()))
        plant = g.start("plant_sim", *LOCKSTEP)
        assert plant.wait_for_output("steps/s", 60), plant.output()
        os.kill(ctl.pid, signal.SIGSTOP)
        try:
            code = plant.wait(60)
        finally:
            os.kill(ctl.pid, signal.SIGCONT)
        out = plant.output()
    assert code == 1, out
    failure = out.split("lockstep timeout:")[1]
    assert "the controller is running but did not answer" in failure and "disturbance_observer" not in failure


def test_lockstep_refuses_two_controllers_and_names_them(tmp_path):
    with Graph(tmp_path) as g:
        obs, ctls = _lockstep_graph(g, ("dscndo_controller", ()),
                                    ("second_controller", ("-r", "__node:=dscndo_controller_b")))
        plant = g.start("plant_sim", "-p", "expected_subscribers:=3", "-p", "duration_s:=20.0")
        code = plant.wait(60)
        out = plant.output()
        c_out = ctls[0].output()
    assert code == 1, out
    assert "lockstep refuses mixed streams" in out
    assert "/dscndo_controller, /dscndo_controller_b" in out and "wheel_torque_cmd" in out
    assert "2 publishers on /disturbance_estimate" not in c_out  # the observer is alone on its topic


def test_the_plant_rejects_absurd_commands_and_cut_wrenches_and_keeps_running(tmp_path):
    import math
    import struct

    from geometry_msgs.msg import Wrench
    from injector import Injector, health, plant_rejected, publish_until_rejected
    from mwip_ros.msgs import layouts as L
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    with Graph(tmp_path) as g:
        plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", "-p", "initial.theta_b:=0.0",
                        "-p", "lockstep_timeout_s:=0.5", "-p", "actual.D_w_variance:=0.0",
                        "-p", "tau_ext1.amplitude:=0.0", "-p", "tau_ext2.amplitude:=0.0")   # upright, at rest
        with Injector(g.domain_id) as inj:
            cmd = inj.publisher("wheel_torque_cmd", Float64)
            wr = inj.publisher("external_wrench", Wrench)
            states = inj.record("joint_states", JointState)
            assert inj.wait(lambda: cmd.get_subscription_count() >= 1 and wr.get_subscription_count() >= 1, 30)
            assert inj.wait(lambda: len(states) > 20, 30), plant.output()
            latest = health(inj)
            # realtime: the plant keeps the newest command only (msgs.qos), so one at a time, each until counted
            for u in (1e300, -1e7, math.inf, math.nan):
                assert publish_until_rejected(inj, latest, "/plant_sim", "wheel_torque_cmd", cmd,
                                              L.encode_command(u)), (u, latest)
            full = L.encode_external_wrench(25.0, -3.0)
            for data in (full[:-12],                                      # cut inside torque.y: refused
                         L.encode_external_wrench(1e9, 0.0),              # absurd
                         b"\x00\x01\x00\x00" + struct.pack("<5d", 1, 2, 3, 4, 5)):  # one double short
                assert publish_until_rejected(inj, latest, "/plant_sim", "external_wrench", wr, data), latest
            n = len(states)
            assert inj.wait(lambda: len(states) > n + 100, 30), plant.output()  # still stepping, 200 Hz
            last = L.parse_joint_state(states[-1])[1]
        code = plant.stop()
    out = plant.output()
    assert code == 0, out
    assert all(math.isfinite(v) for v in last) and abs(last.theta_b) < 0.5  # nothing absurd was applied
    rejected = plant_rejected(out)
    assert rejected["wheel_torque_cmd"] >= 4 and rejected["external_wrench"] >= 3, rejected
    assert "implausible command" in out and "not a geometry_msgs/Wrench: message ends at byte" in out
    assert "external wrench: tau_ext1" not in out  # nothing was applied as a push
    assert "Traceback" not in out


def test_two_namespaced_graphs_in_one_domain_do_not_hear_each_other(tmp_path):
    """Each graph under its namespace, /clock remapped into it (docs/graph.md, Namespaces): both runs equal the
    offline simulator, each recorder records its own graph only."""
    import numpy as np

    from bagcheck import decoded_messages
    from graphproc import PARAMS
    from mwip_ros import params as P
    from mwip_ros.core.sim import simulate
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
