"""``mwip_report``: figures and a metrics table from recorded bags or simulator CSVs.

    mwip_report bags/2026-11-22_101500_dsc bags/2026-11-22_101500_dscndo --out bags/report
    mwip_report logs/dsc.csv logs/dscndo.csv --estimates logs/dsc_estimates.csv logs/dscndo_estimates.csv ...

writes ``fig3.png`` (theta_b, theta_b', theta_w', u; one line per run, the paper's Fig. 3
layout), ``observer.png`` (tau_hat against the true lumped disturbance), ``metrics.md`` /
``metrics.json`` (the metrics of docs/theory.md, per run) and ``animation.gif`` (the robot from the side,
one panel per run, :mod:`mwip_ros.cli.animation`; ``--no-animation`` skips it).

What ran is what is judged:

* the metrics window is ``--window`` (default [5, 10] s); when the runs end before the default
  window does, the longest run's second half is used instead and the report says so; a
  ``--window`` given explicitly that the runs do not reach is refused (exit 2);
* ``upright`` means the run never fell (|theta_b| <= fall_angle over the whole run); a fall is
  reported with its time (the plant's own "FALLEN at t = ..." where a bag recorded it, else
  the first sample beyond the fall angle): a ``FELL: <label> at t = <t> s`` line on stdout per
  fallen run (exit 0 still: the report is written), in metrics.md / metrics.json and the figures;
* every run's end is stated ("run ends at t = X s"), a run that ended before the plant's
  configured duration (as the bag's plant log tells it) as cut;
* a bag that ``mwip_bag_repair`` repaired, or whose lockstep recording has gaps, gets a warning;
* with a run labelled ``dscndo``, each law's theta_b peak-to-peak, theta_b RMS and u RMS as a
  ratio to DSCNDO's (else to the last run's).

``--out`` must not already hold a report (exit 2) unless ``--force``, which first removes the
report files there (so none is left over from an earlier report); an ``--out`` that cannot be a
directory or be written into is refused before any input is read (:mod:`mwip_ros.cli.outputs`).

Bounded whatever the inputs hold: a CSV or bag is size-checked before it is read and at most
:data:`mwip_ros.runs.MAX_ROWS` rows (2.8 h at 200 Hz) are read (refused above, one line); every t
must be finite and in order; the figures draw at most :data:`mwip_ros.cli.plotting.MAX_POINTS`
samples a line; the animation has at most :data:`mwip_ros.cli.animation.MAX_FRAMES` frames, counted
before any is allocated, and runs longer than it can play in real time (9 days) are refused with a
pointer to ``--no-animation``.
"""
from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path
from typing import List, Optional, Sequence

import numpy as np

from mwip_ros.bag import REPAIRED_KEY, BagError, read_metadata
from mwip_ros.bag.ledger import GAPS_KEY
from mwip_ros.cli import animation, interrupts, outputs, plotting
from mwip_ros.cli.exits import EXIT_USAGE, epilog
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.closed_loop.trajectory import Trajectory
from mwip_ros.params import defaults_for
from mwip_ros.runs import load_runs

FALL_ANGLE = defaults_for("plant_sim")["fall_angle"]
REPORT_FILES = ("fig3.png", "observer.png", "metrics.md", "metrics.json", "animation.gif")
REFERENCE = "dscndo"     # the law the ratios compare to, when a run carries its label
RATIOS = [("theta_b_p2p", "theta_b p2p"), ("theta_b_rms", "theta_b RMS"), ("u_rms", "u RMS")]
EXIT_BAD_INPUT = EXIT_USAGE   # a run directory or CSV it cannot read (cli.exits)


def bag_custom_data(path) -> dict:
    """A bag's metadata custom_data ({} for a CSV, a bag without it or unreadable metadata)."""
    p = Path(path)
    if p.suffix == ".csv":
        return {}
    try:
        info = read_metadata(p if p.is_dir() else p.parent)
    except BagError:
        return {}
    return dict((info or {}).get("custom_data") or {})


def recording_gaps(path) -> str:
    """What a lockstep bag lacks, as its recorder wrote into the metadata ('' when complete or not a bag)."""
    return str(bag_custom_data(path).get(GAPS_KEY, "") or "")


def repaired(path) -> str:
    """What ``mwip_bag_repair`` wrote into a repaired bag's metadata ('' when it was not repaired)."""
    return str(bag_custom_data(path).get(REPAIRED_KEY, "") or "")


def reference_run(labels: Sequence[str]) -> tuple:
    """(the index of the run the ratios compare to, a sentence saying which and why)."""
    for i, name in enumerate(labels):
        if re.split(r"[^a-z0-9]+", name.lower())[-1:] == [REFERENCE]:   # 'dscndo', '2026-11-22_101500_dscndo'
            return i, f"{name} is the DSCNDO run"
    return len(labels) - 1, f"the last run, as no run is labelled {REFERENCE}"


def ratio_rows(named: Sequence[tuple]) -> tuple:
    """(the reference's label, the sentence of :func:`reference_run`, [(label, [ratio or None, ...])] for every
    other run): its theta_b p2p, theta_b RMS and u RMS over the reference's."""
    i, why = reference_run([n for n, _ in named])
    ref = named[i][1]
    rows = []
    for j, (name, m) in enumerate(named):
        if j == i:
            continue
        vals = []
        for key, _ in RATIOS:   # a run that fell has no steady state to compare: no ratio
            a, b = getattr(m, key), getattr(ref, key)
            ok = m.upright and ref.upright and math.isfinite(a) and math.isfinite(b) and b > 0
            vals.append(a / b if ok else None)
        rows.append((name, vals))
    return named[i][0], why, rows


def ratio_table(named: Sequence[tuple], markdown: bool = True) -> List[str]:
    """The ratios of each run to the reference (:func:`ratio_rows`) as table lines; [] for one run."""
    if len(named) < 2:
        return []
    ref, why, rows = ratio_rows(named)
    head = ["run"] + [f"{label} / {ref} [x]" for _, label in RATIOS]
    fell = {name for name, m in named if not m.upright}

    def missing(name: str) -> str:   # why a run has no ratio
        return "fell" if name in fell else (f"{ref} fell" if ref in fell else "-")

    body = [[name] + [missing(name) if v is None else f"{v:.2f}" for v in vals] for name, vals in rows]
    if markdown:
        return [f"Each run's metrics over {ref}'s ({why}); above 1: {ref}'s is that many times smaller:", "",
                "| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"] + \
               ["| " + " | ".join(r) + " |" for r in body]
    widths = [max(len(head[k]), *(len(r[k]) for r in body)) for k in range(len(head))]
    fmt = "  ".join("{:<%d}" % w for w in widths)
    return [f"ratios to {ref} ({why}):", fmt.format(*head)] + [fmt.format(*r) for r in body]


def run_notes(run: Trajectory, m: metrics.Metrics) -> List[str]:
    """What a run's end was: its fall, its cut (the plant's configured duration, where the bag recorded it); that a
    robot's bag has no truth (its numbers are the estimate's); a spatial plant's (backend mujoco) 3D pose at the end
    (:func:`pose_summary`); with robot_state's odom in the bag, its drift from the true pose (docs/theory.md 6.12)."""
    rec = run.record or {}
    odo = rec.get("odometry")
    pose = pose_summary(run)
    notes = _end_notes(run, m, rec)
    if rec.get("states_from") == "estimate":   # a robot's bag (runs.read_bag_run): no truth to judge
        notes.append("no truth in the bag (a robot): its states and metrics are the state estimator's estimate "
                     "(joint_states)")
    if pose:
        f = {k: _fixed(v, 4 if k != "t_s" else 3) for k, v in pose.items()}
        notes.append(f"3D pose at t = {f['t_s']} s: x {f['x_m']} m, y {f['y_m']} m, yaw {f['yaw_rad']} rad (max "
                     f"|roll| {f['roll_max_abs_rad']} rad); the wheels turned {f['wheel_left_rad']} rad (left) and "
                     f"{f['wheel_right_rad']} rad (right)")
    if odo:
        notes.append(f"odom drifts {odo['drift_m']:.4g} m from the true pose over {odo['t_s']:.3f} s (x "
                     f"{odo['odom_x_m']:.4g} m against {odo['true_x_m']:.4g} m)")
    return notes


def _fixed(v: float, digits: int) -> str:
    """``v`` to ``digits`` decimals, a value that rounds to zero as 0 (never '-0.0000')."""
    return f"{round(v, digits) + 0.0:.{digits}f}"


def pose_summary(run: Trajectory) -> Optional[dict]:
    """A spatial plant's pose columns (core.closed_loop.trajectory.POSE_COLUMNS) summed up: where the axle ends relative
    to where it started (x, y [m], in the frame ``odom`` fixed at the start), the heading at the end, the largest roll,
    and how far each wheel turned [rad].  None for a planar run (no pose columns) or a pose that is not finite (no
    figure from NaN)."""
    if "x" not in run.columns or not len(run):
        return None
    cols = {c: np.asarray(run[c], dtype=float) for c in ("x", "y", "yaw", "roll", "wheel_left", "wheel_right")}
    if not all(np.isfinite(v).all() for v in cols.values()):
        return None
    return {"t_s": float(run.t[-1]), "x_m": float(cols["x"][-1] - cols["x"][0]),
            "y_m": float(cols["y"][-1] - cols["y"][0]), "yaw_rad": float(cols["yaw"][-1]),
            "roll_max_abs_rad": float(np.abs(cols["roll"]).max()),
            "wheel_left_rad": float(cols["wheel_left"][-1] - cols["wheel_left"][0]),
            "wheel_right_rad": float(cols["wheel_right"][-1] - cols["wheel_right"][0])}


def _end_notes(run: Trajectory, m: metrics.Metrics, rec: dict) -> List[str]:
    end = f"run ends at t = {m.t_end:.3f} s"
    if m.t_fall is not None:
        said = f" (the plant logged: \"{rec['fall_text']}\")" if rec.get("fall_text") else ""
        return [f"{end}: it FELL at t = {m.t_fall:.3f} s{said}"]
    dur = rec.get("duration_s")
    if rec.get("interrupted_at") is not None:
        return [f"{end}: cut, the plant was interrupted at t = {rec['interrupted_at']:.3f} s of its configured "
                f"{dur:g} s"]
    h = run.h if run.h and math.isfinite(run.h) else 0.0
    if dur and m.t_end < dur - max(h, 1e-6) / 2:
        return [f"{end}: cut, before the plant's configured duration of {dur:g} s"]
    if dur:
        return [f"{end} (the plant's configured duration: {dur:g} s)"]
    if dur == 0.0:
        return [f"{end} (the plant ran until stopped)"]
    return [end]


def write_report(runs: List[Trajectory], out: Path, window=metrics.WINDOW, fall_angle: float = FALL_ANGLE,
                 warnings: List[str] = (), gif_fps: Optional[float] = animation.FPS,
                 window_requested: bool = False) -> dict:
    """Write the report of ``runs`` into ``out``.

    Returns a dict: ``named`` [(label, Metrics)], ``window`` (the one used), ``window_note`` ('' or why it
    is not the requested one), ``fallen`` {label: t_fall} of the runs that fell (empty: none did),
    ``notes`` {label: [sentences on the run's end]}, ``files`` (the names written).  Raises
    :class:`metrics.WindowError` when ``window_requested`` and the runs do not reach the window."""
    t_end = max(float(r.t[-1]) for r in runs)
    window, window_note = metrics.fit_window(window, t_end, window_requested)
    named, notes = [], {}
    for r in runs:
        rec = r.record or {}
        m = metrics.compute(r.columns, window, rec.get("fall_angle", fall_angle), rec.get("t_fall"))
        named.append((r.label, m))
        notes[r.label] = run_notes(r, m)
        if not m.covers_window and m.upright:
            notes[r.label].append(f"it ends before the window's end ({window[1]:g} s): its metrics cover "
                                  f"{m.samples} samples of the window")
    fallen = {name: m.t_fall for name, m in named if m.t_fall is not None}
    out.mkdir(parents=True, exist_ok=True)
    plotting.fig3(runs, out / "fig3.png", window=window, falls=fallen)
    plotting.observer_plot(runs, out / "observer.png", window=window)
    files = ["fig3.png", "observer.png"]
    if plotting.pitch_estimate_plot(runs, out / "pitch_estimate.png", window=window):   # raw sensors' runs
        files.append("pitch_estimate.png")
    if gif_fps:   # None: no animation; the robot sized by the schema's nominal model (no run records its own)
        animation.write_gif(runs, out / "animation.gif", fps=gif_fps, fall_angle=fall_angle)
        files.append("animation.gif")
    md = ["# mwip_ros report", ""]
    md += [line for w in warnings for line in (f"**Warning:** {w}", "")]
    if window_note:
        md += [f"**Note:** {window_note}.", ""]
    md += [f"Metrics over t in [{window[0]:g}, {window[1]:g}] s. \"upright\": never fell (|theta_b| <= fall angle "
           f"over the whole run).", "", metrics.markdown_table(named), ""]
    md += ["## Runs", ""] + [f"- **{name}**: " + "; ".join(notes[name]) for name, _ in named] + [""]
    md += [f"**FELL: {name} at t = {t:.3f} s**" + "  " for name, t in fallen.items()] + ([""] if fallen else [])
    ratios = ratio_table(named)
    md += ratios + ([""] if ratios else [])
    md += ["![Fig. 3 layout](fig3.png)", "", "![observer](observer.png)", ""]
    md += ["![pitch and its estimate](pitch_estimate.png)", ""] if "pitch_estimate.png" in files else []
    md += ["![animation](animation.gif)", ""] if gif_fps else []
    (out / "metrics.md").write_text("\n".join(md))
    ref, why, rows = ratio_rows(named) if len(named) >= 2 else (None, "", [])
    doc = {"window": list(window), "window_note": window_note, "window_requested": bool(window_requested),
           "runs": {name: m.as_dict() for name, m in named},
           "fallen": fallen, "notes": notes,
           "ratios": {"reference": ref, "why": why, "units": "ratio (run / reference)",
                      "runs": {name: dict(zip((k for k, _ in RATIOS), vals)) for name, vals in rows}},
           "sources": {r.label: len(r) for r in runs}, "warnings": list(warnings),
           "poses": {r.label: p for r in runs for p in (pose_summary(r),) if p}}
    (out / "metrics.json").write_text(json.dumps(metrics.json_safe(doc), indent=2, allow_nan=False))
    files += ["metrics.md", "metrics.json"]
    return {"named": named, "window": window, "window_note": window_note, "fallen": fallen, "notes": notes,
            "files": files}


def existing_report(out: Path) -> List[str]:
    """The report files already in ``out``."""
    return outputs.existing_outputs(out, REPORT_FILES)


def _fail(text: str) -> int:
    print(f"mwip_report: error: {text}", file=sys.stderr)
    return EXIT_BAD_INPUT


def main(argv=None) -> int:
    """mwip_report; SIGTERM is handled like Ctrl-C (one line, exit 143 / 130)."""
    return interrupts.run_main(_main, argv, "mwip_report")


def _main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="mwip_report",
        description="Read recorded bags (rosbag2 MCAP directories) or mwip_sim / plant_sim CSVs and write\n"
                    "fig3.png, observer.png, metrics.md, metrics.json and animation.gif into --out.",
        epilog=epilog(e0="written (also when a run fell: a 'FELL: <label> at t = <t> s' line per fallen run)",
                      e1="", e2="an input cannot be read (a damaged bag names the file and the chunk), --out "
                      "already holds a report (without --force), --window lies outside the runs, or a law plug-in "
                      "failed to import", e3=""),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="bag directories, .mcap files or .csv files (one run each)")
    ap.add_argument("--out", type=Path, required=True,
                    help="directory for the report (created; must not hold a report unless --force)")
    ap.add_argument("--force", action="store_true",
                    help="write into an --out that holds a report: its report files are removed first")
    ap.add_argument("--labels", nargs="+", default=None, help="a label per run (default: the file/dir name)")
    ap.add_argument("--estimates", nargs="+", default=None, metavar="CSV",
                    help="per run, the disturbance_observer's CSV (its csv parameter: t, tau_hat1, tau_hat2), "
                         "joined to the run by stamp; for plant_sim CSVs, which carry no estimates")
    ap.add_argument("--window", type=float, nargs=2, default=None, metavar=("T0", "T1"),
                    help="metrics window [s] (default: 5 10, or the runs' second half when they end before 10 s; "
                         "a window given here must lie within the runs)")
    ap.add_argument("--no-animation", action="store_true", help="do not write animation.gif")
    ap.add_argument("--gif-fps", type=float, default=animation.FPS, metavar="FPS",
                    help=f"animation.gif's frames per second of simulated time, played in real time (default: "
                         f"{animation.FPS:g}; at most 50: browsers slow down shorter GIF frames)")
    ap.add_argument("--render", type=Path, default=None, metavar="FILE",
                    help="also draw the robot in 3D as a viewer of the bag's robot_description and frames shows it "
                         "(Foxglove's 3D panel, RViz): the URDF placed by robot_state's odom and wheel joints; a .png "
                         "sheet of 6 frames or a .gif; one bag recorded with robot_state (run_experiment.sh "
                         "--robot-state); needs OpenGL (headless: MUJOCO_GL=egl or osmesa)")
    args = ap.parse_args(argv)
    if args.render is not None:
        from mwip_ros.cli import render3d
        reason = ("--render draws one bag: give one" if len(args.runs) != 1 or str(args.runs[0]).endswith(".csv")
                  else render3d.suffix_refusal(args.render) or outputs.refuse_existing(args.render, args.force,
                                                                                         "--render")
                  or render3d.gl_refusal())
        if reason:
            return _fail(reason)
    if not 0 < args.gif_fps <= 50:
        ap.error(f"--gif-fps must be in (0, 50], got {args.gif_fps:g}")
    for opt in ("labels", "estimates"):
        given = getattr(args, opt)
        if given and len(given) != len(args.runs):
            ap.error(f"--{opt} needs {len(args.runs)} values (one per run), got {len(given)}")
    reason = outputs.refuse_directory(args.out, REPORT_FILES, args.force, "--out", "a report")
    if reason:
        return _fail(reason)
    runs, warnings = [], []
    for i, path in enumerate(args.runs):
        try:   # a bag with resets holds several runs: each is reported as a run of its own
            got = load_runs(path, args.labels[i] if args.labels else None,
                            args.estimates[i] if args.estimates else None)
        except (OSError, ValueError) as exc:  # BagError too: a clear line per unreadable input, no traceback
            text = " ".join(str(exc).split())
            return _fail(text if text.startswith(str(path)) else f"{path}: {text}")
        except MemoryError:
            return _fail(f"{path}: out of memory reading it")
        for j, run in enumerate(got):
            runs.append(run)
            which = f" run {j + 1} of {len(got)} ({run.label})" if len(got) > 1 else ""
            print(f"read {path}{which}: {len(run)} samples, t = 0 .. {run.t[-1]:.3f} s")
        for what, text in (("incomplete lockstep recording", recording_gaps(path)),
                           ("repaired bag (mwip_bag_repair)", repaired(path))):
            if text:
                warnings.append(f"{runs[-1].label}: {what} ({path}): {text}")
                print(f"mwip_report: WARNING: {warnings[-1]}", file=sys.stderr)
    requested = args.window is not None
    window = tuple(args.window) if requested else metrics.WINDOW
    try:
        metrics.fit_window(window, max(float(r.t[-1]) for r in runs), requested)
    except metrics.WindowError as exc:
        return _fail(f"--window: {exc}")
    why = plotting.refusal(runs)
    if why:
        return _fail(why)
    if not args.no_animation:
        why = animation.refusal(runs)
        if why:
            return _fail(f"{why}; add --no-animation for the rest of the report")
    reason = outputs.remove_stale(args.out, REPORT_FILES)   # --force: nothing of an earlier report is left
    if reason:
        return _fail(reason)
    reason = outputs.make_directory(args.out, "--out")
    if reason:
        return _fail(reason)
    res = write_report(runs, args.out, window, warnings=warnings,
                       gif_fps=None if args.no_animation else args.gif_fps, window_requested=requested)
    if res["window_note"]:
        print(f"NOTE: {res['window_note']}")
    w = res["window"]
    print(f"metrics over t in [{w[0]:g}, {w[1]:g}] s:")
    print(metrics.text_table(res["named"]))
    for line in ratio_table(res["named"], markdown=False):
        print(line)
    for name, lines in res["notes"].items():
        for line in lines:
            print(f"{name}: {line}")
    for name, t in res["fallen"].items():
        print(f"FELL: {name} at t = {t:.3f} s")
    for f in res["files"]:
        print(f"wrote {args.out / f}")
    if args.render is not None:
        try:
            drawn, trees = render3d.film_bag(args.runs[0], args.render)
        except ValueError as exc:
            return _fail(f"--render: {exc}")
        print(f"wrote {drawn} ({trees} frame trees of odom and the wheels)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
