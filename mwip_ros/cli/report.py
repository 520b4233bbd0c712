"""``mwip_report``: figures and a metrics table from recorded bags or simulator CSVs.

    mwip_report bags/2026-11-22_101500_dsc bags/2026-11-22_101500_dscndo --out bags/report
    mwip_report logs/dsc.csv logs/dscndo.csv --estimates logs/dsc_estimates.csv logs/dscndo_estimates.csv ...

writes ``fig3.png`` (theta_b, theta_b', theta_w', u; one line per run, the paper's Fig. 3
layout), ``observer.png`` (tau_hat against the true lumped disturbance), ``metrics.md`` /
``metrics.json`` (the metrics of docs/theory.md, per run) and ``animation.gif`` (the robot from the side,
one panel per run, :mod:`mwip_ros.cli.animation`; ``--no-animation`` skips it).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import List, Optional

from mwip_ros.bag import BagError, read_metadata
from mwip_ros.bag.ledger import GAPS_KEY
from mwip_ros.cli import animation, plotting
from mwip_ros.core import metrics
from mwip_ros.core.trajectory import Trajectory
from mwip_ros.params import defaults_for
from mwip_ros.runs import load_run

FALL_ANGLE = defaults_for("plant_sim")["fall_angle"]


def recording_gaps(path) -> str:
    """What a lockstep bag lacks, as its recorder wrote into the metadata ('' when complete or not a bag)."""
    p = Path(path)
    try:
        info = read_metadata(p if p.is_dir() else p.parent) if p.suffix != ".csv" else None
    except BagError:
        return ""
    return str(((info or {}).get("custom_data") or {}).get(GAPS_KEY, "") or "")


def write_report(runs: List[Trajectory], out: Path, window=metrics.WINDOW, fall_angle: float = FALL_ANGLE,
                 warnings: List[str] = (), gif_fps: Optional[float] = animation.FPS) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    named = [(r.label, metrics.compute(r.columns, window, fall_angle)) for r in runs]
    plotting.fig3(runs, out / "fig3.png")
    plotting.observer_plot(runs, out / "observer.png")
    if gif_fps:   # None: no animation; the robot sized by the schema's nominal model (no run records its own)
        animation.write_gif(runs, out / "animation.gif", fps=gif_fps, fall_angle=fall_angle)
    md = ["# mwip_ros report", ""]
    md += [line for w in warnings for line in (f"**Warning:** {w}", "")]
    md += [f"Metrics over t in [{window[0]:g}, {window[1]:g}] s.", "", metrics.markdown_table(named), ""]
    if len(named) >= 2 and named[-1][1].theta_b_p2p > 0:
        ratio = named[0][1].theta_b_p2p / named[-1][1].theta_b_p2p
        md.append(f"theta_b peak-to-peak, {named[0][0]} / {named[-1][0]}: **{ratio:.2f}x**")
        md.append("")
    md += ["![Fig. 3 layout](fig3.png)", "", "![observer](observer.png)", ""]
    md += ["![animation](animation.gif)", ""] if gif_fps else []
    (out / "metrics.md").write_text("\n".join(md))
    doc = {"window": list(window), "runs": {name: m.as_dict() for name, m in named},
           "sources": {r.label: len(r) for r in runs}, "warnings": list(warnings)}
    (out / "metrics.json").write_text(json.dumps(doc, indent=2, allow_nan=True))
    return {"named": named}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="mwip_report",
        description="Read recorded bags (rosbag2 MCAP directories) or mwip_sim / plant_sim CSVs and write "
                    "fig3.png, observer.png, metrics.md, metrics.json and animation.gif into --out.",
        epilog="Exit codes: 0 written, 2 an input cannot be read (a damaged bag names the file and the chunk).")
    ap.add_argument("runs", nargs="+", help="bag directories, .mcap files or .csv files (one run each)")
    ap.add_argument("--out", type=Path, required=True, help="directory for the report (created)")
    ap.add_argument("--labels", nargs="+", default=None, help="a label per run (default: the file/dir name)")
    ap.add_argument("--estimates", nargs="+", default=None, metavar="CSV",
                    help="per run, the disturbance_observer's CSV (its csv parameter: t, tau_hat1, tau_hat2), "
                         "joined to the run by stamp; for plant_sim CSVs, which carry no estimates")
    ap.add_argument("--window", type=float, nargs=2, default=metrics.WINDOW, metavar=("T0", "T1"),
                    help="metrics window [s] (default: 5 10)")
    ap.add_argument("--no-animation", action="store_true", help="do not write animation.gif")
    ap.add_argument("--gif-fps", type=float, default=animation.FPS, metavar="FPS",
                    help=f"animation.gif's frames per second of simulated time, played in real time (default: "
                         f"{animation.FPS:g}; at most 50: browsers slow down shorter GIF frames)")
    args = ap.parse_args(argv)
    if not 0 < args.gif_fps <= 50:
        ap.error(f"--gif-fps must be in (0, 50], got {args.gif_fps:g}")
    for opt in ("labels", "estimates"):
        given = getattr(args, opt)
        if given and len(given) != len(args.runs):
            ap.error(f"--{opt} needs {len(args.runs)} values (one per run), got {len(given)}")
    runs, warnings = [], []
    for i, path in enumerate(args.runs):
        try:
            runs.append(load_run(path, args.labels[i] if args.labels else None,
                                 args.estimates[i] if args.estimates else None))
        except (OSError, ValueError) as exc:  # BagError too: a clear line per unreadable input, no traceback
            print(f"mwip_report: error: {path}: {exc}", file=sys.stderr)
            return 2
        print(f"read {path}: {len(runs[-1])} samples, t = 0 .. {runs[-1].t[-1]:.3f} s")
        gaps = recording_gaps(path)
        if gaps:
            warnings.append(f"{runs[-1].label}: incomplete lockstep recording ({path}): {gaps}")
            print(f"mwip_report: WARNING: {warnings[-1]}", file=sys.stderr)
    res = write_report(runs, args.out, tuple(args.window), warnings=warnings,
                       gif_fps=None if args.no_animation else args.gif_fps)
    print(metrics.text_table(res["named"]))
    files = ["fig3.png", "observer.png", "metrics.md", "metrics.json"] + ["animation.gif"] * (not args.no_animation)
    for f in files:
        print(f"wrote {args.out / f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
