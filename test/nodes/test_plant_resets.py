"""Resets in any number and rhythm (the hostile-input issue, items 2 and 4).

* in this process (test/nodeharness.py): plant_sim's lockstep under random interleavings of resets and answers,
  with the loop modelled by the observer's and controller's own stamp guard: a new state never repeats the stamp
  the loop answered last (it would be taken for a resend and never answered), each reset goes back below it; the
  loop itself (plant, observer, controller wired): two resets back to back, then bursts of 20 calls at random
  moments: every call answered, the plant never times out, the run completes balanced;
* graphs of processes: realtime, 1,000 concurrent calls through the middleware answered and the loop balances
  after them; a recorded run with a reset splits into two segments (mwip_ros.bag.segments) with the plant's
  sample counts.
"""
import json
import random

import numpy as np
import pytest
from sensor_msgs.msg import JointState

from graphproc import Graph
from injector import Injector
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import SERVICE_QOS
from mwip_ros.nodes.runtime.guards import NEW, REPEAT, RESTART, StampGuard
from mwip_ros.nodes.runtime.services import prove_reply_paths
from nodeharness import Loop, NodeHarness, node_class

BALANCED = 0.05            # |theta_b| [rad] over the last second of a run: recovered from -10 deg
ANSWER_KINDS = ("reset #", "a reset is already pending", "already at the initial state")


def _client(inj):
    """A reset client of the plant's, its answers shown to arrive (the product's barrier, runtime.services: the
    plant answered a get_parameters client made after it) before the test's real calls, each sent once."""
    from std_srvs.srv import Trigger
    client = inj.node.create_client(Trigger, "/plant_sim/reset", qos_profile=SERVICE_QOS)
    assert client.wait_for_service(timeout_sec=30)
    proof = prove_reply_paths(inj.wait, inj.node, "/plant_sim", timeout=30.0)
    assert proof is not None and proof.answer is not None, "the plant did not answer get_parameters"
    return client


def _calls(inj, client, n: int, timeout: float = 60.0):
    """``n`` concurrent reset calls (all sent before any answer is taken); their answers."""
    from std_srvs.srv import Trigger
    futures = [client.call_async(Trigger.Request()) for _ in range(n)]
    assert inj.wait(lambda: all(f.done() for f in futures), timeout), \
        f"{sum(f.done() for f in futures)} of {n} calls answered"
    return [f.result() for f in futures]


# --- in this process --------------------------------------------------------------------------------------
@pytest.mark.node
def test_no_rhythm_of_resets_makes_the_plant_repeat_the_answered_stamp():
    with NodeHarness(node_class("plant_sim"), "-p", "duration_s:=0.0") as h:
        node = h.node
        sent = []   # (k, stamp) of every new state (not the driver's resends)
        send = node.lockstep.send
        node.lockstep.send = lambda k, stamp, data: (sent.append((k, stamp)), send(k, stamp, data))
        guard = StampGuard(window_ns=20 * node.period_ns)    # the observer's and the controller's rule
        rng = random.Random(7)
        node._start("test")
        answered, answers, resets_seen = None, [], 0
        for step in range(1500):   # about 500 resets among the answers
            for _ in range(rng.choice((0, 0, 0, 1, 2, 5)) if step % 50 else 20):
                answers.append(h.call("~/reset"))
            k, stamp = sent[-1]
            verdict = guard.check(stamp)
            while verdict not in (NEW, RESTART):      # the driver resends until the guard follows the restart
                assert verdict != REPEAT, f"state k = {k} repeats the answered stamp {answered}: never answered"
                verdict = guard.check(stamp)
            if answered is not None and stamp < answered:
                resets_seen += 1
                assert k == 0 and verdict == RESTART
            answered = stamp
            h.feed("wheel_torque_cmd", L.encode_command(0.0))   # no torque: the frequent resets keep the robot up
            assert not node.done
        assert len(answers) == node.reset_calls and all(a.success for a in answers)
        assert all(a.message.startswith(ANSWER_KINDS) for a in answers), {a.message for a in answers}
        assert resets_seen == node.resets > 50
        assert sum(a.message.startswith("already at the initial state") for a in answers) > 0


@pytest.mark.node
def test_resets_back_to_back_and_in_bursts_in_lockstep_keep_the_run_going_and_balanced(tmp_path):
    """The loop in this process (plant, observer and controller wired; the plant resends a state nobody answered,
    so the loop follows each reset): two resets back to back (the second joins the first), one while the new state
    0 waits for its answer, then four bursts of 20 calls at random moments; the run after the last reset whole."""
    rng = random.Random()
    seed = rng.randrange(1 << 30)
    rng.seed(seed)
    csv_path, summary = tmp_path / "plant.csv", tmp_path / "summary.json"
    with Loop("-p", "duration_s:=2.0", "-p", f"csv:={csv_path}", "-p", f"summary_json:={summary}") as loop:
        plant = loop.plant
        node = plant.node

        def reset_calls(n):
            return [plant.call("~/reset") for _ in range(n)]
        loop.start()
        assert loop.run(lambda: len(plant.sent("joint_states")) > 50)
        n0 = len(plant.sent("joint_states"))
        answers = reset_calls(2)                  # back to back: the second joins the first
        assert answers[0].message.startswith("reset #1"), answers[0].message
        assert answers[1].message.startswith(ANSWER_KINDS[1:]), answers[1].message
        # the moment: the new state 0 is out, not answered yet (the loop follows after two resends)
        assert loop.run(lambda: any(L.parse_joint_state(d)[0] == 0 for d in plant.sent("joint_states")[n0:]))
        answers += reset_calls(1)
        assert answers[-1].message.startswith(ANSWER_KINDS), answers[-1].message
        for _ in range(4):                        # bursts at random moments (each within the run of 400 states)
            n0, later = len(plant.sent("joint_states")), rng.randrange(1, 150)
            assert loop.run(lambda: len(plant.sent("joint_states")) >= n0 + later), seed
            assert not node.done, (seed, plant.logs()[-3000:])
            answers += reset_calls(20)
        assert loop.run(), (seed, plant.logs()[-3000:])   # to the run's end
        assert node.exit_code == 0, (seed, plant.logs()[-3000:])
        logs = {name: h.logs() for name, h in loop.nodes.items()}
    assert len(answers) == 83 and all(a.success for a in answers), (seed, [a.message for a in answers])
    assert all(a.message.startswith(ANSWER_KINDS) for a in answers), (seed, [a.message for a in answers])
    s = json.loads(summary.read_text())
    assert s["reset_calls"] == 83 and 1 <= s["resets"] <= 6 and s["exit_code"] == 0 and not s["fallen"], s
    assert "lockstep timeout" not in logs["plant_sim"]
    for name in ("disturbance_observer", "dscndo_controller"):   # each reset seen by the loop as a restart
        assert logs[name].count("joint_states restarted at t = 0.000 s") == s["resets"], (seed, logs[name][-2000:])
    run = np.genfromtxt(csv_path, delimiter=",", names=True)
    assert len(run) == 401 and run["t"][-1] == pytest.approx(2.0)   # the run after the last reset, whole
    assert np.abs(run["theta_b"][-200:]).max() < BALANCED, seed


# --- graphs of processes ------------------------------------------------------------------------------
N_REALTIME_CALLS = 1000


@pytest.mark.alone
@pytest.mark.graph
def test_a_thousand_concurrent_resets_in_realtime_are_all_answered_and_the_loop_balances(tmp_path):
    csv_path, summary = tmp_path / "plant.csv", tmp_path / "summary.json"
    with Graph(tmp_path) as g:
        g.start("disturbance_observer", "-p", "mode:=realtime")
        g.start("dscndo_controller", "-p", "mode:=realtime")
        plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=3.0", "-p", f"csv:={csv_path}",
                        "-p", f"summary_json:={summary}")
        with Injector(g.domain_id) as inj:
            client = _client(inj)
            states = inj.record("joint_states", JointState)
            assert inj.wait(lambda: len(states) > 40, 60), plant.output()[-2000:]
            answers = _calls(inj, client, N_REALTIME_CALLS)
            assert inj.wait(lambda: plant.poll() is not None, 60), plant.output()[-3000:]
        code = plant.wait(10)
    out = plant.output()
    assert code == 0, out[-3000:]
    assert len(answers) == N_REALTIME_CALLS and all(a.success for a in answers), {a.message for a in answers}
    assert all(a.message.startswith(ANSWER_KINDS) for a in answers), {a.message for a in answers}
    s = json.loads(summary.read_text())
    assert s["reset_calls"] == N_REALTIME_CALLS and s["resets"] >= 1 and not s["fallen"], s
    run = np.genfromtxt(csv_path, delimiter=",", names=True)
    assert run["t"][-1] == pytest.approx(3.0) and run["t"][0] == 0.0, (run["t"][:3], run["t"][-3:])
    assert np.abs(run["theta_b"][-200:]).max() < BALANCED, (np.abs(run["theta_b"][-200:]).max(), s, out[-3000:])


@pytest.mark.graph
def test_a_recorded_run_with_a_reset_splits_into_two_segments_with_the_plants_counts(tmp_path):
    import re

    from mwip_ros.bag.segments import Segments
    bag, csv_path = tmp_path / "bag", tmp_path / "plant.csv"
    with Graph(tmp_path) as g:
        rec = g.start("mcap_recorder", "-p", f"output:={bag}", "-p", "use_sim_time:=true")
        g.start("disturbance_observer", "-p", "use_sim_time:=true")
        g.start("dscndo_controller", "-p", "use_sim_time:=true")
        # expected_subscribers 4: the observer, the controller, the recorder (the user's count) and this test's reader,
        # made once its reset client is answered: the lockstep run (2 s of states in well under a second) starts
        # only then, so the reset comes inside it (with 3, a run that started first could end before the client)
        plant = g.start("plant_sim", "-p", "duration_s:=2.0", "-p", "expected_subscribers:=4", "-p", f"csv:={csv_path}")
        with Injector(g.domain_id) as inj:
            client = _client(inj)
            states = inj.record("joint_states", JointState)
            at = (50 + random.randrange(100)) * 5_000_000   # a random moment, well before the end (400 states)
            assert inj.wait(lambda: states and L.parse_joint_state(states[-1])[0] >= at, 120), plant.output()[-2000:]
            assert _calls(inj, client, 1)[0].message.startswith("reset #1")
            assert inj.wait(lambda: plant.poll() is not None, 120), plant.output()[-3000:]
        assert plant.wait(10) == 0, plant.output()[-3000:]
        assert rec.stop() == 0, rec.output()[-2000:]
    t_reset = float(re.search(r"reset #1 at t = ([0-9.]+) s", plant.output()).group(1))
    first = round(t_reset / 0.005) + 1          # states 0 .. k: the reset came with the answer to state k
    rows = len(np.genfromtxt(csv_path, delimiter=",", names=True))
    assert rows == 401
    segs = Segments.from_bag(bag)
    assert [s.states for s in segs] == [first, rows], segs.describe()
    assert [s.first_stamp for s in segs] == [0, 0]
    assert segs[0].last_stamp == round(t_reset * 1e9) and segs[1].last_stamp == 2_000_000_000
    assert segs[0].last_index < segs[1].first_index
    counts = segs.count_topics()               # the loop's answers go with the states they answer
    for i, s in enumerate(segs):
        assert counts[i]["/disturbance_estimate"] >= s.states
        assert counts[i]["/lumped_disturbance"] in (s.states - 1, s.states)
