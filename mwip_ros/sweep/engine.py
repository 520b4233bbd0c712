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

__all__ = ["Chunk", "ChunkResult", "make_chunks", "run_chunk", "run_local", "run_dask", "DEFAULT_CHUNK"]

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
    n = len(scenarios)
    out = []
    for ctrl in spec.controllers:
        for first in range(0, n, chunk_size):
            rows = tuple(scenarios.overrides(i) for i in range(first, min(n, first + chunk_size)))
            out.append(Chunk(first, ctrl, spec.base_values, rows, spec.duration_s, spec.window))
    return out


def run_chunk(chunk: Chunk) -> ChunkResult:
    """Simulate one chunk (scenarios that differ in control period or RK4 sub-steps run as separate batches)."""
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
        groups.setdefault((lp.plant.h, lp.plant.substeps), []).append(i)
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


def run_local(chunks: Sequence[Chunk], workers: int = 1) -> Iterator[Tuple[Chunk, ChunkResult]]:
    """Run the chunks here (``workers=1``) or on ``workers`` processes; yields each as it finishes."""
    if workers <= 1:
        for c in chunks:
            yield c, run_chunk(c)
        return
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        todo = list(chunks)
        running = {}
        while todo or running:
            while todo and len(running) < 2 * workers:   # a few ahead: results stream, memory stays small
                c = todo.pop(0)
                running[pool.submit(run_chunk, c)] = c
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for f in done:
                yield running.pop(f), f.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def run_dask(chunks: Sequence[Chunk], address: str) -> Iterator[Tuple[Chunk, ChunkResult]]:
    """Run the chunks on a Dask cluster: ``tcp://host:port`` of a running scheduler, or ``local:N``."""
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if address.startswith("local:"):
        cluster = LocalCluster(n_workers=int(address.split(":", 1)[1]), threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    else:
        client = Client(address, timeout=30)
    try:
        futures = {client.submit(run_chunk, c, pure=False): c for c in chunks}
        for f in as_completed(futures):
            yield futures[f], f.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
