"""The memory budget of the offline tools, and what their runs cost, estimated before anything is allocated.

``mwip_sim``, ``mwip_sweep`` and ``mwip_tune`` compute, from the parameter file or the spec alone, what
a run would hold in memory, and refuse (one line naming the key and the numbers, exit 2) what would not
fit :func:`memory_budget`: 2 GiB per process unless the environment sets ``MWIP_MEMORY_BUDGET`` (bytes,
or with a K, M, G suffix: ``MWIP_MEMORY_BUDGET=8G``).

* the process that expands a sweep (or a tuner's candidates) holds a table of every scenario and, at the
  end, every result row: at most the budget (:func:`sweep_table_bytes`, :func:`tune_table_bytes`);
* one simulation batch (a chunk's scenarios that share the period, sub-steps, encoder and delays) holds
  per scenario its metrics window and its delay queues: at most :func:`batch_budget` (a quarter of the
  budget, 512 MiB by default); a chunk larger than that runs as several batches, each within it
  (:func:`batch_bytes`), and a single scenario beyond it is refused;
* ``mwip_sim`` keeps each law's whole trajectory: at most the budget (:func:`offline_bytes`);
* the Gymnasium vector env's N robots: at most the budget (:func:`vector_env_bytes`).

The per-item costs below were measured (peak RSS, CPython 3.11, numpy 2) with a margin; they are
estimates, not accounting, and only decide what is refused.
"""
from __future__ import annotations

import os
import re
from typing import Optional

__all__ = ["DEFAULT_BUDGET", "BUDGET_ENV", "memory_budget", "batch_budget", "fmt_bytes", "window_samples",
           "scenario_batch_bytes", "batch_fixed_bytes", "sweep_table_bytes", "tune_table_bytes", "offline_bytes",
           "max_workers", "vector_env_bytes"]

GIB = 1 << 30
DEFAULT_BUDGET = 2 * GIB
BUDGET_ENV = "MWIP_MEMORY_BUDGET"

# --- measured costs [bytes] ------------------------------------------------------------------------
BATCH_SCENARIO = 16 * 1024     # a scenario of a batch: its ClosedLoop, generators and noise blocks, state arrays
BATCH_WINDOW_SAMPLE = 64       # per scenario and sample of the metrics window (4 doubles, and the metrics' copies)
BATCH_DELAY_PERIOD = 48        # per scenario and queued measurement (sensors.delay_periods)
BATCH_ACTUATOR_PERIOD = 16     # per scenario and queued command (actuator.delay_periods)
BATCH_QUEUE_ENTRY = 1024       # per queued period, whatever the batch's size (the arrays' headers)
TABLE_SCENARIO = 512           # a sweep scenario: its seed, its values and its overrides
TABLE_AXIS = 96                # ... per varied parameter
RESULT_COLUMN = 136            # a results.csv cell read back for the summary (per run and column)
RESULT_COLUMNS = 13            # the columns every row has besides the varied parameters
TUNE_RUN = 512                 # a tuner's candidate on one scenario: its overrides and its results
TUNE_PARAM = 48                # ... per varied or tuned parameter
OFFLINE_STEP = 400             # mwip_sim: a trajectory row (16 doubles, growth, the copy, metrics, CSV)
OFFLINE_DELAY_PERIOD = 256     # mwip_sim: a queued measurement or command of one plant
WORKER_PROCESS = 256 << 20     # a worker process: Python, numpy, numba and the compiled RK4
ENV_ROBOT = 6 << 10            # a vector env's robot, state sensors: its lanes and noise blocks (3.3-5.0 KB measured)
ENV_ROBOT_RAW = 16 << 10       # ... with raw sensors and the estimator (12.8-13.0 KB measured)


def fmt_bytes(n: float) -> str:
    for unit, size in (("GiB", GIB), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{int(n)} bytes"


def memory_budget() -> int:
    """Bytes one process of the offline tools may plan to hold: ``MWIP_MEMORY_BUDGET`` or 2 GiB.  Raises
    ValueError (one line) for a value that is not a size."""
    text = os.environ.get(BUDGET_ENV, "").strip()
    if not text:
        return DEFAULT_BUDGET
    m = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([kKmMgGtT]?)(?:i?[bB])?", text)
    if not m:
        raise ValueError(f"{BUDGET_ENV}={text[:40]!r} is not a size (bytes, or e.g. 512M, 8G)")
    n = float(m.group(1)) * {"": 1, "k": 1 << 10, "m": 1 << 20, "g": GIB, "t": 1 << 40}[m.group(2).lower()]
    if not n >= 64 << 20:
        raise ValueError(f"{BUDGET_ENV}={text!r} is below 64 MiB")
    return int(n)


def batch_budget(budget: Optional[int] = None) -> int:
    """What one simulation batch may hold: a quarter of the budget (512 MiB by default)."""
    return (memory_budget() if budget is None else budget) // 4


def window_samples(n_steps: int, h: float, window) -> tuple:
    """(first step, number of steps) of the metrics window in a run of ``n_steps`` periods of ``h``: the steps
    k = 0..n_steps with ``window[0] - 1e-9 <= k h <= window[1] + 1e-9`` (k h rises with k, so they are
    consecutive), found without listing them; (0, 0) when there are none."""
    lo, hi = window[0] - 1e-9, window[1] + 1e-9
    k_lo = min(n_steps + 1, max(0, int(lo // h) - 1))
    while k_lo <= n_steps and not k_lo * h >= lo:
        k_lo += 1
    while k_lo > 0 and (k_lo - 1) * h >= lo:
        k_lo -= 1
    k_hi = min(n_steps, max(-1, int(hi // h) + 1))
    while k_hi >= 0 and not k_hi * h <= hi:
        k_hi -= 1
    while k_hi < n_steps and (k_hi + 1) * h <= hi:
        k_hi += 1
    if k_lo > k_hi:
        return 0, 0
    return k_lo, k_hi - k_lo + 1


def scenario_batch_bytes(n_window: int, n_steps: int, delay: int, actuator_delay: int) -> int:
    """What one scenario adds to a batch: its window, and its queues (which never hold more than the run's
    periods)."""
    return (BATCH_SCENARIO + BATCH_WINDOW_SAMPLE * n_window
            + BATCH_DELAY_PERIOD * (min(delay, n_steps) + 1 if delay else 0)
            + BATCH_ACTUATOR_PERIOD * (min(actuator_delay, n_steps) + 1 if actuator_delay else 0))


def batch_fixed_bytes(n_steps: int, delay: int, actuator_delay: int) -> int:
    """What a batch holds whatever its size: a few arrays' headers per queued period."""
    queued = (min(delay, n_steps) + 1 if delay else 0) + (min(actuator_delay, n_steps) + 1 if actuator_delay else 0)
    return BATCH_QUEUE_ENTRY * queued


def sweep_table_bytes(n_scenarios: int, n_axes: int, n_laws: int) -> int:
    """The sweep process's tables: every scenario's values and overrides, and every result row read back."""
    return (n_scenarios * (TABLE_SCENARIO + TABLE_AXIS * n_axes)
            + n_scenarios * n_laws * RESULT_COLUMN * (RESULT_COLUMNS + n_axes))


def tune_table_bytes(n_scenarios: int, n_axes: int, n_candidates: int, n_tuned: int) -> int:
    """A tuner's tables: the search and the held-out scenarios, and a generation's candidates on every one."""
    return (2 * n_scenarios * (TABLE_SCENARIO + TABLE_AXIS * n_axes)
            + n_scenarios * n_candidates * (TUNE_RUN + TUNE_PARAM * (n_axes + n_tuned)))


def offline_bytes(n_steps: int, n_runs: int, delay: int, actuator_delay: int) -> int:
    """``mwip_sim``: ``n_runs`` trajectories of ``n_steps + 1`` rows, and one plant's queues."""
    return (n_runs * (n_steps + 1) * OFFLINE_STEP
            + OFFLINE_DELAY_PERIOD * (min(delay, n_steps) + min(actuator_delay, n_steps) + 2))


def max_workers() -> int:
    """The most worker processes a sweep or a tuner starts: twice the CPUs (at least 4).  More run no faster
    (the work is CPU-bound) and each costs :data:`WORKER_PROCESS` plus up to a batch's budget."""
    return max(4, 2 * (os.cpu_count() or 1))


def vector_env_bytes(n: int, raw: bool, delay_periods: int = 0, actuator_delay_periods: int = 0) -> int:
    """What ``MwipVectorEnv`` of ``n`` robots holds: each robot's lanes and noise streams (``raw``: with raw
    sensors and the estimator) and its delay queues."""
    per = (ENV_ROBOT_RAW if raw else ENV_ROBOT) + delay_periods * BATCH_DELAY_PERIOD \
        + actuator_delay_periods * BATCH_ACTUATOR_PERIOD
    return int(n) * per
