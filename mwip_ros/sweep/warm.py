"""The batch loop compiled before a sweep needs it, with a word to the user.

numba compiles a law's whole batch period (:func:`mwip_ros.core.kernels.compiled.kernel_for`: one loop per law's pure
step, and per estimator with raw sensors) the first time a process runs it, 15 to 40 s each on two shared cores, and
caches the machine code under ``mwip_ros/`` (:mod:`mwip_ros.core.kernels.jitcache`) until the code it is made of
changes.  A sweep of a fresh clone compiled its loops inside its first chunks, each worker the same loop at the same
time, saying nothing for a minute and a half.  Here:

* :func:`cold_kernels`: the compiled loops a list of chunks runs that the cache lacks, each with a chunk of one
  scenario and a few periods that compiles it;
* :func:`compile_first`: ``mwip_sweep`` and ``mwip_tune`` compile those first, one loop per worker at a time, and
  say so (a line, then one every :data:`EVERY_S` s, then how long it took);
* :func:`main` (``python -m mwip_ros.sweep.warm``, run by ``scripts/setup.sh`` when it installs): the loops of every
  registered law with a pure step, with state sensors and with raw sensors and each estimator, so the first sweep of
  a fresh clone runs at the speed of the next.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Callable, List, Optional, Sequence, Tuple

from mwip_ros.sweep.engine import Chunk, batch_groups
from mwip_ros.sweep.progress import Heartbeat

__all__ = ["EVERY_S", "cold_kernels", "compile_first", "shipped_chunks", "main"]

EVERY_S = 5.0        # a line at least this often while compiling
WARM_S = 0.1         # the simulated length of a chunk that compiles a loop [s]


def _values(chunk: Chunk, i: int) -> dict:
    v = dict(chunk.base)
    v.update(chunk.overrides[i])
    return v


def _label(law: type, stage: tuple, values: dict) -> str:
    """'dsc' (the loop of dsc and dscndo), 'lqr with raw sensors (kalman)'."""
    name = getattr(law, "base", law).name
    return f"{name} with raw sensors ({values.get('method')})" if stage[0] else name


def cold_kernels(chunks: Sequence[Chunk]) -> List[Tuple[str, Chunk]]:
    """The compiled loops the ``chunks`` run (:func:`mwip_ros.core.kernels.batch.compiled_form` of each batch of each
    chunk) that numba's cache lacks (:func:`mwip_ros.core.kernels.jitcache.cached` is False), once each, in the chunks'
    order: (a label, a chunk of one of its scenarios, :data:`WARM_S` long, that compiles it)."""
    from mwip_ros import params as P
    from mwip_ros.core.kernels.batch import compiled_form
    seen, out = set(), []
    for chunk in chunks:
        for idx in batch_groups(chunk).values():
            v = _values(chunk, idx[0])
            loop = P.closed_loop(v, duration=chunk.duration_s, controller=chunk.controller)
            form = compiled_form([loop])
            if form is None or id(form[0]) in seen:
                continue
            seen.add(id(form[0]))
            # numba's: only once there is a compiled loop (numba there)
            from mwip_ros.core.kernels.jitcache import cached
            if cached(form[0]) is False:
                h = 1.0 / v["control_rate_hz"]
                length = max(WARM_S, 4 * h)
                out.append((_label(form[1], form[2], v),
                            Chunk(chunk.first + idx[0], chunk.controller, chunk.base, (chunk.overrides[idx[0]],),
                                  length, (0.0, length))))
    return out


def compile_first(runner, chunks: Sequence[Chunk], say: Callable[[str], None], who: str) -> float:
    """Compile the loops of ``chunks`` the cache lacks (:func:`cold_kernels`) on ``runner`` (a
    :class:`~mwip_ros.sweep.engine.Runner`: one loop per worker at a time), saying so: a line naming them, one every
    :data:`EVERY_S` s, and the time it took.  Returns the seconds spent (0 when every loop was cached)."""
    cold = cold_kernels(chunks)
    if not cold:
        return 0.0
    names = ", ".join(label for label, _ in cold)
    say(f"{who}: compiling the batch loop for {names} (numba, once per change of the code, 15 to 40 s each on 2 "
        f"cores; scripts/setup.sh compiles the built-in laws' when it installs) ...")
    t0 = time.monotonic()
    left, chunks = _numbered(cold)
    beat = Heartbeat(EVERY_S, lambda: f"{who}: still compiling ({', '.join(left.values())}): "
                                      f"{time.monotonic() - t0:.0f} s", say)
    with beat:
        try:
            for chunk, _ in runner(chunks):
                with beat.lock:
                    left.pop(chunk.first, None)
        except Exception as exc:  # noqa: BLE001 - e.g. a law that raises: its chunk of the sweep says it, numbered
            say(f"{who}: compiling ahead stopped ({type(exc).__name__}); the chunks compile what is left")
            return time.monotonic() - t0
    say(f"{who}: compiled in {time.monotonic() - t0:.0f} s; cached for the next runs")
    return time.monotonic() - t0


def _numbered(cold: List[Tuple[str, Chunk]]):
    """({i: label}, the chunks numbered 0, 1, ...: told apart as they finish; their results are not kept)."""
    chunks = [Chunk(i, c.controller, c.base, c.overrides, c.duration_s, c.window) for i, (_, c) in enumerate(cold)]
    return {i: label for i, (label, _) in enumerate(cold)}, chunks


def shipped_chunks(config_dir=None) -> List[Chunk]:
    """A chunk per loop a sweep of the shipped files may compile: every registered law with a pure step (one per
    step: dscndo shares dsc's), on ``config/paper.yaml`` with state sensors and with
    ``config/sensors_raw_realistic.yaml`` and each estimator with a pure step."""
    from pathlib import Path

    from mwip_ros import params as P
    from mwip_ros.core import estimators, laws
    from mwip_ros.core.kernels.compiled_stages import pure_form
    from mwip_ros.params.paths import default_params_file
    config = Path(config_dir) if config_dir is not None else default_params_file().parent
    state = P.merged_values(P.load_param_files([config / "paper.yaml"], option="params"))
    raw = P.merged_values(P.load_param_files([config / "paper.yaml", config / "sensors_raw_realistic.yaml"],
                                             option="params"))
    bases = [state] + [dict(raw, method=m) for m in estimators.names()
                       if getattr(estimators.get(m), "pure_step", None) is not None]
    steps, names = set(), []
    for name in laws.names():
        fn = pure_form(laws.get(name))
        if fn is not None and fn not in steps and not laws.unavailable(laws.get(name)):
            steps.add(fn)
            names.append(name)
    return [Chunk(0, name, base, ({"seed": 1},), WARM_S, (0.0, WARM_S)) for base in bases for name in names]


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``python -m mwip_ros.sweep.warm [--workers N]``: compile the shipped loops (:func:`shipped_chunks`) the cache
    lacks, on N worker processes (default: the cores this process may use); exit 0 (also when numba is missing:
    nothing to compile), 1 when a compilation failed."""
    ap = argparse.ArgumentParser(prog="python -m mwip_ros.sweep.warm",
                                 description="Compile the batch loop of every built-in law (numba's cache), so the "
                                             "first sweep runs at the speed of the next.")
    ap.add_argument("--workers", type=int, default=None, help="worker processes (default: the cores)")
    args = ap.parse_args(argv)
    from mwip_ros.core.kernels.batch import numba_missing
    if numba_missing():
        print("setup: numba is missing: sweeps run the scalar loop, nothing to compile")
        return 0
    from mwip_ros.sweep.engine import Runner
    cold = cold_kernels(shipped_chunks())
    if not cold:
        print("setup: the batch loops are compiled (numba's cache is up to date)")
        return 0
    workers = args.workers or (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count())
    print(f"setup: compiling the batch loop of the built-in laws (numba; {len(cold)} loops, once per change of the "
          f"code: a few minutes on 2 cores; mwip_sweep's first run then takes what its next runs take) ...",
          flush=True)
    t0 = time.monotonic()
    left, chunks = _numbered(cold)

    def say(text: str) -> None:
        print(text, flush=True)
    try:
        with Runner(max(1, min(int(workers or 1), len(chunks)))) as runner, \
                Heartbeat(EVERY_S, lambda: f"setup: still compiling ({len(left)} left): "
                                           f"{time.monotonic() - t0:.0f} s", say) as beat:
            for chunk, _ in runner(chunks):
                with beat.lock:
                    label = left.pop(chunk.first, "?")
                    say(f"setup: compiled the batch loop of {label} ({time.monotonic() - t0:.0f} s)")
                    beat.said()
    except Exception as exc:  # noqa: BLE001 - compiling ahead is a convenience: a sweep compiles what is missing
        print(f"setup: warning: compiling the batch loop failed ({type(exc).__name__}: {exc}); a sweep compiles it "
              f"at its start instead", file=sys.stderr)
        return 1
    print(f"setup: compiled {len(chunks)} batch loops in {time.monotonic() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
