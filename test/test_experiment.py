"""The main job end to end, its clean-up on Ctrl-C, and repair of a bag cut by kill -9 mid-run."""
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from bagcheck import distinct_stamps
from graphproc import REPO, Graph, ros_env, script_env, wait_until

rosbags_highlevel = pytest.importorskip("rosbags.highlevel")


def _anyreader_counts(bag: Path) -> dict:
    """Read every message with rosbags (an independent reader) and count per topic."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    counts = {}
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, _t, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
    return counts


def _session_pids(sid: int) -> list:
    out = subprocess.run(["ps", "-e", "-o", "pid=,sid="], capture_output=True, text=True).stdout
    return [int(p) for p, s in (line.split() for line in out.splitlines()) if int(s) == sid]


@pytest.mark.e2e
def test_main_job_records_two_bags_and_writes_the_report(tmp_path):
    r = subprocess.run(["bash", str(REPO / "scripts" / "run_experiment.sh"), "--out", str(tmp_path)],
                       capture_output=True, text=True, timeout=600, env=script_env())
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    bags = sorted(p for p in tmp_path.iterdir() if p.name.endswith(("_dsc", "_dscndo")))
    assert [b.name.rsplit("_", 1)[1] for b in bags] == ["dsc", "dscndo"]
    for bag in bags:
        meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
        declared = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
        counts = _anyreader_counts(bag)
        assert counts == {k: v for k, v in declared.items() if v}
        # lockstep loses nothing: 2001 states, commands, estimates, truths, internals and clocks
        for topic in ("/wheel_torque_cmd", "/lumped_disturbance", "/controller_internals"):   # once per state
            assert counts[topic] == 2001, (bag.name, topic)
        stamped = ("/joint_states", "/disturbance_estimate", "/clock")   # a resent state is recorded twice
        assert distinct_stamps(bag, stamped) == {t: 2001 for t in stamped}, bag.name
    # the report's reading of a bag equals the plant's own CSV of the same run joined with the observer's
    # estimates by stamp (u, estimate, truth)
    from mwip_ros.runs import load_run
    logs = next(p for p in tmp_path.iterdir() if p.name.endswith("_logs"))
    for bag in bags:
        ctrl = bag.name.rsplit("_", 1)[1]
        from_bag, from_csv = load_run(bag), load_run(logs / f"{ctrl}.csv", estimates=logs / f"{ctrl}_estimates.csv")
        for c in ("t", "theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_hat1", "tau_hat2", "tau_d1", "tau_d2"):
            b, v = from_bag[c], from_csv[c]
            assert np.isfinite(b).all(), (ctrl, c)  # the bag has every estimate, also the last one
            known = np.isfinite(v)  # plain DSC's plant may finish before the last estimate reaches it
            assert known.sum() >= len(v) - 1
            assert b[known] == pytest.approx(v[known], abs=1e-12), (ctrl, c)
    report = next(p for p in tmp_path.iterdir() if p.name.endswith("_report"))
    m = json.loads((report / "metrics.json").read_text())["runs"]
    assert m["dsc"]["upright"] and m["dscndo"]["upright"]
    assert m["dsc"]["theta_b_p2p"] >= 3 * m["dscndo"]["theta_b_p2p"]
    for f in ("fig3.png", "observer.png", "metrics.md"):
        assert (report / f).stat().st_size > 0
    assert "report:" in r.stdout and "bags:" in r.stdout


@pytest.mark.e2e
def test_ctrl_c_stops_every_process_and_writes_the_report_of_the_runs_so_far(tmp_path):
    p = subprocess.Popen(["bash", str(REPO / "scripts" / "run_experiment.sh"), "--out", str(tmp_path),
                          "--duration", "60"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         start_new_session=True, env=script_env())
    try:
        deadline = time.monotonic() + 120
        seen = ""
        while time.monotonic() < deadline and "graph matched" not in seen:
            line = p.stdout.readline()
            if not line:
                break
            seen += line
        assert "graph matched" in seen, seen[-2000:]
        while time.monotonic() < deadline and " s simulated" not in seen.split("graph matched", 1)[1]:
            line = p.stdout.readline()   # the plant's progress: the run is under way, states are being recorded
            if not line:
                break
            seen += line
        assert " s simulated" in seen.split("graph matched", 1)[1], seen[-2000:]
        # bash, tail, plant, observer, controller, recorder
        assert wait_until(lambda: len(_session_pids(p.pid)) >= 5, 30), _session_pids(p.pid)
        os.killpg(p.pid, signal.SIGINT)  # what a terminal does on Ctrl-C
        rest, _ = p.communicate(timeout=120)
        assert p.returncode == 130 and "interrupted" in rest, rest[-3000:]
        assert wait_until(lambda: _session_pids(p.pid) == [], 5), _session_pids(p.pid)
        # the recorder closed its bag properly on SIGINT: readable without repair
        bag = next(b for b in tmp_path.iterdir() if b.name.endswith("_dsc"))
        assert (bag / "metadata.yaml").exists() and _anyreader_counts(bag)["/joint_states"] > 0
        # the report of the runs so far is written (docs/getting-started.md): the interrupted dsc run, up to where
        # it stopped; the dscndo run was never started
        assert not any(b.name.endswith("_dscndo") for b in tmp_path.iterdir())
        report = next(p for p in tmp_path.iterdir() if p.name.endswith("_report"))
        runs = json.loads((report / "metrics.json").read_text())["runs"]
        assert list(runs) == ["dsc"] and (report / "fig3.png").stat().st_size > 0
        assert "report: " in rest and "metrics.md" in rest and "the report covers dsc (exit 130)" in rest
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(10)


@pytest.mark.graph
def test_bag_cut_by_kill_9_mid_run_is_repaired(tmp_path):
    bag = tmp_path / "cut"
    with Graph(tmp_path) as g:
        rec = g.start("mcap_recorder", "-p", f"output:={bag}", "-p", "chunk_size:=16384", "-p", "use_sim_time:=true")
        g.start("disturbance_observer", "-p", "use_sim_time:=true")
        g.start("dscndo_controller", "-p", "use_sim_time:=true")
        plant = g.start("plant_sim", "-p", "expected_subscribers:=3", "-p", "duration_s:=0.0")
        assert plant.wait_for_output("graph matched", 60)
        # kill it once 8 chunks of 16 KiB are on disk (about 200 states of the loop's topics uncompressed)
        assert wait_until(lambda: sum(f.stat().st_size for f in bag.glob("*.mcap")) >= 8 * 16384, 60), rec.output()
        os.kill(rec.pid, signal.SIGKILL)
        rec.popen.wait(10)
    subprocess.run(["fastdds", "shm", "clean"], capture_output=True, timeout=60, env=ros_env(0))
    assert not (bag / "metadata.yaml").exists()  # the recorder never got to close the bag
    r = subprocess.run(["python", "-m", "mwip_ros.cli.bag_repair", str(bag)], capture_output=True, text=True,
                       timeout=120, env=ros_env(0))
    assert r.returncode == 0, r.stdout + r.stderr
    counts = _anyreader_counts(bag)
    assert counts["/joint_states"] > 100
    total = sum(counts.values())
    assert str(total) in r.stdout  # it reports how many messages it saved


@pytest.mark.e2e
def test_a_sweep_row_runs_through_the_ros_graph_with_the_same_metrics(tmp_path):
    """mwip_sweep --write-params, then scripts/run_experiment.sh --params: the nodes in lockstep give the row's
    metrics, for both laws of that scenario."""
    import sys
    spec = tmp_path / "spec.yaml"
    spec.write_text(yaml.safe_dump({
        "base": str(REPO / "config" / "paper.yaml"), "controllers": ["dsc", "dscndo"], "duration_s": 10.0,
        "metrics_window_s": [5.0, 10.0], "seed": 11, "samples": 2,
        "vary": {"plant_sim.actual.m_b": {"scale": [0.7, 1.3]}, "dscndo_controller.k1": {"grid": [4.0, 8.0]}}}))
    sweep = [sys.executable, "-m", "mwip_ros.cli.sweep"]
    r = subprocess.run([*sweep, str(spec), "--out", str(tmp_path / "sweep"), "--workers", "1", "--no-figures"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    params = tmp_path / "s3.yaml"
    r = subprocess.run([*sweep, "--results", str(tmp_path / "sweep"), "--scenario", "3", "--write-params",
                        str(params)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    r = subprocess.run(["bash", str(REPO / "scripts" / "run_experiment.sh"), "--params", str(params), "--no-record",
                        "--out", str(tmp_path / "graph")], capture_output=True, text=True, timeout=600,
                       env=script_env())
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    report = next((tmp_path / "graph").glob("*_report"))
    graph = json.loads((report / "metrics.json").read_text())["runs"]
    from mwip_ros.sweep.results import METRICS, read_results
    cols = read_results(tmp_path / "sweep" / "results.csv")
    for law in ("dsc", "dscndo"):
        j = [k for k, (s, c) in enumerate(zip(cols["scenario"], cols["controller"])) if s == 3 and c == law][0]
        assert graph[law]["upright"] == cols["upright"][j]
        for name, ours in METRICS.items():
            assert abs(graph[law][ours] - cols[name][j]) <= 1e-9, (law, name, graph[law][ours], cols[name][j])


RUN_EXPERIMENT = ["bash", str(REPO / "scripts" / "run_experiment.sh")]


def _first_line_domain(stdout: str) -> int:
    import re
    first = stdout.splitlines()[0]
    m = re.fullmatch(r"run_experiment: ROS_DOMAIN_ID=(\d+) \(.*\)", first)
    assert m, f"the domain is not the first line: {first!r}"
    return int(m.group(1))


@pytest.mark.e2e
@pytest.mark.parametrize("args, names", [
    (["--params"], "--params"),
    (["--params", "--duration", "1"], "--params"),
    (["--mode"], "--mode"),
    (["--duration", "-1"], "--duration"),
    (["--laws", "dsc,pid"], "--laws"),
    (["--name", "a/b"], "--name"),
    (["--sensors", "imu"], "--sensors"),
    (["--params", "no_such_file.yaml"], "no_such_file.yaml"),
])
def test_command_line_mistakes_are_one_line_and_exit_2_before_anything_starts(tmp_path, args, names):
    r = subprocess.run([*RUN_EXPERIMENT, *args, "--out", str(tmp_path / "out")], capture_output=True, text=True,
                       timeout=120, env=script_env())
    assert r.returncode == 2, r.stdout + r.stderr
    assert names in r.stderr and "unbound variable" not in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.e2e
def test_a_mistyped_parameter_stops_the_job_before_any_node_or_folder(tmp_path):
    bad = tmp_path / "typo.yaml"
    bad.write_text((REPO / "config" / "paper.yaml").read_text().replace("    k1: ", "    kk1: ", 1))
    r = subprocess.run([*RUN_EXPERIMENT, "--params", str(bad), "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=300, env=script_env())
    assert r.returncode == 2, r.stdout + r.stderr
    assert "dscndo_controller.kk1" in r.stderr and "did you mean 'k1'" in r.stderr
    assert "Theorem 2" not in r.stderr and "===" not in r.stdout   # no wrong warning, no run started
    assert not (tmp_path / "out").exists()


@pytest.mark.e2e
def test_two_experiments_started_together_never_collide(tmp_path):
    """Same output folder, same name (as two runs started in the same second get): each gets its own
    domain, logs folder and bag, and each bag is the whole run."""
    out = tmp_path / "out"
    cmd = [*RUN_EXPERIMENT, "--out", str(out), "--name", "same", "--duration", "1", "--laws", "dscndo"]
    ps = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=script_env())
          for _ in range(2)]
    try:
        res = [p.communicate(timeout=300) for p in ps]
    finally:
        for p in ps:
            if p.poll() is None:
                p.kill()
                p.wait(10)
    for p, (so, se) in zip(ps, res):
        assert p.returncode == 0, so[-3000:] + se[-3000:]
        assert so.count("metrics t in [") == 1, so   # the plant's progress and metrics, shown live
    domains = [_first_line_domain(so) for so, _ in res]
    assert len(set(domains)) == 2 and all(1 <= d <= 101 for d in domains), domains
    assert sorted(p.name for p in out.iterdir()) == sorted(
        f"{n}_{kind}" for n in ("same", "same-2") for kind in ("dscndo", "logs", "report"))
    for n in ("same", "same-2"):
        assert distinct_stamps(out / f"{n}_dscndo", ("/joint_states",)) == {"/joint_states": 201}
        est = (out / f"{n}_logs" / "dscndo_estimates.csv").read_text().splitlines()
        assert len(est) == 1 + 201, (n, len(est))   # header + one estimate per state: no interleaving
        for log in (out / f"{n}_logs").glob("*.log"):
            assert "[ERROR]" not in log.read_text(), log


@pytest.mark.e2e
@pytest.mark.alone   # the domain it frees for the script must not be taken by another test meanwhile
def test_the_users_domain_is_kept_and_a_domain_in_use_is_refused(tmp_path):
    from graphproc import fresh_domain_id, release_domain_id
    free = fresh_domain_id()
    release_domain_id(free)
    r = subprocess.run([*RUN_EXPERIMENT, "--out", str(tmp_path / "a"), "--duration", "0.2", "--laws", "dsc",
                        "--no-record"], capture_output=True, text=True, timeout=300,
                       env=script_env(ROS_DOMAIN_ID=str(free)))
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert _first_line_domain(r.stdout) == free and "(yours" in r.stdout.splitlines()[0]
    held = fresh_domain_id()   # this test session holds it now, as a running experiment would
    try:
        r = subprocess.run([*RUN_EXPERIMENT, "--out", str(tmp_path / "b"), "--duration", "0.2", "--laws", "dsc"],
                           capture_output=True, text=True, timeout=300, env=script_env(ROS_DOMAIN_ID=str(held)))
    finally:
        release_domain_id(held)
    assert r.returncode == 2 and f"ROS_DOMAIN_ID={held} is in use" in r.stderr, r.stdout + r.stderr
    assert not (tmp_path / "b").exists()


@pytest.mark.e2e
def test_a_fall_ends_the_job_with_exit_3_after_every_run_and_the_report(tmp_path):
    weak = tmp_path / "weak_drive.yaml"
    weak.write_text("plant_sim:\n  ros__parameters:\n    torque_limit: 1.0\n")
    r = subprocess.run([*RUN_EXPERIMENT, "--params", str(REPO / "config" / "paper.yaml"), str(weak),
                        "--out", "out", "--duration", "2", "--laws", "dsc,dscndo", "--no-record"],
                       capture_output=True, text=True, timeout=300, env=script_env(), cwd=tmp_path)
    assert r.returncode == 3, r.stdout[-3000:] + r.stderr[-3000:]
    assert r.stdout.count("FALLEN at t = ") == 2   # both runs ran, and each fall was shown live
    assert "the robot fell in: dsc dscndo (exit 3)" in r.stderr and r.stderr.count("the robot fell in") == 1
    # said once per fall: the first run's line says the job goes on; the last run's fall is in the closing line only
    assert "FELL in the dsc run; the next run and the report go on" in r.stderr and "dscndo run" not in r.stderr
    report = next((tmp_path / "out").glob("*_report"))   # --out relative to where the command ran
    assert (report / "metrics.md").is_file()
    # the paths printed are the user's, relative to where the command ran (not to the repository); the figures named
    # are those written
    assert f"report: out/{report.name}/metrics.md (figures fig3.png, observer.png, animation.gif)" in r.stdout
    assert "logs:   out/" in r.stdout


@pytest.mark.e2e
def test_raw_sensors_run_the_state_estimator_in_the_loop_and_record_its_topics(tmp_path):
    """--sensors raw: the realistic IMU and encoder overlay, a state_estimator started beside the observer; the
    bag holds the raw samples, the estimator's joint_states and the true state, every one of the 401 stamps."""
    r = subprocess.run([*RUN_EXPERIMENT, "--sensors", "raw", "--laws", "dscndo", "--duration", "2",
                        "--out", str(tmp_path), "--name", "raw"], capture_output=True, text=True, timeout=600,
                       env=script_env())
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    logs = tmp_path / "raw_logs"
    est = (logs / "dscndo_state_estimator.log").read_text()
    assert "Kalman filter state estimator ready" in est and "estimated 401 samples" in est, est
    assert "publishing imu/data_raw and wheel_encoder" in (logs / "dscndo_plant_sim.log").read_text()
    topics = ("/imu/data_raw", "/wheel_encoder", "/joint_states", "/true_joint_states", "/disturbance_estimate")
    assert distinct_stamps(tmp_path / "raw_dscndo", topics) == {t: 401 for t in topics}
    m = json.loads((tmp_path / "raw_report" / "metrics.json").read_text())["runs"]
    assert m["dscndo"]["upright"]
    # the report judges the estimator from the bag: its joint_states against true_joint_states
    assert 0 < m["dscndo"]["theta_b_est_err_rms"] < 0.01 and 0 < m["dscndo"]["dtheta_b_est_err_rms"] < 0.05
    assert (tmp_path / "raw_report" / "pitch_estimate.png").stat().st_size > 10_000
    assert "(figures fig3.png, observer.png, pitch_estimate.png, animation.gif)" in r.stdout   # named where one looks


def _controller_ready(logs: Path, ctrl: str) -> str:
    """The controller's start-up message in a run's log ('<law title> ready: ...'), without the log prefix."""
    text = (logs / f"{ctrl}_dscndo_controller.log").read_text()
    return next((line.split("[dscndo_controller]: ", 1)[-1] for line in text.splitlines() if " ready: " in line),
                text[-2000:])


@pytest.mark.e2e
def test_raw_sensors_keep_the_estimator_the_users_file_chooses(tmp_path):
    """--sensors raw puts its overlay before the user's files: their state_estimator method: complementary is the
    estimator that runs (it was replaced by the overlay's kalman)."""
    mine = tmp_path / "complementary.yaml"
    mine.write_text("state_estimator:\n  ros__parameters:\n    method: complementary\n")
    r = subprocess.run([*RUN_EXPERIMENT, "--params", str(REPO / "config" / "paper.yaml"), str(mine),
                        "--sensors", "raw", "--laws", "dscndo", "--duration", "0.5", "--no-record",
                        "--out", str(tmp_path / "out"), "--name", "c"], capture_output=True, text=True, timeout=600,
                       env=script_env())
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    est = (tmp_path / "out" / "c_logs" / "dscndo_state_estimator.log").read_text()
    assert "complementary filter state estimator ready" in est and "Kalman" not in est, est


@pytest.mark.e2e
def test_the_files_law_runs_without_and_with_the_observer_when_laws_is_not_given(tmp_path):
    """A user's file with law: smc runs SMC and SMC+NDO (the script's -p law:=dsc replaced it); a duration in
    scientific notation is taken as mwip_sim takes it."""
    from mwip_ros.core import laws
    mine = tmp_path / "smc.yaml"
    mine.write_text("dscndo_controller:\n  ros__parameters:\n    law: smc\n")
    r = subprocess.run([*RUN_EXPERIMENT, "--params", str(REPO / "config" / "paper.yaml"), str(mine),
                        "--duration", "5e-1", "--no-record", "--out", str(tmp_path / "out"), "--name", "s"],
                       capture_output=True, text=True, timeout=600, env=script_env())
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    logs = tmp_path / "out" / "s_logs"
    for ctrl in ("smc", "smc_ndo"):
        assert _controller_ready(logs, ctrl).startswith(f"{laws.get(ctrl).title} ready: "), ctrl
    runs = json.loads((tmp_path / "out" / "s_report" / "metrics.json").read_text())["runs"]
    assert list(runs) == ["smc", "smc_ndo"] and all(m["upright"] for m in runs.values())
    assert "the parameter files' law 'smc'" in r.stderr   # said, not silent
    assert (logs / "smc.csv").read_text().count("\n") == 1 + 101   # 0.5 s at 200 Hz: 101 states


@pytest.mark.e2e
def test_laws_mpc_runs_through_the_script_and_says_what_it_replaces(tmp_path):
    from mwip_ros.core import laws
    mine = tmp_path / "smc.yaml"
    mine.write_text("dscndo_controller:\n  ros__parameters:\n    law: smc\n")
    r = subprocess.run([*RUN_EXPERIMENT, "--params", str(REPO / "config" / "paper.yaml"), str(mine),
                        "--laws", "mpc", "--duration", "0.5", "--no-record", "--out", str(tmp_path / "out"),
                        "--name", "m"], capture_output=True, text=True, timeout=600, env=script_env())
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    ready = _controller_ready(tmp_path / "out" / "m_logs", "mpc")
    assert ready.startswith(f"{laws.get('mpc').title} ready: "), ready
    assert "--laws mpc runs in place of the parameter files' law 'smc'" in r.stderr
    runs = json.loads((tmp_path / "out" / "m_report" / "metrics.json").read_text())["runs"]
    assert list(runs) == ["mpc"] and runs["mpc"]["upright"]


@pytest.mark.e2e
@pytest.mark.parametrize("duration", ["0", "0.0", "inf", "nan", "1e8", "ten"])
def test_a_duration_mwip_sim_refuses_is_refused_in_one_line(tmp_path, duration):
    r = subprocess.run([*RUN_EXPERIMENT, "--duration", duration, "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=120, env=script_env())
    assert r.returncode == 2, r.stdout + r.stderr
    err = [line for line in r.stderr.splitlines() if line.startswith("run_experiment: --duration")]
    assert len(err) == 1 and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.e2e
def test_a_files_duration_0_until_stopped_is_refused_not_run_forever(tmp_path):
    forever = tmp_path / "forever.yaml"
    forever.write_text("plant_sim:\n  ros__parameters:\n    duration_s: 0.0\n")
    r = subprocess.run([*RUN_EXPERIMENT, "--params", str(REPO / "config" / "paper.yaml"), str(forever),
                        "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=120, env=script_env())
    assert r.returncode == 2 and "plant_sim.duration_s is 0" in r.stderr and "give --duration" in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.e2e
def test_robot_state_records_odom_and_the_report_states_its_drift(tmp_path):
    """--robot-state: robot_state beside the loop (counted by the plant); the bag holds odom and the wheel joint
    states for every one of the 401 stamps, the URDF once, and the report states odom's drift from the truth
    (the plant's ideal state, trapezoid rule: micrometres after 2 s; docs/theory.md 6.11)."""
    r = subprocess.run([*RUN_EXPERIMENT, "--robot-state", "--laws", "dscndo", "--duration", "2",
                        "--out", str(tmp_path), "--name", "rs"], capture_output=True, text=True, timeout=600,
                       env=script_env())
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    log = (tmp_path / "rs_logs" / "dscndo_robot_state.log").read_text()
    assert "trapezoid rule" in log and "integrated 401 states" in log, log
    topics = ("/odom", "/wheel_joint_states", "/joint_states")
    assert distinct_stamps(tmp_path / "rs_dscndo", topics) == {t: 401 for t in topics}
    note = json.loads((tmp_path / "rs_report" / "metrics.json").read_text())["notes"]["dscndo"][-1]
    assert note.startswith("odom drifts ") and " over 2.000 s " in note, note
    assert float(note.split()[2]) < 1e-5, note
