#!/usr/bin/env python3
"""Benchmarks (numbers, not pass/fail): offline simulator speed and lockstep graph speed per executor.

    source scripts/env.sh && python scripts/benchmark.py [--repeat N]

Prints steps/s of ``mwip_sim``'s closed loop (10 s scenario, 2001 steps) and of the three-process
lockstep graph with rclpy's EventsExecutor (the default) and SingleThreadedExecutor.
"""
from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "test"))


def offline(repeat: int) -> list:
    from mwip_ros import params as P, sim
    values = sim.merged_values(P.load_param_file(REPO / "config" / "paper.yaml"))
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = sim.simulate(values)
        out.append(len(r) / (time.perf_counter() - t0))
    return out


def graph(executor: str, repeat: int) -> list:
    from graphproc import run_lockstep
    os.environ["MWIP_EXECUTOR"] = executor
    out = []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as d:
            code, _csv, logs = run_lockstep(Path(d), True)
            text = logs["plant_sim"].output()
            if code != 0:
                raise SystemExit(f"lockstep run failed ({executor}):\n{text}")
            out.append(float(re.search(r"\((\d+) steps/s\)", text).group(1)))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    def show(name, xs):
        print(f"{name:<42} median {statistics.median(xs):8.0f} steps/s   (runs: {', '.join(f'{x:.0f}' for x in xs)})")

    show("offline simulator (mwip_sim, DSCNDO)", offline(args.repeat))
    for ex in ("events", "single"):
        show(f"lockstep graph, 3 processes, {ex} executor", graph(ex, args.repeat))
    print("real time needs 200 steps/s (h = 5 ms)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
