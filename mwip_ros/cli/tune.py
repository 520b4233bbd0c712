"""``mwip_tune``: tune gains on a sweep's scenarios (scipy differential evolution), judged on a held-out set."""
from __future__ import annotations

import argparse
import dataclasses
import math
import signal
import sys
import time
from pathlib import Path

import numpy as np

from mwip_ros import params as P
from mwip_ros.core import laws
from mwip_ros.cli import interrupts
from mwip_ros.cli.exits import epilog
from mwip_ros.cli.outputs import refuse_existing
from mwip_ros.cli.sweep import add_runner_arguments, runner_from
from mwip_ros.sweep import engine, warm
from mwip_ros.sweep.scenarios import parameter_overlay
from mwip_ros.sweep.spec import SWEEP_BACKENDS, SpecError, load_spec
from mwip_ros.sweep.tune import KNOBS, Objective, check_memory, Tuner, knobs_for, overlay, parse_bounds

PROG = "mwip_tune"


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog=PROG,
        description="Tune a law's gains on a sweep spec's scenarios with scipy's differential evolution (bounded, "
                    "seeded, in log space), every candidate judged on all scenarios at once by the batch "
                    "simulator (plant_sim.backend: mujoco: MuJoCo's scalar loop, scenario by scenario, as "
                    "mwip_sweep): J = mean over scenarios of theta_b RMS + WEIGHT * u RMS over the metrics window, a "
                    "fall costs 1.0; for DSC/DSCNDO, Theorem 2 (gamma > 0) is a hard constraint. The result is "
                    "judged beside the base file's gains on a held-out set (the same spec, another seed) and "
                    "written as a parameter-file overlay.",
        epilog="examples:\n"
               "  mwip_tune config/sweeps/tune_dscndo.yaml --controller dscndo --tune k1 k2 tau4 X --out tuned.yaml\n"
               "  mwip_tune SPEC.yaml --controller lqr_ndo --tune lqr.Q lqr.R --bounds lqr.R=0.001:0.1 --out lqr.yaml\n"
               "  mwip_sim --params config/paper.yaml tuned.yaml      # the overlay goes after the base file\n\n"
               f"tunable: {', '.join(KNOBS)} (X: its diagonal c1, c4; lqr.Q: its diagonal)\n"
               + epilog(e1="", e2="a bad spec, option or law plug-in (nothing ran), or a law that raised (named "
                        "with its scenario)", e3="", e130="interrupted (Ctrl-C: the best so far is written, judged on "
                        "the held-out set)", e143="terminated (SIGTERM: the best so far is written, not judged)"),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("spec", type=Path, help="a sweep spec (its base file, duration, window, scenarios)")
    ap.add_argument("--controller", required=True, choices=laws.names(), help="the law to tune")
    ap.add_argument("--tune", nargs="+", required=True, metavar="NAME", help="what to tune: " + ", ".join(KNOBS))
    ap.add_argument("--out", type=Path, required=True, metavar="FILE.yaml", help="the overlay to write")
    ap.add_argument("--force", action="store_true", help="overwrite an --out file that exists")
    ap.add_argument("--bounds", nargs="*", default=[], metavar="NAME=LO:HI",
                    help="search bounds (e.g. k1=1:20 X.c1=10:500); defaults: k1, k2 0.5:30, tau4 0.005:1, "
                         "X.c1, X.c4 5:2000, lqr.R 1e-4:1, lqr.Q.* 0.1:1e4")
    ap.add_argument("--weight", type=float, default=1e-4, help="weight of u RMS [N m] against theta_b RMS [rad] "
                                                               "(default %(default)g)")
    ap.add_argument("--maxiter", type=int, default=30, help="generations (default %(default)s)")
    ap.add_argument("--popsize", type=int, default=8, help="population per tuned number (default %(default)s)")
    ap.add_argument("--seed", type=int, default=0, help="the search's seed (default %(default)s)")
    ap.add_argument("--holdout-seed", type=int, default=None,
                    help="the held-out set's spec seed (default: the spec's seed + 1)")
    add_runner_arguments(ap)
    ap.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    return ap


def _fail(text: str) -> int:
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return 2


def main(argv=None) -> int:
    """mwip_tune; SIGTERM is handled like Ctrl-C (the best so far written, workers stopped, exit 143)."""
    return interrupts.run_main(_main, argv, PROG)


def _main(argv=None) -> int:
    args = _parser().parse_args(argv)
    if args.maxiter < 1 or args.popsize < 1:
        return _fail("--maxiter and --popsize must be >= 1")
    if not (math.isfinite(args.weight) and args.weight >= 0):
        return _fail(f"--weight must be >= 0, got {args.weight}")
    for option, seed in (("--seed", args.seed), ("--holdout-seed", args.holdout_seed)):
        if seed is not None and seed < 0:
            return _fail(f"{option} must be >= 0, got {seed}")
    reason = refuse_existing(args.out, args.force, "--out")   # now, not after the search
    if reason:
        return _fail(reason)
    law = args.controller
    reason = laws.unavailable(laws.get(law))   # an optional package the law needs (mpc: daqp)
    if reason:
        return _fail(reason)
    try:
        spec = load_spec(args.spec, backends=SWEEP_BACKENDS)   # mujoco: the scalar loop, as mwip_sweep's
        knobs = knobs_for(args.tune, law)
        bounds = parse_bounds(knobs, args.bounds)
        check_memory(spec, knobs, args.popsize)   # before any scenario is expanded
        holdout = dataclasses.replace(spec, seed=spec.seed + 1 if args.holdout_seed is None else args.holdout_seed)
        if holdout.seed == spec.seed:
            raise SpecError("--holdout-seed", "must differ from the spec's seed (the set is held out)")
    except (SpecError, P.ParamError) as exc:
        return _fail(str(exc))
    base_x = _base_values(knobs, spec.base_values)
    try:
        runner = runner_from(args, PROG)
    except ValueError as exc:
        return _fail(str(exc))
    with runner:
        return _tune(args, spec, holdout, knobs, bounds, base_x, runner)


def _tune(args, spec, holdout, knobs, bounds, base_x, runner) -> int:
    try:
        search = Objective(spec, args.controller, knobs, args.weight, runner, args.chunk)
        held = Objective(holdout, args.controller, knobs, args.weight, runner, args.chunk)
    except (SpecError, P.ParamError) as exc:
        return _fail(str(exc))
    names = [k.name for k in knobs]
    log = (lambda *a: None) if args.quiet else (lambda text: print(f"{PROG}: {text}", file=sys.stderr, flush=True))
    log(f"tuning {', '.join(names)} of {args.controller} on {len(search.scenarios):,} scenarios of "
        f"{spec.duration_s:g} s on {runner.describe()}; {args.maxiter} generations of "
        f"{args.popsize * len(knobs)} candidates at most; bounds "
        + ", ".join(f"{n} [{lo:g}, {hi:g}]" for n, (lo, hi) in zip(names, bounds)))
    # numba's first compilation of the law's loop (tens of seconds), said and done before the search
    warm.compile_first(runner, engine.chunks_of(args.controller, spec.base_values,
                                                [search.scenarios.overrides(0)], spec.duration_s, spec.window),
                       (lambda text: None) if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True)),
                       PROG)
    t0 = time.monotonic()
    bar = None
    if not args.quiet and sys.stderr.isatty():
        from tqdm import tqdm
        bar = tqdm(total=args.maxiter, unit="generation", file=sys.stderr)

    def progress(gen, best_j, best_x):
        text = f"J = {best_j:.6g} at " + ", ".join(f"{n} = {v:.4g}" for n, v in zip(names, best_x))
        if bar is not None:
            bar.set_postfix_str(text, refresh=False)
            bar.update(1)
        else:
            wall = time.monotonic() - t0
            log(f"generation {gen}/{args.maxiter}: best {text} ({search.evaluations} candidates, "
                f"{search.steps / max(wall, 1e-9):,.0f} scenario-steps/s, {wall:.0f} s)")

    tuner = Tuner(search, bounds, seed=args.seed, maxiter=args.maxiter, popsize=args.popsize, progress=progress)
    best_x, best_j, generations = tuner.run()
    if bar is not None:
        bar.close()
    if best_x is None:
        log("interrupted before any candidate was judged; nothing written")
        return 130
    log(("interrupted: keeping the best so far" if tuner.interrupted else "search done")
        + f" after {generations} generation(s), {search.evaluations} candidates, {time.monotonic() - t0:.0f} s")
    before = after = None
    if interrupts.received() != signal.SIGTERM:   # SIGTERM (a scheduler's grace period): write and go
        try:
            before, after = held.judge(base_x), held.judge(best_x)
        except KeyboardInterrupt:
            before = after = None
    _write_overlay(args, spec, holdout, knobs, best_x, best_j, before, after, generations, search.evaluations)
    _print_table(args, names, base_x, best_x, before, after, len(held.scenarios), holdout.seed)
    return 130 if tuner.interrupted else 0


def _base_values(knobs, base) -> np.ndarray:
    out = []
    for k in knobs:
        v = base[k.param]
        if k.index is None:
            out.append(float(v))
        elif k.param == "lqr.Q" and len(v) == 9:
            out.append(float(v[4 * k.index]))
        else:
            out.append(float(v[k.index]))
    return np.array(out)


def settings_of(args, holdout_seed: int) -> str:
    """The options that decide a search's result, as ``mwip_tune`` takes them (the overlay's ``# settings:`` line:
    the command that made a file, less its spec and ``--out``; ``--holdout-seed`` resolved)."""
    words = ["--controller", args.controller, "--tune", *args.tune, "--maxiter", str(args.maxiter),
             "--popsize", str(args.popsize), "--seed", str(args.seed), "--weight", f"{args.weight:g}",
             "--holdout-seed", str(holdout_seed)]
    if args.bounds:
        words += ["--bounds", *args.bounds]
    return " ".join(words)


def _write_overlay(args, spec, holdout, knobs, x, j, before, after, generations, candidates) -> None:
    lines = [f"# {PROG}: {args.controller} tuned on {args.spec} ({', '.join(k.name for k in knobs)}), "
             f"J = {j:.6g} on the search set",
             f"# settings: {settings_of(args, holdout.seed)}",
             f"# search: {generations} generations, {candidates} candidates",
             "# J = mean over scenarios of theta_b RMS + weight * u RMS over the window (a fall costs 1.0), "
             f"weight {args.weight:g}"]
    if after is not None:
        lines.append(f"# held-out set: J {before['J']:.6g} -> {after['J']:.6g}, upright "
                     f"{100 * before['upright_share']:.1f} % -> {100 * after['upright_share']:.1f} %")
    lines.append(f"# an overlay: pass it after the base file(s), e.g. mwip_sim --params "
                 f"{' '.join(map(str, spec.base_path))} {args.out}")
    parameter_overlay(overlay(knobs, x, spec.base_values), args.out, "\n".join(lines) + "\n")


def _median(v: float, fmt: str) -> str:
    """A median over the upright runs; '- (none upright)' when there is none (NaN): never 'nan'."""
    return fmt.format(v) if math.isfinite(v) else "- (none upright)"


def _print_table(args, names, base_x, best_x, before, after, n, seed) -> None:
    print(f"{args.controller}: base file vs tuned" + (f", judged on a held-out set of {n:,} scenarios "
                                                      f"(spec seed {seed})" if after else ""))
    rows = [("", "base file", "tuned")] + [(name, f"{a:.6g}", f"{b:.6g}") for name, a, b in zip(names, base_x, best_x)]
    if after is not None:
        rows += [("J (held out)", f"{before['J']:.6g}", f"{after['J']:.6g}"),
                 ("upright", f"{100 * before['upright_share']:.1f} %", f"{100 * after['upright_share']:.1f} %"),
                 ("theta_b RMS, median [rad]", _median(before['theta_b_rms_median'], "{:.5g}"),
                  _median(after['theta_b_rms_median'], "{:.5g}")),
                 ("u RMS, median [N m]", _median(before['u_rms_median'], "{:.4g}"),
                  _median(after['u_rms_median'], "{:.4g}")),
                 ("Theorem 2 holds", str(before["theorem2_holds"]), str(after["theorem2_holds"]))]
    w = [max(len(r[i]) for r in rows) for i in range(3)]
    for r in rows:
        print(f"  {r[0]:<{w[0]}}  {r[1]:>{w[1]}}  {r[2]:>{w[2]}}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    sys.exit(main())
