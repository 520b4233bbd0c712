"""scripts/bench.sh --quick runs and prints every row (numbers are not judged here: BENCHMARKS.md)."""
import os
import re
import subprocess

import pytest

from graphproc import REPO, script_env

pytestmark = pytest.mark.bench

ROWS = [
    r"1\. DDS floor: Float64 ping-pong, 2 processes, serialized .* \| [\d,]+ round trips/s "
    r"\(RTT p50 \d+ us, p99 \d+ us\)",
    r"1\. the same with rclpy message objects \(typed\) \| [\d,]+ round trips/s",
    r"2\. lockstep graph, 4 processes \(with recorder\) \| [\d,]+ steps/s \(201 steps in [\d.]+ s wall\)",
    r"2\. lockstep graph with foxglove_server \(a client connected\) \| [\d,]+ steps/s",
    r"2\. lockstep rate / DDS floor \| [\d.]+ steps per round trip",
    *[rf"3\. realtime {hz} Hz, 2 s, 4 processes, {sched}[^|]*: loop period p50 / p99 / max "
      r"\| [\d.]+ / [\d.]+ / [\d.]+ ms"
      for hz in (200, 1000) for sched in ("normal scheduling", "SCHED_FIFO 50")],
    *[rf"3\. realtime {hz} Hz, {sched}[^|]*: missed deadlines / stale-command substitutions \| \d+ / \d+ of \d+ "
      "periods" for hz in (200, 1000) for sched in ("normal scheduling", "SCHED_FIFO 50")],
    *[rf"3\. for comparison: a bare Python loop sleeping to {h} ms deadlines .* \| [\d.]+ ms / \d+ of \d+"
      for h in (5, 1)],
    r"4\. offline simulator \(mwip_sim loop, DSCNDO, 10 s\) \| [\d,]+ steps/s",
    *[rf"4\. batch simulator, N = {n} scenarios \(own seeds\), [\d.]+ s, one process \| [\d,]+ scenario-steps/s "
      r"\([\d.]+ x the scalar loop\); peak memory \d+ MiB" for n in ("1", "100", "1,000")],
    r"4\. mwip_sweep engine: mass mismatch .* one process \| [\d,]+ scenario-steps/s \([\d.]+ x the scalar loop\)",
    *([r"4\. mwip_sweep engine: mass mismatch .* worker processes \(all cores\), their start-up included \| "
        r"[\d,]+ scenario-steps/s",
       r"4\. mwip_sweep engine: mass mismatch .* worker processes \(all cores\), already started .* \| "
       r"[\d,]+ scenario-steps/s"]
      if (os.cpu_count() or 1) > 1 else []),
    r"4\. mwip_sweep mass_mismatch_quick\.yaml from the command line, every core: 80 runs, 16,000 scenario-steps \| "
    r"[\d,]+ scenario-steps/s as the command reports it \([\d.]+ x the scalar loop\); [\d.]+ s wall",
] + [rf"5\. peak resident memory: {n} \| [\d.]+ MiB" for n in
     ("plant_sim", "disturbance_observer", "dscndo_controller", "mcap_recorder")]


def test_bench_quick_prints_every_row(tmp_path):
    md = tmp_path / "bench.md"
    r = subprocess.run(["bash", str(REPO / "scripts" / "bench.sh"), "--quick", "--markdown", str(md)],
                       env=script_env(), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    for row in ROWS:
        assert re.search(row, r.stdout), f"missing row /{row}/ in:\n{r.stdout}"
    assert re.search(r"- cpu: .+\n- cores: \d+", r.stdout)
    assert md.read_text() == r.stdout
    # the realtime rows come from 2 s runs of 400 and 2000 periods (+1: the first state), counted as the periods due
    # at the run's last wake (a late last wake finds a few more due; the loop's wakes are fewer when wakes are late)
    due = [int(x) for x in re.findall(r"of (\d+) periods", r.stdout)]
    assert len(due) == 5, due   # 200 Hz twice, 1 kHz twice, then MPC+NDO at 200 Hz beside DSCNDO
    assert all(401 <= t <= 405 for t in due[:2] + due[4:]) and all(2001 <= t <= 2010 for t in due[2:4]), due
    # MPC+NDO beside DSCNDO: one run of each in the quick bench, their missed deadlines side by side
    assert re.search(r"realtime 200 Hz, .*law mpc \(\+NDO\) beside DSCNDO, 1 run\(s\) each, alternating: missed "
                     r"deadlines.* \| (\d+) \(\1; \1\) against DSCNDO's (\d+) \(\2; \2\); \d+ stale of \d+ periods",
                     r.stdout), r.stdout
    assert r.stderr.count("law dsc (run 1 of 1)") == 1 and r.stderr.count("law mpc (run 1 of 1)") == 1, r.stderr
    assert "bench: lockstep run 1/1" in r.stderr  # progress goes to stderr


def test_bench_help_and_bad_arguments():
    r = subprocess.run(["bash", str(REPO / "scripts" / "bench.sh"), "--help"], capture_output=True, text=True,
                       timeout=120, env=script_env())
    assert r.returncode == 0 and "--quick" in r.stdout and "DDS floor" in r.stdout
    r = subprocess.run(["bash", str(REPO / "scripts" / "bench.sh"), "--repeat", "0"], capture_output=True,
                       text=True, timeout=300, env=script_env())
    assert r.returncode == 2 and "--repeat must be at least 1" in r.stderr


def test_the_soak_script_runs_the_realtime_graph_and_reports_every_nodes_memory(tmp_path):
    """scripts/soak_graph.py, briefly (its 15-minute figures are in BENCHMARKS.md): every node's RSS at the start,
    after the warm-up and at the end, and a slope; the recorder split its bag by duration and the bag reads as one
    run.  The slope of 30 s is not judged here (it still holds the warm-up's tail and the machine's load); the
    bounded buffers are checked by size, not by time: test/nodes/test_plant_runners.py,
    test/core/closed_loop/test_trajectory.py, test/bag/test_ledger.py, test/bag/test_writer.py."""
    import json
    import sys
    out = tmp_path / "soak.json"
    r = subprocess.run([sys.executable, str(REPO / "scripts" / "soak_graph.py"), "--duration", "30", "--warmup", "10",
                        "--every", "3", "--max-bagfile-duration", "8", "--workdir", str(tmp_path / "work"), "--json",
                        str(out)], env=script_env(), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr[-3000:]
    got = json.loads(out.read_text())
    assert set(got["nodes"]) == {"plant_sim", "disturbance_observer", "dscndo_controller", "mcap_recorder",
                                 "foxglove_server"}
    for name, n in got["nodes"].items():
        assert all(n[k] > 10 for k in ("rss_start_mib", "rss_warm_mib", "rss_end_mib")), (name, n)
        assert n["samples"] >= 5 and abs(n["slope_mb_per_h"]) < 1e4, (name, n)
        assert re.search(rf"\| {name} \| [\d.]+ \| [\d.]+ \| [\d.]+ \| [+-][\d.]+ \|", r.stdout), r.stdout
    bag = got["bag"]
    assert bag["files"] >= 3, bag   # 30 s and more, split every 8 s
    assert got["periods"] > 0.5 * 30 * 200, got   # the plant ran on (it is stopped after the last sample)
    assert bag["read_as_one_run"] >= 0.9 * got["periods"], (bag, got["periods"])
    assert len(list((tmp_path / "work" / "bag").glob("bag_*.mcap"))) == bag["files"]
    assert (tmp_path / "work" / "plant.csv").stat().st_size > 0
