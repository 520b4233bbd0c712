#!/usr/bin/env python3
"""Turning in place on the MuJoCo plant, measured (docs/theory.md 6.10 "Contact", eq. C1-C3; issue 47 item 1).

Runs a path file (config/square.yaml by default) on config/paper.yaml with one law at the given physics steps and
prints a Markdown table: over the steady turns in place (psi'* at its largest, v* = 0) against the steady straight
(v* at its largest, psi'* = 0), the standard deviation of u's period-to-period change and their ratio, u's changes
of direction a second, the largest change of theta_w' in a period, the mean u_psi against eq. C3, the largest true
tau_d while turning, and tau_hat's error RMS over the metrics window.

    python scripts/turn_in_place.py                       # DSCNDO on the square at 1 ms and 5 ms
    python scripts/turn_in_place.py --law lqr_ndo --steps 0.005
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mwip_ros import params as P  # noqa: E402
from mwip_ros.core.closed_loop import metrics   # noqa: E402
from mwip_ros.core.plants.mujoco_plant import scrub_torque  # noqa: E402
from mwip_ros.core.closed_loop.sim import simulate  # noqa: E402


def turn_stats(c, h: float, values) -> dict:
    """The table's numbers of a run's columns ``c`` (period ``h``, parameter ``values``)."""
    w_top, v_top = np.max(np.abs(c["dpsi_ref"])), np.max(np.abs(c["v_ref"]))
    turn = np.where((np.abs(c["dpsi_ref"]) == w_top) & (c["v_ref"] == 0.0))[0]
    straight = np.where((np.abs(c["v_ref"]) == v_top) & (c["dpsi_ref"] == 0.0))[0]
    turn, straight = turn[turn > 1], straight[straight > 1]
    du = np.diff(c["u"])

    def rough(i):
        return float(np.std(du[i - 1]))

    changes = np.sum(np.sign(du[turn - 1]) * np.sign(du[turn - 2]) < 0) / (len(turn) * h)
    weight = (values["actual.m_b"] + values["actual.m_w"]) * values["actual.g"]
    c3 = 2.0 * values["actual.r"] / values["actual.track_width"] * scrub_torque(values["ground.friction"],
                                                                                values["actual.r"], weight)
    m = metrics.compute(c, (5.0, 10.0), values["fall_angle"])
    return {"rough_turn": rough(turn), "rough_straight": rough(straight), "changes": float(changes),
            "jump": float(np.max(np.abs(np.diff(c["dtheta_w"])[turn - 1]))),
            "u_psi": float(np.mean(np.abs(c["u_psi"][turn]))), "c3": c3,
            "rate": float(np.mean(np.abs(c["gyro_z"][turn]))),
            "tau_d": (float(np.nanmax(np.abs(c["tau_d1"][turn]))), float(np.nanmax(np.abs(c["tau_d2"][turn])))),
            "err": (m.tau_err1_rms, m.tau_err2_rms)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--path", default=str(ROOT / "config" / "square.yaml"), help="the path's parameter file")
    ap.add_argument("--law", default="dscndo")
    ap.add_argument("--steps", nargs="+", type=float, default=[0.001, 0.005], help="MuJoCo physics steps [s]")
    a = ap.parse_args(argv)
    base = P.merged_values(P.load_param_files([ROOT / "config" / "paper.yaml", a.path]))
    print("| physics step | u change std turning / straight [N m] | ratio | u direction changes turning [1/s] | "
          "largest theta_w' change [rad/s] | u_psi [N m] (eq. C3) | yaw rate [rad/s] | largest abs tau_d1 / tau_d2 "
          "turning [N m] | tau_hat1 / tau_hat2 err RMS [5, 10] s [N m] |")
    print("|---|---|---|---|---|---|---|---|---|")
    for step in a.steps:
        v = dict(base, **{"mujoco.timestep": step})
        run = simulate(P.closed_loop(v, controller=a.law))
        s = turn_stats(run.columns, run.h, v)
        print(f"| {step * 1e3:g} ms | {s['rough_turn']:.3f} / {s['rough_straight']:.3f} | "
              f"{s['rough_turn'] / s['rough_straight']:.2f} | {s['changes']:.1f} | {s['jump']:.3f} | "
              f"{s['u_psi']:.1f} ({s['c3']:.1f}) | {s['rate']:.3f} | {s['tau_d'][0]:.0f} / {s['tau_d'][1]:.0f} | "
              f"{s['err'][0]:.1f} / {s['err'][1]:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
