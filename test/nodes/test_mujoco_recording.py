"""A lockstep recording with the MuJoCo plant (``backend: mujoco``, issue 32 item 4): the bag carries each wheel's
angle (``true_wheel_states``) equal to mwip_sim's csv columns, the recorder's ledger counts the topic, ``bag_replay``
resim reproduces the recorded outputs exactly, and ``mwip_report`` on the bag states the 3D pose."""
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("mujoco")

from graphproc import PARAMS, REPO, Graph  # noqa: E402
from test_bag_replay import MODULE, parse_table  # noqa: E402

pytestmark = pytest.mark.graph

DURATION = 1.5
STATES = 301   # 1.5 s at 200 Hz: states k = 0 .. 300


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """(bag, mwip_sim's csv) of the same lockstep DSCNDO run on MuJoCo."""
    work = tmp_path_factory.mktemp("mujoco_rec")
    over = work / "mujoco.yaml"
    over.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n")
    bag, sim_csv = work / "bag", work / "sim.csv"
    with Graph(work) as g:
        rec = g.start("mcap_recorder", "-p", f"output:={bag}", "-p", "use_sim_time:=true")
        g.start("disturbance_observer", "-p", "use_sim_time:=true")
        g.start("dscndo_controller", "-p", "use_sim_time:=true")
        plant = g.start("plant_sim", "-p", f"duration_s:={DURATION}", "-p", "expected_subscribers:=3",
                        params=[PARAMS, over])
        assert plant.wait(180) == 0, plant.output()
        assert rec.stop() == 0, rec.output()
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", "--params", str(PARAMS), str(over), "--controller",
                        "dscndo", "--duration", str(DURATION), "--csv", str(sim_csv), "-q"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return bag, sim_csv


def test_the_bag_carries_each_wheels_angle_equal_to_mwip_sims_csv(recording):
    from mwip_ros.bag import topic_counts
    from mwip_ros.cli.report import recording_gaps
    from mwip_ros.runs import read_bag_run, read_csv
    bag, sim_csv = recording
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


def test_resim_of_the_mujoco_recording_reproduces_it_exactly(tmp_path, recording):
    bag, _ = recording
    with Graph(tmp_path) as g:
        g.start("disturbance_observer", "-p", "use_sim_time:=true")
        g.start("dscndo_controller", "-p", "use_sim_time:=true")
        br = g.start("bag_replay", "-p", f"bag:={bag}", "-p", "mode:=resim", params=None, module=MODULE)
        code, out = br.wait(120), br.output()
    assert code == 0, out
    rows = parse_table(out)
    for name in ("wheel_torque_cmd", "disturbance_estimate", "controller_internals", "u", "tau_hat1", "tau_hat2"):
        compared, missing, diff = rows[name]
        assert compared == STATES and missing in (0, None) and diff == 0.0, (name, out)
    assert "RESULT: REPRODUCED" in out


def test_the_report_of_the_mujoco_bag_states_the_3d_pose(tmp_path, recording):
    import json
    from mwip_ros.runs import read_csv
    bag, sim_csv = recording
    out = tmp_path / "report"
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.report", str(bag), "--out", str(out), "--no-animation"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    sim = read_csv(sim_csv)
    pose = json.loads((out / "metrics.json").read_text())["poses"]["bag"]
    for key, col in (("x_m", "x"), ("y_m", "y"), ("wheel_left_rad", "wheel_left"), ("wheel_right_rad", "wheel_right")):
        assert pose[key] == pytest.approx(sim[col][-1] - sim[col][0], abs=1e-9), key
    assert pose["yaw_rad"] == pytest.approx(sim["yaw"][-1], abs=1e-9)
    assert pose["roll_max_abs_rad"] == pytest.approx(np.abs(sim["roll"]).max(), abs=1e-9)
    line = next(ln for ln in r.stdout.splitlines() if "3D pose at t = 1.500 s" in ln)
    assert f"x {pose['x_m']:.4f} m" in line and "wheels turned" in line, r.stdout
    assert "3D pose" in (out / "metrics.md").read_text()


def test_resim_of_a_mujoco_recording_with_the_yaw_stage_reproduces_its_wheel_torques(tmp_path):
    """Motion on the MuJoCo plant (a speed and a yaw-rate profile): the controller answers each state with the yaw
    stage's two wheel torques (wheel_torques_cmd, docs/theory.md 6.13) instead of wheel_torque_cmd; resim waits for
    those answers and reproduces them exactly."""
    turn = tmp_path / "turn.yaml"
    turn.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n"
                    "dscndo_controller:\n  ros__parameters:\n"
                    "    motion: {profile: [0.0, 0.0, 0.5, 0.3], yaw_profile: [0.0, 0.0, 0.25, 0.5]}\n")
    files = [PARAMS, REPO / "config" / "motion.yaml", turn]
    bag = tmp_path / "bag"
    for d in ("rec", "resim"):
        (tmp_path / d).mkdir()
    with Graph(tmp_path / "rec") as g:
        rec = g.start("mcap_recorder", "-p", f"output:={bag}", "-p", "use_sim_time:=true", params=None)
        g.start("disturbance_observer", "-p", "use_sim_time:=true", params=files)
        g.start("dscndo_controller", "-p", "use_sim_time:=true", params=files)
        plant = g.start("plant_sim", "-p", "duration_s:=1.5", "-p", "expected_subscribers:=3", params=files)
        assert plant.wait(180) == 0, plant.output()
        assert rec.stop() == 0, rec.output()
    from mwip_ros.bag import topic_counts
    counts = topic_counts(bag)
    assert counts.get("/wheel_torques_cmd") == STATES and not counts.get("/wheel_torque_cmd"), counts
    with Graph(tmp_path / "resim") as g:
        g.start("disturbance_observer", "-p", "use_sim_time:=true", params=files)
        g.start("dscndo_controller", "-p", "use_sim_time:=true", params=files)
        br = g.start("bag_replay", "-p", f"bag:={bag}", "-p", "mode:=resim", params=None, module=MODULE)
        code, out = br.wait(180), br.output()
    assert code == 0, out
    rows = parse_table(out)
    for name in ("wheel_torques_cmd", "disturbance_estimate", "controller_internals", "u"):
        compared, missing, diff = rows[name]
        assert compared == STATES and missing in (0, None) and diff == 0.0, (name, out)
    assert "wheel_torque_cmd" not in rows and "RESULT: REPRODUCED" in out
