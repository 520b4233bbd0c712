#!/usr/bin/env python3
"""Does the realtime loop keep the wall clock's schedule under load?  (BENCHMARKS.md, "The realtime loop keeps the
clock's schedule"; docs/graph.md, "Modes".)

    python scripts/bench_realtime.py [--seconds 60] [--busy 2] [--before DIR] [--keep-going]

The realtime graph (plant_sim, disturbance_observer, dscndo_controller, mcap_recorder: four processes, as
scripts/bench.py runs it; DSCNDO at 200 Hz, config/paper.yaml) runs ``--seconds`` of simulated time with ``--busy``
processes spinning beside it (``while True: pass``, normal scheduling); ``--keep-going``: ``exit_on_fall: false``, so a
robot the load starves of commands falls, lies there, and the run still lasts ``--seconds``.  For each run:

* the plant's periods per second of wall time (its summary: periods / ``wall_s``, from its first state to its end),
  against the rate;
* how far the stamps are behind the wall clock at the end: the recorder's receive time (wall clock) of the last
  ``joint_states`` minus its stamp, and the same for the median message (the recorder's own delay);
* the plant's timing report (``realtime`` in its summary: missed deadlines, wake latency, period between wakes).

``--before DIR``: a checkout to compare with (``mkdir DIR && git archive main | tar -x -C DIR``), run first, its
processes importing ``mwip_ros`` from DIR (PYTHONPATH).  The table goes to stdout (markdown), progress to stderr.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "test"))
sys.path.insert(0, str(REPO / "scripts"))
from bench import machine, progress, run_graph  # noqa: E402

from mwip_ros.bag.reader import raw_messages  # noqa: E402
from mwip_ros.msgs.cdr import decode_joint_state  # noqa: E402

BUSY = "while True: pass"


def lag_ms(bag: Path) -> dict:
    """joint_states in the bag: (receive time - stamp) of the last message and the median one [ms], and the count."""
    lags = [(t - decode_joint_state(data)[0]) * 1e-6 for t, _topic, data in raw_messages(bag, ["/joint_states"])]
    if not lags:
        raise SystemExit(f"bench_realtime: no joint_states in {bag}")
    return {"last": lags[-1], "median": statistics.median(lags), "messages": len(lags)}


def one_run(work: Path, seconds: float, busy: int, tree: Optional[Path], keep_going: bool = False) -> dict:
    """The realtime graph for ``seconds`` beside ``busy`` spinning processes (stopped by PID after it);
    ``keep_going``: ``exit_on_fall: false`` (a robot the load starves of commands falls and lies there; the loop's
    schedule is still measured over the whole run)."""
    saved = os.environ.get("PYTHONPATH")
    spinners = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(busy)]
    try:
        if tree is not None:
            os.environ["PYTHONPATH"] = str(tree)   # the graph's processes inherit it (graphproc.ros_env)
        r = run_graph(work, f"realtime {seconds:g} s", ["-p", "mode:=realtime", "-p", f"duration_s:={seconds}",
                                                        *(["-p", "exit_on_fall:=false"] if keep_going else [])],
                      [], timeout=seconds + 180)
    finally:
        for p in spinners:
            p.kill()
            p.wait(10)
        if tree is not None:
            if saved is None:
                os.environ.pop("PYTHONPATH", None)
            else:
                os.environ["PYTHONPATH"] = saved
    r["lag_ms"] = lag_ms(work / "bag")
    return r


def row(name: str, r: dict) -> str:
    rt = r.get("realtime", {})
    rate = r["control_rate_hz"]
    per_s = r["periods"] / r["wall_s"]
    lat = (f"{rt['latency_ms_p50']:.3f} / {rt['latency_ms_p99']:.3f} / {rt['latency_ms_max']:.1f}"
           if "latency_ms_p99" in rt else "(not measured)")
    fell = f" (fell at {r['metrics']['t_fall']:.2f} s)" if r.get("fallen") and r.get("metrics", {}).get("t_fall") \
        else (" (fell)" if r.get("fallen") else "")
    return (f"| {name}{fell} | {r['periods']} in {r['wall_s']:.3f} s: {per_s:.2f} /s "
            f"({(per_s / rate - 1) * 100:+.2f} %) | "
            f"{r['lag_ms']['last']:.1f} (median {r['lag_ms']['median']:.1f}) | {rt.get('missed_deadlines', '')} | "
            f"{lat} | {rt.get('period_ms_p99', float('nan')):.3f} / {rt.get('period_ms_max', float('nan')):.1f} | "
            f"{rt.get('stale_command_substitutions', '')} |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="simulated (= wall) seconds per run (default 60)")
    ap.add_argument("--busy", type=int, default=2, help="spinning processes beside the graph (default 2)")
    ap.add_argument("--before", type=Path, default=None, help="a checkout to compare with, run first")
    ap.add_argument("--keep-going", action="store_true",
                    help="exit_on_fall: false: a robot the load makes fall lies there and the run goes on")
    args = ap.parse_args()
    if args.before is not None and not (args.before / "mwip_ros" / "__init__.py").exists():
        ap.error(f"--before {args.before}: no mwip_ros package there")
    m = machine()
    runs = []
    with tempfile.TemporaryDirectory(prefix="mwip_bench_rt_") as tmp:
        for name, tree in ((("before", args.before.resolve()),) if args.before else ()) + (("this checkout", None),):
            progress(f"{name}: realtime 200 Hz for {args.seconds:g} s beside {args.busy} busy processes ...")
            r = one_run(Path(tmp) / name.replace(" ", "_"), args.seconds, args.busy, tree, args.keep_going)
            progress(f"{name}: {r['periods']} periods in {r['wall_s']:.2f} s wall; last stamp "
                     f"{r['lag_ms']['last']:.1f} ms behind its receipt")
            runs.append((name, r))
    print(f"Machine: {m['cpu']}, {m['cores']} cores, {m['rclpy']}, {m['rmw']}; load average at the start "
          f"{m['load average at start']} (1, 5, 15 min), at the end {' '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"beside the graph {args.busy} processes spinning\n")
    print("| code | periods in wall time (rate vs 200 /s) | last joint_states: receipt - stamp [ms] | missed "
          "deadlines | wake latency p50 / p99 / max [ms] | period between wakes p99 / max [ms] | stale commands |")
    print("|---|---|---|---|---|---|---|")
    for name, r in runs:
        print(row(name, r))
    print("\n" + json.dumps({name: {k: r[k] for k in ("periods", "wall_s", "lag_ms", "realtime") if k in r}
                             for name, r in runs}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
