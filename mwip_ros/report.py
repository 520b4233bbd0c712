"""``mwip_report``: figures and a metrics table from recorded bags or simulator CSVs.

    mwip_report bags/2026-11-22_101500_dsc bags/2026-11-22_101500_dscndo --out bags/report

writes ``fig3.png`` (theta_b, theta_b', theta_w', u; one line per run, the
paper's Fig. 3 layout), ``observer.png`` (tau_hat against the true lumped
disturbance) and ``metrics.md`` / ``metrics.json`` (SPEC section 5, per run).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from mwip_ros import metrics, plotting
from mwip_ros.sim import TRAJECTORY_COLUMNS, SimResult, read_csv
from mwip_ros.topics import leaf

NAN = math.nan


def _ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def read_bag_run(bag, label: Optional[str] = None) -> SimResult:
    """Rebuild the run's columns from a bag: states, applied torque, estimate, truth (matched by stamp).

    u_k is the torque the plant applied over period k, i.e. the effort reported
    with state k+1; the last row takes the last recorded wheel_torque_cmd.
    """
    from mwip_ros.bag.reader import read_messages

    states: Dict[int, tuple] = {}
    est: Dict[int, tuple] = {}
    truth: Dict[int, tuple] = {}
    cmds: List[float] = []
    for topic, _type, _t, msg in read_messages(bag):
        b = leaf(topic)
        if b == "joint_states":
            names = list(msg.name)
            try:
                iw, ib = names.index("wheel"), names.index("body_pitch")
            except ValueError:
                continue
            states[_ns(msg.header.stamp)] = (msg.position[iw], msg.position[ib], msg.velocity[iw],
                                             msg.velocity[ib], msg.effort[iw] if len(msg.effort) else NAN)
        elif b == "disturbance_estimate":
            est[_ns(msg.header.stamp)] = (msg.wrench.torque.x, msg.wrench.torque.y)
        elif b == "lumped_disturbance":
            truth[_ns(msg.header.stamp)] = (msg.wrench.torque.x, msg.wrench.torque.y)
        elif b == "wheel_torque_cmd":
            cmds.append(msg.data)
    if not states:
        raise ValueError(f"{bag}: no joint_states messages (is this an mwip_ros bag?)")
    stamps = sorted(states)
    t0 = stamps[0]
    rows = []
    for i, s in enumerate(stamps):
        x = states[s]
        if i + 1 < len(stamps):
            u = states[stamps[i + 1]][4]
        else:
            u = cmds[-1] if cmds else NAN
        rows.append([(s - t0) * 1e-9, *x[:4], u, *est.get(s, (NAN, NAN)), *truth.get(s, (NAN, NAN))])
    data = np.array(rows, dtype=float)
    cols = {n: data[:, i] for i, n in enumerate(TRAJECTORY_COLUMNS)}
    h = float(np.median(np.diff(cols["t"]))) if len(data) > 1 else NAN
    return SimResult(label or Path(bag).name, cols, False, h)


def load_run(path, label: Optional[str] = None) -> SimResult:
    p = Path(path)
    if p.is_file() and p.suffix == ".csv":
        return read_csv(p, label or p.stem)
    if p.is_dir() or p.suffix == ".mcap":
        return read_bag_run(p, label)
    raise ValueError(f"{path}: not a bag directory, .mcap file or .csv file")


def write_report(runs: List[SimResult], out: Path, window=metrics.WINDOW, fall_angle: float = 1.0472) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    named = [(r.label, metrics.compute(r.columns, window, fall_angle)) for r in runs]
    plotting.fig3(runs, out / "fig3.png")
    plotting.observer_plot(runs, out / "observer.png")
    md = [f"# mwip_ros report", "", f"Metrics over t in [{window[0]:g}, {window[1]:g}] s (SPEC section 5).", "",
          metrics.markdown_table(named), ""]
    if len(named) >= 2 and named[-1][1].theta_b_p2p > 0:
        ratio = named[0][1].theta_b_p2p / named[-1][1].theta_b_p2p
        md.append(f"theta_b peak-to-peak, {named[0][0]} / {named[-1][0]}: **{ratio:.2f}x**")
        md.append("")
    md += ["![Fig. 3 layout](fig3.png)", "", "![observer](observer.png)", ""]
    (out / "metrics.md").write_text("\n".join(md))
    doc = {"window": list(window), "runs": {name: m.as_dict() for name, m in named},
           "sources": {r.label: len(r) for r in runs}}
    (out / "metrics.json").write_text(json.dumps(doc, indent=2, allow_nan=True))
    return {"named": named}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="mwip_report",
        description="Read recorded bags (rosbag2 MCAP directories) or mwip_sim / plant_sim CSVs and write "
                    "fig3.png, observer.png, metrics.md and metrics.json into --out.")
    ap.add_argument("runs", nargs="+", help="bag directories, .mcap files or .csv files (one run each)")
    ap.add_argument("--out", type=Path, required=True, help="directory for the report (created)")
    ap.add_argument("--labels", nargs="+", default=None, help="a label per run (default: the file/dir name)")
    ap.add_argument("--window", type=float, nargs=2, default=metrics.WINDOW, metavar=("T0", "T1"),
                    help="metrics window [s] (default: 5 10)")
    args = ap.parse_args(argv)
    if args.labels and len(args.labels) != len(args.runs):
        ap.error(f"--labels needs {len(args.runs)} labels, got {len(args.labels)}")
    runs = []
    for i, path in enumerate(args.runs):
        try:
            runs.append(load_run(path, args.labels[i] if args.labels else None))
        except Exception as exc:  # a clear line per unreadable input, no traceback
            print(f"mwip_report: error: {path}: {exc}", file=sys.stderr)
            return 1
        print(f"read {path}: {len(runs[-1])} samples, t = 0 .. {runs[-1].t[-1]:.3f} s")
    res = write_report(runs, args.out, tuple(args.window))
    print(metrics.text_table(res["named"]))
    for f in ("fig3.png", "observer.png", "metrics.md", "metrics.json"):
        print(f"wrote {args.out / f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
