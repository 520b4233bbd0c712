"""What the environments take from their caller, checked: one line (ValueError naming the argument) for a wrong one,
never a silent reshape, clip or traceback from deep inside.

* an action: the action space's shape (``MwipEnv``: one number; ``MwipVectorEnv``: one per robot, ``(N,)`` or
  ``(N, 1)``), numbers (a finite one beyond the bound is clipped to the action space; one that is not finite, NaN or
  infinite alike, goes to the drive, which refuses it: the episode ends, ``bad_command``);
* a seed: a whole number in [0, :data:`MAX_SEED`], what ``plant_sim.seed`` (a ROS integer) can hold, so that the
  episode is ``mwip_sim``'s with that seed; robot i of a vector env takes s + i, so s + N - 1 must fit too;
* ``reset(options=...)``: only ``initial``, four finite numbers within the schema's ranges of ``initial.*``;
* ``render_mode``: None (the environments render nothing);
* ``num_envs``: what the robots take, estimated before anything is allocated, within the memory budget
  (:func:`mwip_ros.core.kernels.budget.vector_env_bytes`, ``MWIP_MEMORY_BUDGET``).
"""
from __future__ import annotations

import numbers
from typing import Any, Mapping, Optional, Sequence

import numpy as np

__all__ = ["MAX_SEED", "whole", "action", "actions", "seed", "seeds", "options", "render_mode", "num_envs"]

MAX_SEED = 2 ** 63 - 1   # plant_sim.seed is a ROS integer (int64)
INITIAL = ("theta_w", "theta_b", "dtheta_w", "dtheta_b")


def action(a) -> float:
    """The one number of a scalar env's action (a number, or an array of one); ValueError else."""
    try:
        arr = np.asarray(a, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"action: {str(a)[:60]!r} is not a number") from None
    if arr.size != 1:
        raise ValueError(f"action: one number (the action space's shape (1,)), got shape {arr.shape}")
    return float(arr.reshape(-1)[0])


def actions(a, n: int) -> np.ndarray:
    """The (n,) actions of a vector env of ``n`` robots: shape (n,) or (n, 1); ValueError else."""
    try:
        arr = np.asarray(a, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"actions: {str(a)[:60]!r} are not numbers") from None
    if arr.shape not in ((n,), (n, 1)):
        raise ValueError(f"actions: one per robot, shape ({n},) or ({n}, 1), got shape {arr.shape}")
    return arr.reshape(n)


def whole(s) -> bool:
    """Whether ``s`` is a whole number (an int or a numpy integer, not a bool)."""
    return isinstance(s, (numbers.Integral, np.integer)) and not isinstance(s, (bool, np.bool_))


def seed(s, n: int = 1) -> Optional[int]:
    """``s`` (None, or a whole number with s + n - 1 <= :data:`MAX_SEED`) as an int; ValueError else."""
    if s is None:
        return None
    if not whole(s) or not 0 <= int(s) <= MAX_SEED - (n - 1):
        most = f"2**63 - {n} (robot i's, s + i, is plant_sim.seed's: at most 2**63 - 1)" if n > 1 else \
            "2**63 - 1 (plant_sim.seed's range)"
        raise ValueError(f"seed: a whole number from 0 to {most}, got {str(s)[:40]}")
    return int(s)


def seeds(values: Sequence, n: int) -> np.ndarray:
    """A list of ``n`` seeds, one per robot, each as :func:`seed`; ValueError else."""
    values = list(values)
    if len(values) != n:
        raise ValueError(f"seed: a list of {n} seeds (one per robot), got {len(values)}")
    return np.array([seed(v) for v in values], dtype=np.int64)


def options(opts: Optional[Mapping[str, Any]]) -> Optional[tuple]:
    """The initial state of ``reset(options=...)`` (None: the files'); ValueError for another key, or an initial
    state that is not four finite numbers within the schema's ``initial.*`` ranges."""
    if opts is None:
        return None
    if not isinstance(opts, Mapping):
        raise ValueError(f"options: a dict ({{'initial': (theta_w, theta_b, theta_w', theta_b')}}), got "
                         f"{type(opts).__name__}")
    unknown = [k for k in opts if k != "initial"]
    if unknown:
        raise ValueError(f"options: unknown {', '.join(map(str, unknown))} (only 'initial')")
    if opts.get("initial") is None:
        return None
    try:
        x = [float(v) for v in opts["initial"]]
    except (TypeError, ValueError):
        raise ValueError(f"options['initial']: four numbers (theta_w, theta_b, theta_w', theta_b'), got "
                         f"{str(opts['initial'])[:60]}") from None
    if len(x) != 4:
        raise ValueError(f"options['initial']: four numbers (theta_w, theta_b, theta_w', theta_b'), got {len(x)}")
    from mwip_ros.params import ParamError, specs_for
    specs = specs_for("plant_sim")
    for name, v in zip(INITIAL, x):
        try:
            specs[f"initial.{name}"].validate(v, f"initial.{name}")
        except ParamError as exc:
            raise ValueError(f"options['initial']: {exc}") from None
    return tuple(x)


def render_mode(mode) -> None:
    """None, or ValueError: the environments render nothing (``metadata['render_modes']`` is empty)."""
    if mode is not None:
        raise ValueError(f"render_mode: {str(mode)[:40]!r}: the MWIP environments render nothing (render_modes [])")


def num_envs(n, setup=None) -> int:
    """``n`` as an int >= 1 whose robots fit the memory budget (estimated from ``setup``, when given: raw sensors,
    delays); ValueError naming ``num_envs`` with the numbers, else."""
    from mwip_ros.core.kernels.budget import BUDGET_ENV, fmt_bytes, memory_budget, vector_env_bytes
    if not whole(n) or int(n) < 1:
        raise ValueError(f"num_envs: a whole number >= 1, got {str(n)[:40]}")
    n = int(n)
    if setup is None:
        return n
    pc = setup.loop.plant
    raw = pc.raw is not None
    sc = pc.sensing
    need, budget = vector_env_bytes(n, raw, sc.delay_periods, sc.actuator_delay_periods), memory_budget()
    if need > budget:
        per = vector_env_bytes(1, raw, sc.delay_periods, sc.actuator_delay_periods)
        raise ValueError(f"num_envs: {n:,} robots would take about {fmt_bytes(need)} ({fmt_bytes(per)} each), more "
                         f"than the memory budget {fmt_bytes(budget)} ({BUDGET_ENV}); at most {budget // per:,} here")
    return n

