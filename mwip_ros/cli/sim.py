"""``mwip_sim``: the offline DSC / DSCNDO simulator (no ROS needed).

The verdict of each run is never computed from NaN: a run fails (exit 3) when the robot falls, the law's command is
not a finite number or is implausible, or the state diverges (:func:`mwip_ros.core.closed_loop.sim.simulate`), and says
when and why; a run that ends before the metrics window does is said so, its verdict qualified.  Exit codes:
:mod:`.exits`."""
from __future__ import annotations

import argparse
import math
import os
import signal
import sys
from pathlib import Path

from mwip_ros import params as P
from mwip_ros.cli import interrupts, plotting, render3d
from mwip_ros.cli.exits import EXIT_FELL, EXIT_OK, EXIT_USAGE, epilog
from mwip_ros.cli.outputs import refuse_existing
from mwip_ros.cli.theorem import theorem_report
from mwip_ros.core.kernels import budget
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core import laws
from mwip_ros.core.mobile_base.path import path_metrics, path_table
from mwip_ros.core.plants.plant import PlantDiverged
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.params.paths import default_params_file
from mwip_ros.runs import write_csv


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="mwip_sim",
        description="Simulate the MWIP closed loop offline with the discrete-time contract the ROS graph "
                    "uses (docs/theory.md), print the metrics over the window, optionally write a CSV and "
                    "a plot in the layout of the paper's Fig. 3.",
        epilog="examples:\n  mwip_sim --controller dscndo --plot dscndo.png\n"
               "  mwip_sim --compare --plot compare.png --csv runs.csv   (writes runs_dsc.csv, runs_dscndo.csv)\n"
               "  mwip_sim --compare dsc dscndo lqr lqr_ndo              (the paper's laws and the LQR baseline)\n\n"
               + epilog(e0="every run stayed upright", e1="", e3="a run fell or failed (a line says when and why: "
                        "|theta_b| beyond fall_angle, the law's command not a finite number or beyond 1e6 N m, the "
                        "state diverged)", e130="interrupted (Ctrl-C: finished runs keep their CSVs)",
                        e143="terminated (SIGTERM)"),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--params", type=Path, nargs="+", default=None, metavar="FILE",
                    help="ROS 2 parameter file(s), merged in order as ROS merges repeated --params-file (e.g. "
                         "config/paper.yaml config/sensing_realistic.yaml); default: the package's config/paper.yaml")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--controller", "--law", choices=laws.names(), default=None,
                      help="dsc, dscndo (DSC with the observer term), lqr (the LQR baseline), lqr_ndo (LQR with the "
                           "observer term); default: the file's law and use_observer")
    mode.add_argument("--compare", nargs="*", choices=laws.names(), metavar="LAW",
                      help="run several laws (default: dsc dscndo), overlay them, print a row each")
    ap.add_argument("--duration", type=float, default=None, metavar="S",
                    help="simulated seconds (default: plant_sim.duration_s)")
    ap.add_argument("--csv", type=Path, default=None, metavar="FILE",
                    help="write the trajectory; with --compare, FILE gets _dsc / _dscndo suffixes")
    ap.add_argument("--plot", type=Path, default=None, metavar="FILE.png", help="write the Fig. 3 plot")
    ap.add_argument("--render", type=Path, default=None, metavar="FILE",
                    help="draw the robot in 3D with MuJoCo's renderer as it runs (plant_sim.backend: mujoco): a .gif "
                         "of the run in real time, or a .png sheet of 6 frames; with --compare, FILE gets a suffix "
                         "per law; needs OpenGL (headless: MUJOCO_GL=egl or osmesa)")
    ap.add_argument("--force", action="store_true", help="overwrite a --csv, --plot or --render file that exists")
    ap.add_argument("--window", type=float, nargs=2, default=metrics.WINDOW, metavar=("T0", "T1"),
                    help="metrics window [s] (default: 5 10)")
    ap.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    return ap


def _suffixed(path: Path, label: str) -> Path:
    return path.with_name(f"{path.stem}_{label}{path.suffix or '.csv'}")


def _fail(text: str) -> int:
    print(f"mwip_sim: error: {text}", file=sys.stderr)
    return EXIT_USAGE


DURATION_MAX_S = P.specs_for("plant_sim")["duration_s"].hi   # the parameter file's own limit


def duration_error(seconds: float):
    """The one-line refusal of a ``--duration`` (mwip_sim's, run_experiment.sh's), or None when it is finite,
    > 0 and within ``plant_sim.duration_s``'s range."""
    if math.isfinite(seconds) and 0 < seconds <= DURATION_MAX_S:
        return None
    return f"--duration must be > 0 and <= {DURATION_MAX_S:g} s (plant_sim.duration_s's range), got {seconds:g}"


def _memory_refusal(values, duration, n_runs: int):
    """Why the runs would not fit the memory budget (core.kernels.budget: every law's trajectory is kept), or None."""
    try:
        cap = budget.memory_budget()
    except ValueError as exc:
        return str(exc)
    rate = values["control_rate_hz"]
    dur = values["duration_s"] if duration is None else duration
    n_steps = int(round(dur * rate))
    need = budget.offline_bytes(n_steps, n_runs, values["sensors.delay_periods"], values["actuator.delay_periods"])
    if need <= cap:
        return None
    key = "--duration" if duration is not None else "plant_sim.duration_s"
    most = (cap // (n_runs * budget.OFFLINE_STEP) - 1) / rate
    return (f"{key} {dur:g} s at {rate:g} Hz is {n_steps + 1:,} rows per law x {n_runs} law(s): about "
            f"{budget.fmt_bytes(need)} of trajectories; the memory budget is {budget.fmt_bytes(cap)} (at most "
            f"{most:,.0f} s here; {budget.BUDGET_ENV} sets it)")


def main(argv=None) -> int:
    """mwip_sim; Ctrl-C or SIGTERM: the runs finished so far keep their CSVs, exit 130 / 143."""
    return interrupts.run_main(_main, argv, "mwip_sim")


def _write_atomic(run, out: Path) -> None:
    """The CSV appears whole or not at all (an interrupt mid-write leaves no half file)."""
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        write_csv(run, tmp)
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()


def _main(argv=None) -> int:
    args = _parser().parse_args(argv)
    paths = args.params or [default_params_file()]
    try:
        values = P.merged_values(P.load_param_files(paths, option="--params"))
    except P.ParamError as exc:
        return _fail(str(exc))
    err = duration_error(args.duration) if args.duration is not None else None
    if err:
        return _fail(err)
    if args.compare is not None:
        names = list(dict.fromkeys(args.compare or ["dsc", "dscndo"]))
    else:
        try:
            names = [args.controller or laws.variant(values["law"], values["use_observer"]).name]
        except ValueError as exc:
            return _fail(str(exc))
    reason = next(filter(None, map(laws.unavailable, map(laws.get, names))), None)   # mpc without daqp
    reason = reason or _memory_refusal(values, args.duration, len(names))
    if reason:
        return _fail(reason)
    csv_paths, render_paths = {}, {}
    if args.csv:
        csv_paths = {label: _suffixed(args.csv, label) if len(names) > 1 else args.csv for label in names}
    if args.render:
        reason = _render_refusal(args.render, values)
        if reason:
            return _fail(reason)
        render_paths = {label: _suffixed(args.render, label) if len(names) > 1 else args.render for label in names}
    args.render_paths = render_paths
    outputs = ([("--csv", p) for p in csv_paths.values()] + ([("--plot", args.plot)] if args.plot else [])
               + [("--render", p) for p in render_paths.values()])
    for option, path in outputs:   # before any work: a run is not lost to an output it cannot write
        reason = refuse_existing(path, args.force, option)
        if reason:
            return _fail(reason)
    first = {laws.get(n).family: n for n in reversed(names)}   # a law per family: lqr, lqr_ndo share K
    designed = [laws.get(n).from_params(values, P.physical(values, "nominal"), P.period(values))
                for n in reversed(list(first.values()))]
    # allowed (a weak drive is worth simulating, a chattering law too), but said with the figures
    for warning in [*P.typed.limit_warnings(values, names), *(w for law in designed for w in law.warnings())]:
        print(f"mwip_sim: warning: {warning}", file=sys.stderr)
    if not args.quiet:
        print(theorem_report(values), file=sys.stderr)
        for law in designed:
            text = law.design_text(values)
            if text:
                print(text, file=sys.stderr)
    runs, written = [], []
    try:
        _run_laws(args, values, names, csv_paths, runs, written)
    except KeyboardInterrupt:
        if not args.quiet and sys.stderr.isatty():
            print(file=sys.stderr)
        sig = signal.Signals(interrupts.received()).name if interrupts.received() else "SIGINT"
        kept = f"; kept {', '.join(map(str, written))}" if written else "; no file written"
        print(f"mwip_sim: interrupted ({sig}) after {len(runs)} of {len(names)} run(s){kept}", file=sys.stderr)
        return interrupts.exit_code()
    except PlantDiverged as exc:   # a fault of the physics (backend mujoco), not a trajectory to score
        print(f"mwip_sim: {names[len(runs)]}: {exc}; kept {', '.join(map(str, written)) or 'no file'}",
              file=sys.stderr)
        return 1
    return _finish(args, values, runs)


def _render_refusal(path: Path, values):
    """Why ``--render path`` cannot be drawn (the suffix, the backend, no OpenGL), or None (cli.render3d)."""
    if values["backend"] != "mujoco":
        return (f"--render draws the MuJoCo model, and plant_sim.backend is {values['backend']}: add a parameter file "
                "that sets plant_sim's backend: mujoco (config/square.yaml does)")
    return render3d.suffix_refusal(path) or render3d.gl_refusal()


def _run_laws(args, values, names, csv_paths, runs, written) -> None:
    for label in names:
        def progress(frac, label=label):
            if not args.quiet and sys.stderr.isatty():
                print(f"\r  {label}: {frac * 100:5.1f} %", end="", file=sys.stderr, flush=True)

        loop = P.closed_loop(values, duration=args.duration, controller=label)
        filmer = render3d.Filmer(loop.plant, loop.duration_s, args.render_paths[label]) if args.render else None
        run = simulate(loop, label, progress, on_period=filmer)
        if not args.quiet:
            print(f"\r  {label}: done, {len(run)} samples, h = {run.h * 1e3:.3f} ms"
                  + (f"  FAILED ({run.record.get('failure', 'fall')})" if run.fallen else ""), file=sys.stderr)
        runs.append(run)
        if filmer is not None:
            print(f"wrote {filmer.write(label)}")
        if args.csv:
            out = csv_paths[label]
            _write_atomic(run, out)
            written.append(out)
            print(f"wrote {out}")


def _finish(args, values, runs) -> int:
    named = [(r.label, metrics.compute(r.columns, args.window, values["fall_angle"], r.record.get("t_fall")))
             for r in runs]
    w0, w1 = args.window
    print(f"metrics over t in [{w0:g}, {w1:g}] s:")
    print(metrics.text_table(named))
    short = [m for _, m in named if m.upright and not m.covers_window]
    if short:   # the window was not reached: say so, the metrics are over what there is (or none)
        t_end = max(m.t_end for m in short)
        print(f"note: the run{'s end' if len(short) > 1 else ' ends'} at t = {t_end:.3f} s, before the metrics window "
              f"[{w0:g}, {w1:g}] s ends: the metrics need t >= {w1:g} s ({'none' if t_end < w0 else 'part'} of the "
              f"window was simulated; --duration {w1:g} or a --window inside the run)")
    moving = [(r.label, metrics.motion_metrics(r.columns, values["nominal.r"], values["fall_angle"],
                                               r.record.get("t_fall"))) for r in runs if "v_ref" in r.columns]
    if moving:   # motion.enabled: how each law tracked v* and held its position (docs/theory.md 6.11)
        print("motion (v* of motion.profile or cmd_vel; the hold: v* = 0 at the end, from "
              f"{metrics.HOLD_SETTLE_S:g} s after the stop):")
        print(metrics.motion_table(moving))
    driven = [r for r in runs if "dpsi_ref" in r.columns and "x" in r.columns]
    if driven:   # the yaw stage on a 3D plant: the path against the references' (docs/laws.md, Driving a path)
        print("path (the axle's centre against the ideal path of v* and psi'*):")
        print(path_table([(r.label, path_metrics(r.columns, r.h)) for r in driven]))
    by = dict(named)
    if "dsc" in by and "dscndo" in by:
        print(ratio_line(by["dsc"], by["dscndo"]))
    for run, (_, m) in zip(runs, named):
        print(verdict_line(run, m, w1))
    if args.plot:   # shaded like mwip_report's: the window the metrics above are over, each fall marked
        falls = {name: m.t_fall for name, m in named if m.t_fall is not None}
        plotting.fig3(runs, args.plot, window=args.window, falls=falls)
        print(f"wrote {args.plot}")
        if moving:   # v and v* per law, beside it
            speed = args.plot.with_name(f"{args.plot.stem}_speed{args.plot.suffix}")
            source = " ".join(str(p) for p in (args.params or [default_params_file().name]))   # the references'
            plotting.speed_plot([r for r in runs if "v_ref" in r.columns], speed, values["nominal.r"], source, falls)
            print(f"wrote {speed}")
        if driven:
            where = args.plot.with_name(f"{args.plot.stem}_path{args.plot.suffix}")
            plotting.path_plot(driven, where, driven[0].h, falls=falls)
            print(f"wrote {where}")
    return EXIT_FELL if any(not m.upright for _, m in named) else EXIT_OK


def ratio_line(dsc: metrics.Metrics, dscndo: metrics.Metrics) -> str:
    """DSCNDO's theta_b peak-to-peak over DSC's, or why there is no ratio (a run fell, no sample in the window): never
    a ratio of NaN or of a run that fell."""
    head = "DSCNDO / DSC theta_b peak-to-peak:"
    fell = [name for name, m in (("DSC", dsc), ("DSCNDO", dscndo)) if not m.upright]
    if fell:
        return f"{head} no ratio, {'both fell' if len(fell) == 2 else fell[0] + ' fell'}"
    a, b = dsc.theta_b_p2p, dscndo.theta_b_p2p
    if not (math.isfinite(a) and math.isfinite(b)):
        return f"{head} no ratio, no sample in the window"
    if not (a > 0 and b > 0):
        return f"{head} no ratio, a peak-to-peak of 0 (DSC {a:g}, DSCNDO {b:g} rad)"
    return f"{head} {b / a:.3f} (DSCNDO is {a / b:.1f}x smaller)"


def verdict_line(run, m: metrics.Metrics, window_end: float) -> str:
    """'<label>: stayed upright (max |theta_b| = ... rad)', qualified when the run ended before ``window_end``, or the
    line of its failure (:func:`mwip_ros.core.closed_loop.sim.simulate`'s ``fall_text``): when and why."""
    if not m.upright:
        text = run.record.get("fall_text") or f"FELL at t = {m.t_fall:.3f} s"
        return f"{run.label}: {text}"
    peak = f"max |theta_b| = {float(abs(run['theta_b']).max()):.4f} rad"
    if not m.covers_window:
        return (f"{run.label}: stayed upright to the run's end at t = {m.t_end:.3f} s ({peak}); the metrics window "
                f"needs t >= {window_end:g} s")
    return f"{run.label}: stayed upright ({peak})"


if __name__ == "__main__":
    sys.exit(main())
