"""What the planar model cannot show, measured in MuJoCo (docs/laws.md "Terrain"; docs/theory.md 6.10): per law, the
steepest slope it balances and holds on, the highest step it drives over, its slip on slippery ground and the
largest lateral push it survives.

mwip_sweep's metrics judge the pitch only; these need the 3D pose (drift, passing a step, roll), so each is a scan
of scalar ``mwip_sim`` runs (:func:`~mwip_ros.core.closed_loop.sim.simulate`, ``backend: mujoco``) judged here:

- **slope** (``ground.slope`` 0, 1, ... 15 deg, uphill ahead, the paper's scenario otherwise): *balances* = stays up
  for the run (``motion.enabled`` false, as the paper); *holds* = with ``motion.enabled`` and the profile [0, 0]
  (the hold from the start, docs/theory.md 6.14) it stays up and its position along the slope drifts less than
  :data:`HOLD_DRIFT` over :data:`HOLD_WINDOW`: the position averaged over one period of the paper's disturbance
  tau_ext1 (2 pi / omega, pi s) at the window's end less that at its start (:func:`hold_drift`; the average takes out
  the disturbance's own swing, reported beside it as the band, max - min over the window).
- **step** (``ground.bumps`` [``STEP_AT``, h]): with ``motion.enabled`` and the profile [0, 0, 2, 0.5] (0.5 m/s
  from 2 s, as config/motion.yaml starts) it stays up and its axle ends past the step by more than a metre.
- **friction** (``ground.friction``): the paper's scenario; slip = r theta_w' - x' (the wheel's rim speed less the
  axle's, along x), its largest magnitude and the distance slipped, r theta_w(T) - x(T).
- **push**: force.y for :data:`PUSH_S` from :data:`PUSH_AT` (external_wrench's lateral force, on the body's centre
  of gravity); survives = stays up and |roll| stays below :data:`ROLL_LIMIT`.

A scan climbs its grid and stops at the first failure: the answer is the last value before it (the grids are
monotone in practice; a law that fails at the first value reads "-").  ``python -m mwip_ros.sweep.terrain`` prints
the tables (``--realistic``: config/sensors_raw_realistic.yaml and config/motor_realistic.yaml on top) and draws
the figure.  The paper has no torque limit: these runs cap the torque at :data:`TORQUE_LIMIT` (the realistic drive
has its own, 120 N m), as the shipped disturbance and region-of-attraction sweeps do.
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

__all__ = ["LAWS", "SLOPES_DEG", "STEPS", "FRICTIONS", "PUSHES", "HOLD_DRIFT", "HOLD_WINDOW", "STEP_AT", "PUSH_AT",
           "PUSH_S", "hold_drift",
           "ROLL_LIMIT", "TORQUE_LIMIT", "TIMESTEP", "Outcome", "base_values", "slope_run", "step_run", "friction_run",
           "push_run", "scan", "tables", "markdown", "figure", "main"]

LAWS = ("dsc", "dscndo", "lqr", "lqr_ndo", "smc", "smc_ndo", "mpc", "mpc_ndo")
SLOPES_DEG = tuple(range(16))
STEPS = (0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.08, 0.10, 0.12, 0.15)   # m
FRICTIONS = (2.0, 1.0, 0.5, 0.3, 0.2, 0.1, 0.05)
PUSHES = (1000.0, 2000.0, 3000.0, 4000.0, 5000.0, 6000.0, 8000.0, 10000.0)   # N, for PUSH_S
HOLD_DRIFT = 0.025   # m: "holds" = drifts less than this over HOLD_WINDOW, along the slope (hold_drift)
HOLD_WINDOW = (5.0, 10.0)   # s
STEP_AT = 2.0        # m: the step's edge (the robot starts at 0 and recovers from the paper's tilt first)
PUSH_AT, PUSH_S = 5.0, 0.1   # s: the push starts once the paper's initial tilt is recovered; it lasts 0.1 s
ROLL_LIMIT = 0.5     # rad: a body rolled further is on its way onto its side
DURATION = 10.0
STEP_DURATION = 12.0
DRIVE_AT = 2.0       # s: the drive starts once the paper's initial tilt is recovered (as config/motion.yaml)
REALISTIC = ("sensors_raw_realistic.yaml", "motor_realistic.yaml")
TORQUE_LIMIT = 300.0   # N m, as config/sweeps/roa.yaml and disturbance.yaml (a plausible drive for this robot)
TIMESTEP = 0.001       # s: MuJoCo's physics step here, not the default 5 ms: the contact with a step's edge is 4
                       # physics steps stiff (docs/theory.md 6.10), and the tables were measured at 1 ms


def base_values(realistic: bool = False) -> Dict[str, object]:
    """The paper's parameter file (with ``realistic``: the raw sensors' and the drive's overlays), backend mujoco at a
    physics step of :data:`TIMESTEP`."""
    from mwip_ros import params as P
    from mwip_ros.params.paths import default_params_file
    files = [default_params_file()]
    if realistic:
        files += [default_params_file().parent / name for name in REALISTIC]
    v = dict(P.merged_values(P.load_param_files(files)), backend="mujoco", **{"mujoco.timestep": TIMESTEP})
    if not v["torque_limit"]:   # the paper has none; a law that blows up would push the robot with 1e5 N m
        v["torque_limit"] = TORQUE_LIMIT
    return v


def _simulate(values, law: str, duration: float, push: Optional[Tuple[float, float, float]] = None):
    """``mwip_sim``'s run of ``law`` with ``values``: its columns, or None when it failed (fell, diverged).  ``push``
    (start [s], length [s], force.y [N]): external_wrench's lateral force held over that window (the offline loop's
    wrench, :class:`~mwip_ros.core.closed_loop.loop.Period`, as the node holds a published one)."""
    from mwip_ros import params as P
    from mwip_ros.core.closed_loop.sim import simulate
    P.check_derived(values)
    loop = P.closed_loop(values, controller=law, duration=duration)
    tr = simulate(loop, diverged_fails=True, wrench=_push_wrench(*push) if push is not None else None)
    return None if tr.record.get("failure") else tr.columns


def _push_wrench(t0: float, length: float, fy: float):
    """external_wrench's (tau_ext1, tau_ext2, force.y, torque.z) at t_k: force.y ``fy`` [N] for t_k in [t0, t0 +
    length), none else."""
    def wrench(t: float):
        return (0.0, 0.0, fy if t0 - 1e-9 <= t < t0 + length - 1e-9 else 0.0, 0.0)
    return wrench


@dataclass(frozen=True)
class Outcome:
    """One run judged: ``ok`` the criterion, ``value`` the measured number it rests on (drift, distance, slip, roll)."""

    ok: bool
    value: float = math.nan
    extra: float = math.nan


def hold_drift(t, s, period: float, window=HOLD_WINDOW) -> Tuple[float, float]:
    """(drift, band) of the positions ``s`` [m] at the times ``t`` over ``window``: the mean over the window's last
    ``period`` s less the mean over its first (the average over a period of a sinusoidal disturbance takes out its
    swing), and max - min over the window."""
    import numpy as np
    t, s = np.asarray(t), np.asarray(s)
    w0, w1 = window
    first = (t >= w0 - 1e-9) & (t <= w0 + period + 1e-9)
    last = (t >= w1 - period - 1e-9) & (t <= w1 + 1e-9)
    inside = (t >= w0 - 1e-9) & (t <= w1 + 1e-9)
    return float(np.mean(s[last]) - np.mean(s[first])), float(np.ptp(s[inside]))


def slope_run(values, law: str, deg: float, hold: bool) -> Outcome:
    """Balances (``hold`` false: stays up) or holds (``hold``: stays up, :func:`hold_drift` along the slope below
    HOLD_DRIFT over HOLD_WINDOW with the period of tau_ext1; value the drift, extra the band)."""
    a = math.radians(deg)
    v = dict(values, **{"ground.slope": a})
    if hold:
        v.update({"motion.enabled": True, "motion.profile": [0.0, 0.0]})
    c = _simulate(v, law, DURATION)
    if c is None:
        return Outcome(False)
    if not hold:
        return Outcome(True, float((c["x"][-1] - c["x"][0]) / math.cos(a)))
    omega = v["tau_ext1.omega"]
    period = 2.0 * math.pi / omega if omega > 0.0 else 1.0
    drift, band = hold_drift(c["t"], (c["x"] - c["x"][0]) / math.cos(a), min(period, HOLD_WINDOW[1] - HOLD_WINDOW[0]))
    return Outcome(bool(abs(drift) < HOLD_DRIFT), drift, band)


def step_run(values, law: str, height: float, speed: float = 0.5) -> Outcome:
    """Drives over a step ``height`` high at ``STEP_AT`` at ``speed``: stays up, ends past it by a metre."""
    v = dict(values, **{"motion.enabled": True, "motion.profile": [0.0, 0.0, DRIVE_AT, speed],
                        "ground.bumps": [STEP_AT, height] if height > 0 else []})
    c = _simulate(v, law, STEP_DURATION)
    if c is None:
        return Outcome(False)
    return Outcome(bool(c["x"][-1] > STEP_AT + 1.0), float(c["x"][-1]))


def friction_run(values, law: str, friction: float) -> Outcome:
    """The paper's scenario on ``ground.friction``: stays up; value the largest |slip speed| [m/s], extra the
    distance slipped [m] (module docstring)."""
    v = dict(values, **{"ground.friction": friction})
    c = _simulate(v, law, DURATION)
    if c is None:
        return Outcome(False)
    r, h = v["actual.r"], 1.0 / v["control_rate_hz"]
    x, w, dw = c["x"], c["theta_w"], c["dtheta_w"]
    slip = max(abs(r * dw[k] - (x[k + 1] - x[k - 1]) / (2 * h)) for k in range(1, len(x) - 1))
    return Outcome(True, float(slip), float(r * (w[-1] - w[0]) - (x[-1] - x[0])))


def push_run(values, law: str, force: float) -> Outcome:
    """A lateral push ``force`` [N] for PUSH_S from PUSH_AT: stays up and |roll| < ROLL_LIMIT; value max |roll|."""
    c = _simulate(values, law, DURATION, push=(PUSH_AT, PUSH_S, force))
    if c is None:
        return Outcome(False)
    roll = max(abs(r) for r in c["roll"])
    return Outcome(bool(roll < ROLL_LIMIT), float(roll))


def scan(run, grid: Sequence[float]) -> Tuple[Optional[float], List[Outcome]]:
    """Climb ``grid`` with ``run(value)`` until the first failure: (the last value that passed or None, outcomes)."""
    best, seen = None, []
    for g in grid:
        o = run(g)
        seen.append(o)
        if not o.ok:
            break
        best = g
    return best, seen


# --- the tables -----------------------------------------------------------------------------------------------------
def _fmt(v, unit=""):
    return "-" if v is None else f"{v:g}{unit}"


def _num(v: float, spec: str) -> str:
    """``v`` formatted, or "falls" for the NaN of a run that fell (no number is shown from it)."""
    return "falls" if math.isnan(v) else format(v, spec)


def tables(laws: Sequence[str] = LAWS, realistic: bool = False, which: Sequence[str] = ("slope", "step",
           "friction", "push"), progress=None) -> Dict[str, Dict[str, object]]:
    """Per table and law, the scans' answers (module docstring)."""
    base = base_values(realistic)
    out: Dict[str, Dict[str, object]] = {w: {} for w in which}
    for law in laws:
        if progress:
            progress(law)
        if "slope" in which:
            bal, _ = scan(lambda d: slope_run(base, law, d, False), SLOPES_DEG)
            hold, seen = scan(lambda d: slope_run(base, law, d, True), SLOPES_DEG)
            out["slope"][law] = (bal, hold, seen[0].value, seen[0].extra)
        if "step" in which:
            best, seen = scan(lambda h: step_run(base, law, h), STEPS)
            out["step"][law] = (best, seen[-1] if not seen[-1].ok else None)
        if "friction" in which:
            out["friction"][law] = [friction_run(base, law, f) for f in FRICTIONS]
        if "push" in which:
            best, seen = scan(lambda f: push_run(base, law, f), PUSHES)
            out["push"][law] = (best, seen[PUSHES.index(best)].value if best is not None else math.nan)
    return out


def markdown(res: Dict[str, Dict[str, object]]) -> str:
    """The tables of :func:`tables` as markdown (docs/laws.md "Terrain")."""
    lines = []
    if res.get("slope"):
        lines += ["| law | balances up to [deg] | holds up to [deg] | drift over [5, 10] s on flat ground, holding [m] "
                  "| band over [5, 10] s [m] |", "|---|---|---|---|---|"]
        lines += [f"| {law} | {_fmt(b)} | {_fmt(h)} | {_num(d, '.4f')} | {_num(w, '.3f')} |"
                  for law, (b, h, d, w) in res["slope"].items()]
        lines.append("")
    if res.get("step"):
        lines += ["| law | highest step driven over at 0.5 m/s [m] | the next step |", "|---|---|---|"]
        for law, (best, fail) in res["step"].items():
            nxt = STEPS[STEPS.index(best) + 1 if best is not None else 0] if fail is not None else None
            how = ("-" if fail is None else f"{nxt:g} m: falls" if math.isnan(fail.value)
                   else f"{nxt:g} m: stops at x = {fail.value:.2f} m")
            lines.append(f"| {law} | {_fmt(best)} | {how} |")
        lines.append("")
    if res.get("friction"):
        lines += ["| law | " + " | ".join(f"mu {f:g}" for f in FRICTIONS) + " |",  # largest slip [m/s] / slipped [m]
                  "|---|" + "---|" * len(FRICTIONS)]
        for law, row in res["friction"].items():
            lines.append(f"| {law} | " + " | ".join(f"{o.value:.2g} / {o.extra:.2g}" if o.ok else "falls"
                                                    for o in row) + " |")
        lines.append("")
    if res.get("push"):
        lines += [f"| law | largest force.y survived for {PUSH_S:g} s [N] | its max abs roll [rad] |",
                  "|---|---|---|"]
        lines += [f"| {law} | {_fmt(b)} | {r:.4f} |" for law, (b, r) in res["push"].items()]
        lines.append("")
    return "\n".join(lines)


def figure(res: Dict[str, Dict[str, object]], path) -> None:
    """Bars per law: the steepest slope balanced and held [deg], the highest step driven over [cm]."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    laws = list(res["slope"])
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 3.8))
    xs = range(len(laws))
    bal = [res["slope"][k][0] or 0 for k in laws]
    hold = [res["slope"][k][1] or 0 for k in laws]
    a.bar([x - 0.2 for x in xs], bal, 0.4, label="balances")
    a.bar([x + 0.2 for x in xs], hold, 0.4, label=f"holds (drift < {100 * HOLD_DRIFT:g} cm over [5, 10] s)")
    a.set_ylabel("steepest slope [deg]")
    a.set_xticks(list(xs), laws, rotation=30)
    a.set_ylim(0, SLOPES_DEG[-1] + 5)
    a.legend(loc="upper right", ncol=2, fontsize="small")
    a.set_title(f"slope (0..{SLOPES_DEG[-1]} deg in 1 deg steps)")
    b.bar(list(xs), [100 * (res["step"][k][0] or 0) for k in laws], 0.6, color="tab:green")
    b.set_ylabel("highest step [cm]")
    b.set_xticks(list(xs), laws, rotation=30)
    b.set_title("a step driven over at 0.5 m/s")
    fig.suptitle(f"MuJoCo, the paper's robot and scenario, torque at most {TORQUE_LIMIT:g} N m "
                 "(a bar at 0: not even 1 deg, 1 cm)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mwip_ros.sweep.terrain", description=__doc__.split("\n\n")[0])
    ap.add_argument("--laws", nargs="+", default=list(LAWS))
    ap.add_argument("--only", nargs="+", default=["slope", "step", "friction", "push"],
                    choices=["slope", "step", "friction", "push"])
    ap.add_argument("--realistic", action="store_true", help="raw sensors and the drive (config overlays)")
    ap.add_argument("--figure", help="write the bar figure here (needs slope and step)")
    a = ap.parse_args(argv)
    from mwip_ros.core import laws
    unknown = [law for law in a.laws if law not in laws.names()]
    if unknown:   # before any scan: one line, not a KeyError after an hour of them
        ap.error(f"--laws: {', '.join(unknown)} is not a registered law ({', '.join(laws.names())})")
    if a.figure and not {"slope", "step"} <= set(a.only):
        ap.error(f"--figure draws the slope and step scans: give --only with slope and step (got {' '.join(a.only)})")
    res = tables(a.laws, a.realistic, a.only, progress=lambda law: print(f"... {law}", file=sys.stderr))
    print(markdown(res))
    if a.figure:
        figure(res, a.figure)
    return 0


if __name__ == "__main__":
    sys.exit(main())
