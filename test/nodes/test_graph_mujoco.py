"""The graph with the MuJoCo plant (``plant_sim: backend: mujoco``, docs/theory.md 6.10): lockstep equal to
``mwip_sim`` with it, pose columns and ``true_pose`` included; ``~/reset`` restarts it; a diverging simulation is the
driver's ``diverged`` fault (exit 1, nothing that is not finite recorded); raw sensors through the estimator; a fall
in a state no stage answers; realtime balances.

Two lockstep graphs of the observer and the controller at once (test/loopgraph.py), a plant process per run: a run
that ends after its first state (diverged, or a fall no stage answers) leaves the loop's stream at stamp 0, where the
next plant's first state would be a resend, so each such run is its graph's last."""
import json
import math

import numpy as np
import pytest

pytest.importorskip("mujoco")

from graphproc import PARAMS, Graph  # noqa: E402
from loopgraph import LoopGraph, concurrently  # noqa: E402
from mwip_ros import params as P  # noqa: E402
from mwip_ros.core.closed_loop.sim import simulate  # noqa: E402
from mwip_ros.core.closed_loop.trajectory import POSE_COLUMNS  # noqa: E402
from mwip_ros.runs import read_bag_run, read_csv  # noqa: E402

MUJOCO = ("-p", "backend:=mujoco")
STATE = ["theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_d1", "tau_d2"]
# MuJoCo's hinge damping far beyond what its explicit RK4 step holds: it warns (mjWARN_BADQ*) in the first period
# (at a physics step of 1 ms: five steps a period blow up past 1e10 within it)
DIVERGING = ("-p", "actual.I_w:=0.000001", "-p", "actual.D_b:=1000000.0", "-p", "mujoco.timestep:=0.001")


def _paper(**over):
    return dict(P.merged_values(P.load_param_file(PARAMS)), backend="mujoco", **over)


def _recorded(loop, out, label, *plant_args):
    """A run with a recorder started before it (``LABEL.bag``), stopped after it."""
    bag = loop.workdir / f"{label}.bag"
    rec = loop.graph.start("mcap_recorder", "-p", f"output:={bag}", "-p", "use_sim_time:=true", label=f"rec_{label}")
    out["runs"][label] = loop.run(label, *plant_args)
    out["recorders"][label] = (rec.stop(), rec.output(), bag)


def _reset_midway(out):
    """``wait`` for a plant run: a reset client shown to work by a no-op call (at the initial state) before the
    plant starts (it waits for this test's joint_states subscription, made after: expected_subscribers 4), then one
    reset once 60 states came; the plant's exit."""
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger

    from injector import Injector, call_until_answered
    from mwip_ros.msgs.qos import SERVICE_QOS

    def wait(plant, timeout):
        with Injector(out["domain"]) as inj:
            client = inj.node.create_client(Trigger, "/plant_sim/reset", qos_profile=SERVICE_QOS)
            assert client.wait_for_service(timeout_sec=30), plant.output()
            first, _ = call_until_answered(inj, client, Trigger.Request)
            assert first.success and first.message.startswith("already at the initial state"), first.message
            states = inj.record("joint_states", JointState)
            assert inj.wait(lambda: len(states) > 60, timeout), plant.output()[-2000:]
            future = client.call_async(Trigger.Request())
            assert inj.wait(future.done, 60), plant.output()[-2000:]
            out["reset_answer"] = future.result().message
            assert inj.wait(lambda: plant.poll() is not None, timeout), plant.output()[-3000:]
        return plant.wait(10)
    return wait


def _pose_reset_diverged(work, out):
    """Graph 1: the pose run (1.5 s, recorded), a run reset after 60 states (recorded), a diverging run
    (recorded)."""
    with LoopGraph(work) as loop:
        out["domain"] = loop.domain_id
        loop.start()
        _recorded(loop, out, "pose", "-p", "duration_s:=1.5", "-p", "expected_subscribers:=3", *MUJOCO)
        bag = loop.workdir / "reset.bag"
        rec = loop.graph.start("mcap_recorder", "-p", f"output:={bag}", "-p", "use_sim_time:=true", label="rec_reset")
        out["runs"]["reset"] = loop.run("reset", "-p", "duration_s:=1.0", "-p", "expected_subscribers:=4", *MUJOCO,
                                        wait=_reset_midway(out))
        out["recorders"]["reset"] = (rec.stop(), rec.output(), bag)
        _recorded(loop, out, "diverged", "-p", "duration_s:=1.0", "-p", "expected_subscribers:=3",
                  "-p", f"summary_json:={out['work'] / 'diverged.json'}", *MUJOCO, *DIVERGING)


def _raw_and_fall(work, out):
    """Graph 2: raw sensors through the estimator (1 s), then (the estimator stopped) a fall no stage answers."""
    with LoopGraph(work) as loop:
        loop.start()
        loop.start("state_estimator", params=out["raw_params"])
        out["runs"]["raw"] = loop.run("raw", params=out["raw_params"])
        out["estimator"] = loop.stop("state_estimator")
        out["runs"]["fall"] = loop.run("fall", "-p", "duration_s:=1.0", "-p", "expected_subscribers:=2",
                                       "-p", f"summary_json:={out['work'] / 'fall.json'}", *MUJOCO, *DIVERGING[:4],
                                       "-p", "lockstep_timeout_s:=3.0", timeout=120)


@pytest.fixture(scope="module")
def mujoco(tmp_path_factory):
    """Graphs 1 and 2 (test/loopgraph.py), at once."""
    from test_graph import RAW
    work = tmp_path_factory.mktemp("mujoco")
    out = {"runs": {}, "recorders": {}, "work": work}
    over = work / "mujoco.yaml"
    over.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n    duration_s: 1.0\n")
    out["raw_params"] = [*RAW, over]
    concurrently(lambda: _pose_reset_diverged(work / "one", out), lambda: _raw_and_fall(work / "two", out))
    return out


def _recording(mujoco, label):
    code, out, bag = mujoco["recorders"][label]
    assert code == 0, out
    return bag


@pytest.mark.graph
def test_lockstep_mujoco_graph_equals_mwip_sim_with_the_pose_and_the_bag_holds_it(mujoco):
    """Deterministic: the graph's trajectory, its pose columns included, equals mwip_sim's with backend mujoco to
    1e-9 over 1.5 s of DSCNDO, and the recorded true_pose and true_wheel_states are that pose (the rk4 csv has no
    pose columns)."""
    run = mujoco["runs"]["pose"]
    assert run.code == 0, run.output()
    bag = _recording(mujoco, "pose")
    assert "MuJoCo" in run.output()
    offline = simulate(P.closed_loop(_paper(), duration=1.5, controller="dscndo"))
    graph = read_csv(run.csv)
    assert len(graph) == len(offline) == 301
    assert list(graph.columns)[-len(POSE_COLUMNS):] == POSE_COLUMNS
    for c in STATE + POSE_COLUMNS:
        assert np.isfinite(offline[c]).all(), c
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)
    assert offline["x"][-1] != offline["x"][0] and offline["wheel_left"][-1] != offline["wheel_left"][0]  # it moved
    from_bag = read_bag_run(bag)
    assert len(from_bag) == 301
    for c in POSE_COLUMNS:   # true_pose's position and quaternion, true_wheel_states' positions
        np.testing.assert_allclose(from_bag[c], offline[c], rtol=0, atol=1e-9, err_msg=c)
    np.testing.assert_allclose(from_bag["theta_b"], offline["theta_b"], rtol=0, atol=1e-9)


@pytest.mark.graph
def test_reset_restarts_the_mujoco_plant_and_the_run_after_it_equals_mwip_sim(mujoco):
    """``~/reset`` builds the MuJoCo model afresh at the initial state: the run after it (the csv keeps it) equals
    mwip_sim's from the start, pose included, and the recording splits into two runs there."""
    from mwip_ros.bag.segments import Segments
    run = mujoco["runs"]["reset"]
    assert run.code == 0, run.output()[-3000:]
    bag = _recording(mujoco, "reset")
    assert mujoco["reset_answer"].startswith("reset #1"), mujoco["reset_answer"]
    assert "reset #1 at t = " in run.output()
    offline = simulate(P.closed_loop(_paper(), duration=1.0, controller="dscndo"))
    graph = read_csv(run.csv)
    assert len(graph) == len(offline) == 201
    for c in STATE + POSE_COLUMNS:
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)
    segs = Segments.from_bag(bag)
    assert len(segs) == 2 and segs[1].states == 201, segs.describe()
    second = read_bag_run(bag, segment=1)   # the pose of the run after the reset, from true_pose
    np.testing.assert_allclose(second["x"], offline["x"], rtol=0, atol=1e-9)


@pytest.mark.graph
def test_a_diverging_mujoco_simulation_is_a_diverged_fault_exit_1_and_nothing_non_finite_recorded(mujoco):
    run = mujoco["runs"]["diverged"]
    bag = _recording(mujoco, "diverged")
    out = run.output()
    assert run.code == 1, out
    lines = [ln for ln in out.splitlines() if "diverged" in ln and "ERROR" in ln]
    assert len(lines) == 1 and "t = 0.000 s" in lines[0] and "mjWARN_BADQ" in lines[0], out
    s = json.loads((mujoco["work"] / "diverged.json").read_text())
    assert s["driver_state"] == "fault" and s["fault_reason"] == "diverged" and s["exit_code"] == 1, s
    assert s["diverged_at"] == 0.0 and s["metrics"]["upright"] is False, s   # never scored upright
    assert "DIVERGED" in out and "upright" not in out.split("lockstep run:")[1].splitlines()[0], out
    rows = read_csv(run.csv)
    assert len(rows) == 1
    for c in ("theta_w", "theta_b", "dtheta_w", "dtheta_b", *POSE_COLUMNS):
        assert np.isfinite(rows[c]).all(), c
    from_bag = read_bag_run(bag)
    assert len(from_bag) == 1 and all(math.isfinite(from_bag[c][0]) for c in ("theta_b", "x", "yaw"))


@pytest.mark.graph
def test_a_fall_in_the_state_no_stage_answers_is_fallen_at_its_time_never_upright(mujoco):
    """At the default 5 ms physics step the diverging model does not overflow within a period: it lands at
    |theta_b| = 1.31 rad, a state the observer refuses as absurd (it never answers it). The lockstep timeout then
    ends the run; the state it did not record is FALLEN at t = 0.005 s, not the one recorded row's "upright"."""
    run = mujoco["runs"]["fall"]
    out = run.output()
    assert run.code == 1, out
    verdict = out.split("lockstep run:")[1].splitlines()[0]
    assert "FALLEN (fell at 0.005 s)" in verdict and "upright" not in verdict, out
    s = json.loads((mujoco["work"] / "fall.json").read_text())
    assert s["fallen"] is True and s["fault_reason"] == "watchdog" and s["metrics"]["upright"] is False, s


@pytest.mark.graph
def test_lockstep_mujoco_graph_with_raw_sensors_equals_mwip_sim(mujoco):
    """sensors.model raw: the MuJoCo plant's raw samples (its accelerations at t_k^-, core.plants.raw_sensors) through
    the state estimator, the observer and the controller: the graph equals mwip_sim with backend mujoco to 1e-9."""
    run = mujoco["runs"]["raw"]
    assert run.code == 0, run.output()
    assert mujoco["estimator"] == 0
    params = mujoco["raw_params"]
    offline = simulate(P.closed_loop(P.merged_values(P.load_param_files(params)), controller="dscndo"))
    assert not offline.fallen and len(offline) == 201
    graph = read_csv(run.csv)
    assert len(graph) == 201
    for c in STATE + POSE_COLUMNS:
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)
    mine = read_csv(mujoco["work"] / "two" / "estimator.csv")   # every raw sample the estimator took, as mwip_sim's
    for c in ("gyro", "accel_x", "accel_z", "encoder", "theta_b_hat"):
        np.testing.assert_allclose(mine[c], offline[c], rtol=0, atol=1e-9, err_msg=c)


@pytest.mark.alone
@pytest.mark.graph
def test_realtime_mujoco_graph_balances(tmp_path):
    with Graph(tmp_path) as g:
        g.start("disturbance_observer", "-p", "mode:=realtime")
        g.start("dscndo_controller", "-p", "mode:=realtime")
        plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=3.0",
                        "-p", f"csv:={tmp_path / 'rt.csv'}", *MUJOCO)
        code = plant.wait(90)
    assert code == 0, plant.output()
    run = read_csv(tmp_path / "rt.csv")
    assert run.t[-1] == pytest.approx(3.0) and len(run) == 601
    assert np.isfinite(run["x"]).all() and np.abs(run["yaw"]).max() < 1e-9   # u / 2 per wheel: straight ahead
    assert np.abs(run["theta_b"][-100:]).max() < 0.1, run["theta_b"][-100:]   # recovering from -10 deg, upright
