"""Run a sweep's chunks: in this process, on local worker processes, or on a Dask cluster.

A :class:`Chunk` is up to ``chunk_size`` consecutive scenarios under one law (fewer, :data:`SLOW_CHUNK`, for a
law the batch cannot compile: its chunks take minutes otherwise, and progress would stand still); :func:`run_chunk`
(a plain function of plain data, so any process or Dask worker can run it) builds each
scenario's :class:`~mwip_ros.core.closed_loop.sim.ClosedLoop` from the base values and the scenario's
overrides and runs them through :func:`~mwip_ros.core.kernels.batch.simulate_batch`.  The chunks are
cut the same way whatever runs them, so the results are identical however the sweep ran.  :func:`make_chunks`
takes the laws in turn (each law's first chunk, the slow laws' first, then each law's second, ...), so every
law's cost per scenario is measured early (:class:`ChunkResult.seconds`; the time left, :mod:`mwip_ros.sweep.progress`).

Runners yield ``(chunk, result)`` as chunks finish:

* :func:`run_local` with ``workers=1``: in this process, in order.
* :func:`run_local` with ``workers=N``: a pool of up to N processes (spawned, not forked), never more
  than there are chunks.
* :func:`run_dask`: ``address`` of a running ``dask.distributed`` scheduler, or ``local:N`` for a
  local cluster of N single-threaded worker processes started for this sweep.
"""
from __future__ import annotations

import gc
import os
import time
from dataclasses import dataclass
from typing import Any, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

from mwip_ros.core.kernels import budget
from mwip_ros.core import laws
from mwip_ros.core.kernels.budget import window_samples
from mwip_ros.sweep.workers import signals_held, stop_resource_tracker, worker_init

__all__ = ["Chunk", "ChunkResult", "make_chunks", "chunks_of", "chunk_size_for", "run_chunk", "batch_groups", "Runner",
           "run_local", "run_dask", "DEFAULT_CHUNK", "SLOW_CHUNK"]

DEFAULT_CHUNK = 5000   # scenarios per chunk: numpy's per-call cost is small against 5,000 elements, and a
                       # 10 s run's window (4 x 1,001 samples per scenario) takes 160 MB (docs/benchmarks-history.md)
SLOW_CHUNK = 50        # scenarios per chunk of a law without a pure form (Law.pure_step: MPC, a plug-in): the batch
                       # runs it over numpy arrays or scenario by scenario, about 100 times slower per scenario
                       # than a compiled law (BENCHMARKS.md), so a chunk is seconds, not minutes, of a worker


@dataclass(frozen=True)
class Chunk:
    first: int                         # index of the first scenario
    controller: str                    # a registered law (core.laws.names()): 'dsc', 'dscndo', 'lqr', 'lqr_ndo'
    base: Dict[str, Any]               # the base file's merged values
    overrides: Tuple[Dict[str, Any], ...]   # per scenario (seed included)
    duration_s: float
    window: Tuple[float, float]

    def __len__(self) -> int:
        return len(self.overrides)


@dataclass
class ChunkResult:
    upright: np.ndarray
    t_fall: np.ndarray
    metrics: Dict[str, np.ndarray]
    steps: int
    seconds: float = 0.0   # wall time the chunk took where it ran (a worker): the law's cost, for the time left
    # why each failed: a core.closed_loop.trajectory.FAILURES code (0: it did not)
    failure: Optional[np.ndarray] = None


def chunk_size_for(controller: str, chunk_size: int = DEFAULT_CHUNK) -> int:
    """Scenarios per chunk of ``controller``: ``chunk_size``, at most :data:`SLOW_CHUNK` for a law without a pure
    form (:func:`~mwip_ros.core.kernels.compiled_stages.pure_form`: the batch cannot compile it), and for every law
    without numba (the scalar loop runs each scenario: :func:`~mwip_ros.core.kernels.batch.numba_missing`)."""
    from mwip_ros.core import laws
    from mwip_ros.core.kernels.batch import numba_missing
    slow = max(1, min(chunk_size, SLOW_CHUNK))
    if numba_missing():
        return slow
    from mwip_ros.core.kernels.compiled_stages import pure_form
    return chunk_size if pure_form(laws.get(controller)) is not None else slow


def make_chunks(spec, scenarios, chunk_size: int = DEFAULT_CHUNK) -> List[Chunk]:
    """Every law's runs, :func:`chunk_size_for` scenarios at a time, the laws taken in turn: each law's first
    chunk, then each law's second, ..., the slow laws (small chunks) first in each turn, so every law's cost is
    measured early, the slowest first."""
    overrides = [scenarios.overrides(i) for i in range(len(scenarios))]
    sizes = {ctrl: chunk_size_for(ctrl, chunk_size) for ctrl in spec.controllers}
    per_law = [chunks_of(ctrl, spec.base_values, overrides, spec.duration_s, spec.window, sizes[ctrl])
               for ctrl in sorted(spec.controllers, key=lambda c: sizes[c] == chunk_size)]   # stable: slow ones first
    return [law[k] for k in range(max((len(law) for law in per_law), default=0)) for law in per_law if k < len(law)]


def chunks_of(controller: str, base: Dict[str, Any], overrides: Sequence[Dict[str, Any]], duration_s: float,
              window: Tuple[float, float], chunk_size: int = DEFAULT_CHUNK) -> List[Chunk]:
    """Runs of one law, one per entry of ``overrides`` (changes to ``base``), ``chunk_size`` at a time."""
    n = len(overrides)
    return [Chunk(first, controller, base, tuple(overrides[first:first + chunk_size]), duration_s, window)
            for first in range(0, n, chunk_size)]


def scenario_cost(values: Dict[str, Any], duration_s: float, window: Tuple[float, float]) -> Tuple[int, int]:
    """(bytes per scenario, bytes per batch) of a run of these merged values in a batch (core.kernels.budget)."""
    h = 1.0 / values["control_rate_hz"]   # params.typed.period: the batch's h
    n_steps = int(round(duration_s / h))
    n_window = window_samples(n_steps, h, window)[1]
    d, a = int(values["sensors.delay_periods"]), int(values["actuator.delay_periods"])
    return budget.scenario_batch_bytes(n_window, n_steps, d, a), budget.batch_fixed_bytes(n_steps, d, a)


def run_chunk(chunk: Chunk, batch_bytes: Optional[int] = None) -> ChunkResult:
    """Simulate one chunk (scenarios that differ in control period, RK4 sub-steps, encoder or delays run as
    separate batches).  A batch whose estimated memory (core.kernels.budget) is above ``batch_bytes`` (default: the
    budget's :func:`~mwip_ros.core.kernels.budget.batch_budget`) runs as several, each within it; the scenarios'
    ClosedLoops are built a batch at a time.  Python's cyclic garbage collector is off meanwhile
    (:class:`_gc_held`)."""
    t0 = time.perf_counter()
    with _gc_held():
        result = _run_chunk(chunk, batch_bytes)
    result.seconds = time.perf_counter() - t0
    return result


class _gc_held:
    """Python's cyclic garbage collector off inside (as it was after): a chunk's thousands of ClosedLoops and
    their rows of numbers trigger its collections, the full ones going over every object of the process (numba
    is a large heap): 0.2 to 0.3 s of a chunk of 5,000 (2026-12-01, AMD EPYC).  What a chunk makes is freed by
    reference counting; cyclic garbage (numba's, when a chunk compiles the kernel: 23 MiB more peak memory,
    measured) waits for the next collection after the chunk."""

    def __enter__(self):
        self.was = gc.isenabled()
        gc.disable()

    def __exit__(self, *exc):
        if self.was:
            gc.enable()


def batch_groups(chunk: Chunk) -> Dict[tuple, List[int]]:
    """The chunk's scenarios (indices) by what makes them separate batches: the control period, the RK4 sub-steps,
    the encoder and the delays (PlantConfig's), the stages (sensors' model, motor, excitation, the estimator,
    motion)."""
    groups: Dict[tuple, List[int]] = {}
    for i, ov in enumerate(chunk.overrides):
        v = dict(chunk.base)
        v.update(ov)
        key = (1.0 / v["control_rate_hz"], int(v["substeps"]), v["sensors.encoder_counts_per_rev"],
               v["sensors.delay_periods"], v["actuator.delay_periods"],   # PlantConfig's h, substeps, sensing
               v.get("sensors.model"), v.get("motor.enabled"), v.get("excitation.type"), v.get("method"),
               v.get("motion.enabled"))   # stages
        groups.setdefault(key, []).append(i)
    return groups


def _run_chunk(chunk: Chunk, batch_bytes: Optional[int]) -> ChunkResult:
    from mwip_ros import params as P
    from mwip_ros.core.kernels.batch import simulate_batch
    cap = budget.batch_budget() if batch_bytes is None else batch_bytes

    def values(ov):
        v = dict(chunk.base)
        v.update(ov)
        return v

    n = len(chunk.overrides)
    groups = batch_groups(chunk)
    upright, t_fall, failure = np.zeros(n, dtype=bool), np.full(n, np.nan), np.zeros(n, dtype=np.int64)
    metrics: Dict[str, np.ndarray] = {}
    steps = 0
    for group in groups.values():
        per, fixed = scenario_cost(values(chunk.overrides[group[0]]), chunk.duration_s, chunk.window)
        size = max(1, int((cap - fixed) // per)) if cap > fixed + per else 1   # one scenario fits (load_spec)
        for start in range(0, len(group), size):
            idx = group[start:start + size]
            loops = [P.closed_loop(values(chunk.overrides[i]), duration=chunk.duration_s, controller=chunk.controller)
                     for i in idx]
            try:
                r = simulate_batch(loops, chunk.window)
            except laws.LawError as exc:   # its scenario, as the sweep numbers them
                raise exc.in_scenario(chunk.first + idx[exc.scenario] if exc.scenario is not None else None) \
                    from None
            del loops
            upright[idx], t_fall[idx], failure[idx] = r.upright, r.t_fall, r.failure
            for k, v in r.metrics.items():
                metrics.setdefault(k, np.full(n, np.nan))[idx] = v
            steps += r.steps
    return ChunkResult(upright, t_fall, metrics, steps, failure=failure)


class Runner:
    """Where chunks run: this process (``workers=1``), a pool of ``workers`` processes (spawned once, kept for
    the runner's life: a tuner sends it a generation at a time), or a Dask cluster (``dask``: the address
    of a running scheduler, or ``local:N``).  ``runner(chunks)`` yields ``(chunk, result)`` as each
    finishes; use it as a context manager, or call :meth:`close`.

    No more local processes start than the first call has chunks (``started``; one chunk runs in this
    process).  An interrupt (Ctrl-C, or SIGTERM through :mod:`mwip_ros.cli.interrupts`) or a failed chunk
    stops the workers at once (:meth:`close` with ``stop``): terminated, joined, and multiprocessing's
    resource tracker stopped, so no process of the run outlives it."""

    def __init__(self, workers: int = 1, dask: str = None):
        self.workers, self.dask = max(1, int(workers)), dask
        local = dask[len("local:"):] if dask and dask.startswith("local:") else None
        for option, n in (("--workers", self.workers), ("--dask local:N", local)):
            if n is not None and str(n).isdigit() and int(n) > budget.max_workers():
                raise ValueError(f"{option} {n}: at most {budget.max_workers()} worker processes (twice this "
                                 f"machine's {os.cpu_count() or 1} CPUs: more run no faster, and each takes about "
                                 f"{budget.fmt_bytes(budget.WORKER_PROCESS)} plus up to "
                                 f"{budget.fmt_bytes(budget.batch_budget())} of batch arrays)")
        if dask:   # optional (mwip_ros.optional): without it --dask is refused in one line, before any work
            from mwip_ros.optional import missing
            text = missing("dask.distributed", "--dask")
            if text:
                raise ValueError(text)
        self.started = 0   # the worker processes actually started (at most one per chunk)
        self._pool = self._client = self._cluster = None

    def describe(self, chunks: int = None) -> str:
        """Where the chunks run; with ``chunks``, the worker processes that many chunks start (one per chunk
        at most)."""
        if self.dask:
            if self.dask.startswith("local:") and chunks is not None:
                return f"Dask at local:{max(1, min(int(self.dask[6:]), chunks))}"
            return f"Dask at {self.dask}"
        n = self.workers if chunks is None else max(1, min(self.workers, chunks))
        return f"{n} worker processes" if n > 1 else "this process"

    def __call__(self, chunks: Sequence[Chunk]) -> Iterator[Tuple[Chunk, ChunkResult]]:
        chunks = list(chunks)
        if self.dask:
            yield from self._dask(chunks)
        elif self.workers <= 1 or (len(chunks) <= 1 and self._pool is None):   # one chunk: no process to spawn
            for c in chunks:
                yield c, run_chunk(c)
        else:
            yield from self._local(chunks)

    def _local(self, chunks):
        import multiprocessing
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

        todo, running = list(chunks), {}
        if self._pool is None:   # never more processes than chunks: an idle worker costs ~160 MiB
            n = max(1, min(self.workers, len(todo)))
            self._pool = ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=worker_init)
            self.started = n
        try:
            while todo or running:
                while todo and len(running) < 2 * self.started:   # a few ahead: results stream, memory stays small
                    c = todo.pop(0)
                    running[self._pool.submit(run_chunk, c)] = c
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for f in done:
                    yield running.pop(f), f.result()
        except BaseException:
            self.close(stop=True)   # an interrupt (Ctrl-C, SIGTERM) or a failed chunk: stop the workers now
            raise

    def _dask(self, chunks):
        from mwip_ros.optional import required
        with required("dask", "--dask"):   # checked in __init__ already: this is the import itself
            from dask.distributed import Client, LocalCluster, as_completed

        chunks = list(chunks)
        if self._client is None:
            if self.dask.startswith("local:"):
                n = max(1, min(int(self.dask.split(":", 1)[1]), len(chunks)))
                self.started = n
                self._cluster = LocalCluster(n_workers=n, threads_per_worker=1,
                                             processes=True, dashboard_address=None)
                self._client = Client(self._cluster)
            else:
                self._client = Client(self.dask, timeout=30)
        try:
            futures = {self._client.submit(run_chunk, c, pure=False): c for c in chunks}
            for f in as_completed(futures):
                yield futures[f], f.result()
        except BaseException:
            self.close(stop=True)
            raise

    def close(self, stop: bool = False) -> None:
        """Shut the workers down: after the running chunks (``stop=False``), or at once (``stop``: an interrupt
        or a failure; running chunks are abandoned, no process is left behind).  SIGINT and SIGTERM wait
        until it is done."""
        with signals_held():
            if self._pool is not None:
                pool, self._pool = self._pool, None
                procs = list((getattr(pool, "_processes", None) or {}).values()) if stop else []
                for p in procs:
                    if p.is_alive():
                        p.terminate()
                pool.shutdown(wait=True, cancel_futures=True)
                for p in procs:
                    p.join(5)
                    if p.is_alive():
                        p.kill()
                        p.join(5)
                stop_resource_tracker()   # no worker holds it now: it exits, and is waited for, not orphaned
            if self._client is not None:
                client, self._client = self._client, None
                try:
                    client.close(timeout=10)
                except Exception:  # noqa: BLE001 - a scheduler already gone: nothing more to close
                    pass
            if self._cluster is not None:
                cluster, self._cluster = self._cluster, None
                try:
                    cluster.close(timeout=20)
                except Exception:  # noqa: BLE001
                    pass
                stop_resource_tracker()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def run_local(chunks: Sequence[Chunk], workers: int = 1) -> Iterator[Tuple[Chunk, ChunkResult]]:
    """Run the chunks here (``workers=1``) or on ``workers`` processes; yields each as it finishes."""
    with Runner(workers) as runner:
        yield from runner(chunks)


def run_dask(chunks: Sequence[Chunk], address: str) -> Iterator[Tuple[Chunk, ChunkResult]]:
    """Run the chunks on a Dask cluster: ``tcp://host:port`` of a running scheduler, or ``local:N``."""
    with Runner(dask=address) as runner:
        yield from runner(chunks)
