#!/usr/bin/env python3
"""A flood on each input of the realtime loop, one at a time, as fast as one local publisher can send it.

    source scripts/env.sh && python scripts/bench_input_flood.py [--params FILE ...] [--topics T1,T2,...]
        [--flood-s 5] [--markdown FILE]

Per topic (default: none, then cmd_vel, emergency_stop, external_wrench, driver_state, disturbance_estimate,
joint_states, and the last two's ``_bad`` kinds: NaN and absurd values) it runs the realtime graph
(disturbance_observer, dscndo_controller, plant_sim for ``--flood-s`` + 3 s; the parameter files default to
config/paper.yaml and config/drive.yaml: the MuJoCo plant, cmd_vel tracked, the yaw stage) and, from the 100th state,
``test/side_flooder.py`` on that topic for ``--flood-s`` seconds (what each topic gets: see that file; ``none``: no
flooder, the machine's own baseline). It prints one row per run: what the flooder sent and its rate, whether the robot
stayed up (or when it fell, or the driver's fault), the plant's period (p99 and the longest), its missed deadlines and
stale-command substitutions, the states the controller answered, and the wall time the run took against its simulated
time. The numbers are this machine's at that moment (print ``uptime`` beside them): BENCHMARKS.md, "Input floods", has a
table. Exit 0.
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "test"))
from graphproc import Graph  # noqa: E402

FLOODER = REPO / "test" / "side_flooder.py"
TOPICS = ("none", "cmd_vel", "cmd_vel_bad", "cmd_vel_valid", "emergency_stop", "external_wrench", "driver_state",
          "disturbance_estimate", "joint_states", "disturbance_estimate_bad", "joint_states_bad")


def run(work: Path, topic: str, files, flood_s: float) -> dict:
    """One realtime run with a flood on ``topic`` (``none``: none): its row."""
    run_s = flood_s + 3.0
    work.mkdir(parents=True, exist_ok=True)
    with Graph(work) as g:
        g.start("disturbance_observer", "-p", "mode:=realtime", params=files)
        ctl = g.start("dscndo_controller", "-p", "mode:=realtime", params=files)
        flood = None if topic == "none" else g.start(
            "side_flooder", cmd=[sys.executable, str(FLOODER), topic, str(flood_s), "100"], params=None, as_given=True)
        plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", f"duration_s:={run_s}", params=files)
        code = plant.wait(180 + run_s)
        if flood is not None:
            flood.wait(60)
        ctl.stop()
        g.close()
    out, c_out = plant.output(), ctl.output()
    row = {"topic": topic, "exit": code}
    if flood is not None:
        m = re.search(r"flooded (\d+) in ([\d.]+) s", flood.output())
        row["sent"], row["rate"] = (int(m.group(1)), int(m.group(1)) / float(m.group(2))) if m else (None, None)
    fell = re.search(r"FALLEN at t = ([\d.]+)", out)
    fault = re.search(r"driver: t = ([\d.]+) s: \w+ -> fault \((\w+)", out)
    row["outcome"] = (f"fell at {fell.group(1)} s" if fell else "upright") + \
        (f" ({fault.group(2)} fault at {fault.group(1)} s)" if fault else "")
    rt = re.search(r"period between wakes p50 = [\d.]+ ms, p99 = ([\d.]+) ms, max = ([\d.]+) ms.*stale-command "
                   r"substitutions = (\d+)", out)
    if rt:
        row.update(p99=float(rt.group(1)), longest=float(rt.group(2)), stale=int(rt.group(3)))
    missed = re.search(r"(\d+) missed \(deadline", out) or re.search(r"missed deadlines = (\d+)", out)
    if missed:
        row["missed"] = int(missed.group(1))
    if not rt:   # the line before issue 47's schedule: "p99 = .., max = .. (nominal ..); missed deadlines = .."
        old = re.search(r"p99 = ([\d.]+) ms, max = ([\d.]+) ms.*stale-command substitutions = (\d+)", out)
        if old:
            row.update(p99=float(old.group(1)), longest=float(old.group(2)), stale=int(old.group(3)))
    sim = re.search(r"([\d.]+) s simulated in ([\d.]+) s wall", out)
    if sim:
        row["sim"], row["wall"] = float(sim.group(1)), float(sim.group(2))
    ans = re.search(r"answered (\d+) states", c_out)
    row["answered"] = int(ans.group(1)) if ans else None
    acc = re.search(r"cmd_vel: (\d+) accepted", c_out)
    row["accepted"] = int(acc.group(1)) if acc else None
    return row


def table(rows) -> str:
    lines = ["| flood on | sent (rate) | outcome | plant period p99 / longest [ms] | missed deadlines | stale commands "
             "| answered | cmd_vel accepted | simulated / wall [s] |", "|---|---|---|---|---|---|---|---|---|"]
    nan = float("nan")
    for r in rows:
        sent = "-" if r["topic"] == "none" else (f"{r['sent']:,} ({r['rate'] / 1000:.0f} k/s)" if r.get("sent")
                                                 else "the flooder failed")
        lines.append(f"| {r['topic']} | {sent} | {r['outcome']} | {r.get('p99', nan):.1f} / "
                     f"{r.get('longest', nan):.0f} | {r.get('missed', '-')} | {r.get('stale', '-')} | "
                     f"{r.get('answered', '-')} | {r.get('accepted') if r.get('accepted') is not None else '-'} | "
                     f"{r.get('sim', nan):.2f} / {r.get('wall', nan):.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--params", nargs="+", type=Path,
                    default=[REPO / "config" / "paper.yaml", REPO / "config" / "drive.yaml"])
    ap.add_argument("--topics", default=",".join(TOPICS), help="comma-separated, of: " + ", ".join(TOPICS))
    ap.add_argument("--flood-s", type=float, default=5.0)
    ap.add_argument("--markdown", type=Path, default=None, help="write the table here too")
    a = ap.parse_args(argv)
    topics = [t for t in a.topics.split(",") if t]
    unknown = [t for t in topics if t not in TOPICS]
    if unknown:
        ap.error(f"--topics: {', '.join(unknown)} (one of {', '.join(TOPICS)})")
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"start: {load}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory(prefix="mwip_flood_") as tmp:
        for i, topic in enumerate(topics):
            t0 = time.monotonic()
            rows.append(run(Path(tmp) / f"{i}_{topic}", topic, a.params, a.flood_s))
            print(f"{topic}: {rows[-1]} ({time.monotonic() - t0:.0f} s)", flush=True)
    load_end = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    text = table(rows) + f"\n\n(start: {load}; end: {load_end})\n"
    print(text)
    if a.markdown is not None:
        a.markdown.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
