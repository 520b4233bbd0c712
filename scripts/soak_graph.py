#!/usr/bin/env python3
"""Soak of the realtime graph: each node's resident memory over a long run, and its slope after a warm-up.

    source scripts/env.sh && python scripts/soak_graph.py [--duration 600] [--warmup 60] [--every 10]
        [--max-bagfile-size BYTES] [--max-bagfile-duration S] [--no-split] [--memtrace NODE,...] [--json FILE]
        [--markdown FILE]

Runs plant_sim (realtime, 200 Hz, DSCNDO, its ``csv`` set), disturbance_observer, dscndo_controller,
mcap_recorder (splitting its bag by size and duration, rosbag2's ``max_bagfile_size`` and
``max_bagfile_duration``) and the live view foxglove_server with a WebSocket client subscribed to every channel,
for ``--duration`` seconds from the plant's start.  It samples every node's VmRSS (/proc/PID/status) every
``--every`` seconds and reports, per node, the RSS at the start, after ``--warmup`` and at the end, and the
least-squares slope of the samples after the warm-up in MB per hour (goal: under 1 MB/h for every node).  Then it
reads the bag as one run (every file of it) and says how many files and messages it has.

The slope is what matters: on a machine loaded by other work the absolute RSS moves with it too (allocator
arenas, the DDS's buffers under a slow reader), but a per-period buffer shows as a steady slope.  A short run
(--duration 60) is a smoke test: its slope still contains the warm-up's tail.  ``--memtrace`` runs the nodes it
names under ``MWIP_MEMTRACE`` (:mod:`mwip_ros.nodes.runtime.memtrace`) and adds, for each, the slopes of its Python
heap (tracemalloc) and of glibc's heap in use and free: which of them a growing RSS follows says whose it is
(tracemalloc slows the node and its snapshot at the warm-up's end is a step in its RSS).  Exit 0 when the run completed
(whatever the slopes: they are measurements, compared in BENCHMARKS.md), 1 when it did not.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "test"))
sys.path.insert(0, str(REPO / "scripts"))
from graphproc import Graph  # noqa: E402

from mwip_ros.nodes.runtime.memtrace import status_kib  # noqa: E402

NODES = ("plant_sim", "disturbance_observer", "dscndo_controller", "mcap_recorder", "foxglove_server")
GOAL_MB_PER_H = 1.0


PARTS = ("RssAnon", "RssFile", "RssShmem")   # VmRSS = their sum: the heaps, mapped files, shared memory (Fast DDS)


def rss_kib(pid: int) -> Optional[int]:
    r = status_kib("VmRSS", pid=pid)["VmRSS"]
    return None if r < 0 else r


def slope_mb_per_h(samples: List[tuple]) -> float:
    """The least-squares slope of (t [s], RSS [KiB]) samples, in MB (10^6 bytes) per hour."""
    n = len(samples)
    if n < 2:
        return float("nan")
    mt = sum(t for t, _ in samples) / n
    mr = sum(r for _, r in samples) / n
    den = sum((t - mt) ** 2 for t, _ in samples)
    if den <= 0:
        return float("nan")
    kib_per_s = sum((t - mt) * (r - mr) for t, r in samples) / den
    return kib_per_s * 1024 * 3600 / 1e6


def memtrace_slopes(path: Path, warmup: float) -> Optional[dict]:
    """The slopes [MB/h] after ``warmup`` of a node's MWIP_MEMTRACE file (mwip_ros.nodes.runtime.memtrace): RSS, the
    Python heap (tracemalloc) and glibc's heap in use and free; its closing lines (what grew, malloc_trim)."""
    if not path.exists():
        return None
    rows, notes, base = [], [], None
    for line in path.read_text().splitlines():
        if line.startswith("# baseline snapshot"):
            base = len(rows)   # the snapshot is a step in RSS: the slopes start after it (the node's own clock)
        elif line.startswith("#"):
            notes.append(line[2:])
        elif line.strip():
            rows.append([float(v) for v in line.split()])
    after = rows[base:] if base is not None else []
    kib = 1024.0
    out = {name: slope_mb_per_h([(r[0], r[i] / kib if i > 1 else r[i]) for r in after])
           for i, name in ((1, "rss"), (2, "python_heap"), (3, "glibc_in_use"), (4, "glibc_free"))}
    out["python_heap_mib"] = [rows[0][2] / 2**20, rows[-1][2] / 2**20] if rows else None
    out["notes"] = notes[1:]
    out["rss_shmem"] = slope_mb_per_h([(r[0], r[8]) for r in after]) if rows and len(rows[0]) > 8 else float("nan")
    return out


def soak(work: Path, duration: float, warmup: float, every: float, split: Dict[str, str], rate_hz: float,
         memtrace=()) -> dict:
    from bench import _start_foxglove, _stop_foxglove

    bag = work / "bag"
    summary = work / "summary.json"
    rt = ["-p", "mode:=realtime"]
    with Graph(work) as g:
        def traced(name: str):   # MWIP_MEMTRACE for the nodes named by --memtrace (each its own file)
            g.env.pop("MWIP_MEMTRACE", None)
            if name in memtrace:
                g.env.update(MWIP_MEMTRACE=str(work / f"{name}.mem"), MWIP_MEMTRACE_WARMUP=f"{warmup:g}",
                             MWIP_MEMTRACE_EVERY=f"{every:g}")
            return name

        procs = {
            "mcap_recorder": g.start(traced("mcap_recorder"), "-p", f"output:={bag}",
                                     *[a for k, v in split.items() for a in ("-p", f"{k}:={v}")]),
            "disturbance_observer": g.start(traced("disturbance_observer"), *rt),
            "dscndo_controller": g.start(traced("dscndo_controller"), *rt, "-p", f"control_rate_hz:={rate_hz:.1f}"),
        }
        traced("foxglove_server")
        client = _start_foxglove(g, procs, work)
        traced("plant_sim")
        procs["plant_sim"] = g.start("plant_sim", *rt, "-p", "expected_subscribers:=4", "-p",
                                     f"duration_s:={duration + 30:.1f}", "-p", f"control_rate_hz:={rate_hz:.1f}",
                                     "-p", f"csv:={work / 'plant.csv'}", "-p", f"summary_json:={summary}")
        if not procs["plant_sim"].wait_for_output("starting realtime run", 120):
            raise SystemExit(f"soak: plant_sim did not start; logs in {work}:\n{procs['plant_sim'].output()}")
        t0 = time.monotonic()
        samples: Dict[str, List[tuple]] = {n: [] for n in NODES}
        parts: Dict[str, List[tuple]] = {n: [] for n in NODES}   # (t, RssAnon, RssFile, RssShmem)
        ended = None
        while True:
            t = time.monotonic() - t0
            for name in NODES:
                r = rss_kib(procs[name].pid)
                if r is not None:
                    samples[name].append((t, r))
                    p = status_kib(*PARTS, pid=procs[name].pid)
                    parts[name].append((t, *(p[k] for k in PARTS)))
            gone = [name for name in NODES if procs[name].poll() is not None]
            if gone:
                ended = f"{', '.join(gone)} exited at t = {t:.0f} s (code {procs[gone[0]].poll()})"
                break
            if t >= duration:
                break
            print(f"soak: t = {t:5.0f} s: " + ", ".join(f"{n} {samples[n][-1][1] / 1024:.1f} MiB"
                                                         for n in NODES if samples[n]), file=sys.stderr, flush=True)
            time.sleep(max(0.0, every - (time.monotonic() - t0 - t)))
        procs["plant_sim"].stop()
        for name in ("dscndo_controller", "disturbance_observer", "mcap_recorder"):
            procs[name].stop()
        _stop_foxglove(procs, client)
    out = {"duration_s": duration, "warmup_s": warmup, "every_s": every, "rate_hz": rate_hz, "split": split,
           "ended_early": ended, "nodes": {}}
    for name in NODES:
        s = samples[name]
        after = [p for p in s if p[0] >= warmup]
        out["nodes"][name] = {
            "rss_start_mib": s[0][1] / 1024 if s else None,
            "rss_warm_mib": after[0][1] / 1024 if after else None,
            "rss_end_mib": s[-1][1] / 1024 if s else None,
            "slope_mb_per_h": slope_mb_per_h(after), "samples": len(after),
            # the second half of the samples after the warm-up alone: a slope that is the warm-up's tail falls here
            "slope_last_half_mb_per_h": slope_mb_per_h([p for p in after if p[0] >= (warmup + duration) / 2]),
            "rss_kib": [[round(t, 1), r] for t, r in s],
            # VmRSS's parts after the warm-up: which of them the slope is in
            **{f"slope_{k}_mb_per_h": slope_mb_per_h([(q[0], q[1 + i]) for q in parts[name] if q[0] >= warmup])
               for i, k in enumerate(PARTS)},
            "rss_parts_kib": [[round(q[0], 1), *q[1:]] for q in parts[name]]}
        if name in memtrace:
            out["nodes"][name]["memtrace"] = memtrace_slopes(work / f"{name}.mem", warmup)
    if summary.exists():
        plant = json.loads(summary.read_text())
        out["periods"] = plant.get("periods")
        out["realtime"] = {k: v for k, v in plant.get("realtime", {}).items() if k != "missed_at_s"}
    from mwip_ros.bag import mcap_files, topic_counts
    from mwip_ros.bag.reader import raw_messages
    files = mcap_files(bag)
    out["bag"] = {"files": len(files), "messages": sum(topic_counts(bag).values()),
                  "read_as_one_run": sum(1 for _ in raw_messages(bag, ["/joint_states"])),
                  "bytes": sum(f.stat().st_size for f in files)}
    return out


def table(r: dict) -> str:
    lines = [f"Soak of the realtime graph, {r['duration_s']:g} s at {r['rate_hz']:g} Hz (RSS sampled every "
             f"{r['every_s']:g} s; slope: least squares after a {r['warmup_s']:g} s warm-up; goal < "
             f"{GOAL_MB_PER_H:g} MB/h)", "",
             "| node | RSS at start [MiB] | after warm-up [MiB] | at the end [MiB] | slope after warm-up [MB/h] "
             "| slope over its second half [MB/h] | slope of RssAnon / RssFile / RssShmem [MB/h] |",
             "|---|---|---|---|---|---|---|"]
    def cell(v):
        return "-" if v is None else f"{v:.1f}"

    for name, n in r["nodes"].items():
        lines.append(f"| {name} | {cell(n['rss_start_mib'])} | {cell(n['rss_warm_mib'])} | {cell(n['rss_end_mib'])} "
                     f"| {n['slope_mb_per_h']:+.2f} | {n['slope_last_half_mb_per_h']:+.2f} | "
                     + " / ".join(f"{n.get(f'slope_{k}_mb_per_h', float('nan')):+.2f}" for k in PARTS) + " |")
    traced = {name: n["memtrace"] for name, n in r["nodes"].items() if n.get("memtrace")}
    if traced:
        lines += ["", "Under MWIP_MEMTRACE (tracemalloc and glibc's mallinfo2), slopes after the warm-up [MB/h]:", "",
                  "| node | RSS | RssShmem | Python heap | glibc heap in use | glibc heap free, kept |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {name} | {m['rss']:+.2f} | {m['rss_shmem']:+.2f} | {m['python_heap']:+.2f} | "
                  f"{m['glibc_in_use']:+.2f} | {m['glibc_free']:+.2f} |" for name, m in traced.items()]
    b = r["bag"]
    lines += ["", f"plant periods: {r.get('periods')}; bag: {b['files']} file(s), {b['bytes'] / 2**20:.1f} MiB, "
                  f"{b['messages']:,} messages ({b['read_as_one_run']:,} joint_states read as one run)"
              + (f"; {r['ended_early']}" if r["ended_early"] else "")]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=600.0, help="seconds from the plant's start (default 600)")
    ap.add_argument("--warmup", type=float, default=60.0, help="seconds before the slope's samples (default 60)")
    ap.add_argument("--every", type=float, default=10.0, help="seconds between RSS samples (default 10)")
    ap.add_argument("--rate", type=float, default=200.0, help="control rate [Hz] (default 200)")
    ap.add_argument("--max-bagfile-size", type=int, default=50_000_000,
                    help="the recorder's max_bagfile_size [bytes] (default 50 MB)")
    ap.add_argument("--max-bagfile-duration", type=int, default=120,
                    help="the recorder's max_bagfile_duration [s] (default 120)")
    ap.add_argument("--no-split", action="store_true", help="record one file (a recorder without splitting)")
    ap.add_argument("--memtrace", default="", help="comma-separated nodes to run under MWIP_MEMTRACE "
                    "(tracemalloc and glibc's heap; mwip_ros.nodes.runtime.memtrace), e.g. "
                    "mcap_recorder,foxglove_server")
    ap.add_argument("--workdir", type=Path, help="keep the logs, csv and bag here (default: a temporary directory)")
    ap.add_argument("--json", type=Path, help="write the results as JSON here")
    ap.add_argument("--markdown", type=Path, help="write the table here")
    args = ap.parse_args(argv)
    if not (args.duration > args.warmup >= 0 and args.every > 0):
        ap.error("need --duration > --warmup >= 0 and --every > 0")
    memtrace = {n.strip() for n in args.memtrace.split(",") if n.strip()}
    if memtrace - set(NODES):
        ap.error(f"--memtrace: unknown node(s) {', '.join(sorted(memtrace - set(NODES)))}; "
                 f"the nodes: {', '.join(NODES)}")
    split = {} if args.no_split else {"max_bagfile_size": str(args.max_bagfile_size),
                                      "max_bagfile_duration": str(args.max_bagfile_duration)}
    with tempfile.TemporaryDirectory() as tmp:
        work = args.workdir or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        r = soak(work, args.duration, args.warmup, args.every, split, args.rate, memtrace)
    text = table(r)
    print(text)
    if args.json:
        args.json.write_text(json.dumps(r, indent=1))
    if args.markdown:
        args.markdown.write_text(text + "\n")
    return 1 if r["ended_early"] else 0


if __name__ == "__main__":
    sys.exit(main())
