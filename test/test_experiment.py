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
from graphproc import REPO, Graph, ros_env

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


def test_main_job_records_two_bags_and_writes_the_report(tmp_path):
    r = subprocess.run(["bash", str(REPO / "scripts" / "run_experiment.sh"), "--out", str(tmp_path)],
                       capture_output=True, text=True, timeout=600, env=dict(os.environ))
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


def test_ctrl_c_stops_every_process(tmp_path):
    p = subprocess.Popen(["bash", str(REPO / "scripts" / "run_experiment.sh"), "--out", str(tmp_path),
                          "--duration", "60"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         start_new_session=True, env=dict(os.environ))
    try:
        deadline = time.monotonic() + 120
        seen = ""
        while time.monotonic() < deadline and "graph matched" not in seen:
            line = p.stdout.readline()
            if not line:
                break
            seen += line
        assert "graph matched" in seen, seen[-2000:]
        time.sleep(1.0)
        assert len(_session_pids(p.pid)) >= 5  # bash, tail, plant, observer, controller, recorder
        os.killpg(p.pid, signal.SIGINT)  # what a terminal does on Ctrl-C
        rest, _ = p.communicate(timeout=60)
        assert p.returncode != 0 and "interrupted" in rest
        time.sleep(0.5)
        assert _session_pids(p.pid) == []
        # the recorder closed its bag properly on SIGINT: readable without repair
        bag = next(b for b in tmp_path.iterdir() if b.name.endswith("_dsc"))
        assert (bag / "metadata.yaml").exists() and _anyreader_counts(bag)["/joint_states"] > 0
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(10)


def test_bag_cut_by_kill_9_mid_run_is_repaired(tmp_path):
    bag = tmp_path / "cut"
    with Graph(tmp_path) as g:
        rec = g.start("mcap_recorder", "-p", f"output:={bag}", "-p", "chunk_size:=16384", "-p", "use_sim_time:=true")
        g.start("disturbance_observer", "-p", "use_sim_time:=true")
        g.start("dscndo_controller", "-p", "use_sim_time:=true")
        plant = g.start("plant_sim", "-p", "expected_subscribers:=3", "-p", "duration_s:=0.0")
        assert plant.wait_for_output("graph matched", 60)
        time.sleep(2.0)
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
                       env=dict(os.environ))
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
