"""``mwip_robot``: the closed loop on a robot's own interface, offline, in one process (no ROS): the project's state
estimator, observer and law (:func:`mwip_ros.core.closed_loop.loop.decide`) between a backend's reads and writes
(:mod:`mwip_ros.robot.closed_loop`).

    mwip_robot --robot upkie-pybullet --params config/paper.yaml config/upkie.yaml
    mwip_robot --robot upkie-pybullet --params config/paper.yaml config/upkie.yaml --controller lqr_ndo --push 20 0.1 15
    mwip_robot --robot upkie-spine --params config/paper.yaml config/upkie.yaml --realtime     # on the robot

Prints the run's numbers against the goals (docs/hardware-upkie.md): upright, theta_b RMS and worst over the window,
the estimator's pitch error, u RMS, the axle's largest and final distance from its start; ``--csv`` writes the
trajectory (``mwip_report`` and ``mwip_identify --raw`` read it), ``--json`` the numbers.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

from mwip_ros import params as P
from mwip_ros.cli.exits import EXIT_FELL, EXIT_OK, EXIT_USAGE, epilog, plugin_refusal
from mwip_ros.cli.outputs import refuse_existing
from mwip_ros.core import laws
from mwip_ros.core.closed_loop.metrics import json_safe
from mwip_ros.params.paths import default_params_file

PROG = "mwip_robot"
ROBOTS = ("upkie-pybullet", "upkie-spine")


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog=PROG,
        description="Run the closed loop (state estimator, observer, law) on a robot's own interface, in one process "
                    "without ROS: upkie-pybullet is Upkie in its own PyBullet simulation (headless, stepped on demand, "
                    "or paced with --realtime), upkie-spine is Upkie's spine (the robot; it cannot be tried without "
                    "one). The raw IMU and wheel encoders go through the state estimator (--measure truth: the "
                    "simulator's true state instead). Prints upright, theta_b RMS and worst over the window, the "
                    "estimator's pitch error, u RMS and the axle's drift.",
        epilog="examples:\n"
               "  mwip_robot --robot upkie-pybullet --params config/paper.yaml config/upkie.yaml\n"
               "  mwip_robot --robot upkie-pybullet --params config/paper.yaml config/upkie.yaml --controller lqr_ndo "
               "--push 20 0.1 15\n"
               "  mwip_robot --robot upkie-pybullet --params config/paper.yaml config/upkie.yaml config/identify_upkie"
               ".yaml --csv ident.csv\n\n"
               + epilog(e3="the robot fell, its command was refused, or a device reported a fault (the line says "
                           "when and why)", e130="", e143=""),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", choices=ROBOTS, required=True, help="the robot side")
    ap.add_argument("--params", type=Path, nargs="+", default=None, metavar="FILE",
                    help="ROS 2 parameter file(s), merged in order (default: the package's config/paper.yaml; for "
                         "Upkie: config/paper.yaml config/upkie.yaml)")
    ap.add_argument("--controller", choices=laws.names(), default=None,
                    help="the law (default: the file's law and use_observer)")
    ap.add_argument("--duration", type=float, default=None, metavar="S",
                    help="seconds to run (default: plant_sim.duration_s)")
    ap.add_argument("--measure", choices=("raw", "truth"), default="raw",
                    help="raw: the IMU and encoders through the state estimator (default); truth: the simulator's "
                         "true planar state")
    ap.add_argument("--push", type=float, nargs=3, default=None, metavar=("T", "DURATION", "FORCE"),
                    help="a forward push of FORCE newtons on the body from T for DURATION seconds (PyBullet)")
    ap.add_argument("--realtime", action="store_true", help="pace the periods to the wall clock (and report the "
                                                            "timing); without it a simulation runs in lockstep")
    ap.add_argument("--window", type=float, nargs=2, default=None, metavar=("T0", "T1"),
                    help="the metrics window [s] (default: 5 s to the end; the second half of a run shorter than 10 s)")
    ap.add_argument("--csv", type=Path, default=None, metavar="FILE", help="write the trajectory (mwip_sim's columns)")
    ap.add_argument("--json", type=Path, default=None, metavar="FILE", help="write the numbers as JSON")
    ap.add_argument("--force", action="store_true", help="overwrite --csv / --json files that exist")
    return ap


def _fail(text: str) -> int:
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return EXIT_USAGE


def main(argv=None) -> int:
    """mwip_robot: 0 upright, 2 a mistake in the input (one line), 3 the robot fell or faulted."""
    args = _parser().parse_args(argv)
    refusal = plugin_refusal(PROG)
    if refusal is not None:
        return refusal
    try:
        values = P.merged_values(P.load_param_files(args.params or [default_params_file()], option="--params"))
    except P.ParamError as exc:
        return _fail(str(exc))
    for option, path in (("--csv", args.csv), ("--json", args.json)):
        reason = refuse_existing(path, args.force, option) if path is not None else None
        if reason:
            return _fail(reason)
    duration = values["duration_s"] if args.duration is None else args.duration
    if not (math.isfinite(duration) and duration > 0.0):
        return _fail(f"--duration {duration:g}: give a positive number of seconds (plant_sim.duration_s 0, 'until "
                     f"stopped', is for the graph)")
    if args.window is None:
        window = (5.0, duration) if duration >= 10.0 else (duration / 2.0, duration)
    else:
        window = tuple(args.window)
        if not (0.0 <= window[0] < window[1] <= duration):
            return _fail(f"--window {window[0]:g} {window[1]:g}: give 0 <= T0 < T1 <= the run's {duration:g} s")
    if args.measure == "raw" and values.get("sensors.model") != "raw":
        return _fail("--measure raw needs sensors.model: raw and a state_estimator method in the parameter files "
                     "(config/upkie.yaml sets them)")
    from mwip_ros.params.upkie import upkie_config
    from mwip_ros.robot.backend import BackendError
    from mwip_ros.robot.closed_loop import Push, run, summary
    from mwip_ros.robot.upkie import UpkieBackend
    try:
        loop = P.typed.closed_loop(values, controller=args.controller)
        config = upkie_config(values)
    except ValueError as exc:
        return _fail(str(exc))
    push = Push(*args.push) if args.push else None
    try:
        backend = UpkieBackend.pybullet(config) if args.robot == "upkie-pybullet" else UpkieBackend.spine(config)
    except BackendError as exc:
        return _fail(str(exc))
    with backend:
        traj = run(backend, loop, duration, measure=args.measure, push=push, realtime=args.realtime)
    s = summary(traj, window)
    s.update(robot=args.robot, controller=loop.controller, measure=args.measure, window=list(window),
             duration=duration, push=list(args.push) if args.push else None, timing=traj.record.get("timing"))
    _print(s)
    if args.csv is not None:
        from mwip_ros.runs import write_csv
        tmp = args.csv.with_name(f".{args.csv.name}.{os.getpid()}.tmp")
        write_csv(traj, tmp)
        os.replace(tmp, args.csv)
    if args.json is not None:
        args.json.write_text(json.dumps(json_safe(s), indent=1) + "\n")
    return EXIT_OK if s["upright"] else EXIT_FELL


def _num(v: float, fmt: str) -> str:
    """A number, or '-' where the run has none (a window it did not cover: no figure is made of NaN)."""
    return format(v, fmt) if isinstance(v, float) and math.isfinite(v) else "-"


def _print(s: dict) -> None:
    w0, w1 = s["window"]
    lines = [f"{s['robot']}, {s['controller']}, measured {s['measure']}: "
             + ("upright" if s["upright"] else s["failure"]),
             f"  theta_b over [{w0:g}, {w1:g}] s: RMS {_num(s['theta_b_rms'], '.5f')} rad, worst "
             f"{_num(s['theta_b_max_abs'], '.5f')} rad",
             f"  estimator pitch error RMS {_num(s['theta_b_est_err_rms'], '.5f')} rad, u RMS "
             f"{_num(s['u_rms'], '.4f')} N m",
             f"  axle drift: largest {_num(s['max_drift'], '.4f')} m, final {_num(s['final_drift'], '.4f')} m"]
    if s.get("timing"):
        t = s["timing"]
        lines.append(f"  realtime: {t['periods']} periods in {t['wall_s']:.1f} s, {t['late']} late (> 1 period), "
                     f"lateness p99 {t['lateness_p99_ms']:.3f} ms, worst {t['lateness_max_ms']:.3f} ms; a period's "
                     f"work median {t['work_p50_ms']:.3f} ms, p99 {t['work_p99_ms']:.3f} ms, worst "
                     f"{t['work_max_ms']:.3f} ms")
    print("\n".join(lines))


if __name__ == "__main__":   # pragma: no cover
    sys.exit(main())
