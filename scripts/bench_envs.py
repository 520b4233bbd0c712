#!/usr/bin/env python3
"""The Gymnasium environments' speed beside the batch simulator's, measured in one run on this machine.

    scripts/bench_envs.py [--n 4096] [--steps 500] [--repeat 3] [--params FILE ...] [--json FILE]

Rows (config/paper.yaml unless --params; best of --repeat, after a warm-up that compiles or loads the kernels):

* ``MwipVectorEnv, random policy``: N robots, ``action_space.sample()`` each step, autoreset included (a random
  torque topples a robot in about 0.15 s, so about N / 30 of them restart in every step): env-steps/s;
* ``MwipVectorEnv, base_law dscndo``: the same with a zero residual on DSCNDO (no falls);
* ``simulate_batch (compiled)``: the batch simulator over the same N scenarios (DSCNDO, seeds 0 .. N - 1) for the
  same number of periods, its compiled loop (``core.kernels.compiled``): scenario-steps/s;
* ``MwipEnv``: one robot, a random policy, env-steps/s;
* the two ``raw sensors, kalman`` rows: the vector env with a random policy and the batch simulator as above, with
  ``config/sensors_raw_realistic.yaml`` added (raw IMU and encoder samples, the EKF per robot).

Everything runs in this one process (one core; the batch's kernel and the vector env's RK4 are single-threaded).
The table goes to stdout; ``--json`` also writes the numbers.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time


def _with_raw(params):
    """``params`` (None: config/paper.yaml) with config/sensors_raw_realistic.yaml after them."""
    from mwip_ros.params.paths import default_params_file
    config = default_params_file().parent
    return [*(params or [config / "paper.yaml"]), config / "sensors_raw_realistic.yaml"]


def _vector(n, steps, params, base_law):
    import numpy as np
    from mwip_ros.envs import MwipVectorEnv
    env = MwipVectorEnv(n, params, duration=10.0, base_law=base_law)
    env.reset(seed=0)
    env.action_space.seed(0)
    zero = np.zeros((n, 1))
    act = (lambda: zero) if base_law else env.action_space.sample
    for _ in range(10):
        env.step(act())
    t = time.perf_counter()
    for _ in range(steps):
        env.step(act())
    return n * steps / (time.perf_counter() - t)


def _batch(n, steps, params):
    from mwip_ros import params as P
    from mwip_ros.core.kernels.batch import simulate_batch
    from mwip_ros.envs import load_values
    values = load_values(params)
    loop = P.closed_loop(values, controller="dscndo")
    loop = dataclasses.replace(loop, duration_s=steps * loop.plant.h)
    loops = [dataclasses.replace(loop, plant=dataclasses.replace(loop.plant, seed=i)) for i in range(n)]
    simulate_batch(loops[:8], (0.0, loop.duration_s), compiled=True)   # the kernel compiled or loaded
    t = time.perf_counter()
    res = simulate_batch(loops, (0.0, loop.duration_s), compiled=True)
    return res.steps / (time.perf_counter() - t)


def _scalar(steps, params):
    from mwip_ros.envs import MwipEnv
    env = MwipEnv(params, duration=10.0)
    env.reset(seed=0)
    env.action_space.seed(0)
    t = time.perf_counter()
    for _ in range(steps):
        if any(env.step(env.action_space.sample())[2:4]):
            env.reset()
    return steps / (time.perf_counter() - t)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench_envs.py", description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=4096, help="robots of the vector env and scenarios of the batch")
    ap.add_argument("--steps", type=int, default=500, help="steps (periods) timed")
    ap.add_argument("--repeat", type=int, default=3, help="best of this many")
    ap.add_argument("--params", nargs="+", default=None, metavar="FILE")
    ap.add_argument("--json", default=None, metavar="FILE")
    args = ap.parse_args(argv)
    rows = {
        "MwipVectorEnv, random policy [env-steps/s]": lambda: _vector(args.n, args.steps, args.params, None),
        "MwipVectorEnv, base_law dscndo, zero residual [env-steps/s]":
            lambda: _vector(args.n, args.steps, args.params, "dscndo"),
        "simulate_batch, compiled, DSCNDO [scenario-steps/s]": lambda: _batch(args.n, args.steps, args.params),
        "MwipEnv, random policy [env-steps/s]": lambda: _scalar(args.steps * 4, args.params),
        "MwipVectorEnv, raw sensors, kalman, random policy [env-steps/s]":
            lambda: _vector(args.n, args.steps, _with_raw(args.params), None),
        "simulate_batch, compiled, DSCNDO, raw sensors, kalman [scenario-steps/s]":
            lambda: _batch(args.n, args.steps, _with_raw(args.params)),
    }
    best = {name: max(f() for _ in range(args.repeat)) for name, f in rows.items()}
    ref = best["simulate_batch, compiled, DSCNDO [scenario-steps/s]"]
    print(f"N = {args.n}, {args.steps} steps, best of {args.repeat}")
    print("| | rate | / batch |\n|---|---|---|")
    for name, v in best.items():
        print(f"| {name} | {v / 1e6:.3g} M | {v / ref:.3g} |")   # significant digits: a slow row is not 0.00
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"n": args.n, "steps": args.steps, "rates": best}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
