#!/usr/bin/env python3
"""The MuJoCo plant's speed beside the rk4 plant's, and beside another checkout's MuJoCo plant (before / after a
change), every figure measured in this one invocation (BENCHMARKS.md, "The lockstep graph with the MuJoCo plant").

    python scripts/bench_mujoco.py [--pairs N] [--seconds S] [--before DIR]

``--before DIR``: a checkout of the code to compare with (e.g. ``mkdir DIR && git archive main | tar -x -C DIR``),
run at a physics step of 1 ms (``mujoco.timestep: 0.001``, the default before it became 5 ms; ``--before-timestep``
another, e.g. 0.005 to compare two checkouts at today's default); its processes
import ``mwip_ros`` from DIR (PYTHONPATH), the others from this checkout.

1. The lockstep graph (plant_sim, disturbance_observer, dscndo_controller, mcap_recorder: four processes, as
   scripts/bench.py runs it), the paper's scenario (DSCNDO): ``backend: rk4``, ``backend: mujoco`` at the default
   physics step and at 1 ms, and the ``--before`` checkout's mujoco at 1 ms, taking turns ``--pairs`` times:
   steps/s each and each mujoco variant's ratio to the rk4 run of its turn (both see the same load).
   Then the rk4 and the mujoco (default step) graphs of this checkout side by side, at the same time, ``--pairs``
   times: the same load at every moment.  Each graph run simulates ``--seconds`` (default 60 s, 8-11 s of wall
   time): a run of the paper's 10 s lasts 1.2-1.6 s, and on 2 shared cores the ratio of two such runs scattered
   from 0.80x to 1.00x over 7 turns, where 60 s runs in the same turns gave 0.81x-0.87x (docs/benchmarks-history.md,
   "Steady-state runs").
2. ``mwip_sim``'s loop (10 s of DSCNDO, one process per run, the first run of each process not timed), the same
   variants taking turns: periods/s and the ratios per turn.
3. Where a period's time goes, in process (this checkout): one plant period (``lumped_disturbance`` and ``step``,
   as a loop period calls them) of each backend and physics step, MuJoCo's own ``mj_step`` (times the steps per
   period) and ``mj_forward`` (the true tau_d's accelerations).

The table goes to stdout (markdown); progress to stderr.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path[:0] = [str(Path(__file__).resolve().parent.parent), str(Path(__file__).resolve().parent)]   # this checkout
from bench import PARAMS, REPO, machine, progress, run_graph  # noqa: E402

OLD_STEP = ["-p", "mujoco.timestep:=0.001"]
# name -> (checkout (None: this one), plant_sim's -p rules); "rk4" first: each turn's reference
VARIANTS = {"rk4": (None, ["-p", "backend:=rk4"]),
            "before": ("before", ["-p", "backend:=mujoco", *OLD_STEP]),
            "mujoco_1ms": (None, ["-p", "backend:=mujoco", *OLD_STEP]),
            "mujoco": (None, ["-p", "backend:=mujoco"])}
LABELS = {"before": "mujoco, the `--before` checkout, 1 ms", "mujoco_1ms": "mujoco, this checkout, 1 ms",
          "mujoco": "mujoco, this checkout, default step (5 ms)"}

# one mwip_sim run in a fresh process (the checkout's mwip_ros on PYTHONPATH): a warm-up run, then the timed one
OFFLINE = """
import json, sys, time
from mwip_ros import params as P
from mwip_ros.core.closed_loop.sim import simulate
v = P.merged_values(P.load_param_file(sys.argv[1]))
v.update(json.loads(sys.argv[2]))
loop = P.closed_loop(v, use_observer=True, duration=float(sys.argv[3]))
simulate(loop)
t0 = time.perf_counter()
r = simulate(loop)
print(json.dumps({"periods_per_s": len(r) / (time.perf_counter() - t0), "fallen": r.fallen}))
"""


def _values(args):
    """plant_sim's -p rules as parameter values (for the in-process mwip_sim run)."""
    rules = [a.split(":=", 1) for a in args if ":=" in a]
    return {k: (float(x) if k == "mujoco.timestep" else x) for k, x in rules}


def _env(tree):
    return dict(os.environ, PYTHONPATH=str(tree))


def graph_turns(pairs: int, seconds: float, work: Path, trees: dict):
    """steps/s of each variant's lockstep graph, the variants taking turns."""
    out = {v: [] for v in trees}
    saved = os.environ.get("PYTHONPATH")
    try:
        for i in range(pairs):
            for v in trees:
                os.environ["PYTHONPATH"] = str(trees[v])   # the graph's processes inherit it (graphproc.ros_env)
                r = run_graph(work / f"{v}{i}", f"lockstep {v}",
                              ["-p", "mode:=lockstep", "-p", f"duration_s:={seconds}", *VARIANTS[v][1]], [],
                              timeout=600, recorder_args=["-p", "use_sim_time:=true"])
                out[v].append(r["steps_per_s"])
                progress(f"lockstep {v} {i + 1}/{pairs}: {r['periods']} steps, {r['steps_per_s']:.0f} steps/s")
    finally:
        if saved is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = saved
    return out


def graph_side_by_side(pairs: int, seconds: float, work: Path):
    """steps/s of the rk4 and the mujoco (default step) lockstep graphs of this checkout run at the same time, each
    on its own ROS domain, ``pairs`` times: both see the same load at every moment (the machine's and each
    other's), so their ratio is what a MuJoCo step costs beside an rk4 one, not the load's drift between turns."""
    from concurrent.futures import ThreadPoolExecutor
    out = {"rk4": [], "mujoco": []}
    for i in range(pairs):
        with ThreadPoolExecutor(2) as pool:
            runs = {v: pool.submit(run_graph, work / f"side_{v}{i}", f"side by side {v}",
                                   ["-p", "mode:=lockstep", "-p", f"duration_s:={seconds}", *VARIANTS[v][1]], [],
                                   600, ["-p", "use_sim_time:=true"]) for v in out}
            for v, r in runs.items():
                out[v].append(r.result()["steps_per_s"])
        progress(f"side by side {i + 1}/{pairs}: rk4 {out['rk4'][-1]:.0f}, mujoco {out['mujoco'][-1]:.0f} steps/s")
    return out


def offline_turns(pairs: int, trees: dict):
    """mwip_sim's periods/s of each variant, one process per run, the variants taking turns."""
    out = {v: [] for v in trees}
    for i in range(pairs):
        for v in trees:
            r = subprocess.run([sys.executable, "-c", OFFLINE, str(PARAMS), json.dumps(_values(VARIANTS[v][1])), "10"],
                               env=_env(trees[v]), capture_output=True, text=True, timeout=600, cwd=trees[v])
            if r.returncode != 0:
                raise SystemExit(f"bench_mujoco: mwip_sim {v}: {r.stderr.strip()}")
            res = json.loads(r.stdout.strip().splitlines()[-1])
            if res["fallen"]:
                raise SystemExit(f"bench_mujoco: mwip_sim {v}: the robot fell")
            out[v].append(res["periods_per_s"])
        progress(f"mwip_sim {i + 1}/{pairs}: " + ", ".join(f"{v} {out[v][-1]:.0f}" for v in trees) + " periods/s")
    return out


def per_period(n: int = 2000, repeat: int = 5):
    """us of one plant period (lumped_disturbance + step, the best of ``repeat``) of rk4 and of mujoco at 1 ms and
    5 ms, of the mj_steps of a period alone and of one mj_forward."""
    import mujoco

    from mwip_ros import params as P
    from mwip_ros.core.plants.plant import make_plant
    values = P.merged_values(P.load_param_file(PARAMS))
    out = {}
    for name, over in (("rk4", {"backend": "rk4"}), ("mujoco_1ms", {"backend": "mujoco", "mujoco.timestep": 0.001}),
                       ("mujoco", {"backend": "mujoco"})):
        best = []
        for _ in range(repeat):
            p = make_plant(P.plant_config(dict(values, **over)))
            t0 = time.perf_counter()
            for _ in range(n):
                p.lumped_disturbance(0.0)
                p.step(0.0)
                p.k = 0   # the same instant: the robot falls otherwise; the cost is the same
            best.append((time.perf_counter() - t0) / n * 1e6)
        out[name] = min(best)
        if name != "rk4":
            m, d = p.model, p.data
            t0 = time.perf_counter()
            for _ in range(n):
                for _ in range(p.n):
                    mujoco.mj_step(m, d)
            out[f"{name}_mj_step"] = (time.perf_counter() - t0) / n * 1e6
            out[f"{name}_n"] = p.n
            t0 = time.perf_counter()
            for _ in range(n):
                mujoco.mj_forward(m, d)
            out["mj_forward"] = (time.perf_counter() - t0) / n * 1e6
    progress(f"per period: {out}")
    return out


def _ratios(a, b):
    return [y / x for x, y in zip(a, b)]


def _spread(r):
    return f"{statistics.median(r):.2f}x ({min(r):.2f}-{max(r):.2f}; turns: {', '.join(f'{x:.2f}' for x in r)})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pairs", type=int, default=3, help="turns of the variants (each runs once a turn)")
    ap.add_argument("--seconds", type=float, default=60.0,
                    help="simulated seconds of each lockstep graph run (default 60: a steady rate, see above)")
    ap.add_argument("--before", type=Path, default=None,
                    help="a checkout of the code to compare with, run at mujoco.timestep 0.001 (none: left out)")
    ap.add_argument("--before-timestep", type=float, default=0.001, metavar="S",
                    help="the --before checkout's mujoco.timestep [s] (default 0.001)")
    args = ap.parse_args()
    if not 0 < args.before_timestep <= 0.005:
        ap.error(f"--before-timestep: in (0, 0.005] s, got {args.before_timestep:g}")
    step = ["-p", f"mujoco.timestep:={args.before_timestep!r}"]
    VARIANTS["before"] = ("before", ["-p", "backend:=mujoco", *step])
    LABELS["before"] = f"mujoco, the `--before` checkout, {args.before_timestep * 1e3:g} ms"
    if args.pairs < 1 or args.seconds <= 0:
        ap.error("--pairs must be at least 1 and --seconds positive")
    if args.before is not None and not (args.before / "mwip_ros" / "__init__.py").exists():
        ap.error(f"--before {args.before}: no mwip_ros package there")
    trees = {v: (args.before.resolve() if t == "before" else REPO) for v, (t, _) in VARIANTS.items()
             if t != "before" or args.before is not None}
    m = machine()
    with tempfile.TemporaryDirectory(prefix="mwip_bench_mujoco_") as tmp:
        g = graph_turns(args.pairs, args.seconds, Path(tmp), trees)
        side = graph_side_by_side(args.pairs, args.seconds, Path(tmp))
    off = offline_turns(args.pairs, trees)
    pp = per_period()
    rows = ["| item | steps/s or periods/s (median) | / rk4 of the same turn: median (range; turns) |",
            "|---|---|---|",
            f"| lockstep graph, rk4 ({args.seconds:g} s of DSCNDO, 4 processes) | "
            f"{statistics.median(g['rk4']):,.0f} | |"]
    rows += [f"| lockstep graph, {LABELS[v]} | {statistics.median(g[v]):,.0f} | {_spread(_ratios(g['rk4'], g[v]))} |"
             for v in trees if v != "rk4"]
    rows += [f"| lockstep graphs side by side (at the same time): rk4 | {statistics.median(side['rk4']):,.0f} | |",
             f"| lockstep graphs side by side: {LABELS['mujoco']} | {statistics.median(side['mujoco']):,.0f} | "
             f"{_spread(_ratios(side['rk4'], side['mujoco']))} |"]
    rows += [f"| mwip_sim's loop, rk4 (10 s of DSCNDO) | {statistics.median(off['rk4']):,.0f} | |"]
    rows += [f"| mwip_sim's loop, {LABELS[v]} | {statistics.median(off[v]):,.0f} | "
             f"{_spread(_ratios(off['rk4'], off[v]))} |" for v in trees if v != "rk4"]
    per = ["| one plant period (lumped_disturbance + step), this checkout | us |", "|---|---|",
           f"| rk4 ({values_substeps()} RK4 sub-steps of eq. 1) | {pp['rk4']:.1f} |"]
    for name in ("mujoco_1ms", "mujoco"):
        steps = pp[f"{name}_n"]
        per += [f"| mujoco, {steps} physics step{'s' if steps > 1 else ''} a period | {pp[name]:.1f} |",
                f"| of which mj_step x {pp[f'{name}_n']} | {pp[f'{name}_mj_step']:.1f} |"]
    per += [f"| mj_forward (the true tau_d's accelerations, once a period) | {pp['mj_forward']:.1f} |"]
    print(f"Machine: {m.get('cpu', '?')}, {m.get('cores', '?')} cores; Python {m.get('python', '?')}; "
          f"load average at start {m.get('load average at start', '?')}, at the end "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}\n")
    print("\n".join(rows))
    print()
    print("\n".join(per))
    return 0


def values_substeps() -> int:
    from mwip_ros import params as P
    return P.merged_values(P.load_param_file(PARAMS))["substeps"]


if __name__ == "__main__":
    sys.exit(main())
