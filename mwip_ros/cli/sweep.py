"""``mwip_sweep``: robustness sweeps with the batch simulator, on this machine or a Dask cluster."""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import signal
import sys
import time
from pathlib import Path

from mwip_ros import params as P
from mwip_ros.cli import interrupts, outputs
from mwip_ros.cli.exits import EXIT_USAGE, epilog
from mwip_ros.sweep import engine, results, warm
from mwip_ros.sweep import progress as sweep_progress
from mwip_ros.sweep.scenarios import expand, parameter_file
from mwip_ros.core.kernels import batch
from mwip_ros.core import laws as registry
from mwip_ros.sweep.spec import SWEEP_BACKENDS, SpecError, load_spec

PROG = "mwip_sweep"
EXIT_BAD_INPUT, EXIT_INTERRUPTED = EXIT_USAGE, interrupts.EXIT_SIGINT   # 143 after SIGTERM (interrupts.run_main)
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
               + epilog(e0="done (runs that fell or failed are rows with upright 0 and their failure, not an "
                        "error)", e1="a worker failed", e2="a bad spec, option or law plug-in (nothing ran), or a law "
                        "that raised (named with its scenario and its own error)", e3="",
                        e130="interrupted (Ctrl-C)", e143="terminated (SIGTERM: timeout, kill, a batch scheduler)")
               + "\nfinished rows are in results.csv and no worker is left running",
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
    back.add_argument("--controller", choices=registry.names(),
                      help="the row's law (default: dscndo when the sweep ran it)")
    back.add_argument("--write-params", type=Path, metavar="FILE",
                      help="write the scenario's complete parameter file (for mwip_sim --params or "
                           "scripts/run_experiment.sh --params)")
    back.add_argument("--plot-rms", type=Path, metavar="FILE.png",
                      help="the theta_b RMS distribution of each --results DIR, side by side on one axis")
    return ap


def cores() -> int:
    """The cores this process may run on (its CPU affinity: a container's or ``taskset``'s share)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


_LOCAL = re.compile(r"local:([0-9]{1,9})")


def add_runner_arguments(ap: argparse.ArgumentParser) -> None:
    """--workers, --dask, --chunk, --oversubscribe: where a sweep's (or a tuner's) chunks run."""
    ap.add_argument("--workers", type=int, default=cores(), metavar="N",
                    help="local worker processes (default: the cores this process may use, %(default)s); 1 = in "
                         "this process; at most one per chunk and, without --oversubscribe, one per core")
    ap.add_argument("--dask", metavar="ADDRESS",
                    help="run the chunks on a dask.distributed scheduler (tcp://host:8786), or 'local:N' for a "
                         "local cluster of N >= 1 workers (capped like --workers); --workers is then ignored")
    ap.add_argument("--chunk", type=int, default=engine.DEFAULT_CHUNK, metavar="N",
                    help="runs per chunk (default %(default)s; at most " + str(engine.SLOW_CHUNK) + " for a law the "
                         "batch cannot compile, MPC: its chunks would take minutes); the laws take turns, so the time "
                         "left knows each law's cost early")
    ap.add_argument("--oversubscribe", action="store_true",
                    help="allow more local workers (--workers, --dask local:N) than cores")


def runner_from(args, prog: str = PROG) -> engine.Runner:
    """The runner the arguments ask for; ValueError (the message for the user) when they make no sense.

    Local workers are capped by the cores (unless ``--oversubscribe``; a note says so) and, when the runner
    starts, by the number of chunks (:class:`engine.Runner`): 18 idle processes on 2 cores help nobody."""
    if args.workers < 1 or args.chunk < 1:
        raise ValueError(f"--workers and --chunk must be >= 1, got --workers {args.workers} --chunk {args.chunk}")
    n_cores = cores()
    oversubscribe = getattr(args, "oversubscribe", False)
    quiet = getattr(args, "quiet", False)
    dask = args.dask
    if dask is not None:
        dask = dask.strip()
        if not dask:
            raise ValueError("--dask needs an address (tcp://host:8786) or local:N")
        if dask.startswith("local:"):
            m = _LOCAL.fullmatch(dask)
            if not m:
                raise ValueError(f"--dask local:N needs a whole number of workers, got {args.dask!r}")
            n = int(m.group(1))
            if n < 1:
                raise ValueError(f"--dask local:N needs N >= 1 workers, got {args.dask!r}")
            if n > n_cores and not oversubscribe:
                if not quiet:
                    print(f"{prog}: note: --dask local:{n} capped at local:{n_cores}, the cores this process may use "
                          f"(--oversubscribe for more)", file=sys.stderr)
                n = n_cores
            dask = f"local:{n}"
        return engine.Runner(1, dask)
    workers = args.workers
    if workers > n_cores and not oversubscribe:
        if not quiet:
            print(f"{prog}: note: --workers {workers} capped at {n_cores}, the cores this process may use "
                  f"(--oversubscribe for more)", file=sys.stderr)
        workers = n_cores
    return engine.Runner(workers, None)


def _fail(text: str) -> int:
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _refuse_file(path, force: bool, option: str) -> int:
    """0 when the file output ``path`` can be written (:func:`outputs.refuse_existing`), else the error exit
    code after one line."""
    reason = outputs.refuse_existing(path, force, option)
    return _fail(reason) if reason else 0


def main(argv=None) -> int:
    """mwip_sweep; SIGTERM is handled like Ctrl-C (finished rows kept, workers stopped, exit 143)."""
    return interrupts.run_main(_main, argv, PROG)


def _main(argv=None) -> int:
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
        spec = load_spec(args.spec, backends=SWEEP_BACKENDS)   # mujoco: the scalar loop (core.kernels.batch)
        scenarios = expand(spec)
    except (SpecError, P.ParamError) as exc:
        return _fail(str(exc))
    spec_copy = args.out / "spec.yaml"   # re-running an output's own spec.yaml: that file is the input, kept
    same = _same_file(spec_copy, args.spec)
    mine = [f for f in SWEEP_FILES if not (same and f == "spec.yaml")]
    reason = (outputs.refuse_directory(args.out, mine, args.force, "--out", "a sweep's outputs")
              or outputs.remove_stale(args.out, mine))
    if reason:
        return _fail(reason)
    reason = outputs.make_directory(args.out, "--out")
    if reason:
        return _fail(reason)
    info = _sweep_info(spec, args)
    (args.out / "sweep.json").write_text(json.dumps(info, indent=2))
    parameter_file(spec.base_sections, {}, args.out / "base.yaml",   # the base (and overlays) as one file
                   f"# {PROG}: the base of this sweep: {' + '.join(map(str, spec.base_path))}\n")
    if not same:
        shutil.copyfile(args.spec, spec_copy)

    chunks = engine.make_chunks(spec, scenarios, args.chunk)
    total = sum(len(c) for c in chunks)
    where = runner.describe(len(chunks))
    if not args.quiet:
        print(f"{PROG}: {len(scenarios):,} scenarios x {len(spec.controllers)} law(s) = {total:,} runs of "
              f"{spec.duration_s:g} s in {len(chunks)} chunk(s), on {where}", file=sys.stderr)
    slow = batch.numba_missing()
    if slow and not args.quiet:
        print(f"{PROG}: warning: {slow}; the scalar loop runs instead, scenario by scenario (slower, the same "
              f"numbers)", file=sys.stderr)
    writer = results.ResultsWriter(args.out / "results.csv", [a.key for a in spec.axes], extra=_has_stages(spec))
    progress = None
    try:
        # numba's first compilation of a law's loop (tens of seconds), said and done before the chunks, once a loop
        warm.compile_first(runner, chunks, (lambda text: None) if args.quiet else _say, PROG)
        progress = _Progress(chunks, args.quiet, workers=lambda: runner.started or 1)
        for chunk, res in runner(chunks):
            writer.add(chunk, res, scenarios)
            progress.update(chunk, res)
    except KeyboardInterrupt:
        runner.close(stop=True)   # before the message: no worker is left when the line is read
        _close(progress)
        writer.close()
        sig = signal.Signals(interrupts.received()).name if interrupts.received() else "SIGINT"
        print(f"\n{PROG}: interrupted ({sig}): {writer.rows:,} of {total:,} rows are in {args.out / 'results.csv'}",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    except registry.LawError as exc:   # a law's step raised: the law, the scenario, when, its own error
        runner.close(stop=True)
        _close(progress)
        writer.close()
        print(f"{PROG}: error: {exc}; {writer.rows:,} finished rows are in {args.out / 'results.csv'}",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:   # a worker's failure (or a lost Dask connection): keep what finished
        _close(progress)
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


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _sweep_info(spec, args) -> dict:
    def dist(a):
        return f"{a.kind} {list(a.args)}" if a.kind != "grid" or len(a.args) <= 6 else f"grid of {len(a.args)}"
    return {"name": args.spec.stem, "spec": str(args.spec), "base": [str(b) for b in spec.base_path],
            "controllers": list(spec.controllers), "duration_s": spec.duration_s, "window": list(spec.window),
            "seed": spec.seed, "samples": spec.samples, "scenarios": spec.n_scenarios,
            "varied": {a.key: dist(a) for a in spec.axes},
            "axes": [{"key": a.key, "section": a.section, "name": a.name, "type": a.type, "kind": a.kind}
                     for a in spec.axes]}


def _has_stages(spec) -> bool:
    """Whether the sweep's loop has raw sensors, the motor or motion references, in its base file or on an axis
    (their metrics: results.EXTRA_METRICS)."""
    v = spec.base_values
    names = {a.name for a in spec.axes}
    return v.get("sensors.model") == "raw" or bool(v.get("motor.enabled")) or bool(v.get("motion.enabled")) or bool(
        {"sensors.model", "motor.enabled", "motion.enabled"} & names)


def _figures(cols, spec, doc, out: Path) -> list:
    from mwip_ros.cli import plotting
    written = []
    numeric = [(a.key, not a.random) for a in spec.axes if a.type in ("double", "integer")]
    # a panel (a line, a histogram) per group of the summary: per law, and per choice (sensors.model, ...)
    cols = dict(cols, controller=results.run_labels(cols, doc["spec"]))
    if plotting.sweep_upright_map(cols, numeric, out / "upright_map.png"):
        written.append("upright_map.png")
    plotting.sweep_rms_distribution(cols, out / "theta_b_rms.png")
    written.append("theta_b_rms.png")
    if results.THETA0_KEY in cols:
        roa = {c: e.get("region_of_attraction_theta_b0") for c, e in doc["controllers"].items()}
        plotting.sweep_roa(cols, results.THETA0_KEY, roa, out / "roa.png")
        written.append("roa.png")
    return written


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _close(progress) -> None:
    if progress is not None:
        progress.close()


class _Progress:
    """tqdm on a terminal (runs done, scenario-steps/s, time left); a plain line at least every 5 s otherwise,
    whether a chunk finished or not (:class:`progress.Heartbeat`: chunks of a slow configuration take tens of
    seconds each).

    The time left is each law's scenarios left at its own measured cost (:class:`progress.Eta`), not the runs
    left at the average rate: MPC's chunks cost ~100 times a compiled law's; between two finished chunks it counts
    down.  ``workers()`` is how many chunks run at once."""

    EVERY_S = 5.0   # a plain line at least this often

    def __init__(self, chunks, quiet: bool, workers=lambda: 1):
        self.total, self.done, self.steps = sum(len(c) for c in chunks), 0, 0
        self.eta = sweep_progress.Eta(chunks)
        self.workers = workers
        self.t0 = self._at = time.monotonic()
        self.quiet = quiet
        self.bar = None
        self._left = None   # (seconds left, the untimed laws) at the last finished chunk
        if not quiet and sys.stderr.isatty():
            from tqdm import tqdm   # its own remaining time assumes every run costs the same: ours instead
            self.bar = tqdm(total=self.total, unit="run", file=sys.stderr, dynamic_ncols=True, smoothing=0.1,
                            bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}{postfix}]")
        self.beat = None
        if not quiet:   # a line (or the bar redrawn) at least every EVERY_S, between chunks too
            self.beat = sweep_progress.Heartbeat(self.EVERY_S, self._heartbeat, _say).__enter__()

    def left(self) -> str:
        if self._left is None:
            return sweep_progress.describe_left(*self.eta.estimate(self.workers()))
        seconds, untimed = self._left
        return sweep_progress.describe_left(max(0.0, seconds - (time.monotonic() - self._at)), untimed)

    def _line(self) -> str:
        wall = time.monotonic() - self.t0
        rate = f", {self.steps / max(1e-9, wall):,.0f} scenario-steps/s" if self.done else ""
        return (f"{PROG}: {self.done:,}/{self.total:,} runs ({100 * self.done / self.total:.0f} %){rate}, "
                f"{wall:.0f} s in, {self.left()}")

    def _heartbeat(self):
        if self.bar is not None:
            self.bar.set_postfix_str(self._postfix(), refresh=False)
            self.bar.refresh()   # its elapsed time and our time left, between chunks
            return None
        return self._line()

    def _postfix(self) -> str:
        rate = self.steps / max(1e-9, time.monotonic() - self.t0)
        return f"{rate / 1e6:.2f} M scenario-steps/s, {self.left()}"

    def update(self, chunk, result) -> None:
        lock = self.beat.lock if self.beat is not None else _NoLock()
        with lock:
            self.done += len(chunk)
            self.steps += result.steps
            self.eta.done(chunk.controller, len(chunk), result.seconds)
            self._left, self._at = self.eta.estimate(self.workers()), time.monotonic()
            if self.bar is not None:
                self.bar.set_postfix_str(self._postfix(), refresh=False)
                self.bar.update(len(chunk))
            elif not self.quiet and (self.beat is None or time.monotonic() - self.beat._last >= self.EVERY_S
                                     or self.done == self.total):
                _say(self._line())
                if self.beat is not None:
                    self.beat.said()
        if self.done >= self.total and self.beat is not None:   # nothing more to wait for: silent from here
            self.beat.__exit__(None, None, None)
            self.beat = None

    def close(self) -> None:
        if self.beat is not None:
            self.beat.__exit__(None, None, None)
            self.beat = None
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        if not self.quiet and self.done:
            wall = time.monotonic() - self.t0
            print(f"{PROG}: {self.done:,} runs, {self.steps:,} scenario-steps in {wall:.1f} s "
                  f"({self.steps / max(wall, 1e-9):,.0f} scenario-steps/s)", file=sys.stderr)


class _NoLock:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def _plot_rms(args) -> int:
    if not args.results:
        return _fail("--plot-rms needs --results DIR [DIR ...]")
    named = []
    for d in args.results:
        try:
            info = _read_sweep_json(d)
            named.append((str(info.get("name", d.name))[:200], results.read_results(d / "results.csv")))
        except (OSError, ValueError) as exc:
            return _fail(f"{d} is not a sweep's output directory ({exc})")
    refused = _refuse_file(args.plot_rms, args.force, "--plot-rms")
    if refused:
        return refused
    from mwip_ros.cli import plotting
    plotting.sweep_rms_panels(named, args.plot_rms)
    print(f"wrote {args.plot_rms}")
    return 0


def _read_sweep_json(d: Path) -> dict:
    """A sweep's sweep.json, checked for what --write-params uses; ValueError (one line) when it lacks it."""
    from mwip_ros.yamlio import FileTooLarge, read_bytes
    path = d / "sweep.json"
    try:   # a regular file (a FIFO or a device is refused unread), bounded
        data = read_bytes(path, SWEEP_JSON_MAX_BYTES, "sweep.json")
    except FileTooLarge as exc:
        raise ValueError(f"{path}: {exc} (more than a sweep writes)") from None
    try:
        info = json.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path} is not text ({exc.reason})") from None
    except RecursionError:
        raise ValueError(f"{path} is nested too deeply") from None
    if not isinstance(info, dict):
        raise ValueError(f"{path} holds no object")

    def need(key, ok, what):
        if key not in info:
            raise ValueError(f"{path} has no {key!r}")
        if not ok(info[key]):
            raise ValueError(f"{path}: {key!r} must be {what}, got {_short(info[key])}")

    def num(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    need("controllers", lambda v: isinstance(v, list) and v and all(c in registry.names() for c in v),
         f"a non-empty list of {', '.join(registry.names())}")
    need("axes", lambda v: isinstance(v, list) and all(
        isinstance(a, dict) and all(isinstance(a.get(k), str) for k in ("key", "section", "name", "type"))
        for a in v), "a list of {key, section, name, type} objects")
    need("scenarios", lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0, "a count")
    need("duration_s", lambda v: num(v) and v > 0, "a number of seconds > 0")
    need("window", lambda v: isinstance(v, list) and len(v) == 2 and all(num(x) for x in v), "[t0, t1]")
    return info


def _short(v, n: int = 60) -> str:
    text = repr(v)
    return text if len(text) <= n else text[:n] + f"... ({len(text):,} characters)"


SWEEP_JSON_MAX_BYTES = 16 << 20   # a sweep.json names its axes: kilobytes; a larger one was not written by a sweep


def _write_params(args) -> int:
    if args.results is None or len(args.results) != 1 or args.scenario is None or args.write_params is None:
        return _fail("--write-params needs one --results DIR and --scenario N")
    d = args.results[0]
    try:
        info = _read_sweep_json(d)
        cols = results.read_results(d / "results.csv")
    except (OSError, ValueError) as exc:
        return _fail(f"{d} is not a sweep's output directory ({exc})")
    laws = info["controllers"]
    law = args.controller or ("dscndo" if "dscndo" in laws else laws[0])
    if law not in laws:
        return _fail(f"--controller {law}: the sweep ran {', '.join(laws)}")
    missing = [a["key"] for a in info["axes"] if a["key"] not in cols]
    if missing:
        return _fail(f"{d / 'results.csv'} has no column {missing[0]!r} (an axis of {d / 'sweep.json'}); "
                     f"not this sweep's results")
    rows = [j for j, (s, c) in enumerate(zip(cols["scenario"], cols["controller"])) if s == args.scenario and c == law]
    if not rows:
        return _fail(f"no row for scenario {args.scenario} ({law}) in {d / 'results.csv'} (scenarios 0.."
                     f"{info['scenarios'] - 1}; an interrupted sweep lacks some)")
    refused = _refuse_file(args.write_params, args.force, "--write-params")
    if refused:
        return refused
    j = rows[0]
    placed = {("plant_sim", "seed"): cols["seed"][j], ("plant_sim", "duration_s"): float(info["duration_s"]),
              ("dscndo_controller", "use_observer"): registry.get(law).observer,
              ("dscndo_controller", "law"): registry.get(law).family}
    for a in info["axes"]:
        v = cols[a["key"]][j]
        if a["type"] == "integer":
            if not (isinstance(v, float) and math.isfinite(v) and v == int(v)):
                return _fail(f"{d / 'results.csv'}: scenario {args.scenario} ({law}): {a['key']} = {_short(v)} is "
                             f"not an integer")
            v = int(v)
        try:
            spec = P.specs_for(a["section"])[a["name"]]
        except KeyError:
            return _fail(f"{d / 'sweep.json'}: axis {a['key']!r} is no parameter ({a['section']}.{a['name']})")
        try:
            placed[(a["section"], a["name"])] = spec.validate(v, a["key"], f"{d / 'results.csv'} scenario "
                                                                            f"{args.scenario} ({law})")
        except P.ParamError as exc:
            return _fail(_one_line(exc))
    out = args.write_params
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")   # checked before it replaces anything: no bad file left
    try:
        base = P.load_param_file(d / "base.yaml")
        header = (f"# {PROG}: scenario {args.scenario} of {d} ({law}), a complete parameter file.\n"
                  f"# Its results.csv row: upright {cols['upright'][j]}, theta_b RMS {cols['theta_b_rms'][j]!r} rad "
                  f"over t in {info['window']} s.\n")
        parameter_file(base.sections, placed, tmp, header)
        os.replace(tmp, out)
    except (P.ParamError, ArithmeticError, TypeError) as exc:   # values that pass alone, not together
        return _fail(f"scenario {args.scenario} ({law}) of {d} gives no valid parameter file: "
                     f"{_one_line(exc).replace(str(tmp), str(out))}")
    except (OSError, ValueError) as exc:
        return _fail(f"--write-params {out}: {_one_line(exc)}")
    finally:
        try:
            tmp.unlink()
        except OSError:
            pass
    print(f"wrote {args.write_params} (scenario {args.scenario}, {law})")
    return 0


def _one_line(exc) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 300 else text[:300] + "..."


if __name__ == "__main__":
    sys.exit(main())
