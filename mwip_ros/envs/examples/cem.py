"""A linear policy for the MWIP learned by the cross-entropy method, in numpy only, judged beside DSCNDO and LQR.

    python -m mwip_ros.envs.examples.cem [--iterations 12] [--out policy.json]

The policy is ``a = clip(w1 theta_b + w2 theta_b' + w3 theta_w', -1, 1)`` of the measured state (the torque a S,
S = 256 N m on the paper's robot, :class:`~mwip_ros.envs.MwipVectorEnv`'s normalised action;
:class:`mwip_ros.policy.LinearPolicy`): the LQR's form, its gains found by search, without the model.  Its file
(``--out``) is what the law ``policy`` reads (``MWIP_ROS_LAWS=mwip_ros.policy_law``, ``policy.file``).

The cross-entropy method keeps a Gaussian over (w1, w2, w3); each
iteration draws :data:`POPULATION` candidates, runs each on the :data:`TRAIN` training robots (the first robots of
``config/sweeps/mass_mismatch.yaml``: body mass, inertia and centre-of-gravity height each scaled by 0.7 to 1.3, the
paper's friction noise and tau_ext) for :data:`EPISODE_S` seconds, every candidate a robot of one vector env per
training robot, scores each by its mean return (the default reward), and refits the Gaussian to the
:data:`ELITE` best.  It is then judged on :data:`HELD_OUT` held-out robots (the same spec with its seed + 1, as
``mwip_tune`` holds out), 10 s each, theta_b's RMS over [5, 10] s, beside DSCNDO and LQR (the batch simulator on the
same robots).  docs/learning.md shows the table; a test recomputes it.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Dict, List, Sequence

import numpy as np

from mwip_ros import params as P
from mwip_ros.core.kernels.batch import simulate_batch
from mwip_ros.core.kernels.budget import window_samples
from mwip_ros.params.paths import default_params_file
from mwip_ros.policy import LinearPolicy
from mwip_ros.sweep.scenarios import expand
from mwip_ros.sweep.spec import load_spec

from .. import MwipVectorEnv

__all__ = ["SPEC", "robots", "train", "judge", "table", "main"]

SPEC = default_params_file().parent / "sweeps" / "mass_mismatch.yaml"
POPULATION, ELITE, TRAIN, HELD_OUT = 32, 6, 4, 16
EPISODE_S = 3.0
FEATURES = (1, 3, 2)   # theta_b, theta_b', theta_w' of the observation (theta_w, theta_b, theta_w', theta_b')


def robots(seed_offset: int, count: int) -> List[Dict]:
    """The merged values of the first ``count`` robots of :data:`SPEC` with its seed + ``seed_offset``."""
    spec = load_spec(SPEC)
    spec = dataclasses.replace(spec, seed=spec.seed + seed_offset, samples=count)
    sc = expand(spec)
    return [{**spec.base_values, **sc.overrides(i)} for i in range(count)]


def _returns(envs: Sequence[MwipVectorEnv], W: np.ndarray, seed: int) -> np.ndarray:
    """Each candidate's (a row of ``W``) mean return over ``envs``' robots: its first episode on each."""
    total = np.zeros(len(W))
    for env in envs:
        obs, _ = env.reset(seed=seed)
        ret, live = np.zeros(len(W)), np.ones(len(W), dtype=bool)
        while live.any():
            a = np.clip(np.einsum("ij,ij->i", obs[:, FEATURES], W), -1.0, 1.0)[:, None]
            obs, r, term, trunc, _ = env.step(a)
            ret += np.where(live, r, 0.0)
            live &= ~(term | trunc)
        total += ret
    return total / len(envs)


def train(iterations: int = 12, seed: int = 0, log=None) -> LinearPolicy:
    """The cross-entropy search (see the module), deterministic for a ``seed``."""
    rng = np.random.default_rng(seed)
    envs = [MwipVectorEnv(POPULATION, v, duration=EPISODE_S) for v in robots(0, TRAIN)]
    mean, sd = np.zeros(3), np.array([4.0, 1.5, 0.2])
    for it in range(iterations):
        W = mean + sd * rng.standard_normal((POPULATION, 3))
        score = _returns(envs, W, seed=it)
        elite = W[np.argsort(score)[-ELITE:]]
        mean, sd = elite.mean(axis=0), elite.std(axis=0) + 1e-3
        if log:
            log(f"iteration {it + 1:2d}: best return {score.max():8.2f}, mean {score.mean():8.2f}, "
                f"w = {np.array2string(mean, precision=3)}")
    return LinearPolicy(tuple(float(v) for v in mean), envs[0].setup.scale)


def _policy_rms(policy: LinearPolicy, values: Dict, window) -> float:
    """theta_b's RMS over ``window`` of one 10 s run of ``policy`` on ``values``' robot (NaN: it fell)."""
    duration = window[1]
    env = MwipVectorEnv(1, values, duration=duration)
    obs, _ = env.reset(seed=int(values["seed"]))
    theta = [env.lanes.x[1][0]]
    while True:
        obs, _, term, trunc, _ = env.step(policy(obs))
        if term[0]:
            return float("nan")
        theta.append(env.lanes.x[1][0])
        if trunc[0]:
            break
    first, count = window_samples(len(theta) - 1, env.lanes.h, window)
    return float(np.sqrt(np.mean(np.square(theta[first:first + count]))))


def judge(policy: LinearPolicy) -> Dict[str, np.ndarray]:
    """theta_b's RMS over the sweep's window on the :data:`HELD_OUT` held-out robots: the policy, DSCNDO, LQR."""
    spec = load_spec(SPEC)
    held = robots(1, HELD_OUT)
    out = {"policy": np.array([_policy_rms(policy, v, spec.window) for v in held])}
    for law in ("dscndo", "lqr"):
        loops = [P.closed_loop(v, duration=spec.duration_s, controller=law) for v in held]
        out[law] = simulate_batch(loops, spec.window).metrics["theta_b_rms"]
    return out


def table(rms: Dict[str, np.ndarray]) -> str:
    """The comparison as a Markdown table (theta_b RMS in mrad: mean, max; robots that fell)."""
    rows = ["| controller | theta_b RMS, mean [mrad] | theta_b RMS, max [mrad] | fell |", "|---|---|---|---|"]
    for name, title in (("policy", "linear policy (cross-entropy)"), ("dscndo", "DSCNDO"), ("lqr", "LQR")):
        v = rms[name]
        ok = v[np.isfinite(v)]
        rows.append(f"| {title} | {1e3 * ok.mean():.2f} | {1e3 * ok.max():.2f} | {int((~np.isfinite(v)).sum())} |")
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mwip_ros.envs.examples.cem", description=__doc__.split("\n")[0])
    ap.add_argument("--iterations", type=int, default=12, help="cross-entropy iterations (default 12)")
    ap.add_argument("--seed", type=int, default=0, help="the search's seed")
    ap.add_argument("--out", type=Path, default=None, metavar="FILE.json",
                    help="write the policy (its weights and scale: the law policy's policy.file)")
    args = ap.parse_args(argv)
    policy = train(args.iterations, args.seed, log=lambda s: print(s, file=sys.stderr))
    print(f"w = {policy.w}")
    if args.out:
        policy.save(args.out)
    print(table(judge(policy)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
