"""Fault injection: hostile messages, stamps and neighbours never crash, poison, stall or hijack a node.

The observer and the controller, in this process (test/nodeharness.py, the observer's estimates handed to the
controller), are driven state by state from the test (as the lockstep plant would), with hostile messages
between the good ones; what they answer must equal the core's observer and controller run on the good states
alone, to the last bit. A /clock that rclpy's time source would raise on kills neither a node with use_sim_time
nor the recorder. A flood's memory is a process's (its resident size): a process-level test.
"""
import math
import time

import pytest
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState

from graphproc import PARAMS, Graph
from injector import Injector, flood, rejected_counts, rss_mib
from mwip_ros import params as P
from mwip_ros.core.control.controller import DscController
from mwip_ros.core.plants.model import State
from mwip_ros.core.control.observer import DiscreteObserver
from mwip_ros.msgs import cdr
from mwip_ros.msgs import layouts as L
from nodeharness import NodeHarness, Wire, node_class

PERIOD_NS = 5_000_000
DEFAULTS = {**P.defaults_for("dscndo_controller"), **P.defaults_for("disturbance_observer")}


def _good_state(k: int, stamp: int = None) -> tuple:
    x = State(0.01 * k, -0.17 + 0.002 * k, 0.3 * math.sin(0.1 * k), 0.5 * math.cos(0.07 * k))
    return (k * PERIOD_NS if stamp is None else stamp), x, 10.0 * math.sin(0.05 * k)


def _hostile_states(stamp_now: int) -> list:
    """Messages on joint_states that must all be rejected (stamp_now: the stream's last stamp)."""
    good = L.encode_state(stamp_now + PERIOD_NS, State(0.1, 0.1, 0.1, 0.1), 1.0)
    long_names = cdr.JointStateEncoder(("wheel" + "x" * 5000, "body_pitch"))
    return [
        L.encode_state(stamp_now + PERIOD_NS, State(0.0, math.nan, 0.0, 0.0), 0.0),      # NaN
        L.encode_state(stamp_now + PERIOD_NS, State(0.0, 0.0, 1e160, 0.0), 0.0),         # absurd but finite
        L.encode_state(stamp_now + PERIOD_NS, State(0.0, 4.0, 0.0, 0.0), 0.0),           # upside down
        L.encode_state(stamp_now + PERIOD_NS, State(0.0, 0.0, 0.0, 0.0), 1e300),         # absurd effort
        L.encode_state(stamp_now + 10 ** 15, State(0.0, 0.0, 0.0, 0.0), 0.0),            # far in the future
        L.encode_state(stamp_now + 10 * 10 ** 9, State(0.0, 0.0, 0.0, 0.0), 0.0),        # 10 s ahead
        L.encode_state(max(0, stamp_now - 7 * PERIOD_NS), State(0.0, 0.0, 0.0, 0.0), 0.0),  # from the past
        good[:-5],  # cut short (DDS pads a payload to 4 bytes with zeros: a cut of 1-3 bytes is not visible)
        b"\x00\x07" + good[2:],                                                           # bad encapsulation
        bytes(range(256)) * 4,                                                            # noise
        long_names(stamp_now + PERIOD_NS, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0)),          # long unknown names
    ]


def _offline(fed):
    """The core's observer and controller on the good states alone: (estimates, commands) in order."""
    nom = P.physical(P.defaults_for("plant_sim"), "nominal")
    h = PERIOD_NS * 1e-9
    obs = DiscreteObserver(nom, P.observer_gain(DEFAULTS), h)
    ctrl = DscController(nom, P.gains(DEFAULTS), h)
    est_seq, cmd_seq = [], []
    for stamp, x, u_prev in fed:
        if stamp is None:  # the stream restarts here
            obs.reset()
            ctrl.x4d = None
            continue
        e = obs.update(x, u_prev)
        est_seq.append(e)
        cmd_seq.append(ctrl.step(x, e).u)
    return est_seq, cmd_seq


@pytest.mark.node
def test_hostile_states_and_estimates_change_nothing():
    with NodeHarness(node_class("disturbance_observer")) as obs, \
            NodeHarness(node_class("dscndo_controller")) as ctl:
        wire = Wire(obs, ctl)   # the observer's estimates to the controller

        def publish(data):
            """A message on joint_states, as the one publisher of states delivers it to both nodes."""
            obs.feed("joint_states", data)
            ctl.feed("joint_states", data)
            wire.pump()

        def send(data, stamp):
            """Publish a state and see its command."""
            publish(data)
            return any(L.parse_internals(d)[0] == stamp for d in ctl.sent("controller_internals")[-3:])

        def intrude(data):
            """An estimate from a second publisher on disturbance_estimate (the observer is the first)."""
            ctl.feed("disturbance_estimate", data, feeder="intruder")

        fed = []
        for k in range(120):
            stamp, x, u_prev = _good_state(k)
            fed.append((stamp, x, u_prev))
            assert send(L.encode_state(stamp, x, u_prev), stamp), (k, ctl.logs()[-2000:])
            if k % 10 == 5:
                for data in _hostile_states(stamp):
                    publish(data)
                for t1 in (math.nan, 1e300):  # estimates for the next state that must not be used
                    intrude(L.encode_wrench(stamp + PERIOD_NS, t1, 0.0))
                intrude(L.encode_wrench(stamp + 10 ** 12, 1.0, 1.0))   # far ahead of the states
                intrude(b"\x00\x01\x00\x00\x01\x02")
                publish(L.encode_state(stamp, x, u_prev))                # a resend: answered once
        # the stream restarts at t = 0 (a new plant): two stamps are rejected, the third restarts it
        fed.append((None, None, None))
        for k in range(40):
            stamp, x, u_prev = _good_state(1000 + k, stamp=k * PERIOD_NS)
            if k < 2:
                publish(L.encode_state(stamp, x, u_prev))
            else:
                fed.append((stamp, x, u_prev))
                assert send(L.encode_state(stamp, x, u_prev), stamp), (k, ctl.logs()[-2000:])
        assert not obs.node.done and not ctl.node.done
        est_raw, int_raw, cmd_raw = (obs.sent("disturbance_estimate"), ctl.sent("controller_internals"),
                                     ctl.sent("wheel_torque_cmd"))
    est_seq, cmd_seq = _offline(fed)
    assert len(cmd_seq) == 120 + 38
    # one command per good state and nothing for a hostile one, each equal to the core on the good states
    internals = [L.parse_internals(d) for d in int_raw]
    assert [s for s, _ in internals] == [s for s, _, _ in fed if s is not None]
    got_u = [v["u"] for _, v in internals]
    assert got_u == cmd_seq, (next(i for i, (a, b) in enumerate(zip(got_u, cmd_seq)) if a != b), ctl.logs()[-3000:])
    assert [L.parse_command(d) for d in cmd_raw] == cmd_seq
    # the observer's answers (a resent state answered again with the same estimate)
    answers = [(s, (a, b)) for s, a, b in map(L.parse_wrench, est_raw)]
    assert [a for _, a in _dedup(answers)] == est_seq
    o, c = obs.logs(), ctl.logs()
    assert "joint_states restarted at t = 0.010 s" in o and "re-initialising" in c
    for words in ("non-finite joint state", "implausible theta_w'", "implausible theta_b", "implausible effort",
                  "jumps ahead of the stream", "is older than the stream", "message ends at byte",
                  "is not CDR_LE"):
        assert words in o, words
    assert "non-finite torque" in c and "implausible torque" in c and "ahead of the states" in c


def _dedup(answers):
    """The observer answers a resent state again with the same estimate: keep the first answer per stamp run."""
    out = []
    for s, a in answers:
        if out and out[-1][0] == s:
            assert out[-1][1] == a  # the repeat is the same estimate, not a second integration
            continue
        out.append((s, a))
    return out


@pytest.mark.graph
def test_a_flood_of_hostile_messages_leaves_memory_bounded(tmp_path):
    """Short soak (CI); scripts/soak.py runs the long one (a million messages)."""
    with Graph(tmp_path) as g:
        obs = g.start("disturbance_observer")
        with Injector(g.domain_id) as inj:
            js = inj.publisher("joint_states", JointState)
            est = inj.record("disturbance_estimate", WrenchStamped)
            assert inj.wait(lambda: js.get_subscription_count() >= 1, 30)
            assert obs.wait_for_output("ready", 30)
            before = rss_mib(obs.pid)
            sent = flood(inj, js, 20000)
            # still answering, with the right numbers: a good state after the flood is estimated from scratch
            stamp, x, u_prev = _good_state(0, stamp=0)
            js.publish(L.encode_state(stamp, x, u_prev))
            assert inj.wait(lambda: any(L.parse_wrench(d)[0] == 0 for d in est), 60), obs.output()[-2000:]
            after = rss_mib(obs.pid)
        obs.stop()
    out = obs.output()
    # a reader keeps the last 1000: what a flood outruns is dropped by DDS, what arrives is rejected, all of it
    rejected = int(out.split("rejected: joint_states: ")[1].split()[0])
    assert sent // 10 < rejected <= sent and "estimated 1 states" in out, out[-1500:]
    assert after - before < 40, (before, after)  # 60 x 1 MiB names and 20,000 layouts kept nothing
    assert out.count("rejected message #") < 60  # rate-limited: a line per kind, then one per 100


ARENAS = """
import contextlib, ctypes, importlib, io, sys, threading
if sys.argv[1] == "entry":      # as the console script runs a node: entry first, then the node (rclpy) imported
    from mwip_ros.nodes.runtime import entry
    with contextlib.redirect_stdout(io.StringIO()):
        assert entry.main(["python", "disturbance_observer", "--help"]) == 0
elif sys.argv[1] == "run_node":  # python -m mwip_ros.nodes.NODE: the node module (rclpy) imported, then run_node
    node = importlib.import_module("mwip_ros.nodes.loop.disturbance_observer")
    with contextlib.redirect_stdout(io.StringIO()):
        assert node.main(["disturbance_observer", "--help"]) == 0
elif sys.argv[1] == "import":    # importing changes nothing
    for name in ("runtime.entry", "runtime.rclpy_compat", "runtime.process", "loop.plant_sim",
                 "loop.disturbance_observer", "loop.dscndo_controller"):
        importlib.import_module("mwip_ros.nodes." + name)
def work():
    keep = [bytearray(1000 + i % 500) for i in range(20000)]   # malloc, not Python's small-object pool
    del keep
threads = [threading.Thread(target=work) for _ in range(4)]
for t in threads:
    t.start()
for t in threads:
    t.join()
libc = ctypes.CDLL(None)
libc.fdopen.restype = ctypes.c_void_p
out = ctypes.c_void_p(libc.fdopen(1, b"w"))
libc.malloc_info(0, out)
libc.fflush(out)
"""


def _malloc_heaps(*runs) -> list:
    """The glibc heaps (arenas) of each run ``(argument, environment)`` of :data:`ARENAS`, the runs side by side."""
    import subprocess
    import sys
    procs = [subprocess.Popen([sys.executable, "-c", ARENAS, arg], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, env=env) for arg, env in runs]
    try:
        outs = [p.communicate(timeout=60) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    assert all(p.returncode == 0 for p in procs), [err for _, err in outs]
    return [out.count("<heap nr=") for out, _ in outs]


@pytest.mark.cli
def test_a_node_process_allocates_from_one_malloc_arena():
    """What keeps a flood's RSS flat (scripts/soak.py): threads that allocate share one glibc arena."""
    import os
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    plain, imported, entry, run_node, users = _malloc_heaps(
        ("plain", env), ("import", env), ("entry", env), ("run_node", env), ("entry", dict(env, MALLOC_ARENA_MAX="3")))
    assert plain > 1      # glibc's default: an arena per allocating thread
    assert imported > 1   # importing the nodes sets no limit (no import side effect)
    assert entry == 1     # mwip_ros.nodes.runtime.entry limits it before rclpy's threads start
    assert run_node > 1   # run_node's own call comes after rclpy's import started threads with arenas of their own
    assert users > 1      # the user's setting wins


@pytest.mark.node
@pytest.mark.parametrize("node", ["disturbance_observer", "mcap_recorder"])
def test_a_negative_or_wild_clock_kills_no_node(tmp_path, node):
    """rclpy's time source raises on a negative /clock; a node with use_sim_time (the observer, the recorder, in this
    process) survives it and says so: each /clock handed to its subscriptions (rclpy's time source's, and the
    recorder's own) is taken (its clock, on /diagnostics) or rejected (counted there)."""
    from rosgraph_msgs.msg import Clock

    args = ("-p", f"output:={tmp_path / 'bag'}") if node == "mcap_recorder" else ()
    with NodeHarness(node_class(node), "-p", "use_sim_time:=true", *args,
                     params=None if node == "mcap_recorder" else PARAMS) as h:
        diagnostics = h.diagnostics()

        def report():
            """(the node's clock [s], {topic: rejected}) of a /diagnostics report made now."""
            arr = diagnostics.report(time.monotonic())
            values = {kv.key: kv.value for st in arr.status for kv in st.values}
            return arr.header.stamp.sec, rejected_counts(values.get("rejected_by_topic", ""))
        assert h.subscriptions("/clock"), "use_sim_time: rclpy's time source listens to /clock"
        for sec, taken in ((1, True), (-5, False), (10 ** 6, False), (2, True), (-(2 ** 31), False)):
            before = report()[1].get("/clock", 0)
            c = Clock()
            c.clock.sec, c.clock.nanosec = sec, 0
            h.feed("/clock", c)
            now, rejected = report()
            assert (now == sec) if taken else (rejected.get("/clock", 0) > before), (sec, now, rejected)
        if node == "disturbance_observer":
            stamp, x, u_prev = _good_state(0, stamp=0)
            h.feed("joint_states", L.encode_state(stamp, x, u_prev))
            assert h.sent("disturbance_estimate"), h.logs()[-2000:]
        assert not h.node.done
    out = h.logs()
    assert "rejected message #1 on /clock: /clock -5000000000 ns is negative" in out, out[-2000:]
    assert "/clock 1000000.000000 s jumps ahead of the stream's 1.000000 s" in out, out[-2000:]
