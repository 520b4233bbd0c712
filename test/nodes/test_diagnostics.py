"""Every node reports its health on /diagnostics once a second; ERROR when the robot fell or a peer is missing."""
from types import SimpleNamespace

import pytest
from diagnostic_msgs.msg import DiagnosticArray

from graphproc import Graph
from injector import Injector
from mwip_ros.nodes.runtime.diagnostics import publishers_by_topic, topic_counts

pytestmark = pytest.mark.graph


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


def test_a_lockstep_run_reports_every_node_and_a_fall_is_an_error(tmp_path):
    with Graph(tmp_path) as g, Injector(g.domain_id) as inj:
        got = _listen(inj)
        # |u| <= 10 N m cannot catch 0.9 rad: the robot falls. The plant first, heard before its peers come
        # (it waits for them), so its last word cannot be missed by a listener still discovering it.
        plant = g.start("plant_sim", "-p", "duration_s:=30.0", "-p", "torque_limit:=10.0",
                        "-p", "initial.theta_b:=0.9", "-p", "lockstep_timeout_s:=30.0")
        assert inj.wait(lambda: "/plant_sim" in _by_node(got), 30), plant.output()
        g.start("disturbance_observer")
        g.start("dscndo_controller")
        assert inj.wait(lambda: plant.popen.poll() is not None, 120), plant.output()
        assert plant.popen.returncode == 3, plant.output()
        assert inj.wait(lambda: any(lv == 2 for lv, *_ in _by_node(got).get("/plant_sim", [])), 10)
        inj.spin(1.5)   # the others keep reporting once a second
    reports = _by_node(got)
    level, message, values = [r for r in reports["/plant_sim"] if r[0] == 2][-1]
    assert message.startswith("FALLEN at t = ") and int(values["handled"]) > 0 and values["mode"] == "lockstep"
    for name in ("/disturbance_observer", "/dscndo_controller"):
        assert reports[name], name
        level, message, values = reports[name][-1]
        assert level == 0 and {"rate_per_s", "handled", "rejected_messages"} <= set(values), (name, values)
        assert int(values["handled"]) == int(values.get("commands", values.get("estimates")))
    assert "DSCNDO" in reports["/dscndo_controller"][-1][1]
    # each subscription's matched publishers: the plant's states, the observer's estimate (one publisher each)
    matched = {name: [topic_counts(v.get("publishers_by_topic", "")) for _, _, v in reports[name]]
               for name in ("/disturbance_observer", "/dscndo_controller")}
    assert any(c.get("/joint_states") == 1 for c in matched["/disturbance_observer"]), matched
    assert any(c.get("/joint_states") == 1 and c.get("/disturbance_estimate") == 1
               for c in matched["/dscndo_controller"]), matched


def test_publishers_by_topic_names_each_subscription_and_its_fewest_matches():
    subs = [SimpleNamespace(topic_name=t, get_publisher_count=lambda n=n: n)
            for t, n in (("/joint_states", 2), ("/cmd_vel", 0), ("/joint_states", 1))]
    text = publishers_by_topic(SimpleNamespace(subscriptions=subs))
    assert text == "/cmd_vel: 0, /joint_states: 1"
    assert topic_counts(text) == {"/cmd_vel": 0, "/joint_states": 1}
    assert publishers_by_topic(SimpleNamespace(subscriptions=[])) == "" and topic_counts("") == {}
    assert topic_counts("none") == {} and topic_counts("/clock: 2, joint_states: 5") == {"/clock": 2,
                                                                                        "joint_states": 5}


def test_a_plant_without_its_peers_warns_then_reports_the_timeout_as_an_error(tmp_path):
    with Graph(tmp_path) as g, Injector(g.domain_id) as inj:
        got = _listen(inj)
        plant = g.start("plant_sim", "-p", "lockstep_timeout_s:=8.0")
        # the first report comes a second after start; the timeout 8 s after it (discovery takes its time)
        assert inj.wait(lambda: "/plant_sim" in _by_node(got), 30), plant.output()
        assert inj.wait(lambda: plant.popen.poll() is not None, 60)
        assert inj.wait(lambda: any(lv == 2 for lv, *_ in _by_node(got).get("/plant_sim", [])), 10)
    reports = _by_node(got)["/plant_sim"]
    assert reports[0][0] == 1 and "waiting for the graph" in reports[0][1] and "dscndo_controller" in reports[0][1]
    assert reports[-1][0] == 2 and "lockstep timeout" in reports[-1][1] and "dscndo_controller" in reports[-1][1]
    out = plant.output()   # the log: progress while waiting, the reasons in the failure
    assert "waiting for the graph to come up" in out and "waiting for: " not in out.split("[ERROR]")[0], out
    assert "waiting for the graph: dscndo_controller, disturbance_observer (started? same ROS_DOMAIN_ID?)" in out, out
    assert "lockstep timeout: graph not ready after 8 s; waiting for: dscndo_controller (nothing publishes" in out, out
