"""``mwip_identify``: the nominal body (m_b, I_b, l) identified from a recorded run (docs/theory.md 6.9).

    mwip_identify runs/ident.csv --out identified.yaml
    mwip_identify bags/2026-11-22_101500_ident --params config/paper.yaml --out identified.yaml --force
    mwip_sim --params config/paper.yaml identified.yaml          # the overlay goes after the base file

Reads a CSV written by ``mwip_sim --csv`` (or ``plant_sim``'s) or an MCAP bag written by the recorder
(:func:`mwip_ros.runs.load_run`, as ``mwip_report`` reads them); the torque is the CSV's ``u_applied``
column where it has one (the torque that acted, with a motor) else ``u``, and a bag's applied torque
(the effort reported with the next state).  The base parameter file(s) give ``nominal.m_w``, ``I_w``,
``r``, ``g`` (known); :func:`mwip_ros.core.identification.identify.identify` fits eq. (1) by least squares.

Prints every value with its 95 % interval, the residual RMS of each row of eq. (1), the condition
number, D_w, D_b and the check of G_b against m_b g l; writes a ROS 2 parameter overlay with
``nominal.m_b``, ``nominal.I_b``, ``nominal.l`` under ``/**`` (where the base file keeps the nominal model
that the observer and the controller share), checked by merging it over the base file.

``--drive`` fits the drive instead (:mod:`mwip_ros.core.identification.drive_identify`: K_t, R, I_max with V_max the
base file's ``motor.voltage_limit``) from ``u``, ``u_applied`` and the wheel speed, and writes ``plant_sim``'s
``motor.*`` overlay; ``config/identify_drive.yaml`` is its experiment.

``--raw`` fits the raw sensors alone (:mod:`mwip_ros.core.identification.identify_raw`); a bag's are read from its
``imu/data_raw`` and ``wheel_encoder`` messages (:mod:`mwip_ros.cli.identify_bag`: a robot's bag of the realtime graph,
nothing else needed).  ``--retune`` then tunes ``--law``'s gains on the identified model
(:mod:`mwip_ros.cli.identify_retune`, ``mwip_tune``'s search) and writes them with ``nominal.*`` into one parameter
file.

Exit 0 when written; 2 (one line on stderr saying why) for a log that is too short or does not excite
the parameters, a raw log whose drive is saturated throughout, a bag cut short, for an unreadable log or
parameter file, or for an existing ``--out`` without ``--force`` (checked before the log is read).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

import numpy as np

from mwip_ros.cli.exits import EXIT_USAGE, plugin_refusal
from mwip_ros import params as P
from mwip_ros.cli.outputs import refuse_existing
from mwip_ros.core.identification import identify as ID
from mwip_ros.params.paths import default_params_file

PROG = "mwip_identify"
EXIT_REFUSED = EXIT_USAGE   # an input it refuses, in one line (cli.exits)
NEEDED = ("t", "theta_b", "dtheta_w", "dtheta_b")
RAW = ("gyro", "accel_x", "accel_z", "encoder", "encoder_rate", "u_applied")
SATURATED_SHARE = 0.5   # --raw: refused when the torque sits at its largest magnitude in more of the periods


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog=PROG,
        description="Identify the body's mass m_b, inertia I_b and centre of gravity l from a recorded balancing "
                    "run with a known excitation (excitation.type chirp or prbs on the controller, no tau_ext): "
                    "least squares on both rows of eq. (1), linear in m11, m12, m22, G_b, D_w, D_b, with m_w, I_w, "
                    "r, g known from the base parameter file. Prints each value with its 95 % confidence interval, "
                    "the residual RMS per row, the condition number, D_w, D_b and the G_b check; writes the "
                    "nominal.m_b, nominal.I_b, nominal.l overlay. Refuses (exit 2) a log that is too short or does "
                    "not excite the parameters.",
        epilog="examples:\n  mwip_identify ident.csv --out identified.yaml\n"
               "  mwip_identify bags/ident --params config/paper.yaml --out identified.yaml --force\n"
               "  mwip_identify bags/robot --params config/paper.yaml --raw --out identified.yaml   (a robot's bag)\n"
               "  mwip_identify ident.csv --params config/paper.yaml --retune --out gains.yaml   (and tune DSCNDO)\n"
               "  mwip_sim --params config/paper.yaml identified.yaml   (use the overlay after the base file)\n\n"
               "exit status: 0 written; 2 refused (too short, not excited, a drive saturated throughout, a bag cut "
               "short, unreadable input, --out exists)",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log", type=Path, metavar="BAG_OR_CSV",
                    help="a CSV written by mwip_sim --csv / plant_sim (columns t, theta_w, theta_b, dtheta_w, "
                         "dtheta_b and u_applied or u), or a bag directory / .mcap file written by the recorder")
    ap.add_argument("--params", type=Path, nargs="+", default=None, metavar="BASE",
                    help="base ROS 2 parameter file(s), merged in order, for nominal.m_w, I_w, r, g (default: the "
                         "package's config/paper.yaml)")
    ap.add_argument("--out", type=Path, required=True, metavar="FILE.yaml",
                    help="the parameter overlay to write (nominal.m_b, nominal.I_b, nominal.l under /**)")
    ap.add_argument("--force", action="store_true", help="overwrite an --out file that exists")
    ap.add_argument("--state", choices=("auto", "estimate", "true"), default="auto",
                    help="the motion to fit: the state estimator's (theta_b_hat, ...: what a robot with raw sensors "
                         "knows of itself), the true state (a simulator's), or auto: the estimate when the log has "
                         "one (default)")
    ap.add_argument("--window", type=float, nargs=2, default=None, metavar=("T0", "T1"),
                    help="use only the rows with T0 <= t <= T1 [s] (default: the whole log)")
    ap.add_argument("--run", type=int, default=None, metavar="N",
                    help="the run of a bag that holds several (1-based; a plant reset starts a new run)")
    ap.add_argument("--cutoff", type=float, default=ID.CUTOFF_HZ, metavar="HZ",
                    help=f"zero-phase low-pass on every regressor and the torque [Hz], for noisy measured rates; "
                         f"0 = none (default: {ID.CUTOFF_HZ:g}: unfiltered, the period's own friction noise in its "
                         f"differenced rates biases the fit)")
    ap.add_argument("--block", type=float, default=ID.BLOCK_S, metavar="S",
                    help=f"the block of the delete-a-block jackknife that gives the intervals [s] (default: "
                         f"{ID.BLOCK_S:g}; shorter on a log of fewer than {ID.MIN_BLOCKS} blocks)")
    ap.add_argument("--max-condition", type=float, default=ID.MAX_CONDITION, metavar="X",
                    help=f"refuse a regressor whose condition number passes X (default: {ID.MAX_CONDITION:g})")
    ap.add_argument("--max-relative-ci", type=float, default=ID.MAX_RELATIVE_CI, metavar="F",
                    help=f"refuse when the 95 %% interval of m_b, I_b or l is wider than F of its value "
                         f"(default: {ID.MAX_RELATIVE_CI:g})")
    ap.add_argument("--drive", action="store_true",
                    help="identify the drive instead of the body: K_t, R and I_max (docs/theory.md 6.7) from the "
                         "command u, the torque that acted u_applied and the wheel speed, with V_max the base file's "
                         "motor.voltage_limit (the battery's voltage: only three combinations of the four constants "
                         "reach the torque); writes plant_sim's motor.* overlay. The log of config/identify_drive.yaml")
    ap.add_argument("--raw", action="store_true",
                    help="identify from the raw sensors alone (gyro, accel_x, accel_z, encoder, encoder_rate and the "
                         "torque; neither the state nor the estimate): a prediction-error fit over 0.25 s windows "
                         "that also fits D_w, D_b, the gyro bias and the IMU offset, starting from the base file's "
                         "nominal body and sensors.imu.offset (docs/theory.md 6.9). A bag (a robot's, of the realtime "
                         "graph) is read from its imu/data_raw and wheel_encoder messages alone, the torque of each "
                         "period from the encoder's next sample; a period without one is left out of the windows, a "
                         "sample recorded twice counts once. Refused: a drive at its limit in most periods, a body "
                         "left unresolved (95 %% interval wider than --max-relative-ci)")
    ap.add_argument("--validate", type=Path, default=None, metavar="LOG2",
                    help="check the identified model on another log (CSV or bag, read as the first): re-simulate it "
                         "open-loop with LOG2's torque over 1 s windows, each from its measured start (--raw: from a "
                         "start fitted to the window's first 0.2 s of raw samples, against LOG2's estimated pitch), "
                         "and print the pitch prediction error (RMS, worst) against the nominal model of the base "
                         "file(s)")
    ap.add_argument("--retune", action="store_true",
                    help="after identifying, tune the law's gains (--law) on the identified model with mwip_tune's "
                         "search (differential evolution, seeded): the base file's scenario with the identified body "
                         "as the nominal model and as the robot (8 draws within +-5 %% of it), J = theta_b RMS + "
                         "1e-4 u RMS, for DSC/DSCNDO only gains that satisfy Theorem 2 on the identified model "
                         "(gamma > 0); judged beside the base file's gains on a held-out set. --out is then one "
                         "ROS 2 parameter file with the identified nominal.* and the tuned gains")
    ap.add_argument("--law", default="dscndo", metavar="LAW",
                    help="--retune: the law whose gains are tuned (default: dscndo; one of dsc, dscndo, lqr, "
                         "lqr_ndo, smc, smc_ndo: k1 k2 tau4, lqr.Q lqr.R, smc.k smc.boundary_layer, and the "
                         "observer's X.c1 X.c4 with the observer term)")
    ap.add_argument("--maxiter", type=int, default=30, metavar="N",
                    help="--retune: generations of the search (default: %(default)s, as mwip_tune)")
    ap.add_argument("--popsize", type=int, default=8, metavar="N",
                    help="--retune: population per tuned number (default: %(default)s, as mwip_tune)")
    ap.add_argument("--bounds", nargs="*", default=[], metavar="NAME=LO:HI",
                    help="--retune: search bounds, as mwip_tune's --bounds (e.g. X.c1=0.02:1.3 X.c4=0.6:20: a small "
                         "robot's observer gains stay below 2 / (h max eig(M_hat^-1)))")
    ap.add_argument("--min-samples", type=int, default=ID.MIN_SAMPLES, metavar="N",
                    help=f"refuse a log of fewer than N periods (default: {ID.MIN_SAMPLES})")
    return ap


def _fail(text: str) -> int:
    print(f"{PROG}: error: {' '.join(str(text).split())}", file=sys.stderr)
    return EXIT_REFUSED


def _options_refusal(args):
    if args.window is not None:
        t0, t1 = args.window
        if not (math.isfinite(t0) and math.isfinite(t1) and t0 < t1):
            return f"--window: T0 < T1 and both finite, got {t0:g} {t1:g}"
    if args.raw and args.drive:
        return "--raw and --drive: one at a time (the body from the raw sensors, or the drive)"
    if args.validate is not None and args.drive:
        return "--validate: checks the body's fit; not with --drive"
    if args.retune:
        from mwip_ros.cli.identify_retune import tunable_laws
        if args.drive:
            return "--retune: tunes the body's law; not with --drive"
        if args.law not in tunable_laws():
            return f"--law: one of {', '.join(tunable_laws())} (a law with gains to tune), got {args.law!r}"
        if args.maxiter < 1 or args.popsize < 1:
            return f"--maxiter and --popsize: 1 or more, got {args.maxiter} and {args.popsize}"
        from mwip_ros.cli.identify_retune import knob_names
        from mwip_ros.sweep.spec import SpecError
        from mwip_ros.sweep.tune import knobs_for, parse_bounds
        try:   # before the fit: a mistake in the bounds loses no work
            parse_bounds(knobs_for(knob_names(args.law), args.law), args.bounds)
        except SpecError as exc:
            return str(exc)
    elif args.bounds:
        return "--bounds: the search bounds of --retune; give --retune too"
    if args.run is not None and args.run < 1:
        return f"--run: 1 or more, got {args.run}"
    if not (math.isfinite(args.cutoff) and args.cutoff >= 0):
        return f"--cutoff: a frequency >= 0 Hz, got {args.cutoff:g}"
    if not (math.isfinite(args.block) and args.block > 0):
        return f"--block: a duration > 0 s, got {args.block:g}"
    if not (args.max_condition > 1):
        return f"--max-condition: more than 1, got {args.max_condition:g}"
    if not (math.isfinite(args.max_relative_ci) and args.max_relative_ci > 0):
        return f"--max-relative-ci: more than 0, got {args.max_relative_ci:g}"
    if args.min_samples < len(ID.THETA) + 1:
        return f"--min-samples: at least {len(ID.THETA) + 1}, got {args.min_samples}"
    return None


def _is_csv(args, p) -> bool:
    """True for a CSV log, False for a bag (a directory or an .mcap file); else raise ValueError (one line): no such
    file, another kind of file, or --run with a CSV."""
    if not p.exists():
        raise ValueError(f"{p}: no such file or directory")
    if p.is_file() and p.suffix == ".csv":
        if args.run is not None:
            raise ValueError("--run is for a bag of several runs; a CSV holds one")
        return True
    if p.is_dir() or p.suffix == ".mcap":
        return False
    raise ValueError(f"{p}: not a bag directory, .mcap file or .csv file")


def _in_window(args, t) -> np.ndarray:
    """The rows of times ``t`` within --window (all without one)."""
    t = np.asarray(t, dtype=float)
    return np.ones(len(t), dtype=bool) if args.window is None else (t >= args.window[0]) & (t <= args.window[1])


# what a column of a log may read (msgs.layouts.LIMITS, RAW_LIMITS: what the nodes accept); a value beyond it is
# no robot's, refused naming the column (not read as data: it would make the fit "not excited" or overflow)
_PLAUSIBLE = {"theta_w": ("theta_w", "rad"), "theta_b": ("theta_b", "rad"), "dtheta_w": ("rate", "rad/s"),
              "dtheta_b": ("rate", "rad/s"), "u": ("torque", "N m"), "u_applied": ("torque", "N m"),
              "gyro": ("gyro", "rad/s"), "accel_x": ("accel", "m/s^2"), "accel_z": ("accel", "m/s^2"),
              "encoder": ("phi", "rad"), "encoder_rate": ("rate", "rad/s")}


def _plausible(p, cols) -> None:
    """ValueError naming the column, the row and the time of the first value beyond what a robot of this kind reads
    (:data:`_PLAUSIBLE`); NaN is left to the fit (a period with one is dropped)."""
    from mwip_ros.msgs.layouts import LIMITS, RAW_LIMITS
    limits = {**LIMITS, **RAW_LIMITS}
    for c, (kind, unit) in _PLAUSIBLE.items():
        if c not in cols:
            continue
        v = np.asarray(cols[c], dtype=float)
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(np.abs(v) > limits[kind])
        if len(bad):
            k = int(bad[0])
            raise ValueError(f"{p}: column {c}: {v[k]:g} at t = {cols['t'][k]:g} s (data row {k + 1}) is beyond any "
                             f"robot of this kind (|{c}| <= {limits[kind]:g} {unit}); {len(bad)} such value(s)")


def _load(args, p=None):
    """(columns, torque column name) of the log (``p``, default ``args.log``), or raise ValueError (one line)."""
    from mwip_ros.runs import load_run, read_bag_run
    p = args.log if p is None else p
    run = load_run(p) if _is_csv(args, p) else read_bag_run(p, segment=None if args.run is None else args.run - 1)
    cols = dict(run.columns)
    estimated = "theta_b_hat" in cols
    if args.state == "estimate" and not estimated:
        raise ValueError(f"{p}: no estimate columns (theta_b_hat, ...): --state estimate is for a raw-sensor run")
    if args.state == "estimate" or (args.state == "auto" and estimated):
        # what a real robot knows of itself: the state estimator's output, not the simulator's truth
        for c in ("theta_w", "theta_b", "dtheta_w", "dtheta_b"):
            cols[c] = cols[f"{c}_hat"]
    torque = "u_applied" if "u_applied" in cols else "u"
    missing = [c for c in (*NEEDED, torque) if c not in cols]
    if missing:
        raise ValueError(f"{p}: no {', '.join(missing)} column(s)")
    keep = _in_window(args, cols["t"])
    if args.drive and not ("u" in cols and "u_applied" in cols):
        raise ValueError(f"{p}: --drive needs the columns u and u_applied (a run with motor.enabled: true)")
    _plausible(p, cols)
    return {c: np.asarray(cols[c], dtype=float)[keep] for c in (*NEEDED, "theta_w", "u", torque) if c in cols}, torque


def _load_raw(args, p=None):
    """--raw: the columns ``t`` and :data:`RAW` of the log (a bag: :func:`mwip_ros.cli.identify_bag.read_raw_bag`, the
    IMU's and the encoder's messages alone; a CSV: its raw columns, ``t`` on the stamps' grid and a repeated row
    counted once) within --window, and what the reading said (a list of phrases); or raise ValueError (one line)."""
    from mwip_ros.cli.identify_bag import on_stamp_grid, read_raw_bag
    from mwip_ros.runs import read_csv
    p = args.log if p is None else p
    notes = []
    if _is_csv(args, p):
        cols = dict(read_csv(p).columns)
        missing = [c for c in ("t", *RAW) if c not in cols]
        if "u_applied" in missing and "u" in cols:
            missing.remove("u_applied")
            cols["u_applied"] = cols["u"]
        if missing:
            raise ValueError(f"{p}: no {', '.join(missing)} column(s): --raw is for a log of the raw sensors")
        once, dropped = ID._once(*(cols[c] for c in ("t", *RAW)))
        cols = dict(zip(("t", *RAW), once))
        cols["t"] = on_stamp_grid(cols["t"])
        if dropped:
            notes.append(f"{dropped} repeated row(s) counted once")
    else:
        log = read_raw_bag(p, segment=None if args.run is None else args.run - 1)
        cols = log.columns
        for n, what in ((log.duplicates, "sample(s) recorded twice counted once"),
                        (log.unpaired, "sample(s) without the other sensor's left out"),
                        (log.missing_torque, "period(s) without a reported torque left out of the windows")):
            if n:
                notes.append(f"{n} {what}")
    keep = _in_window(args, cols["t"])
    _plausible(p, cols)
    return {c: np.asarray(cols[c], dtype=float)[keep] for c in ("t", *RAW)}, notes


def main(argv=None) -> int:
    """mwip_identify; returns the exit status."""
    args = _parser().parse_args(argv)
    refused = plugin_refusal(PROG)
    if refused is not None:
        return refused
    reason = _options_refusal(args) or refuse_existing(args.out, args.force, "--out")
    if reason:
        return _fail(reason)
    base = args.params or [default_params_file()]
    try:
        values = P.merged_values(P.load_param_files(base, option="--params"))
    except P.ParamError as exc:
        return _fail(str(exc))
    known = P.physical(values, "nominal")
    if args.raw:
        try:
            cols, notes = _load_raw(args)
        except (ValueError, OSError) as exc:
            return _fail(str(exc))
        return _raw(args, base, values, known, cols, notes)
    try:
        cols, torque = _load(args)
    except (ValueError, OSError) as exc:
        return _fail(str(exc))
    if args.drive:
        return _drive(args, base, values, cols)
    c = cols
    try:
        res = ID.identify(c["t"], c.get("theta_w", np.zeros_like(c["t"])), c["theta_b"], c["dtheta_w"],
                          c["dtheta_b"], c[torque], known, cutoff_hz=args.cutoff, min_samples=args.min_samples,
                          max_condition=args.max_condition, max_relative_ci=args.max_relative_ci,
                          block_s=args.block)
    except ID.IdentificationError as exc:
        return _fail(f"{args.log}: {exc}")
    _print(args, res, torque, known)
    if args.validate is not None:
        why = _validate(args, res.physical(), res.D_w.value, res.D_b.value, P.physical(values, "nominal"))
        if why:
            return _fail(why)
    if args.retune:
        return _retune(args, base, res.physical(), _header(args, base, res))
    why = _write(args, base, res)
    if why:
        return _fail(why)
    print(f"wrote {args.out}")
    return 0


def _retune(args, base, physical, header: str) -> int:
    """--retune: tune the law on the identified body, write its nominal.* and the gains to --out; the exit status."""
    from types import SimpleNamespace
    from mwip_ros.cli.identify_retune import retune
    from mwip_ros.cli.tune import _print_table
    from mwip_ros.sweep.spec import SpecError
    print(f"retuning {args.law} on the identified model (m_b = {physical.m_b:.6g} kg, I_b = {physical.I_b:.6g} kg m^2, "
          f"l = {physical.l:.6g} m): {args.maxiter} generation(s), population {args.popsize} per gain", flush=True)
    try:
        r = retune(base, physical, args.law, args.maxiter, args.popsize, bounds=args.bounds,
                   log=lambda text: print(f"{PROG}: {text}", file=sys.stderr, flush=True))
    except (SpecError, P.ParamError) as exc:
        return _fail(f"--retune: {exc}")
    except KeyboardInterrupt:
        return _fail("--retune: interrupted before any candidate was judged; nothing written")
    if r.margin == math.inf:
        gamma = "the law has no Theorem 2 condition"
    elif r.margin > 0:
        gamma = f"Theorem 2 holds on the identified model: gamma = {r.margin:.4g}"
    else:   # every candidate broke it (or it cannot be evaluated: NaN): nothing is written
        return _fail(f"--retune: no gains of {args.law} within the search bounds satisfy Theorem 2 on the identified "
                     f"model (gamma = {r.margin:.4g} at the best); nothing written")
    placed = {("/**", f"nominal.{k}"): float(f"{getattr(physical, k):.6g}") for k in ("m_b", "I_b", "l")}
    placed.update(r.placed)
    lines = [header.rstrip("\n"),
             f"# --retune: {args.law}'s {', '.join(r.names)} tuned on the identified model ({r.generations} "
             f"generations, {r.candidates} candidates, J = {r.j:.6g}); {gamma}",
             f"# held-out set: J {r.before['J']:.6g} -> {r.after['J']:.6g}, theta_b RMS median "
             f"{r.before['theta_b_rms_median']:.5g} -> {r.after['theta_b_rms_median']:.5g} rad"]
    why = _overlay(args, base, placed, "\n".join(lines) + "\n")
    if why:
        return _fail(why)
    print(f"  {gamma}")
    _print_table(SimpleNamespace(controller=args.law, out=args.out), r.names, r.base_x, r.x, r.before, r.after,
                 r.held_scenarios, r.holdout_seed)
    return 0


def _drive(args, base, values, cols) -> int:
    """--drive: fit, print and write plant_sim's motor.* overlay; the exit status."""
    from mwip_ros.core.identification.drive_identify import DriveIdentificationError, identify_drive
    v_max = float(values.get("motor.voltage_limit", float("nan")))
    try:
        d = identify_drive(cols["u"], cols["u_applied"], cols["dtheta_w"], cols["dtheta_b"], v_max)
    except DriveIdentificationError as exc:
        return _fail(f"{args.log}: {exc}")
    free, cur, volt = d.periods
    print(f"{args.log}: drive from {free + cur + volt} periods ({free} unsaturated, {cur} on the current limit, "
          f"{volt} on the voltage limit); V_max = {d.voltage_limit:g} V known (motor.voltage_limit)")
    print(f"  K_t   = {d.torque_constant:.5g} N m/A\n  R     = {d.resistance:.5g} ohm\n"
          f"  I_max = {d.current_limit:.5g} A\n  peak torque K_t I_max = {d.peak_torque:.5g} N m, stall torque "
          f"K_t V_max / R = {d.stall_torque:.5g} N m, back-EMF slope K_t^2 / R = {d.slope:.5g} N m s/rad")
    print(f"  residual RMS of u_applied against the drive's model {d.residual_rms:.4g} N m")
    placed = {("plant_sim", f"motor.{k}"): float(f"{getattr(d, k):.6g}")
              for k in ("torque_constant", "resistance", "voltage_limit", "current_limit")}
    why = _overlay(args, base, placed, f"# {PROG} --drive: the drive identified from {args.log}\n")
    if why:
        return _fail(why)
    print(f"wrote {args.out}")
    return 0


def _raw_refusal(args, c):
    """Why the raw log cannot identify the body before any fit (a saturated drive, too few periods), or None."""
    from mwip_ros.cli.identify_bag import saturated_share
    periods, pinned, top = saturated_share(c["u_applied"])
    if periods and pinned > SATURATED_SHARE * periods:
        return (f"saturated drive: the torque that acted is at its limit +-{top:.4g} N m in {pinned} of {periods} "
                f"periods ({100 * pinned / periods:.0f} %); the drive, not the body, shaped the motion: excite within "
                f"the drive's limits")
    usable = int(np.count_nonzero(np.isfinite(np.column_stack([c[k] for k in RAW])).all(axis=1)))
    if usable < args.min_samples:
        return (f"too short: {usable} period(s) with every raw sample and the torque, at least {args.min_samples} "
                f"needed (a few seconds of excited balancing)")
    return None


def _raw(args, base, values, known, c, notes=()) -> int:
    """--raw: fit, print and write the nominal overlay; the exit status."""
    from mwip_ros.core.identification.identify_raw import identify_raw
    why = _raw_refusal(args, c)
    if why:
        return _fail(f"{args.log}: {why}")
    try:
        res = identify_raw(c["t"], *(c[k] for k in RAW), known=known, start=known,
                           imu_offset=float(values.get("sensors.imu.offset", 0.0)))
    except ValueError as exc:
        return _fail(f"{args.log}: {exc}")
    got = res.values
    for k in ("m_b", "I_b", "l"):
        if not got[k] > 0:
            return _fail(f"{args.log}: unphysical: {k} = {got[k]:.4g}; the model does not fit this log")
    if not res.condition_number <= args.max_condition:
        return _fail(f"{args.log}: ill-conditioned: the condition number of the body's and sensors' columns is "
                     f"{res.condition_number:.4g} (at most {args.max_condition:g}, --max-condition); the log does not "
                     f"tell them apart: add a chirp or PRBS excitation (config/identify.yaml)")
    for k in ("m_b", "I_b", "l"):
        rel = res.half_width(k) / abs(got[k])
        if not rel <= args.max_relative_ci:
            return _fail(f"{args.log}: not excited enough: {k} = {got[k]:.4g} is unresolved, its 95 % interval is "
                         f"+-{100 * rel:.3g} % (at most {100 * args.max_relative_ci:g} %; cluster-robust, "
                         f"docs/theory.md 6.9); add a chirp or PRBS excitation (config/identify.yaml)")
    said = f" ({'; '.join(notes)})" if notes else ""
    print(f"{args.log}: raw sensors only, {res.windows} windows of 0.25 s, {res.evaluations} evaluations{said}; known "
          f"m_w = {known.m_w:g} kg, I_w = {known.I_w:g} kg m^2, r = {known.r:g} m")
    units = {"m_b": "kg", "I_b": "kg m^2", "l": "m", "D_w": "N m s", "D_b": "N m s", "gyro_bias": "rad/s",
             "imu_offset": "m"}
    for k, unit in units.items():
        print(f"  {k:<10} = {got[k]:.5g} {unit}  (95 % CI +-{res.half_width(k):.2g}: cluster-robust, t with "
              f"{res.dof[k]:.3g} degrees of freedom)")
    g, ax, az, e = res.residual_rms
    print(f"  residual RMS: gyro {g:.3g} rad/s, accel_x {ax:.3g} m/s^2, accel_z {az:.3g} m/s^2, encoder {e:.3g} rad; "
          f"condition number {res.condition_number:.4g}")
    header = (f"# {PROG} --raw: nominal body identified from the raw sensors of {args.log}\n"
              f"# an overlay: pass it after the base file(s), e.g. mwip_sim --params {' '.join(map(str, base))} "
              f"{args.out}\n")
    if args.validate is not None:
        why = _validate_raw(args, res, P.physical(values, "nominal"))
        if why:
            return _fail(why)
    if args.retune:
        return _retune(args, base, res.physical(), header)
    placed = {("/**", f"nominal.{k}"): float(f"{got[k]:.6g}") for k in ("m_b", "I_b", "l")}
    why = _overlay(args, base, placed, header)
    if why:
        return _fail(why)
    print(f"wrote {args.out}")
    return 0


def _validate(args, identified, D_w: float, D_b: float, nominal):
    """--validate: print the pitch prediction errors on LOG2 of the identified body (with its D_w, D_b) and the
    nominal one; the reason it cannot, or None."""
    from mwip_ros.core.identification.identify_validate import prediction_errors
    try:
        c, torque = _load(args, args.validate)
        cols = [c["t"], c.get("theta_w", np.zeros_like(c["t"])), c["theta_b"], c["dtheta_w"], c["dtheta_b"], c[torque]]
        got = {name: prediction_errors(*cols, p, D_w, D_b)
               for name, p in (("identified", identified), ("nominal", nominal))}
    except (ValueError, OSError) as exc:
        return f"--validate {args.validate}: {exc}"
    print(f"validation on {args.validate}: open-loop pitch prediction over {got['identified'].windows} windows of "
          f"1 s from each window's measured start, the log's torque {torque!r}, D_w and D_b as identified")
    for name, e in got.items():
        print(f"  {name:<10} pitch error RMS {e.rms:.4g} rad ({np.degrees(e.rms):.3g} deg), worst {e.worst:.4g} rad "
              f"({np.degrees(e.worst):.3g} deg)")
    return None


def _validate_raw(args, res, nominal):
    """--raw --validate: the pitch prediction errors on LOG2's raw samples of the identified body and the nominal one
    (each with the fit's D_w, D_b, gyro bias and IMU offset), each window's start fitted to its first 0.2 s, against
    LOG2's estimated pitch (core.identification.identify_validate.raw_prediction_errors); the reason it cannot, or
    None."""
    from mwip_ros.cli.identify_bag import on_stamp_grid
    from mwip_ros.core.identification.identify_validate import FIT_S, raw_prediction_errors
    try:
        raw, _ = _load_raw(args, args.validate)
        c, _ = _load(args, args.validate)   # theta_b: the estimator's where the log has it (what a robot knows)
        at = np.searchsorted(on_stamp_grid(c["t"]), raw["t"])
        at = np.minimum(at, len(c["t"]) - 1)
        ref = np.where(np.abs(on_stamp_grid(c["t"])[at] - raw["t"]) < 1e-9, c["theta_b"][at], np.nan)
        g = res.values
        got = {name: raw_prediction_errors(raw["t"], *(raw[k] for k in RAW), ref, p, g["D_w"], g["D_b"],
                                           g["gyro_bias"], g["imu_offset"])
               for name, p in (("identified", res.physical()), ("nominal", nominal))}
    except (ValueError, OSError) as exc:
        return f"--validate {args.validate}: {exc}"
    print(f"validation on {args.validate}: open-loop pitch prediction over {got['identified'].windows} windows of "
          f"1 s, each from a start fitted to its first {FIT_S:g} s of raw samples, the reported torque, D_w, D_b, "
          f"the gyro bias and the IMU offset as identified; against the log's estimated pitch, whose own error is "
          f"part of the figure")
    for name, e in got.items():
        print(f"  {name:<10} pitch error RMS {e.rms:.4g} rad ({np.degrees(e.rms):.3g} deg), worst {e.worst:.4g} rad "
              f"({np.degrees(e.worst):.3g} deg)")
    return None


def g_b_verdict(chk: ID.Estimate) -> str:
    """Whether 0 lies in the G_b check's 95 % interval: 'within', 'OUTSIDE', or, when the difference or its interval
    is not a number, 'with no verdict (not a number)' (never a verdict from NaN)."""
    if not (math.isfinite(chk.value) and math.isfinite(chk.half_width)):
        return "with no verdict (not a number)"
    return "within" if chk.low <= 0.0 <= chk.high else "OUTSIDE"


def _print(args, res: ID.IdentificationResult, torque: str, known) -> None:
    once = f" ({res.duplicates} repeated row(s) counted once)" if res.duplicates else ""
    print(f"{args.log}: {res.samples} periods{once}, torque from column {torque!r}; known m_w = {known.m_w:g} kg, "
          f"I_w = {known.I_w:g} kg m^2, r = {known.r:g} m, g = {known.g:g} m/s^2")
    rows = [("m_b", res.m_b, "kg"), ("I_b", res.I_b, "kg m^2"), ("l", res.l, "m"),
            ("m11", res.m11, "kg m^2"), ("m12", res.m12, "kg m^2"), ("m22", res.m22, "kg m^2"),
            ("G_b", res.G_b, "N m"), ("D_w", res.D_w, "N m s"), ("D_b", res.D_b, "N m s")]
    for name, e, unit in rows:
        print(f"  {name:<4} = {e.text(unit)}")
    chk = res.G_b_check
    within = g_b_verdict(chk)
    print(f"  G_b check: fitted {res.G_b.value:.6g} N m vs m_b g l = {res.G_b_model.value:.6g} N m, difference "
          f"{chk.value:+.4g} N m ({100 * chk.value / res.G_b_model.value:+.3g} %), {within} its 95 % interval "
          f"+-{chk.half_width:.3g}")
    print(f"  residual RMS: row 1 (wheel) {res.residual_rms[0]:.4g} N m, row 2 (body) {res.residual_rms[1]:.4g} N m; "
          f"condition number {res.condition_number:.4g}; intervals from a delete-a-block jackknife over "
          f"{res.blocks} blocks of {res.block_s:.3g} s (Student's t, {res.blocks - 1} degrees of freedom: "
          f"x{res.m_b.quantile:.3g}; delta method for m_b, I_b, l)")


def _header(args, base, res: ID.IdentificationResult) -> str:
    return (f"# {PROG}: nominal body identified from {args.log} ({res.samples} periods)\n"
            f"#   m_b {res.m_b.text('kg')}\n#   I_b {res.I_b.text('kg m^2')}\n#   l   {res.l.text('m')}\n"
            f"#   residual RMS {res.residual_rms[0]:.4g} / {res.residual_rms[1]:.4g} N m, condition number "
            f"{res.condition_number:.4g}\n"
            f"# an overlay: pass it after the base file(s), e.g. mwip_sim --params "
            f"{' '.join(map(str, base))} {args.out}\n")


def _write(args, base, res: ID.IdentificationResult):
    """Write the body's overlay (:func:`_overlay`); the reason it cannot, or None."""
    placed = {("/**", f"nominal.{k}"): float(f"{getattr(res, k).value:.6g}") for k in ("m_b", "I_b", "l")}
    return _overlay(args, base, placed, _header(args, base, res))


def _overlay(args, base, placed, header):
    """Write ``placed`` to --out atomically, checked by merging it over the base file; the reason it cannot, or
    None."""
    from mwip_ros.sweep.scenarios import parameter_overlay
    out = Path(args.out)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        parameter_overlay(placed, tmp, header)
        P.merged_values(P.load_param_files([*base, tmp], option="--out"))   # the base with it still makes a model
        os.replace(tmp, out)
    except (P.ParamError, OSError) as exc:
        return f"--out {out}: the identified values do not make a valid parameter file ({exc})"
    finally:
        if tmp.exists():
            tmp.unlink()
    return None


if __name__ == "__main__":
    sys.exit(main())
