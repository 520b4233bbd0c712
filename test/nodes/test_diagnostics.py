"""Every node reports its health on /diagnostics once a second; ERROR when the robot fell or a peer is missing.

The reports' contents in a lockstep run (the loop in this process, each node's reporter as run_node attaches it:
test/nodeharness.py); a plant process alone, its reports heard by another process, to its last word at the timeout.
"""
from types import SimpleNamespace

import pytest
from diagnostic_msgs.msg import DiagnosticArray

from graphproc import Graph
from injector import Injector
from mwip_ros.nodes.runtime.diagnostics import publishers_by_topic, topic_counts
from nodeharness import Loop


def _listen(inj):
    got = []
    inj.node.create_subscription(DiagnosticArray, "/diagnostics", got.append, 100)
    return got


def _by_node(got):
    out = {}
    for arr in got:
        for st in arr.status:
            out.setdefault(st.name, []).append((st.level[0] if isinstance(st.level, bytes) else st.level, st.message,
                                                {kv.key: kv.value for kv in st.values}))
    return out


@pytest.mark.node
def test_a_lockstep_run_reports_every_node_and_a_fall_is_an_error():
    """|u| <= 10 N m cannot catch 0.9 rad: the robot falls (exit 3). Each node's report (made as run_node's loop
    makes it once a second: here at the start, in the run and at its end) says what it did."""
    with Loop("-p", "duration_s:=30.0", "-p", "torque_limit:=10.0", "-p", "initial.theta_b:=0.9") as loop:
        reporters = {name: h.diagnostics() for name, h in loop.nodes.items()}
        loop.start()
        for name, d in reporters.items():
            d.tick(now=True)
        assert loop.run(lambda: loop.plant.node.plant.k >= 20)
        for d in reporters.values():
            d.tick(now=True)
        assert loop.run() and loop.plant.node.exit_code == 3, loop.plant.logs()[-2000:]
        for d in reporters.values():
            d.tick(force=True)   # the run's last word
        got = [m for h in loop.nodes.values() for m in h.messages("/diagnostics", DiagnosticArray)]
    reports = _by_node(got)
    level, message, values = [r for r in reports["/plant_sim"] if r[0] == 2][-1]
    assert message.startswith("FALLEN at t = ") and int(values["handled"]) > 0 and values["mode"] == "lockstep"
    for name in ("/disturbance_observer", "/dscndo_controller"):
        assert len(reports[name]) == 3, name
        level, message, values = reports[name][-1]
        assert level == 0 and {"rate_per_s", "handled", "rejected_messages"} <= set(values), (name, values)
        assert int(values["handled"]) == int(values.get("commands", values.get("estimates"))) > 20
        assert float(values["rate_per_s"]) > 0
    assert "DSCNDO" in reports["/dscndo_controller"][-1][1]
    # each subscription's matched publishers: the plant's states, the observer's estimate (one publisher each)
    matched = {name: [topic_counts(v.get("publishers_by_topic", "")) for _, _, v in reports[name]]
               for name in ("/disturbance_observer", "/dscndo_controller")}
    assert any(c.get("/joint_states") == 1 for c in matched["/disturbance_observer"]), matched
    assert any(c.get("/joint_states") == 1 and c.get("/disturbance_estimate") == 1
               for c in matched["/dscndo_controller"]), matched


@pytest.mark.unit
def test_publishers_by_topic_names_each_subscription_and_its_fewest_matches():
    subs = [SimpleNamespace(topic_name=t, get_publisher_count=lambda n=n: n)
            for t, n in (("/joint_states", 2), ("/cmd_vel", 0), ("/joint_states", 1))]
    text = publishers_by_topic(SimpleNamespace(subscriptions=subs))
    assert text == "/cmd_vel: 0, /joint_states: 1"
    assert topic_counts(text) == {"/cmd_vel": 0, "/joint_states": 1}
    assert publishers_by_topic(SimpleNamespace(subscriptions=[])) == "" and topic_counts("") == {}
    assert topic_counts("none") == {} and topic_counts("/clock: 2, joint_states: 5") == {"/clock": 2,
                                                                                        "joint_states": 5}


@pytest.mark.graph
def test_a_plant_without_its_peers_warns_then_reports_the_timeout_as_an_error(tmp_path):
    with Graph(tmp_path) as g, Injector(g.domain_id) as inj:
        got = _listen(inj)
        plant = g.start("plant_sim", "-p", "lockstep_timeout_s:=4.0")
        # the first report comes a second after start, the progress line naming the missing nodes after 2 s, the
        # timeout after 4 s
        assert inj.wait(lambda: "/plant_sim" in _by_node(got), 30), plant.output()
        assert inj.wait(lambda: plant.popen.poll() is not None, 60)
        assert inj.wait(lambda: any(lv == 2 for lv, *_ in _by_node(got).get("/plant_sim", [])), 10)
    reports = _by_node(got)["/plant_sim"]
    assert reports[0][0] == 1 and "waiting for the graph" in reports[0][1] and "dscndo_controller" in reports[0][1]
    assert reports[-1][0] == 2 and "lockstep timeout" in reports[-1][1] and "dscndo_controller" in reports[-1][1]
    out = plant.output()   # the log: progress while waiting, the reasons in the failure
    assert "waiting for the graph to come up" in out and "waiting for: " not in out.split("[ERROR]")[0], out
    assert "waiting for the graph: dscndo_controller, disturbance_observer (started? same ROS_DOMAIN_ID?)" in out, out
    assert "lockstep timeout: graph not ready after 4 s; waiting for: dscndo_controller (nothing publishes" in out, out
