#!/usr/bin/env python3
"""The MuJoCo plant's speed beside the rk4 plant's, every figure measured in this one invocation (BENCHMARKS.md,
"The lockstep graph with the MuJoCo plant").

    python scripts/bench_mujoco.py [--pairs N] [--seconds S]

1. The lockstep graph (plant_sim, disturbance_observer, dscndo_controller, mcap_recorder: four processes, as
   scripts/bench.py runs it), the paper's scenario (DSCNDO), with ``backend: rk4`` and ``backend: mujoco`` taking
   turns ``--pairs`` times: steps/s each and their ratio per pair (both see the same load).
2. ``mwip_sim``'s loop (in process, 10 s of DSCNDO), the two backends taking turns: periods/s and the ratio.
3. Where a period's time goes, in process: one plant period (``Plant.step``) of each backend, MuJoCo's own
   ``mj_step`` (times the steps per period) and ``mj_forward`` (the true tau_d's accelerations), against the
   lockstep graph's wall time per step.

The table goes to stdout (markdown); progress to stderr.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench import PARAMS, machine, progress, run_graph  # noqa: E402


VARIANTS = {"rk4": ["-p", "backend:=rk4"], "mujoco": ["-p", "backend:=mujoco"],
            "mujoco_5ms": ["-p", "backend:=mujoco", "-p", "mujoco.timestep:=0.005"]}


def graph_pairs(pairs: int, seconds: float, work: Path):
    """steps/s of each variant's lockstep graph, the variants taking turns."""
    out = {v: [] for v in VARIANTS}
    for i in range(pairs):
        for v, args in VARIANTS.items():
            r = run_graph(work / f"{v}{i}", f"lockstep {v}",
                          ["-p", "mode:=lockstep", "-p", f"duration_s:={seconds}", *args], [],
                          timeout=600, recorder_args=["-p", "use_sim_time:=true"])
            out[v].append(r["steps_per_s"])
            progress(f"lockstep {v} {i + 1}/{pairs}: {r['periods']} steps, {r['steps_per_s']:.0f} steps/s")
    return out


def offline(pairs: int):
    from mwip_ros import params as P
    from mwip_ros.core.sim import simulate
    values = P.merged_values(P.load_param_file(PARAMS))
    loops = {b: P.closed_loop(dict(values, backend=b), use_observer=True, duration=10.0) for b in ("rk4", "mujoco")}
    out = {"rk4": [], "mujoco": []}
    for _ in range(pairs):
        for b, loop in loops.items():
            t0 = time.perf_counter()
            r = simulate(loop)
            out[b].append(len(r) / (time.perf_counter() - t0))
    progress(f"mwip_sim: rk4 {statistics.median(out['rk4']):.0f}, mujoco {statistics.median(out['mujoco']):.0f} "
             f"periods/s")
    return out


def per_period(n: int = 2000):
    """us per plant period (rk4, mujoco), per period of mj_step alone, per mj_forward."""
    import mujoco

    from mwip_ros import params as P
    from mwip_ros.core.plant import make_plant
    values = P.merged_values(P.load_param_file(PARAMS))
    out = {}
    for b in ("rk4", "mujoco"):
        p = make_plant(P.plant_config(dict(values, backend=b)))
        t0 = time.perf_counter()
        for _ in range(n):
            p.step(0.0)
            p.k = 0   # the same instant: the robot falls otherwise; the cost is the same
        out[b] = (time.perf_counter() - t0) / n * 1e6
    m, d = p.model, p.data
    t0 = time.perf_counter()
    for _ in range(n):
        for _ in range(p.n):
            mujoco.mj_step(m, d)
    out["mj_step"] = (time.perf_counter() - t0) / n * 1e6
    t0 = time.perf_counter()
    for _ in range(n):
        mujoco.mj_forward(m, d)
    out["mj_forward"] = (time.perf_counter() - t0) / n * 1e6
    out["n"] = p.n
    progress(f"per period: {out}")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="mwip_bench_mujoco_") as tmp:
        g = graph_pairs(args.pairs, args.seconds, Path(tmp))
    rk, mj, mj5 = g["rk4"], g["mujoco"], g["mujoco_5ms"]
    off = offline(max(args.pairs, 3))
    pp = per_period()
    ratios = [b / a for a, b in zip(rk, mj)]
    ratios5 = [b / a for a, b in zip(rk, mj5)]
    offr = [b / a for a, b in zip(off["rk4"], off["mujoco"])]
    m = machine()
    rows = [
        "| item | rk4 | mujoco | mujoco / rk4 |", "|---|---|---|---|",
        f"| lockstep graph, 4 processes, {args.seconds:g} s of DSCNDO (median of {args.pairs}, turns) | "
        f"{statistics.median(rk):,.0f} steps/s | {statistics.median(mj):,.0f} steps/s | "
        f"{statistics.median(ratios):.2f}x (pairs: {', '.join(f'{r:.2f}' for r in ratios)}) |",
        f"| the same, `mujoco.timestep: 0.005` (one MuJoCo step a period) | | {statistics.median(mj5):,.0f} steps/s | "
        f"{statistics.median(ratios5):.2f}x (pairs: {', '.join(f'{r:.2f}' for r in ratios5)}) |",
        f"| the same, wall time per step (1 ms) | {1e6 / statistics.median(rk):.0f} us | "
        f"{1e6 / statistics.median(mj):.0f} us | |",
        f"| mwip_sim's loop, 10 s of DSCNDO (median of {len(offr)}) | {statistics.median(off['rk4']):,.0f} periods/s | "
        f"{statistics.median(off['mujoco']):,.0f} periods/s | {statistics.median(offr):.2f}x |",
        f"| one plant period (Plant.step) | {pp['rk4']:.0f} us | {pp['mujoco']:.0f} us | |",
        f"| of which MuJoCo's mj_step x {pp['n']} | | {pp['mj_step']:.0f} us | |",
        f"| mj_forward (the true tau_d's accelerations, once a period) | | {pp['mj_forward']:.0f} us | |",
    ]
    print(f"Machine: {m.get('cpu', '?')}, {m.get('cores', '?')} cores; Python {m.get('python', '?')}\n")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
