"""The mcap_recorder node: as separate processes fed from this test over an isolated ROS domain (what it records,
stopped by SIGINT or SIGTERM; killed by SIGKILL, then repaired), and in this process (its subscriptions, what it
refuses, the topics it selects, the completeness it judges)."""
import os
import signal
import subprocess
import sys

import pytest
import yaml
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from graphproc import Graph, wait_until
from mwip_ros.bag import type_hash

TS = get_typestore(Stores.ROS2_JAZZY)
MODULE = "mwip_ros.nodes.tools.mcap_recorder"
N = 60


@pytest.fixture
def graph(tmp_path, monkeypatch):
    """A private ROS domain: the recorder process and this test's own rclpy context."""
    import rclpy
    g = Graph(tmp_path)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(g.domain_id))
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=g.domain_id)
    node = rclpy.create_node("recorder_test_publisher", context=ctx)
    g.ctx, g.node = ctx, node
    try:
        yield g
    finally:
        g.close()
        node.destroy_node()
        rclpy.shutdown(context=ctx)


def start_recorder(g, *params, name: str = "mcap_recorder"):
    args = ["-r", f"__node:={name}"] if name != "mcap_recorder" else []
    for p in params:
        args += ["-p", p]
    proc = g.start("mcap_recorder", *args, params=None, module=MODULE, label=name)
    assert proc.wait_for_output("recording ", timeout=30), proc.output()
    return proc


def publishers(g, topics):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from mwip_ros.msgs.topics import msg_class
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    return {name: g.node.create_publisher(msg_class(t), name, qos) for name, t in topics.items()}


def wait_matched(g, pubs, timeout=20.0, n=1):
    if wait_until(lambda: all(p.get_subscription_count() >= n for p in pubs.values()), timeout):
        return
    raise AssertionError("the recorder's subscriptions did not match: "
                         + str({n: p.get_subscription_count() for n, p in pubs.items()}))


def wait_written(g, n: int, timeout: float = 30.0, name: str = "mcap_recorder") -> dict:
    """Until the recorder's /diagnostics (a report every wall second) says it has written ``n`` messages or more:
    the event to wait for before stopping or killing it, not a sleep. Returns that report's values."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    written, reports = [], []

    def take(arr):
        for st in arr.status:
            if st.name.endswith(f"/{name}"):
                reports.append({kv.key: kv.value for kv in st.values})
                written.append(int(reports[-1]["messages_written"]))
    sub = g.node.create_subscription(DiagnosticArray, "/diagnostics", take, 10)
    ex = SingleThreadedExecutor(context=g.ctx)
    ex.add_node(g.node)
    try:
        ok = wait_until(lambda: bool(written) and written[-1] >= n, timeout,
                        spin=lambda step: ex.spin_once(timeout_sec=step))
    finally:
        ex.remove_node(g.node)
        ex.shutdown()
        g.node.destroy_subscription(sub)
    assert ok, f"the recorder reported {written[-1:] or 'nothing'} messages written, not {n}"
    return reports[-1]


def wait_acked(pubs):
    from rclpy.duration import Duration
    for name, p in pubs.items():
        assert p.wait_for_all_acked(Duration(seconds=10)), name


def joint_state(i, empty_effort):
    from sensor_msgs.msg import JointState
    m = JointState()
    m.header.stamp.sec, m.header.stamp.nanosec = i, 7
    m.header.frame_id = "base_link"
    m.name = ["wheel", "body_pitch"]
    m.position = [0.5 * i, -0.25 * i]
    m.velocity = [float(i), 2.0]
    m.effort = [] if empty_effort else [1.5 * i, 0.0]
    return m


def read_bag(bag):
    with AnyReader([bag], default_typestore=TS) as reader:
        msgs = {}
        for c, t, raw in reader.messages():
            msgs.setdefault(c.topic, []).append((t, reader.deserialize(raw, c.msgtype)))
        counts = {c.topic: c.msgcount for c in reader.connections}
    return msgs, counts


@pytest.mark.graph
def test_records_exactly_what_was_published_and_finishes_the_bag_on_sigint_and_sigterm(graph, tmp_path):
    """Two recorders of the same publishers, one stopped by SIGINT, the other by SIGTERM: each bag holds every
    message as published, its metadata finished."""
    from geometry_msgs.msg import WrenchStamped
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Float64

    bags = {sig: tmp_path / "bags" / f"run{int(sig)}" for sig in (signal.SIGINT, signal.SIGTERM)}
    recs = {sig: start_recorder(graph, f"output:={bag}", "chunk_size:=4096", "compression:=zstd",
                                name=f"mcap_recorder_{int(sig)}") for sig, bag in bags.items()}
    topics = {"joint_states": "sensor_msgs/msg/JointState", "wheel_torque_cmd": "std_msgs/msg/Float64",
              "disturbance_estimate": "geometry_msgs/msg/WrenchStamped", "/clock": "rosgraph_msgs/msg/Clock"}
    pubs = publishers(graph, topics)
    wait_matched(graph, pubs, n=2)
    for i in range(N):
        pubs["joint_states"].publish(joint_state(i, empty_effort=(i % 3 == 0)))
        pubs["wheel_torque_cmd"].publish(Float64(data=0.125 * i))
        w = WrenchStamped()
        w.header.stamp.sec = i
        w.wrench.force.x, w.wrench.torque.y = float(i), -float(i)
        pubs["disturbance_estimate"].publish(w)
        c = Clock()
        c.clock.sec, c.clock.nanosec = i, 5
        pubs["/clock"].publish(c)
    wait_acked(pubs)
    for sig in recs:   # its /diagnostics count (system topics included); the rest is drained at stop
        wait_written(graph, 4 * N, name=f"mcap_recorder_{int(sig)}")
    for sig, rec in recs.items():
        assert rec.stop(sig, timeout=20) == 0, rec.output()
    for sig, rec in recs.items():
        _check_recorded(bags[sig], rec.output(), topics, f"mcap_recorder_{int(sig)}")


def _check_recorded(bag, out, topics, name):
    assert (bag / "metadata.yaml").exists(), out   # the bag was finished; its counts are read from it below
    msgs, counts = read_bag(bag)
    system = {t: counts.pop(t) for t in ("/rosout", "/parameter_events", "/diagnostics") if t in counts}
    assert system.get("/rosout", 0) >= 1, system   # ROS's own topics too (/parameter_events: test_param_events)
    assert any(m.name == name and "recording" in m.msg for _, m in msgs["/rosout"])
    for topic in topics:   # volatile publishers cannot match the graph's QoS: each topic was subscribed again
        assert f"a publisher on /{topic.lstrip('/')} cannot match the graph's QoS" in out, out
    assert counts == {"/joint_states": N, "/wheel_torque_cmd": N, "/disturbance_estimate": N, "/clock": N}
    for i, (_, m) in enumerate(msgs["/joint_states"]):
        assert (m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id) == (i, 7, "base_link")
        assert list(m.name) == ["wheel", "body_pitch"]
        assert list(m.position) == [0.5 * i, -0.25 * i] and list(m.velocity) == [float(i), 2.0]
        assert list(m.effort) == ([] if i % 3 == 0 else [1.5 * i, 0.0])
    assert [m.data for _, m in msgs["/wheel_torque_cmd"]] == [0.125 * i for i in range(N)]
    assert [(m.header.stamp.sec, m.wrench.force.x, m.wrench.torque.y) for _, m in msgs["/disturbance_estimate"]] \
        == [(i, float(i), -float(i)) for i in range(N)]
    assert [(m.clock.sec, m.clock.nanosec) for _, m in msgs["/clock"]] == [(i, 5) for i in range(N)]
    times = [t for _, t_msgs in msgs.items() for t, _ in t_msgs]
    assert all(t > 1_000_000_000 * 1_000_000_000 for t in times)  # receive time (wall clock)

    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["message_count"] == 4 * N + sum(system.values())
    for e in meta["topics_with_message_count"]:
        if e["topic_metadata"]["name"] in system:
            continue
        tm = e["topic_metadata"]
        assert e["message_count"] == N
        assert tm["type_description_hash"] == type_hash(tm["type"])
        assert [q["reliability"] for q in tm["offered_qos_profiles"]] == ["reliable"]


@pytest.mark.node
def test_the_loop_topics_are_subscribed_before_any_publisher(tmp_path):
    """So a plant that waits for the recorder (expected_subscribers) starts only once it listens, and the
    graph's transient-local writers (GRAPH_QOS) match it with no graph query in between; a volatile publisher
    (here on /clock) cannot match that QoS: its topic is subscribed again, said in the log."""
    from mwip_ros.msgs.qos import GRAPH_QOS
    from mwip_ros.msgs.topics import GRAPH_TOPICS, USER_TOPICS, msg_class
    from mwip_ros.nodes.tools.mcap_recorder import McapRecorder
    from nodeharness import NodeHarness
    loop = {"/" + t.lstrip("/") for t in GRAPH_TOPICS} - {"/" + t for t in USER_TOPICS}
    with NodeHarness(McapRecorder, "-p", f"output:={tmp_path / 'early'}", params=None) as rec:
        assert {t: len(rec.subscriptions(t)) for t in loop} == {t: 1 for t in loop}
        assert not rec.subscriptions("/external_wrench")   # subscribed once a publisher shows
        pub = rec.peer("publisher").create_publisher(msg_class(GRAPH_TOPICS["wheel_torque_cmd"]), "wheel_torque_cmd",
                                                     GRAPH_QOS)
        rec.peer("publisher").create_publisher(msg_class(GRAPH_TOPICS["/clock"]), "/clock", 10)   # volatile
        assert rec.turn(10.0, until=lambda: pub.get_subscription_count() == 1
                        and "a publisher on /clock cannot match" in rec.logs()), rec.logs()
        assert rec.turn(10.0, until=lambda: "subscribed /clock" in rec.logs()), rec.logs()
    out = rec.logs()
    assert "a publisher on /wheel_torque_cmd cannot match" not in out and "subscribed /wheel_torque_cmd" not in out, \
        out


@pytest.mark.node
def test_refuses_existing_output(tmp_path):
    from mwip_ros.nodes.tools.mcap_recorder import McapRecorder
    from nodeharness import refused
    out = tmp_path / "exists"
    out.mkdir()
    line = refused(McapRecorder, "-p", f"output:={out}", params=None)
    assert "output" in line and str(out) in line and "exists" in line, line
    assert os.listdir(out) == []
    assert "'output'" in refused(McapRecorder, params=None)


@pytest.mark.node
def test_topics_parameter_selects_topics(tmp_path):
    from std_msgs.msg import Float64

    from mwip_ros.nodes.tools.mcap_recorder import McapRecorder
    from nodeharness import NodeHarness
    bag = tmp_path / "sel"
    with NodeHarness(McapRecorder, "-p", f"output:={bag}", "-p", "topics:=[wheel_torque_cmd]", params=None) as rec:
        assert rec.node.tap.subs.keys() == {"/wheel_torque_cmd"} and not rec.node.tap.pending
        for i in range(5):
            assert rec.feed("wheel_torque_cmd", Float64(data=float(i))) == 1
        assert not rec.subscriptions("joint_states") and not rec.subscriptions("/rosout")
        report = rec.node.diagnostic_status()[2]
    assert report["topics_subscribed"] == 1 and report["messages_written"] == 5, report
    assert read_bag(bag)[1] == {"/wheel_torque_cmd": 5}


@pytest.mark.graph
def test_kill_9_then_repair(graph, tmp_path):
    bag = tmp_path / "killed"
    rec = start_recorder(graph, f"output:={bag}", "chunk_size:=2048", "topics:=[joint_states]")
    pubs = publishers(graph, {"joint_states": "sensor_msgs/msg/JointState"})
    wait_matched(graph, pubs)
    n = 400
    for i in range(n):
        pubs["joint_states"].publish(joint_state(i, empty_effort=False))
    wait_acked(pubs)
    wait_written(graph, n)  # the recorder has written what it received (only /joint_states is recorded)
    os.kill(rec.pid, signal.SIGKILL)
    rec.popen.wait(timeout=10)
    assert not (bag / "metadata.yaml").exists()
    with pytest.raises(Exception):   # noqa: B017 - any error of the reader: the bag ends mid-write
        read_bag(bag)

    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.bag_repair", str(bag)], env=graph.env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "killed_0.mcap.broken" in r.stdout and "total:" in r.stdout
    msgs, counts = read_bag(bag)
    saved = counts["/joint_states"]
    assert n - 50 <= saved < n  # everything but the unfinished last chunk
    assert [m.position[0] for _, m in msgs["/joint_states"]] == [0.5 * i for i in range(saved)]
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == saved
    tm = meta["topics_with_message_count"][0]["topic_metadata"]
    assert tm["type_description_hash"] == type_hash("sensor_msgs/msg/JointState")
    assert tm["offered_qos_profiles"][0]["reliability"] == "reliable"


@pytest.mark.node
def test_a_recording_that_lacks_states_says_so_and_names_the_remedy(tmp_path):
    """In process, messages handed to the recorder's callback: /clock and joint_states for states 0..9, the
    estimate for 0..4 only. At shutdown the log's warning names the gap and the remedy (count the recorder in
    expected_subscribers), and the bag's metadata holds the gap."""
    from mwip_ros.bag.ledger import GAPS_KEY
    from mwip_ros.msgs import layouts as L
    from mwip_ros.msgs.cdr import encode_clock
    from mwip_ros.nodes.tools.mcap_recorder import McapRecorder
    from nodeharness import NodeHarness
    bag = tmp_path / "bag"
    with NodeHarness(McapRecorder, "-p", f"output:={bag}", "-p", "topics:=[joint_states, disturbance_estimate, /clock]",
                     params=None) as rec:
        h = 5_000_000
        for k in range(10):
            rec.feed("/clock", encode_clock(k * h))
            rec.feed("joint_states", L.encode_state(k * h, (0.0,) * 4, 0.0))
            if k < 5:
                rec.feed("disturbance_estimate", L.encode_wrench(k * h, 0.0, 0.0))
    warnings = rec.logs("WARN").splitlines()
    assert len(warnings) == 1 and warnings[0].startswith("INCOMPLETE lockstep recording: /disturbance_estimate: 5 of "
                                                         "10"), rec.logs()
    assert "count it in plant_sim's expected_subscribers" in warnings[0]
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["custom_data"][GAPS_KEY] in warnings[0] and "expected_subscribers" not in meta["custom_data"][GAPS_KEY]
