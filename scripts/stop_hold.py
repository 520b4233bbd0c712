#!/usr/bin/env python3
"""After a stop, where does the robot hold? (docs/theory.md 6.14; issue 47 item 3)

config/drive.yaml's motion (the teleop overlay) with a profile instead of cmd_vel: 1 m/s from 2 s, the stop
commanded at 8 s (v* at 0 from 10 s), 22 s, on the planar plant (it and the MuJoCo plant agree to 1e-5 rad driving
straight; ``--backend mujoco`` to run MuJoCo).  Per law a Markdown row: the time from v* = 0 to below 0.05 m/s, where
the robot first came to rest (its speed reached zero) against where the references stopped, and where it is over the
run's last period of the paper's disturbance (pi s) against that first rest.

    python scripts/stop_hold.py
    python scripts/stop_hold.py --set motion.hold_settle_s=0 motion.hold_filter_s=0   # without the hold
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mwip_ros import params as P  # noqa: E402
from mwip_ros.core.closed_loop.sim import simulate  # noqa: E402

LAWS = ("dsc", "dscndo", "lqr", "lqr_ndo", "smc", "smc_ndo", "mpc", "mpc_ndo")


def stop_row(columns, r: float):
    """(s to below 0.05 m/s, first rest - where the references stopped [m], mean over the last pi s - first rest
    [m]) of a run's columns."""
    t, x, v = columns["t"], r * columns["theta_w"], r * columns["dtheta_w"]
    k0 = int(np.where(columns["v_ref"] != 0.0)[0][-1]) + 1
    slow = k0 + int(np.argmax(np.abs(v[k0:]) < 0.05))
    rest = k0 + 1 + int(np.argmax(v[k0 + 1:] * v[k0:-1] <= 0.0))
    stopped = r * columns["theta_w_ref"][k0] if "theta_w_ref" in columns else math.nan
    last = t >= t[-1] - math.pi
    return t[slow] - t[k0], x[rest] - stopped, float(np.mean(x[last])) - x[rest]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backend", default="rk4", choices=["rk4", "mujoco"])
    ap.add_argument("--laws", nargs="+", default=list(LAWS))
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="parameter overrides (floats)")
    a = ap.parse_args(argv)
    v = P.merged_values(P.load_param_files([ROOT / "config" / "paper.yaml", ROOT / "config" / "drive.yaml"]))
    v.update({"backend": a.backend, "motion.profile": [0.0, 0.0, 2.0, 1.0, 8.0, 0.0]})
    v.update({k: float(x) for k, x in (kv.split("=", 1) for kv in a.set)})
    print("| law | below 0.05 m/s after v* = 0 [s] | first rest beyond where the references stopped [m] | "
          "mean over the last pi s from the first rest [m] |")
    print("|---|---|---|---|")
    for law in a.laws:
        run = simulate(P.closed_loop(v, controller=law, duration=22.0))
        if run.fallen:
            print(f"| {law} | fell at {run.record['t_fall']:.3f} s | | |")
            continue
        slow, over, held = stop_row(run.columns, v["nominal.r"])
        print(f"| {law} | {slow:.2f} | {over:+.3f} | {held:+.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
