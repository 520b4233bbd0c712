#!/usr/bin/env python3
"""Benchmarks of mwip_ros, every figure measured in this one invocation on this machine.

    scripts/bench.sh [--quick] [--repeat N] [--markdown FILE]

1. DDS floor: two-process ping-pong of std_msgs/Float64 (reliable, depth 1) with the
   nodes' executor and, like the nodes, serialized messages: round trips/s; and the same
   with rclpy message objects, for comparison.
2. Lockstep graph: plant_sim, disturbance_observer, dscndo_controller and mcap_recorder
   as four processes, the paper's scenario (DSCNDO, 10 s at 200 Hz): control steps per
   wall-clock second, and that rate divided by the floor; and, in the same run, alternating
   with it, the same graph with ``foxglove_server`` and a WebSocket client subscribed to
   every channel it advertises (what a live view costs the loop).
3. Real time: the same four processes, plant_sim in realtime mode, 30 s at 200 Hz and
   at 1 kHz, with normal scheduling and with realtime_priority 50 (SCHED_FIFO; needs root
   or CAP_SYS_NICE): loop period p50/p99/max, missed deadlines (periods whose state was never published on time),
   stale-command substitutions; beside them, the wake-up latency of two bare Python sleep
   loops (no ROS), the machine's own limit without SCHED_FIFO.
4. Offline simulator: control steps/s of mwip_sim's closed loop, 10 s scenario; the batch
   simulator's scenario-steps/s at N = 1, 100, 10,000 in one process, and a mass-mismatch
   sweep through mwip_sweep's engine in one process and on every core.
5. Memory: peak resident memory (ru_maxrss) of each node in the lockstep run.

``--quick`` shortens every run (a smoke test: the tests run it); its numbers are rougher.
The table goes to stdout; progress goes to stderr.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Dict, List, Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "test"))
from graphproc import PARAMS, Graph  # noqa: E402

from mwip_ros.sweep.engine import DEFAULT_CHUNK  # noqa: E402

NODES = ("plant_sim", "disturbance_observer", "dscndo_controller", "mcap_recorder")
RT_PRIORITY = 50     # the realtime runs are made with normal scheduling and with this SCHED_FIFO priority
MSGS_PER_STEP = 1.5  # round trips of messages on a lockstep step's critical path (docs/theory.md, discrete time)


@dataclass
class Plan:
    pings: int
    lockstep_s: float
    realtime_s: float
    repeat: int
    pairs: int   # realtime runs of another law beside DSCNDO's, each (alternating)


FULL = Plan(pings=20000, lockstep_s=10.0, realtime_s=30.0, repeat=3, pairs=5)
QUICK = Plan(pings=1000, lockstep_s=1.0, realtime_s=2.0, repeat=1, pairs=1)


def progress(text: str) -> None:
    print(f"bench: {text}", file=sys.stderr, flush=True)


def median_run(runs: List[dict], key: str) -> dict:
    """The run whose ``key`` is the median of the runs' (the upper middle one of an even count)."""
    return sorted(runs, key=lambda r: r[key])[len(runs) // 2]


def machine() -> Dict[str, str]:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        rclpy_version = metadata.version("ros-jazzy-rclpy")
    except metadata.PackageNotFoundError:
        rclpy_version = "?"
    return {"cpu": cpu, "cores": str(os.cpu_count()), "kernel": platform.release(),
            "python": platform.python_version(), "rclpy": f"ros-jazzy-rclpy {rclpy_version}",
            "rmw": os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp (default)"),
            "executor": os.environ.get("MWIP_EXECUTOR", "events"),
            "load average at start": " ".join(f"{x:.2f}" for x in os.getloadavg())}


# --- 1. DDS floor --------------------------------------------------------------------------------

def dds_floor(plan: Plan, work: Path, typed: bool = False) -> dict:
    runs = []
    script = str(REPO / "scripts" / "bench_pingpong.py")
    flag = ["--typed"] if typed else []
    kind = "typed" if typed else "serialized"
    work.mkdir(parents=True, exist_ok=True)
    for i in range(plan.repeat):
        with Graph(work) as g:
            g.start("pong", params=None, label=f"pong_{kind}{i}", cmd=[sys.executable, script, "pong", *flag])
            out = work / f"ping_{kind}{i}.json"
            ping = g.start("ping", params=None, label=f"ping_{kind}{i}",
                           cmd=[sys.executable, script, "ping", *flag, "--count", str(plan.pings), "--json", str(out)])
            code = _wait(ping, 120)
            if code != 0 or not out.exists():
                raise SystemExit(f"bench: ping-pong failed (exit {code}):\n{ping.output()}")
            runs.append(json.loads(out.read_text()))
        progress(f"DDS floor ({kind}) run {i + 1}/{plan.repeat}: {runs[-1]['round_trips_per_s']:.0f} round trips/s")
    best = median_run(runs, "round_trips_per_s")
    return {"per_s": best["round_trips_per_s"], "runs": [r["round_trips_per_s"] for r in runs],
            "rtt_us_p50": best["rtt_us_p50"], "rtt_us_p99": best["rtt_us_p99"]}


# --- 2./3./5. the graph --------------------------------------------------------------------------

def _wait(proc, timeout: float) -> Optional[int]:
    """The exit code, or None when the process did not end within ``timeout`` (the caller reports it)."""
    try:
        return proc.wait(timeout)
    except subprocess.TimeoutExpired:
        return None


FOXGLOVE_CLIENT = """
import json, sys
from websockets.sync.client import connect
counts, sizes, topics = {}, {}, {}
with connect("ws://127.0.0.1:" + sys.argv[1], subprotocols=["foxglove.sdk.v1"], open_timeout=60,
             max_size=None) as ws:
    print("connected", flush=True)
    try:
        for frame in ws:
            if isinstance(frame, str):
                m = json.loads(frame)
                new = []
                if m["op"] == "advertise":
                    for c in m["channels"]:
                        topics[c["id"]] = c["topic"]
                        new.append({"id": c["id"], "channelId": c["id"]})
                elif m["op"] == "status" and m.get("message", "").startswith("Unknown channel ID: "):
                    cid = int(m["message"].rsplit(" ", 1)[1])   # foxglove-sdk 0.30.3: advertised a moment too early
                    new.append({"id": cid, "channelId": cid})
                if new:
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
            elif frame[0] == 1:
                sub = int.from_bytes(frame[1:5], "little")
                counts[sub] = counts.get(sub, 0) + 1
                sizes[sub] = sizes.get(sub, 0) + len(frame) - 13
    except KeyboardInterrupt:
        pass
    except Exception as exc:
        print(f"foxglove client: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
print(json.dumps({"messages": sum(counts.values()), "bytes": sum(sizes.values()),
                  "by_topic": {topics.get(k, str(k)): n for k, n in counts.items()}}), flush=True)
"""


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_foxglove(g: Graph, procs: dict, work: Path):
    """foxglove_server, and a client subscribed to every channel it advertises, connected before the plant starts."""
    port = _free_port()
    procs["foxglove_server"] = g.start("foxglove_server", "-p", f"port:={port}")
    if not procs["foxglove_server"].wait_for_output(f"on ws://127.0.0.1:{port}", 60):
        raise SystemExit(f"bench: foxglove_server did not start; logs in {work}:\n{procs['foxglove_server'].output()}")
    client = g.start("foxglove_client", params=None, cmd=[sys.executable, "-c", FOXGLOVE_CLIENT, str(port)])
    if not client.wait_for_output("connected", 60):
        raise SystemExit(f"bench: the WebSocket client did not connect; logs in {work}:\n{client.output()}")
    return client


def _stop_foxglove(procs: dict, client) -> dict:
    """Stop foxglove_server (its clients see the connection close) and return what the client received."""
    procs["foxglove_server"].stop()
    if _wait(client, 30) is None:
        client.stop()
    lines = [line for line in client.output().splitlines() if line.startswith("{")]
    if not lines:
        raise SystemExit(f"bench: the WebSocket client gave no result:\n{client.output()}")
    return json.loads(lines[-1])


def run_graph(work: Path, label: str, plant_args: List[str], shared: List[str], timeout: float,
              recorder_args: List[str] = (), foxglove: bool = False) -> dict:
    """Observer, controller, recorder and plant, started as scripts/run_experiment.sh starts them;
    returns the plant's summary and each node's peak RSS."""
    work.mkdir(parents=True, exist_ok=True)
    summary = work / "summary.json"
    loop_mode = ["-p", "mode:=realtime"] if "mode:=realtime" in plant_args else []   # the QoS of the plant's mode
    with Graph(work) as g:
        procs = {
            "mcap_recorder": g.start("mcap_recorder", "-p", f"output:={work / 'bag'}", *recorder_args, *shared),
            "disturbance_observer": g.start("disturbance_observer", *loop_mode, *shared),
            "dscndo_controller": g.start("dscndo_controller", *loop_mode, *shared),
        }
        client = _start_foxglove(g, procs, work) if foxglove else None
        procs["plant_sim"] = g.start("plant_sim", "-p", "expected_subscribers:=3", "-p", f"summary_json:={summary}",
                                     *plant_args, *shared)
        code = _wait(procs["plant_sim"], timeout)
        for name in ("dscndo_controller", "disturbance_observer", "mcap_recorder"):
            procs[name].stop()
        received = _stop_foxglove(procs, client) if client is not None else None
    if code not in (0, 3) or not summary.exists():  # 3: the robot fell; the summary says so
        raise SystemExit(f"bench: {label}: plant_sim exit {code}; logs in {work}:\n{procs['plant_sim'].output()}")
    result = json.loads(summary.read_text())
    if result["fallen"]:
        progress(f"{label}: the robot FELL after {result['periods']} periods; the numbers are for that shorter run")
    result["peak_rss_mib"] = {n: (p.peak_rss_kib or 0) / 1024 for n, p in procs.items()}
    result["fifo_refused"] = any("cannot switch to SCHED_FIFO" in p.output() for p in procs.values())
    if received is not None:
        result["foxglove_client"] = received
    return result


def lockstep(plan: Plan, work: Path) -> dict:
    runs, fox_runs = [], []
    for i in range(plan.repeat):   # without and with foxglove_server in turn: both see the same machine load
        r = run_graph(work / f"lockstep{i}", "lockstep", ["-p", "mode:=lockstep", "-p",
                      f"duration_s:={plan.lockstep_s}"], [], timeout=300, recorder_args=["-p", "use_sim_time:=true"])
        runs.append(r)
        progress(f"lockstep run {i + 1}/{plan.repeat}: {r['periods']} steps, {r['steps_per_s']:.0f} steps/s")
        r = run_graph(work / f"lockstep_foxglove{i}", "lockstep with foxglove_server",   # the server counted in
                      ["-p", "mode:=lockstep", "-p", f"duration_s:={plan.lockstep_s}", "-p", "expected_subscribers:=4"],
                      [], timeout=300, recorder_args=["-p", "use_sim_time:=true"], foxglove=True)
        fox_runs.append(r)
        progress(f"lockstep run with foxglove_server {i + 1}/{plan.repeat}: {r['periods']} steps, "
                 f"{r['steps_per_s']:.0f} steps/s; its client received {r['foxglove_client']['messages']} messages")
    best = median_run(runs, "steps_per_s")
    rss = {n: max(r["peak_rss_mib"][n] for r in runs) for n in NODES}
    fox = median_run(fox_runs, "steps_per_s")
    return {"per_s": best["steps_per_s"], "runs": [r["steps_per_s"] for r in runs], "wall_s": best["wall_s"],
            "periods": best["periods"], "peak_rss_mib": rss,
            "foxglove": {"per_s": fox["steps_per_s"], "runs": [r["steps_per_s"] for r in fox_runs],
                         "wall_s": fox["wall_s"], "periods": fox["periods"], "client": fox["foxglove_client"],
                         "peak_rss_mib": max(r["peak_rss_mib"]["foxglove_server"] for r in fox_runs)}}


def realtime(plan: Plan, rate_hz: float, priority: int, work: Path, law: str = "dsc", run: str = "") -> dict:
    """The realtime graph at ``rate_hz``; ``law``: the controller's family (with the observer term: DSCNDO,
    MPC+NDO), the row of a law beside DSCNDO's in the same run; ``run``: which of several runs."""
    sched = f"SCHED_FIFO {priority}" if priority else "normal scheduling"
    progress(f"realtime {rate_hz:g} Hz, {sched}, law {law}{run and f' ({run})'}, for {plan.realtime_s:g} s ...")
    shared = ["-p", f"control_rate_hz:={rate_hz:.1f}", "-p", f"realtime_priority:={priority}",
              "-p", f"dscndo_controller:law:={law}"]   # the controller's own rule: the file's section cannot beat it
    r = run_graph(work / f"realtime{rate_hz:g}_{priority}_{law}{run and '_' + run.replace(' ', '_')}",
                  f"realtime {rate_hz:g} Hz ({law})",
                  ["-p", "mode:=realtime", "-p", f"duration_s:={plan.realtime_s}"], shared,
                  timeout=plan.realtime_s + 120)
    rt = r.get("realtime")
    if rt is None:
        raise SystemExit(f"bench: realtime {rate_hz:g} Hz: the plant ran too few periods to time ({r['periods']})")
    rt["sched"] = sched if not r["fifo_refused"] else f"{sched} refused (needs root or CAP_SYS_NICE): normal"
    progress(f"realtime {rate_hz:g} Hz, {rt['sched']}: period p99 {rt['period_ms_p99']:.3f} ms, "
             f"max {rt['period_ms_max']:.3f} ms, missed {rt['missed_deadlines']}, "
             f"stale {rt['stale_command_substitutions']}")
    return rt


def beside(plan: Plan, law: str, work: Path) -> List[tuple]:
    """``law`` (+NDO) and DSCNDO at 200 Hz with normal scheduling, ``plan.pairs`` runs each, alternating (DSCNDO
    first, then the other first, ...): a missed deadline is the machine's wake-up latency under load, which
    drifts within minutes (4 to 46 in 30 s runs of one law within ten minutes here), so one run of each,
    minutes apart, compares the drift rather than the laws.  Returns (DSCNDO's run, ``law``'s run) pairs."""
    pairs = []
    for i in range(plan.pairs):
        run = f"run {i + 1} of {plan.pairs}"
        order = ("dsc", law) if i % 2 == 0 else (law, "dsc")
        got = {name: realtime(plan, 200.0, 0, work, law=name, run=run) for name in order}
        pairs.append((got["dsc"], got[law]))
    return pairs


SLEEP_LOOP = """
import json, sys, time
h, T = float(sys.argv[1]), float(sys.argv[2])
t0 = time.monotonic(); k = 0; worst = 0.0; late = 0
while (k + 1) * h <= T:
    k += 1
    target = t0 + k * h
    d = target - time.monotonic()
    if d > 0:
        time.sleep(d)
    lag = time.monotonic() - target
    worst = max(worst, lag)
    late += lag > h / 2
print(json.dumps({"h_ms": h * 1e3, "periods": k, "worst_ms": worst * 1e3, "late": late}))
"""


def os_floor(plan: Plan) -> List[dict]:
    """The machine's own wake-up latency: two bare Python loops (5 ms and 1 ms) sleeping to fixed deadlines
    side by side, no ROS.  What the realtime graph cannot beat without SCHED_FIFO."""
    progress(f"wake-up latency of bare sleep loops for {plan.realtime_s:g} s ...")
    procs = [subprocess.Popen([sys.executable, "-c", SLEEP_LOOP, str(h), str(plan.realtime_s)],
                              stdout=subprocess.PIPE, text=True) for h in (0.005, 0.001)]
    out = []
    for p in procs:
        try:
            text, _ = p.communicate(timeout=plan.realtime_s + 60)
        except subprocess.TimeoutExpired:
            text = ""
        finally:
            if p.poll() is None:
                p.kill()
                p.wait(5)
        if not text.strip():
            raise SystemExit(f"bench: the bare sleep loop (pid {p.pid}) gave no result (exit {p.returncode})")
        out.append(json.loads(text))
    return out


# --- 4. offline ----------------------------------------------------------------------------------

def offline(plan: Plan) -> dict:
    """mwip_sim's loop (DSCNDO, 10 s); and with ``plant_sim.backend: mujoco`` (docs/theory.md 6.10) when MuJoCo is
    installed, the two backends' runs taking turns, so both see the same load."""
    import importlib.util
    from mwip_ros import params as P
    from mwip_ros.core.closed_loop.sim import simulate
    values = P.merged_values(P.load_param_file(PARAMS))
    loop = P.closed_loop(values, use_observer=True, duration=10.0)
    mj = None
    if importlib.util.find_spec("mujoco") is not None:
        mj = P.closed_loop(dict(values, backend="mujoco"), use_observer=True, duration=10.0)
    runs, mj_runs = [], []
    for _ in range(max(plan.repeat, 3)):
        t0 = time.perf_counter()
        r = simulate(loop)
        runs.append(len(r) / (time.perf_counter() - t0))
        if mj is not None:
            t0 = time.perf_counter()
            m = simulate(mj)
            mj_runs.append(len(m) / (time.perf_counter() - t0))
    progress(f"offline: {statistics.median(runs):.0f} steps/s"
             + (f"; backend mujoco {statistics.median(mj_runs):.0f} steps/s" if mj_runs else ""))
    return {"per_s": statistics.median(runs), "runs": runs, "steps": len(r), "batch": batch(plan),
            "mujoco_per_s": statistics.median(mj_runs) if mj_runs else None, "mujoco_runs": mj_runs}


def batch(plan: Plan) -> list:
    """The batch simulator: scenario-steps/s for N scenarios in this one process (each its own seed, the
    rest shared), and the peak memory the largest batch allocated (tracemalloc: numpy's arrays included);
    then a mass-mismatch sweep (m_b, I_b, l scaled per scenario) through mwip_sweep's engine, in one process
    and on every core, worker start-up included."""
    import tracemalloc

    from mwip_ros import params as P
    from mwip_ros.core.kernels.batch import simulate_batch
    from mwip_ros.sweep import engine
    from mwip_ros.sweep.scenarios import expand
    from mwip_ros.sweep.spec import parse_spec
    values = P.merged_values(P.load_param_file(PARAMS))
    out = []
    for n, duration in ((1, 2.0), (100, 2.0), (1000, 1.0)) if plan.repeat == 1 else \
            ((1, 10.0), (100, 10.0), (10000, 2.0)):
        loops = [P.closed_loop(dict(values, seed=i), use_observer=True, duration=duration) for i in range(n)]
        t0 = time.perf_counter()
        r = simulate_batch(loops, (0.5 * duration, duration))
        wall = time.perf_counter() - t0
        tracemalloc.start()  # a second run for the memory alone: tracing slows the small arrays down a lot
        simulate_batch(loops, (0.5 * duration, duration))
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        out.append({"n": n, "per_s": r.steps / wall, "peak_mib": peak / 2 ** 20, "what": "seeds", "workers": 1,
                    "duration": duration})
        progress(f"batch N = {n}: {r.steps / wall:,.0f} scenario-steps/s, peak {peak / 2 ** 20:.0f} MiB")
    n, duration = (2000, 1.0) if plan.repeat == 1 else (20000, 4.0)   # 2 chunks per core: worker start amortized
    spec = parse_spec({"base": str(PARAMS), "duration_s": duration, "metrics_window_s": [0.5 * duration, duration],
                       "controllers": ["dscndo"], "seed": 1, "samples": n,
                       "vary": {f"plant_sim.actual.{k}": {"scale": [0.7, 1.3]} for k in ("m_b", "I_b", "l")}},
                      "bench")
    chunks = engine.make_chunks(spec, expand(spec), engine.DEFAULT_CHUNK)
    cores = os.cpu_count() or 1
    for workers in sorted({1, cores}):
        runs, steady = [], []
        for _ in range(plan.repeat):
            with engine.Runner(workers) as runner:
                for into in (runs, steady) if workers > 1 else (runs,):
                    # the first pass starts the workers; the second finds them running (mwip_tune's generations)
                    t0 = time.perf_counter()
                    steps = sum(res.steps for _, res in runner(chunks))
                    into.append(steps / (time.perf_counter() - t0))
        for what, per_s in (("mass", runs), ("steady", steady)):
            if per_s:
                out.append({"n": n, "per_s": statistics.median(per_s), "runs": per_s, "what": what,
                            "workers": workers, "duration": duration})
                progress(f"mass-mismatch sweep, N = {n}, {workers} worker(s){', started' if what == 'steady' else ''}"
                         f": {statistics.median(per_s):,.0f} scenario-steps/s (median of {len(per_s)})")
    out.append(worker_startup(chunks[0], plan))
    out.append(sweep_cli(plan))
    return out


def worker_startup(chunk, plan: Plan) -> dict:
    """A sweep worker's start-up: a process spawned as engine.Runner spawns them, from the pool's creation to the
    result of its first chunk, one scenario of 0.1 s (the interpreter, the imports, numba loading the compiled
    loop from its cache, the chunk); numba's cache is warm (the sweep rows above ran)."""
    import dataclasses
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from mwip_ros.sweep import engine
    from mwip_ros.sweep.workers import worker_init
    chunk = dataclasses.replace(chunk, overrides=chunk.overrides[:1], duration_s=0.1, window=(0.05, 0.1))
    runs = []
    for _ in range(max(3, plan.repeat)):
        t0 = time.perf_counter()
        with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=worker_init) as pool:
            pool.submit(engine.run_chunk, chunk).result()
            runs.append(time.perf_counter() - t0)
    progress(f"sweep worker start-up: {statistics.median(runs):.3f} s (median of {len(runs)})")
    return {"what": "startup", "s": statistics.median(runs), "runs": runs}


def sweep_cli(plan: Plan) -> dict:
    """``mwip_sweep config/sweeps/mass_mismatch.yaml`` as a user runs it (default workers: every core), end to
    end: the command's own figure (scenario-steps over the time from the first chunk sent to the last row
    written) and the wall time of the whole command (start-up, summary and figures included).  ``--quick``:
    20 scenarios of 1 s."""
    import yaml
    spec_path = REPO / "config" / "sweeps" / "mass_mismatch.yaml"
    runs = []
    with tempfile.TemporaryDirectory(prefix="mwip_bench_sweep_") as tmp:
        if plan.repeat == 1:
            from mwip_ros.yamlio import load_yaml
            doc = load_yaml(spec_path, "sweep spec")   # the project's one bounded YAML reader
            doc.update(samples=20, duration_s=1.0, metrics_window_s=[0.5, 1.0], base=str(PARAMS))
            spec_path = Path(tmp) / "mass_mismatch_quick.yaml"
            spec_path.write_text(yaml.safe_dump(doc))
        for i in range(plan.repeat):
            t0 = time.perf_counter()
            r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sweep", str(spec_path), "--out",
                                str(Path(tmp) / f"run{i}")], capture_output=True, text=True, timeout=1800)
            wall = time.perf_counter() - t0
            if r.returncode != 0:
                raise RuntimeError(f"mwip_sweep failed ({r.returncode}): {r.stderr[-2000:]}")
            found = re.search(r"([\d,]+) runs, ([\d,]+) scenario-steps in ([\d.]+) s \(([\d,]+) scenario-steps/s\)",
                              r.stderr)
            runs.append({"wall_s": wall, "runs": int(found[1].replace(",", "")),
                         "steps": int(found[2].replace(",", "")), "per_s": float(found[4].replace(",", ""))})
    best = median_run(runs, "per_s")
    progress(f"mwip_sweep {spec_path.name}: {best['per_s']:,.0f} scenario-steps/s, {best['wall_s']:.1f} s wall")
    return dict(best, what="cli", all=[x["per_s"] for x in runs], spec=spec_path.name)


# --- the table ------------------------------------------------------------------------------------

def table(plan: Plan, quick: bool, m: Dict[str, str], floor: dict, typed: dict, ls: dict,
          rts: Dict[tuple, dict], sleep: List[dict], off: dict, pairs: Dict[str, List[tuple]]) -> str:
    rows = []

    def row(item, measured, target="", met=None):
        rows.append(f"| {item} | {measured} | {target} | {'' if met is None else ('yes' if met else 'NO')} |")

    row("1. DDS floor: Float64 ping-pong, 2 processes, serialized (as the nodes publish)",
        f"{floor['per_s']:,.0f} round trips/s (RTT p50 {floor['rtt_us_p50']:.0f} us, p99 {floor['rtt_us_p99']:.0f} us)")
    row("1. the same with rclpy message objects (typed)",
        f"{typed['per_s']:,.0f} round trips/s (RTT p50 {typed['rtt_us_p50']:.0f} us, p99 {typed['rtt_us_p99']:.0f} us)")
    ratio = ls["per_s"] / floor["per_s"]
    row("2. lockstep graph, 4 processes (with recorder)",
        f"{ls['per_s']:,.0f} steps/s ({ls['periods']} steps in {ls['wall_s']:.2f} s wall)", ">= 1,000 steps/s",
        ls["per_s"] >= 1000)
    row("2. lockstep rate / DDS floor",
        f"{ratio:.2f} steps per round trip (ideal ~{1 / MSGS_PER_STEP:.2f}: a step is ~{MSGS_PER_STEP} round trips)")
    fox = ls["foxglove"]
    row("2. lockstep graph with foxglove_server (a client connected)",
        f"{fox['per_s']:,.0f} steps/s ({fox['periods']} steps in {fox['wall_s']:.2f} s wall; "
        f"{fox['per_s'] / ls['per_s']:.0%} of the rate without it; the client, subscribed to every channel, "
        f"received {fox['client']['messages']:,} messages, {fox['client']['bytes'] / 2 ** 20:.1f} MiB)")
    for key, rt in rts.items():
        hz = key[0]
        target = "0 missed" if hz == 200 else ""
        row(f"3. realtime {hz:g} Hz, {plan.realtime_s:g} s, 4 processes, {rt['sched']}: loop period p50 / p99 / max",
            f"{rt['period_ms_p50']:.3f} / {rt['period_ms_p99']:.3f} / {rt['period_ms_max']:.3f} ms "
            f"(nominal {1e3 / hz:g} ms)")
        row(f"3. realtime {hz:g} Hz, {rt['sched']}: missed deadlines / stale-command substitutions",
            f"{rt['missed_deadlines']} / {rt['stale_command_substitutions']} of {rt['periods_due']} periods", target,
            (rt["missed_deadlines"] == 0) if hz == 200 else None)
    for law, runs in pairs.items():   # another law beside DSCNDO, alternating: no more missed deadlines
        mine, ref = ([r[j]["missed_deadlines"] for r in runs] for j in (1, 0))
        last = runs[-1][1]
        row(f"3. realtime 200 Hz, {last['sched']}, law {law} (+NDO) beside DSCNDO, {len(runs)} run(s) each, "
            f"alternating: missed deadlines, median (each run; in all); stale commands, loop period p99 / max of its "
            f"last run", f"{statistics.median(mine):g} ({', '.join(map(str, mine))}; {sum(mine)}) against DSCNDO's "
            f"{statistics.median(ref):g} ({', '.join(map(str, ref))}; {sum(ref)}); "
            f"{last['stale_command_substitutions']} stale "
            f"of {last['periods_due']} periods; {last['period_ms_p99']:.3f} / {last['period_ms_max']:.3f} ms",
            "<= DSCNDO's median", statistics.median(mine) <= statistics.median(ref))
    for f in sleep:
        row(f"3. for comparison: a bare Python loop sleeping to {f['h_ms']:g} ms deadlines beside a second one, "
            f"no ROS: worst wake-up lateness / periods > h/2 late",
            f"{f['worst_ms']:.3f} ms / {f['late']} of {f['periods']}")
    row("4. offline simulator (mwip_sim loop, DSCNDO, 10 s)", f"{off['per_s']:,.0f} steps/s", ">= 20,000 steps/s",
        off["per_s"] >= 20000)
    if off.get("mujoco_per_s"):
        ratio = off["mujoco_per_s"] / off["per_s"]
        row("4. the same with plant_sim.backend mujoco (mujoco.timestep 1 ms), runs taking turns with the rk4 one's",
            f"{off['mujoco_per_s']:,.0f} steps/s ({ratio:.2f} x the rk4 backend's)", ">= 0.5 x rk4", ratio >= 0.5)
    for b in off["batch"]:
        if b["what"] == "startup":
            row("4. mwip_sweep worker start-up: a spawned worker to its first chunk's result (one scenario, 0.1 s; "
                "numba's cache warm)", f"{b['s']:.2f} s (runs {' / '.join(f'{r:.2f}' for r in b['runs'])})")
            continue
        ratio = f"{b['per_s'] / off['per_s']:.1f} x the scalar loop"
        if b["what"] == "seeds":
            row(f"4. batch simulator, N = {b['n']:,} scenarios (own seeds), {b['duration']:g} s, one process",
                f"{b['per_s']:,.0f} scenario-steps/s ({ratio}); peak memory {b['peak_mib']:.0f} MiB "
                f"(window of half the run kept per scenario)")
        elif b["what"] in ("mass", "steady"):
            where = "one process" if b["workers"] == 1 else f"{b['workers']} worker processes (all cores), " + \
                ("their start-up included" if b["what"] == "mass" else "already started (a second sweep on the "
                 "same pool, as mwip_tune's generations run)")
            spread = f"; runs {' / '.join(f'{r:,.0f}' for r in b['runs'])}" if len(b["runs"]) > 1 else ""
            row(f"4. mwip_sweep engine: mass mismatch (m_b, I_b, l scaled), N = {b['n']:,}, {b['duration']:g} s, "
                f"chunks of {DEFAULT_CHUNK:,}, {where}",
                f"{b['per_s']:,.0f} scenario-steps/s ({ratio}{spread})",
                ">= 2,000,000 on 2 cores" if b["what"] == "mass" and b["workers"] > 1 else "",
                b["per_s"] >= 2e6 if b["what"] == "mass" and b["workers"] > 1 else None)
        else:
            spread = f"; runs {' / '.join(f'{r:,.0f}' for r in b['all'])}" if len(b["all"]) > 1 else ""
            row(f"4. mwip_sweep {b['spec']} from the command line, every core: {b['runs']:,} runs, "
                f"{b['steps']:,} scenario-steps", f"{b['per_s']:,.0f} scenario-steps/s as the command reports it "
                f"({ratio}{spread}); {b['wall_s']:.1f} s wall for the whole command (start-up, summary, figures)")
    for n in NODES:
        row(f"5. peak resident memory: {n}", f"{ls['peak_rss_mib'][n]:.1f} MiB")
    row("5. peak resident memory: foxglove_server (a client connected)", f"{ls['foxglove']['peak_rss_mib']:.1f} MiB")
    head = [f"mwip_ros benchmarks{' (--quick: short runs, rough numbers)' if quick else ''}", ""]
    head += [f"- {k}: {v}" for k, v in m.items()]
    head += ["", "| measurement | result | target | met |", "|---|---|---|---|"]
    return "\n".join(head + rows) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="short runs (smoke test, about a minute)")
    ap.add_argument("--repeat", type=int, help="runs of the floor and the lockstep graph; the median is shown "
                                               "(default 3, --quick 1)")
    ap.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    ap.add_argument("--keep", metavar="DIR", help="keep the runs' logs and bags in DIR (default: a temporary "
                                                  "directory, removed)")
    args = ap.parse_args()
    plan = QUICK if args.quick else FULL
    if args.repeat is not None:
        if args.repeat < 1:
            ap.error("--repeat must be at least 1")
        plan = Plan(plan.pings, plan.lockstep_s, plan.realtime_s, args.repeat, plan.pairs)
    m = machine()
    with tempfile.TemporaryDirectory(prefix="mwip_bench_") as tmp:
        work = Path(args.keep).resolve() if args.keep else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        progress(f"DDS floor: {plan.repeat} x {plan.pings} round trips ...")
        floor = dds_floor(plan, work / "floor")
        typed = dds_floor(plan, work / "floor", typed=True)
        progress(f"lockstep graph: {plan.repeat} x {plan.lockstep_s:g} s ...")
        ls = lockstep(plan, work)
        rts = {(hz, prio): realtime(plan, hz, prio, work) for hz in (200.0, 1000.0) for prio in (0, RT_PRIORITY)}
        pairs = {"mpc": beside(plan, "mpc", work)}   # MPC+NDO beside DSCNDO
        sleep = os_floor(plan)
        off = offline(plan)
    text = table(plan, args.quick, m, floor, typed, ls, rts, sleep, off, pairs)
    print(text, end="")
    if args.markdown:
        Path(args.markdown).write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
