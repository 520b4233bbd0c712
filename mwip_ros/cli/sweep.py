"""``mwip_sweep``: robustness sweeps with the batch simulator, on this machine or a Dask cluster."""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

from mwip_ros import params as P
from mwip_ros.sweep import engine, results
from mwip_ros.sweep.scenarios import expand, parameter_file
from mwip_ros.core.sim import LAWS
from mwip_ros.sweep.spec import CONTROLLERS, SpecError, load_spec

PROG = "mwip_sweep"
EXIT_BAD_INPUT, EXIT_INTERRUPTED = 2, 130
# what a sweep writes into --out: an --out holding any of them is refused without --force, which removes them
SWEEP_FILES = ("results.csv", "summary.md", "summary.json", "sweep.json", "base.yaml", "spec.yaml",
               "upright_map.png", "theta_b_rms.png", "roa.png")


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog=PROG,
        description="Run the closed loop over many scenarios at once (the batch simulator): every grid point of "
                    "the spec's grid axes times `samples` draws of its random axes, for each law. Writes "
                    "results.csv (a row per scenario and law, flushed as chunks finish), summary.md, "
                    "summary.json and figures into --out.",
        epilog="examples:\n"
               "  mwip_sweep config/sweeps/mass_mismatch.yaml --out sweeps/mass\n"
               "  mwip_sweep config/sweeps/roa.yaml --out sweeps/roa --dask tcp://scheduler:8786\n"
               "  mwip_sweep --results sweeps/mass --scenario 17 --controller dscndo --write-params s17.yaml\n"
               "  scripts/run_experiment.sh --params s17.yaml     # the same scenario through the ROS graph\n\n"
               "exit codes: 0 done, 1 a worker failed, 2 a bad spec or option (nothing ran), 130 interrupted "
               "(finished rows are in results.csv)",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("spec", nargs="?", type=Path, help="the sweep spec (YAML); see config/sweeps/")
    ap.add_argument("--out", type=Path, metavar="DIR", help="output directory (created; must not hold results)")
    ap.add_argument("--force", action="store_true",
                    help="overwrite: the outputs already in --out (removed first), the --write-params or "
                         "--plot-rms file")
    add_runner_arguments(ap)
    ap.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    ap.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    back = ap.add_argument_group("from a row back to the ROS graph")
    back.add_argument("--results", type=Path, nargs="+", metavar="DIR",
                      help="a finished (or interrupted) sweep's --out (several with --plot-rms)")
    back.add_argument("--scenario", type=int, metavar="N", help="the row's scenario number")
    back.add_argument("--controller", choices=CONTROLLERS,
                      help="the row's law (default: dscndo when the sweep ran it)")
    back.add_argument("--write-params", type=Path, metavar="FILE",
                      help="write the scenario's complete parameter file (for mwip_sim --params or "
                           "scripts/run_experiment.sh --params)")
    back.add_argument("--plot-rms", type=Path, metavar="FILE.png",
                      help="the theta_b RMS distribution of each --results DIR, side by side on one axis")
    return ap


def add_runner_arguments(ap: argparse.ArgumentParser) -> None:
    """--workers, --dask, --chunk: where a sweep's (or a tuner's) chunks run."""
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1, metavar="N",
                    help="local worker processes (default: the core count, %(default)s); 1 = in this process")
    ap.add_argument("--dask", metavar="ADDRESS",
                    help="run the chunks on a dask.distributed scheduler (tcp://host:8786), or 'local:N' for a "
                         "local cluster of N workers; --workers is then ignored")
    ap.add_argument("--chunk", type=int, default=engine.DEFAULT_CHUNK, metavar="N",
                    help="runs per chunk (default %(default)s); the chunking, not the runner, fixes the results")


def runner_from(args) -> engine.Runner:
    """The runner the arguments ask for; ValueError (the message for the user) when they make no sense."""
    if args.workers < 1 or args.chunk < 1:
        raise ValueError("--workers and --chunk must be >= 1")
    if args.dask and args.dask.startswith("local:") and not args.dask[6:].isdigit():
        raise ValueError(f"--dask local:N needs a number of workers, got {args.dask!r}")
    return engine.Runner(args.workers, args.dask)


def _fail(text: str) -> int:
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _refuse_existing(paths, force: bool, hint: str) -> int:
    """The one check of every output mwip_sweep writes: 0 when none of ``paths`` exists, or with ``force``
    (which removes them: nothing of an earlier output is left beside the new one); else the error exit
    code, after one line naming what exists."""
    there = [Path(p) for p in paths if Path(p).exists()]
    if not there:
        return 0
    if not force:
        if len(paths) == 1:
            return _fail(f"{there[0]} already exists; {hint} or add --force")
        return _fail(f"{there[0].parent} already holds {', '.join(p.name for p in there)}; {hint} or add --force")
    for p in there:
        if p.is_dir():
            return _fail(f"{p} is a directory, not a file")
        p.unlink()
    return 0


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    if args.plot_rms is not None:
        return _plot_rms(args)
    if args.results is not None or args.write_params is not None:
        return _write_params(args)
    if args.spec is None or args.out is None:
        return _fail("give a spec and --out DIR (or --results DIR --scenario N --write-params FILE); see --help")
    try:
        runner = runner_from(args)
    except ValueError as exc:
        return _fail(str(exc))
    try:
        spec = load_spec(args.spec)
        scenarios = expand(spec)
    except (SpecError, P.ParamError) as exc:
        return _fail(str(exc))
    spec_copy = args.out / "spec.yaml"   # re-running an output's own spec.yaml: that file is the input, kept
    same = spec_copy.exists() and spec_copy.resolve() == args.spec.resolve()
    refused = _refuse_existing([args.out / f for f in SWEEP_FILES if not (same and f == "spec.yaml")], args.force,
                               "choose another --out")
    if refused:
        return refused
    args.out.mkdir(parents=True, exist_ok=True)
    info = _sweep_info(spec, args)
    (args.out / "sweep.json").write_text(json.dumps(info, indent=2))
    parameter_file(spec.base_sections, {}, args.out / "base.yaml",   # the base (and overlays) as one file
                   f"# {PROG}: the base of this sweep: {' + '.join(map(str, spec.base_path))}\n")
    if not same:
        shutil.copyfile(args.spec, spec_copy)

    chunks = engine.make_chunks(spec, scenarios, args.chunk)
    total = sum(len(c) for c in chunks)
    steps_per_run = int(round(spec.duration_s * spec.base_values["control_rate_hz"]))
    where = runner.describe()
    if not args.quiet:
        print(f"{PROG}: {len(scenarios):,} scenarios x {len(spec.controllers)} law(s) = {total:,} runs of "
              f"{spec.duration_s:g} s in {len(chunks)} chunk(s), on {where}", file=sys.stderr)
    writer = results.ResultsWriter(args.out / "results.csv", [a.key for a in spec.axes])
    progress = _Progress(total, steps_per_run, args.quiet)
    try:
        for chunk, res in runner(chunks):
            writer.add(chunk, res, scenarios)
            progress.update(len(chunk), res.steps)
    except KeyboardInterrupt:
        progress.close()
        writer.close()
        print(f"\n{PROG}: interrupted: {writer.rows:,} of {total:,} rows are in {args.out / 'results.csv'}",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:   # a worker's failure (or a lost Dask connection): keep what finished
        progress.close()
        writer.close()
        print(f"{PROG}: error: a chunk failed: {type(exc).__name__}: {exc}; {writer.rows:,} finished rows are in "
              f"{args.out / 'results.csv'}", file=sys.stderr)
        return 1
    finally:
        runner.close()
    progress.close()
    writer.close()
    results.sort_file(args.out / "results.csv", list(spec.controllers))
    cols = results.read_results(args.out / "results.csv")
    doc = results.summarize(cols, info)
    results.write_summary(doc, args.out)
    written = ["results.csv", "summary.md", "summary.json"]
    if not args.no_figures:
        written += _figures(cols, spec, doc, args.out)
    print(results.summary_markdown(doc))
    print(f"wrote {', '.join(str(args.out / w) for w in written)}")
    return 0


def _sweep_info(spec, args) -> dict:
    def dist(a):
        return f"{a.kind} {list(a.args)}" if a.kind != "grid" or len(a.args) <= 6 else f"grid of {len(a.args)}"
    return {"name": args.spec.stem, "spec": str(args.spec), "base": [str(b) for b in spec.base_path],
            "controllers": list(spec.controllers), "duration_s": spec.duration_s, "window": list(spec.window),
            "seed": spec.seed, "samples": spec.samples, "scenarios": spec.n_scenarios,
            "varied": {a.key: dist(a) for a in spec.axes},
            "axes": [{"key": a.key, "section": a.section, "name": a.name, "type": a.type, "kind": a.kind}
                     for a in spec.axes]}


def _figures(cols, spec, doc, out: Path) -> list:
    from mwip_ros.cli import plotting
    written = []
    numeric = [(a.key, not a.random) for a in spec.axes if a.type != "double_array"]
    if plotting.sweep_upright_map(cols, numeric, out / "upright_map.png"):
        written.append("upright_map.png")
    plotting.sweep_rms_distribution(cols, out / "theta_b_rms.png")
    written.append("theta_b_rms.png")
    if results.THETA0_KEY in cols:
        roa = {c: e.get("region_of_attraction_theta_b0") for c, e in doc["controllers"].items()}
        plotting.sweep_roa(cols, results.THETA0_KEY, roa, out / "roa.png")
        written.append("roa.png")
    return written


class _Progress:
    """tqdm on a terminal (runs done, scenario-steps/s, time left); a plain line every 5 s otherwise."""

    def __init__(self, total: int, steps_per_run: int, quiet: bool):
        self.total, self.done, self.steps = total, 0, 0
        self.t0 = self._last = time.monotonic()
        self.quiet = quiet
        self.bar = None
        if not quiet and sys.stderr.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=total, unit="run", file=sys.stderr, dynamic_ncols=True, smoothing=0.1)

    def update(self, runs: int, steps: int) -> None:
        self.done += runs
        self.steps += steps
        rate = self.steps / max(1e-9, time.monotonic() - self.t0)
        if self.bar is not None:
            self.bar.set_postfix_str(f"{rate / 1e6:.2f} M scenario-steps/s", refresh=False)
            self.bar.update(runs)
        elif not self.quiet and (time.monotonic() - self._last >= 5.0 or self.done == self.total):
            self._last = time.monotonic()
            left = (time.monotonic() - self.t0) * (self.total - self.done) / max(1, self.done)
            print(f"{PROG}: {self.done:,}/{self.total:,} runs ({100 * self.done / self.total:.0f} %), "
                  f"{rate:,.0f} scenario-steps/s, {left:.0f} s left", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        if not self.quiet and self.done:
            wall = time.monotonic() - self.t0
            print(f"{PROG}: {self.done:,} runs, {self.steps:,} scenario-steps in {wall:.1f} s "
                  f"({self.steps / max(wall, 1e-9):,.0f} scenario-steps/s)", file=sys.stderr)


def _plot_rms(args) -> int:
    if not args.results:
        return _fail("--plot-rms needs --results DIR [DIR ...]")
    named = []
    for d in args.results:
        try:
            info = json.loads((d / "sweep.json").read_text())
            named.append((info.get("name", d.name), results.read_results(d / "results.csv")))
        except (OSError, ValueError) as exc:
            return _fail(f"{d} is not a sweep's output directory ({exc})")
    refused = _refuse_existing([args.plot_rms], args.force, "choose another --plot-rms file")
    if refused:
        return refused
    from mwip_ros.cli import plotting
    plotting.sweep_rms_panels(named, args.plot_rms)
    print(f"wrote {args.plot_rms}")
    return 0


def _write_params(args) -> int:
    if args.results is None or len(args.results) != 1 or args.scenario is None or args.write_params is None:
        return _fail("--write-params needs one --results DIR and --scenario N")
    d = args.results[0]
    try:
        info = json.loads((d / "sweep.json").read_text())
        cols = results.read_results(d / "results.csv")
    except (OSError, ValueError) as exc:
        return _fail(f"{d} is not a sweep's output directory ({exc})")
    laws = info["controllers"]
    law = args.controller or ("dscndo" if "dscndo" in laws else laws[0])
    if law not in laws:
        return _fail(f"--controller {law}: the sweep ran {', '.join(laws)}")
    rows = [j for j, (s, c) in enumerate(zip(cols["scenario"], cols["controller"])) if s == args.scenario and c == law]
    if not rows:
        return _fail(f"no row for scenario {args.scenario} ({law}) in {d / 'results.csv'} (scenarios 0.."
                     f"{info['scenarios'] - 1}; an interrupted sweep lacks some)")
    refused = _refuse_existing([args.write_params], args.force, "choose another --write-params file")
    if refused:
        return refused
    j = rows[0]
    placed = {("plant_sim", "seed"): cols["seed"][j], ("plant_sim", "duration_s"): float(info["duration_s"]),
              ("dscndo_controller", "use_observer"): LAWS[law][1], ("dscndo_controller", "law"): LAWS[law][0]}
    for a in info["axes"]:
        v = cols[a["key"]][j]
        placed[(a["section"], a["name"])] = int(v) if a["type"] == "integer" else v
    try:
        base = P.load_param_file(d / "base.yaml")
        header = (f"# {PROG}: scenario {args.scenario} of {d} ({law}), a complete parameter file.\n"
                  f"# Its results.csv row: upright {cols['upright'][j]}, theta_b RMS {cols['theta_b_rms'][j]!r} rad "
                  f"over t in {info['window']} s.\n")
        parameter_file(base.sections, placed, args.write_params, header)
    except (P.ParamError, OSError) as exc:
        return _fail(str(exc))
    print(f"wrote {args.write_params} (scenario {args.scenario}, {law})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
