"""Run a sweep's chunks: in this process, on local worker processes, or on a Dask cluster.

A :class:`Chunk` is up to ``chunk_size`` consecutive scenarios under one law; :func:`run_chunk`
(a plain function of plain data, so any process or Dask worker can run it) builds each
scenario's :class:`~mwip_ros.core.sim.ClosedLoop` from the base values and the scenario's
overrides and runs them through :func:`~mwip_ros.core.batch.simulate_batch`.  The chunks are
cut the same way whatever runs them, so the results are identical however the sweep ran.

Runners yield ``(chunk, result)`` as chunks finish:

* :func:`run_local` with ``workers=1``: in this process, in order.
* :func:`run_local` with ``workers=N``: a pool of N processes (spawned, not forked).
* :func:`run_dask`: ``address`` of a running ``dask.distributed`` scheduler, or ``local:N`` for a
  local cluster of N single-threaded worker processes started for this sweep.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, Iterator, List, Sequence, Tuple

import numpy as np

__all__ = ["Chunk", "ChunkResult", "make_chunks", "chunks_of", "run_chunk", "Runner", "run_local", "run_dask",
           "DEFAULT_CHUNK"]

DEFAULT_CHUNK = 5000   # scenarios per chunk: numpy's per-call cost is small against 5,000 elements, and a
                       # 10 s run's window (4 x 1,001 samples per scenario) takes 160 MB (BENCHMARKS.md)


@dataclass(frozen=True)
class Chunk:
    first: int                         # index of the first scenario
    controller: str                    # a law of core.sim.LAWS: 'dsc', 'dscndo', 'lqr', 'lqr_ndo'
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


def make_chunks(spec, scenarios, chunk_size: int = DEFAULT_CHUNK) -> List[Chunk]:
    """Law by law, ``chunk_size`` scenarios at a time."""
    overrides = [scenarios.overrides(i) for i in range(len(scenarios))]
    return [c for ctrl in spec.controllers
            for c in chunks_of(ctrl, spec.base_values, overrides, spec.duration_s, spec.window, chunk_size)]


def chunks_of(controller: str, base: Dict[str, Any], overrides: Sequence[Dict[str, Any]], duration_s: float,
              window: Tuple[float, float], chunk_size: int = DEFAULT_CHUNK) -> List[Chunk]:
    """Runs of one law, one per entry of ``overrides`` (changes to ``base``), ``chunk_size`` at a time."""
    n = len(overrides)
    return [Chunk(first, controller, base, tuple(overrides[first:first + chunk_size]), duration_s, window)
            for first in range(0, n, chunk_size)]


def run_chunk(chunk: Chunk) -> ChunkResult:
    """Simulate one chunk (scenarios that differ in control period, RK4 sub-steps, encoder or delays run as
    separate batches)."""
    from mwip_ros import params as P
    from mwip_ros.core.batch import simulate_batch
    from mwip_ros.core.sim import LAWS

    law, use_observer = LAWS[chunk.controller]
    loops = []
    for ov in chunk.overrides:
        v = dict(chunk.base)
        v.update(ov)
        loops.append(P.closed_loop(v, use_observer=use_observer, duration=chunk.duration_s, law=law))
    n = len(loops)
    groups: Dict[tuple, List[int]] = {}
    for i, lp in enumerate(loops):
        sc = lp.plant.sensing
        key = (lp.plant.h, lp.plant.substeps, sc.encoder_counts_per_rev, sc.delay_periods, sc.actuator_delay_periods)
        groups.setdefault(key, []).append(i)
    upright, t_fall = np.zeros(n, dtype=bool), np.full(n, np.nan)
    metrics: Dict[str, np.ndarray] = {}
    steps = 0
    for idx in groups.values():
        r = simulate_batch([loops[i] for i in idx], chunk.window)
        upright[idx], t_fall[idx] = r.upright, r.t_fall
        for k, v in r.metrics.items():
            metrics.setdefault(k, np.full(n, np.nan))[idx] = v
        steps += r.steps
    return ChunkResult(upright, t_fall, metrics, steps)


class Runner:
    """Where chunks run: this process (``workers=1``), a pool of ``workers`` processes (spawned once, kept for
    the runner's life: a tuner sends it a generation at a time), or a Dask cluster (``dask``: the address
    of a running scheduler, or ``local:N``).  ``runner(chunks)`` yields ``(chunk, result)`` as each
    finishes; use it as a context manager, or call :meth:`close`."""

    def __init__(self, workers: int = 1, dask: str = None):
        self.workers, self.dask = max(1, int(workers)), dask
        self._pool = self._client = self._cluster = None

    def describe(self) -> str:
        if self.dask:
            return f"Dask at {self.dask}"
        return f"{self.workers} worker processes" if self.workers > 1 else "this process"

    def __call__(self, chunks: Sequence[Chunk]) -> Iterator[Tuple[Chunk, ChunkResult]]:
        if self.dask:
            yield from self._dask(chunks)
        elif self.workers <= 1:
            for c in chunks:
                yield c, run_chunk(c)
        else:
            yield from self._local(chunks)

    def _local(self, chunks):
        import multiprocessing
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"))
        todo, running = list(chunks), {}
        try:
            while todo or running:
                while todo and len(running) < 2 * self.workers:   # a few ahead: results stream, memory stays small
                    c = todo.pop(0)
                    running[self._pool.submit(run_chunk, c)] = c
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for f in done:
                    yield running.pop(f), f.result()
        except BaseException:
            self.close()   # an interrupt or a failed chunk: cancel the rest
            raise

    def _dask(self, chunks):
        from dask.distributed import Client, LocalCluster, as_completed

        if self._client is None:
            if self.dask.startswith("local:"):
                self._cluster = LocalCluster(n_workers=int(self.dask.split(":", 1)[1]), threads_per_worker=1,
                                             processes=True, dashboard_address=None)
                self._client = Client(self._cluster)
            else:
                self._client = Client(self.dask, timeout=30)
        futures = {self._client.submit(run_chunk, c, pure=False): c for c in chunks}
        for f in as_completed(futures):
            yield futures[f], f.result()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

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
