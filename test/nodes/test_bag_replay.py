"""bag_replay as a process: resim of a recorded lockstep DSCNDO run, timed replay, bad parameters."""
import signal
import subprocess
import re
import sys

import pytest

from graphproc import Graph, wait_until

pytestmark = pytest.mark.graph

MODULE = "mwip_ros.nodes.tools.bag_replay"
STATES = 401  # duration_s 2.0 at 200 Hz: states k = 0 .. 400


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    """A short lockstep DSCNDO run recorded by mcap_recorder (the plant waits for the recorder)."""
    from mwip_ros.bag import topic_counts

    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    from injector import Injector

    work = tmp_path_factory.mktemp("record")
    out = work / "bag"
    # the loop topics the observer and the controller publish: their subscribers, the recorder (and the controller)
    answers = {"/wheel_torque_cmd": 1, "/disturbance_estimate": 2, "/controller_internals": 1}
    with Graph(work) as g, Injector(g.domain_id) as inj:
        rec = g.start("mcap_recorder", "-p", f"output:={out}", params=None)
        obs = g.start("disturbance_observer", "-p", "use_sim_time:=true")
        ctl = g.start("dscndo_controller", "-p", "use_sim_time:=true")
        for p, text in ((rec, "recording "), (obs, "NDO ready"), (ctl, "DSCNDO ready")):
            assert p.wait_for_output(text, timeout=30), p.output()
        # the controller's and observer's publishers and the recorder's subscriptions are discovered (a late
        # match would still get them: the graph's QoS is transient-local, 1000 deep)
        assert wait_until(lambda: all(inj.node.count_publishers(t) >= 1 and inj.node.count_subscribers(t) >= n
                                      for t, n in answers.items()), 30), \
            {t: (inj.node.count_publishers(t), inj.node.count_subscribers(t)) for t in answers}
        cmds = inj.record("wheel_torque_cmd", Float64)
        internals = inj.record("controller_internals", JointState)
        plant = g.start("plant_sim", "-p", "duration_s:=2.0", "-p", "expected_subscribers:=3")
        assert plant.wait(120) == 0, plant.output()
        # the controller has answered the last state (what the recorder received is drained when it stops)
        assert inj.wait(lambda: len(cmds) >= STATES and len(internals) >= STATES, 30), (len(cmds), len(internals))
        for p in (obs, ctl, rec):
            assert p.stop(signal.SIGINT, timeout=20) == 0, p.output()
    from bagcheck import distinct_stamps
    counts = topic_counts(out)
    for topic in ("/wheel_torque_cmd", "/controller_internals"):   # answered once per state
        assert counts.get(topic) == STATES, (counts, rec.output())
    assert distinct_stamps(out, ["/joint_states", "/disturbance_estimate"]) == \
        {"/joint_states": STATES, "/disturbance_estimate": STATES}, (counts, rec.output())   # resends read once
    return out


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


def resim(tmp_path, bag, *controller_args):
    with Graph(tmp_path) as g:
        g.start("disturbance_observer", "-p", "use_sim_time:=true")
        g.start("dscndo_controller", "-p", "use_sim_time:=true", *controller_args)
        br = g.start("bag_replay", "-p", f"bag:={bag}", "-p", "mode:=resim", params=None, module=MODULE)
        code = br.wait(120)
    return code, br.output()


def test_resim_with_the_same_parameters_reproduces_the_recording_exactly(tmp_path, bag):
    code, out = resim(tmp_path, bag)
    assert code == 0, out
    rows = parse_table(out)
    for name in ("wheel_torque_cmd", "disturbance_estimate", "controller_internals", "u", "u_dsc", "u_taud",
                 "tau_hat1", "tau_hat2"):
        compared, missing, diff = rows[name]
        assert compared == STATES and missing in (0, None) and diff == 0.0, (name, out)
    assert "RESULT: REPRODUCED" in out


def test_resim_with_a_changed_gain_reports_the_difference(tmp_path, bag):
    code, out = resim(tmp_path, bag, "-p", "k1:=7.0")
    assert code == 4, out
    rows = parse_table(out)
    assert rows["wheel_torque_cmd"][0] == STATES and rows["wheel_torque_cmd"][2] > 1e-6, out
    assert rows["u"][2] > 1e-6 and rows["u_dsc"][2] > 1e-6, out
    assert rows["disturbance_estimate"][2] == 0.0, out  # the observer sees the same recorded states
    assert "RESULT: DIFFERENT" in out and "wheel_torque_cmd" in out.split("RESULT:")[1]


def test_resim_of_a_controller_that_tracks_cmd_vel_replays_the_bags_and_shows_the_difference(tmp_path, bag):
    """docs/theory.md 6.11: a controller with motion.enabled (and no profile) gets the bag's cmd_vel (none in this
    run: its target stays 0 and it holds its start position), so against this run without motion its commands
    differ (test_resim_motion.py: a run that tracked cmd_vel is reproduced)."""
    code, out = resim(tmp_path, bag, "-p", "motion.enabled:=true")
    assert code == 4, out
    assert "recorded cmd_vel replayed: 0" in out and "RESULT: DIFFERENT" in out, out
    assert parse_table(out)["wheel_torque_cmd"][2] > 1e-6, out


def test_replay_at_rate_4_republishes_every_message_in_a_quarter_of_the_time(tmp_path, bag):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from bagcheck import decoded_messages
    from mwip_ros.bag import topic_counts, topic_types
    from mwip_ros.msgs.qos import GRAPH_QOS
    from mwip_ros.msgs.topics import SYSTEM_TOPICS, msg_class

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


def test_bad_parameters_exit_2_naming_the_key(tmp_path, bag):
    env = Graph(tmp_path).env
    missing = tmp_path / "no_such_bag"
    r = subprocess.run([sys.executable, "-m", MODULE, "--ros-args", "-p", f"bag:={missing}"],
                       env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "'bag'" in r.stderr and str(missing) in r.stderr, r.stderr
    r = subprocess.run([sys.executable, "-m", MODULE, "--ros-args", "-p", f"bag:={bag}", "-p", "topics:=[nope]"],
                       env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "'topics'" in r.stderr and "/joint_states" in r.stderr, r.stdout + r.stderr
    r = subprocess.run([sys.executable, "-m", MODULE, "--help"], env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "exit codes" in r.stdout and "resim" in r.stdout, r.stdout + r.stderr


def _damaged_bag(tmp_path):
    """A graph bag of many chunks whose middle chunk has flipped bytes; returns (bag dir, mcap file)."""
    from bagcheck import damage_cases, write_graph_bag
    good = tmp_path / "good"
    write_graph_bag(good, n=60, chunk_size=2000)
    mcap = next(good.glob("*.mcap"))
    case = dict((name, data) for name, data, _ in damage_cases(mcap))["damaged chunk in the middle"]
    mcap.write_bytes(case)
    return good, mcap


def test_a_damaged_chunk_is_never_replayed_as_data(tmp_path):
    bag, mcap = _damaged_bag(tmp_path)
    env = Graph(tmp_path).env
    for mode in ("replay", "resim"):
        r = subprocess.run([sys.executable, "-m", MODULE, "--ros-args", "-p", f"bag:={bag}", "-p", f"mode:={mode}"],
                           env=env, capture_output=True, text=True, timeout=60)
        assert r.returncode == 2, (mode, r.stdout + r.stderr)
        assert "'bag'" in r.stderr and str(mcap) in r.stderr and "damaged chunk" in r.stderr and "at byte" in r.stderr
        assert "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.report", str(bag), "--out", str(tmp_path / "rep")],
                       env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "damaged chunk" in r.stderr and "Traceback" not in r.stderr, r.stdout + r.stderr
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.bag_repair", str(bag)], env=env, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0 and "damaged chunk" in r.stdout, r.stdout + r.stderr
    from mwip_ros.bag import check
    check(bag)  # repaired: every chunk left is intact


def test_a_resent_state_is_replayed_once(tmp_path):
    from injector import Injector
    from mwip_ros.bag import BagWriter
    from mwip_ros.core.model import State
    from mwip_ros.msgs import layouts as L
    from sensor_msgs.msg import JointState

    bag = tmp_path / "resent"
    with BagWriter(bag) as w:
        w.add_topic("/joint_states", "sensor_msgs/msg/JointState")
        w.add_topic("/clock", "rosgraph_msgs/msg/Clock")
        for k in (0, 0, 1, 2, 3):  # state 0 resent before the graph had matched: recorded twice
            w.write("/clock", L.encode_clock(k * 5_000_000), 10 ** 9 + k * 5_000_000)
            w.write("/joint_states", L.encode_state(k * 5_000_000, State(0.0, 0.1 * k, 0.0, 0.0), 0.0),
                    10 ** 9 + k * 5_000_000 + 1)
    with Graph(tmp_path) as g, Injector(g.domain_id) as inj:
        got = inj.record("joint_states", JointState)
        br = g.start("bag_replay", "-p", f"bag:={bag}", "-p", "wait_for_subscribers:=1", "-p", "topics:=[joint_states]",
                     params=None, module=MODULE)
        assert br.wait(30) == 0, br.output()
        inj.spin(0.5)
    assert [L.parse_joint_state(d)[0] for d in got] == [0, 5_000_000, 10_000_000, 15_000_000]
    assert "1 resent message(s)" in br.output() and "replayed 5 of 5 messages" in br.output(), br.output()


def test_replay_publishes_each_topic_with_its_recorded_qos(tmp_path):
    """A best-effort, volatile topic comes back best-effort and volatile; a reliable, transient-local one as such."""
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    from bagcheck import make_msg, typestore
    from injector import Injector
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
    with Graph(tmp_path) as g, Injector(g.domain_id) as inj:
        node = g.start(MODULE.rsplit(".", 1)[-1], "-p", f"bag:={bag}", "-p", "loop:=true", "-p", "rate:=0.2",
                       params=None, module=MODULE)
        infos = {}

        def seen():
            for topic in topics:
                infos[topic] = inj.node.get_publishers_info_by_topic(topic)
            return all(infos.values())

        assert inj.wait(seen, 30), node.output()
    cmd, js = infos["/wheel_torque_cmd"][0].qos_profile, infos["/joint_states"][0].qos_profile
    assert cmd.reliability == ReliabilityPolicy.BEST_EFFORT and cmd.durability == DurabilityPolicy.VOLATILE
    assert js.reliability == ReliabilityPolicy.RELIABLE and js.durability == DurabilityPolicy.TRANSIENT_LOCAL
