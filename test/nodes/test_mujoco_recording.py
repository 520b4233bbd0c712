"""A lockstep recording with the MuJoCo plant (``backend: mujoco``, issue 32 item 4): the bag carries each wheel's
angle (``true_wheel_states``) equal to mwip_sim's csv columns, the recorder's ledger counts the topic, ``bag_replay``
resim reproduces the recorded outputs exactly, and ``mwip_report`` on the bag states the 3D pose. The two recordings
(the paper's run, and one with the yaw stage), each with its resim, run at once."""
import numpy as np
import pytest

pytest.importorskip("mujoco")

from graphproc import PARAMS, REPO  # noqa: E402
from loopgraph import LoopGraph, concurrently  # noqa: E402
from test_bag_replay import parse_table, resim  # noqa: E402

pytestmark = pytest.mark.graph

DURATION = 1.5
STATES = 301   # 1.5 s at 200 Hz: states k = 0 .. 300


def _recorded(work, files):
    """(bag, resim's exit code and output): a lockstep DSCNDO run of ``files`` recorded (the plant waits for the
    recorder), then bag_replay resim of the bag (a freshly started observer and controller, as it asks)."""
    bag = work / "bag"
    with LoopGraph(work, params=files) as loop:
        rec = loop.graph.start("mcap_recorder", "-p", f"output:={bag}", "-p", "use_sim_time:=true", params=None)
        loop.start()
        run = loop.run("plant", "-p", f"duration_s:={DURATION}", "-p", "expected_subscribers:=3")
        assert run.code == 0, run.output()
        assert rec.stop() == 0, rec.output()
    return bag, resim(work / "resim", bag, params=files)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """Two recordings at once (each a graph of its own, then its resim): {"paper": the DSCNDO run on MuJoCo, "turn":
    with the yaw stage (motion: a speed and a yaw-rate profile)}, each (bag, resim's exit code and output)."""
    work = tmp_path_factory.mktemp("mujoco_rec")
    over = work / "mujoco.yaml"
    over.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n")
    turn = work / "turn.yaml"
    turn.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n"
                    "dscndo_controller:\n  ros__parameters:\n"
                    "    motion: {profile: [0.0, 0.0, 0.5, 0.3], yaw_profile: [0.0, 0.0, 0.25, 0.5]}\n")
    paper, turning = concurrently(lambda: _recorded(work / "paper", [PARAMS, over]),
                                  lambda: _recorded(work / "turn", [PARAMS, REPO / "config" / "motion.yaml", turn]))
    return {"paper": paper, "turn": turning, "over": over}


@pytest.fixture(scope="module")
def recording(recordings, tmp_path_factory):
    """(bag, mwip_sim's csv, resim's exit code and output) of the same lockstep DSCNDO run on MuJoCo."""
    from mwip_ros.cli import sim
    bag, replayed = recordings["paper"]
    sim_csv = tmp_path_factory.mktemp("mujoco_sim") / "sim.csv"
    assert sim.main(["--params", str(PARAMS), str(recordings["over"]), "--controller", "dscndo", "--duration",
                     str(DURATION), "--csv", str(sim_csv), "-q"]) == 0
    return bag, sim_csv, replayed


def test_the_bag_carries_each_wheels_angle_equal_to_mwip_sims_csv(recording):
    from mwip_ros.bag import topic_counts
    from mwip_ros.cli.report import recording_gaps
    from mwip_ros.runs import read_bag_run, read_csv
    bag, sim_csv, _ = recording
    counts = topic_counts(bag)
    assert counts.get("/true_wheel_states") == STATES and counts.get("/true_pose") == STATES, counts
    assert not recording_gaps(bag)   # the ledger judges the recording complete, true_wheel_states included
    run, sim = read_bag_run(bag), read_csv(sim_csv)
    assert len(run) == len(sim) == STATES
    for c in ("wheel_left", "wheel_right", "x", "y", "yaw", "roll", "theta_w", "theta_b"):
        assert np.isfinite(sim[c]).all(), c
        np.testing.assert_allclose(run[c], sim[c], rtol=0, atol=1e-9, err_msg=c)
    assert abs(sim["wheel_left"][-1] - sim["wheel_left"][0]) > 0.1   # the wheels turned
    # the wheels' rates: their mean is theta_w' (each wheel = the body's pitch rate + its hinge's)
    from mwip_ros.bag import raw_messages
    from mwip_ros.msgs import layouts as L
    rates = dict(L.parse_wheel_states(d)[::2] for _t, topic, d in raw_messages(bag) if topic == "/true_wheel_states")
    t0 = min(rates)
    mean = np.array([0.5 * sum(rates[s]) for s in sorted(rates)])
    assert len(rates) == STATES and sorted(rates)[-1] - t0 == 1_500_000_000
    np.testing.assert_allclose(mean, sim["dtheta_w"], rtol=0, atol=1e-9)
    assert np.abs(mean).max() > 0.1


def test_resim_of_the_mujoco_recording_reproduces_it_exactly(recording):
    _bag, _csv, (code, out) = recording
    assert code == 0, out
    rows = parse_table(out)
    for name in ("wheel_torque_cmd", "disturbance_estimate", "controller_internals", "u", "tau_hat1", "tau_hat2"):
        compared, missing, diff = rows[name]
        assert compared == STATES and missing in (0, None) and diff == 0.0, (name, out)
    assert "RESULT: REPRODUCED" in out


def test_the_report_of_the_mujoco_bag_states_the_3d_pose(tmp_path, recording, capsys):
    import json

    from mwip_ros.cli import report
    from mwip_ros.runs import read_csv
    bag, sim_csv, _ = recording
    out = tmp_path / "report"
    assert report.main([str(bag), "--out", str(out), "--no-animation"]) == 0, capsys.readouterr().err
    stdout = capsys.readouterr().out
    sim = read_csv(sim_csv)
    pose = json.loads((out / "metrics.json").read_text())["poses"]["bag"]
    for key, col in (("x_m", "x"), ("y_m", "y"), ("wheel_left_rad", "wheel_left"), ("wheel_right_rad", "wheel_right")):
        assert pose[key] == pytest.approx(sim[col][-1] - sim[col][0], abs=1e-9), key
    assert pose["yaw_rad"] == pytest.approx(sim["yaw"][-1], abs=1e-9)
    assert pose["roll_max_abs_rad"] == pytest.approx(np.abs(sim["roll"]).max(), abs=1e-9)
    line = next(ln for ln in stdout.splitlines() if "3D pose at t = 1.500 s" in ln)
    assert f"x {pose['x_m']:.4f} m" in line and "wheels turned" in line, stdout
    assert "3D pose" in (out / "metrics.md").read_text()


def test_resim_of_a_mujoco_recording_with_the_yaw_stage_reproduces_its_wheel_torques(recordings):
    """Motion on the MuJoCo plant (a speed and a yaw-rate profile): the controller answers each state with the yaw
    stage's two wheel torques (wheel_torques_cmd, docs/theory.md 6.13) instead of wheel_torque_cmd; resim waits for
    those answers and reproduces them exactly."""
    from mwip_ros.bag import topic_counts
    bag, (code, out) = recordings["turn"]
    counts = topic_counts(bag)
    assert counts.get("/wheel_torques_cmd") == STATES and not counts.get("/wheel_torque_cmd"), counts
    assert code == 0, out
    rows = parse_table(out)
    for name in ("wheel_torques_cmd", "disturbance_estimate", "controller_internals", "u"):
        compared, missing, diff = rows[name]
        assert compared == STATES and missing in (0, None) and diff == 0.0, (name, out)
    assert "wheel_torque_cmd" not in rows and "RESULT: REPRODUCED" in out
