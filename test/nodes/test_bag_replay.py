"""bag_replay: resim of a recorded lockstep DSCNDO run (three resims at once, each with a freshly started observer
and controller as bag_replay asks), timed replay, what it refuses, resends and QoS."""
import importlib
import signal

import pytest

from graphproc import PARAMS, Graph
from loopgraph import LoopGraph, concurrently
from nodeharness import NodeHarness, refused

MODULE = "mwip_ros.nodes.tools.bag_replay"
STATES = 401  # duration_s 2.0 at 200 Hz: states k = 0 .. 400


def _bag_replay():
    return importlib.import_module(MODULE).BagReplay


def parse_table(text):
    """{row name: (compared, missing or None, max diff)} from the resim table."""
    rows, on = {}, False
    for line in text.splitlines():
        if line.strip().startswith("---"):
            on = True
            continue
        if on and line.strip().startswith("RESULT"):
            break
        parts = line.split()
        if on and len(parts) in (4, 5) and parts[1].isdigit():
            if len(parts) == 5:
                rows[parts[0]] = (int(parts[1]), int(parts[2]), float(parts[3]))
            else:
                rows[parts[0]] = (int(parts[1]), None, float(parts[2]))
    return rows


def resim(work, bag, *controller_args, params=PARAMS, timeout: float = 180.0):
    """bag_replay resim of ``bag`` in a graph of its own (``work``): a freshly started observer and controller, as
    bag_replay asks (``controller_args``: the controller's own, e.g. a changed gain): (exit code, output)."""
    work.mkdir(parents=True, exist_ok=True)
    with Graph(work) as g:
        g.start("disturbance_observer", "-p", "use_sim_time:=true", params=params)
        g.start("dscndo_controller", "-p", "use_sim_time:=true", *controller_args, params=params)
        br = g.start("bag_replay", "-p", f"bag:={bag}", "-p", "mode:=resim", params=None, module=MODULE)
        return br.wait(timeout), br.output()


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    """A short lockstep DSCNDO run recorded by mcap_recorder (the plant waits for the recorder); then three resims of
    its bag at once, each in a graph of its own: as recorded, with k1 = 7.0, and with motion on."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    from bagcheck import distinct_stamps
    from injector import Injector
    from mwip_ros.bag import topic_counts

    work = tmp_path_factory.mktemp("record")
    bag = work / "bag"
    out = {"bag": bag}
    with LoopGraph(work) as loop, Injector(loop.domain_id) as inj:
        rec = loop.graph.start("mcap_recorder", "-p", f"output:={bag}", params=None)
        loop.start()
        cmds = inj.record("wheel_torque_cmd", Float64)
        internals = inj.record("controller_internals", JointState)
        run = loop.run("plant", "-p", "duration_s:=2.0", "-p", "expected_subscribers:=3", timeout=120)
        assert run.code == 0, run.output()
        # the controller has answered the last state (what the recorder received is drained when it stops)
        assert inj.wait(lambda: len(cmds) >= STATES and len(internals) >= STATES, 30), (len(cmds), len(internals))
        assert rec.stop(signal.SIGINT, timeout=20) == 0, rec.output()
    counts = topic_counts(bag)
    for topic in ("/wheel_torque_cmd", "/controller_internals"):   # answered once per state
        assert counts.get(topic) == STATES, (counts, rec.output())
    assert distinct_stamps(bag, ["/joint_states", "/disturbance_estimate"]) == \
        {"/joint_states": STATES, "/disturbance_estimate": STATES}, (counts, rec.output())   # resends read once
    cases = {"same": (), "k1": ("-p", "k1:=7.0"), "motion": ("-p", "motion.enabled:=true")}
    results = concurrently(*(lambda c=c, a=a: resim(work / f"resim_{c}", bag, *a) for c, a in cases.items()))
    out.update(zip(cases, results))
    return out


@pytest.mark.graph
def test_resim_with_the_same_parameters_reproduces_the_recording_exactly(replayed):
    code, out = replayed["same"]
    assert code == 0, out
    rows = parse_table(out)
    for name in ("wheel_torque_cmd", "disturbance_estimate", "controller_internals", "u", "u_dsc", "u_taud",
                 "tau_hat1", "tau_hat2"):
        compared, missing, diff = rows[name]
        assert compared == STATES and missing in (0, None) and diff == 0.0, (name, out)
    assert "RESULT: REPRODUCED" in out


@pytest.mark.graph
def test_resim_with_a_changed_gain_reports_the_difference(replayed):
    code, out = replayed["k1"]
    assert code == 4, out
    rows = parse_table(out)
    assert rows["wheel_torque_cmd"][0] == STATES and rows["wheel_torque_cmd"][2] > 1e-6, out
    assert rows["u"][2] > 1e-6 and rows["u_dsc"][2] > 1e-6, out
    assert rows["disturbance_estimate"][2] == 0.0, out  # the observer sees the same recorded states
    assert "RESULT: DIFFERENT" in out and "wheel_torque_cmd" in out.split("RESULT:")[1]


@pytest.mark.graph
def test_resim_of_a_controller_that_tracks_cmd_vel_replays_the_bags_and_shows_the_difference(replayed):
    """docs/theory.md 6.11: a controller with motion.enabled (and no profile) gets the bag's cmd_vel (none in this
    run: its target stays 0 and it holds its start position), so against this run without motion its commands
    differ (test_resim_motion.py: a run that tracked cmd_vel is reproduced)."""
    code, out = replayed["motion"]
    assert code == 4, out
    assert "recorded cmd_vel replayed: 0" in out and "RESULT: DIFFERENT" in out, out
    assert parse_table(out)["wheel_torque_cmd"][2] > 1e-6, out


@pytest.mark.graph
def test_replay_at_rate_4_republishes_every_message_in_a_quarter_of_the_time(tmp_path, replayed):
    """Across processes (this test's reader): every topic the run recorded comes back, on the bag's schedule at
    rate 4."""
    import re

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from bagcheck import decoded_messages
    from graphproc import wait_until
    from mwip_ros.bag import topic_counts, topic_types
    from mwip_ros.msgs.qos import GRAPH_QOS
    from mwip_ros.msgs.topics import SYSTEM_TOPICS, msg_class

    bag = replayed["bag"]
    # every topic the run recorded but ROS's own (/rosout, ...: of the recorded run, not replayed by default)
    counts = {t: n for t, n in topic_counts(bag).items() if n and t not in SYSTEM_TOPICS}
    types = topic_types(bag)
    log_times = [t for _, _, t, _ in decoded_messages(bag, ["/joint_states"])]
    span = (log_times[-1] - log_times[0]) * 1e-9
    g = Graph(tmp_path)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=g.domain_id)
    node = rclpy.create_node("replay_test_listener", context=ctx)
    received = {t: [] for t in counts}
    for topic in counts:
        # each message's source timestamp (the replayer's publish time, from DDS): the schedule as published, not
        # as this test's executor got round to it (on a loaded machine, hundreds of messages behind)
        node.create_subscription(msg_class(types[topic]), topic,
                                 lambda _data, info, t=topic: received[t].append(info["source_timestamp"] * 1e-9),
                                 GRAPH_QOS, raw=True)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        with g:
            br = g.start("bag_replay", "-p", f"bag:={bag}", "-p", "rate:=4.0", "-p", "wait_for_subscribers:=1",
                         params=None, module=MODULE)

            def spin(step):
                ex.spin_once(timeout_sec=step)
            wait_until(lambda: br.poll() is not None, 60, step=0.01, spin=spin)
            # every replayed message has arrived (the count is asserted below)
            wait_until(lambda: {t: len(v) for t, v in received.items()} == counts, 10, step=0.01, spin=spin)
            assert br.wait(5) == 0, br.output()
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    got = {t: len(v) for t, v in received.items()}
    assert got["/joint_states"] == counts["/joint_states"] == STATES, (got, counts, br.output())
    assert got == counts, (got, counts)
    js = received["/joint_states"]
    wall = js[-1] - js[0]
    # the schedule is the bag's at rate 4: beyond a quarter of the span, only what the replayer says it was behind
    # (a loaded machine) and a stall of its own between a message's due time and its publish call (200 ms each)
    behind = float(re.search(r"at most ([0-9.]+) s behind the bag's timing", br.output()).group(1))
    print(f"bag span {span:.3f} s; replay at rate 4 took {wall:.3f} s (expected ~{span / 4:.3f} s, {behind} s behind)")
    assert wall < span / 4 + behind + 0.5, (wall, span, behind)
    assert wall > span / 4 * 0.5, (wall, span)  # the recorded timing is kept, not a burst
    assert f"replayed {sum(counts.values())} of {sum(counts.values())} messages" in br.output(), br.output()


@pytest.mark.node
def test_bad_parameters_stop_it_naming_the_key(tmp_path):
    """(The process around a refusal, exit 2 and the one line: test_startup.py.)"""
    from bagcheck import write_graph_bag
    missing = tmp_path / "no_such_bag"
    line = refused(_bag_replay(), "-p", f"bag:={missing}", params=None)
    assert "'bag'" in line and str(missing) in line, line
    write_graph_bag(tmp_path / "bag", n=5)
    line = refused(_bag_replay(), "-p", f"bag:={tmp_path / 'bag'}", "-p", "topics:=[nope]", params=None)
    assert "'topics'" in line and "/joint_states" in line, line


@pytest.mark.unit
def test_help_names_the_exit_codes_and_resim(capsys):
    assert importlib.import_module(MODULE).main(["bag_replay", "--help"]) == 0
    out = capsys.readouterr().out
    assert "exit codes" in out and "resim" in out, out


def _damaged_bag(tmp_path):
    """A graph bag of many chunks whose middle chunk has flipped bytes; returns (bag dir, mcap file)."""
    from bagcheck import damage_cases, write_graph_bag
    good = tmp_path / "good"
    write_graph_bag(good, n=60, chunk_size=2000)
    mcap = next(good.glob("*.mcap"))
    case = dict((name, data) for name, data, _ in damage_cases(mcap))["damaged chunk in the middle"]
    mcap.write_bytes(case)
    return good, mcap


@pytest.mark.node
def test_a_damaged_chunk_is_never_replayed_as_data(tmp_path):
    bag, mcap = _damaged_bag(tmp_path)
    for mode in ("replay", "resim"):
        line = refused(_bag_replay(), "-p", f"bag:={bag}", "-p", f"mode:={mode}", params=None)
        assert "'bag'" in line and str(mcap) in line and "damaged chunk" in line and "at byte" in line, (mode, line)


@pytest.mark.unit
def test_a_damaged_chunk_stops_the_report_and_the_repair_saves_the_rest(tmp_path, capsys):
    from mwip_ros.bag import check
    from mwip_ros.cli import bag_repair, report
    bag, _mcap = _damaged_bag(tmp_path)
    assert report.main([str(bag), "--out", str(tmp_path / "rep")]) == 2
    err = capsys.readouterr().err
    assert "damaged chunk" in err and "Traceback" not in err, err
    assert bag_repair.main([str(bag)]) == 0
    assert "damaged chunk" in capsys.readouterr().out
    check(bag)  # repaired: every chunk left is intact


@pytest.mark.node
def test_a_resent_state_is_replayed_once(tmp_path):
    from mwip_ros.bag import BagWriter
    from mwip_ros.core.plants.model import State
    from mwip_ros.msgs import layouts as L

    bag = tmp_path / "resent"
    with BagWriter(bag) as w:
        w.add_topic("/joint_states", "sensor_msgs/msg/JointState")
        w.add_topic("/clock", "rosgraph_msgs/msg/Clock")
        for k in (0, 0, 1, 2, 3):  # state 0 resent before the graph had matched: recorded twice
            w.write("/clock", L.encode_clock(k * 5_000_000), 10 ** 9 + k * 5_000_000)
            w.write("/joint_states", L.encode_state(k * 5_000_000, State(0.0, 0.1 * k, 0.0, 0.0), 0.0),
                    10 ** 9 + k * 5_000_000 + 1)
    with NodeHarness(_bag_replay(), "-p", f"bag:={bag}", "-p", "wait_for_subscribers:=0",
                     "-p", "topics:=[joint_states]", params=None) as br:
        assert br.turn(timeout=5.0), br.logs()
        sent = br.sent("joint_states")
    assert [L.parse_joint_state(d)[0] for d in sent] == [0, 5_000_000, 10_000_000, 15_000_000]
    assert "1 resent message(s)" in br.logs() and "replayed 5 of 5 messages" in br.logs(), br.logs()


@pytest.mark.node
def test_replay_publishes_each_topic_with_its_recorded_qos(tmp_path):
    """A best-effort, volatile topic comes back best-effort and volatile; a reliable, transient-local one as such
    (as the graph lists its publishers)."""
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    from bagcheck import make_msg, typestore
    from mwip_ros.bag import BagWriter, qos_profiles_yaml

    best_effort = {"history": 1, "depth": 7, "reliability": 2, "durability": 2}
    reliable_tl = {"history": 1, "depth": 1000, "reliability": 1, "durability": 1}
    topics = {"/wheel_torque_cmd": ("std_msgs/msg/Float64", best_effort),
              "/joint_states": ("sensor_msgs/msg/JointState", reliable_tl)}
    bag = tmp_path / "qosbag"
    ts = typestore()
    with BagWriter(bag) as w:
        for topic, (type_name, qos) in topics.items():
            w.add_topic(topic, type_name, qos_profiles_yaml([qos]), "")
        for i in range(20):
            for topic, (type_name, _q) in topics.items():
                w.write(topic, bytes(ts.serialize_cdr(make_msg(type_name, i), type_name)), 10 ** 9 + i * 10 ** 7)
    with NodeHarness(_bag_replay(), "-p", f"bag:={bag}", "-p", "loop:=true", "-p", "rate:=0.2",
                     params=None) as br:
        infos = {t: br.node.get_publishers_info_by_topic(t) for t in topics}
        depths = {t: p.qos_profile.depth for t, p in br.node.mode.pubs.items()}   # (the graph does not list it)
    assert all(len(i) == 1 for i in infos.values()), infos
    cmd, js = infos["/wheel_torque_cmd"][0].qos_profile, infos["/joint_states"][0].qos_profile
    assert cmd.reliability == ReliabilityPolicy.BEST_EFFORT and cmd.durability == DurabilityPolicy.VOLATILE
    assert js.reliability == ReliabilityPolicy.RELIABLE and js.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert depths == {"/wheel_torque_cmd": 7, "/joint_states": 1000}, depths
