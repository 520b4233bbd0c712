#!/usr/bin/env python3
"""The law ``mpc``'s QP: solve time per control period, measured on this machine.

    scripts/bench_mpc.py [--horizon N] [--duration S] [--solvers daqp,osqp,proxqp] [--paced] [--batch N]
                         [--json FILE]

1. Runs the paper's scenario (config/paper.yaml, 200 Hz) offline with the law ``mpc`` (its solver, DAQP) and keeps
   the state z = [theta_b, theta_b', theta_w'] of every period.
2. Replays that one sequence of states through each solver on the same condensed QP
   (:func:`mwip_ros.core.laws.mpc.qp_matrices`), each warm-started from its own previous solution shifted by one
   period, and prints the solve time per period (update + solve + the warm start's bookkeeping) p50 / p99 / max
   [us], the iterations, and the largest |u_0 - u_0 of DAQP| [N m].  ``daqp`` is the law's own solver
   (``MpcLaw``'s workspace) called in every period; ``law`` is the law as it steps: the unconstrained optimum
   first, DAQP only where that leaves the bounds (0 iterations in the periods DAQP is not called); ``osqp``
   (1.x: eps 1e-8, polishing off, adaptive rho every 25 iterations, no time limit) and ``proxqp`` (proxsuite,
   dense, eps 1e-9, warm start given by hand) are measured when installed, and skipped with a note when not.
   ``--paced``: idle a control period before each solve, as the controller node does between states; the caches
   are cold at every solve, as they are there.
3. ``--batch N``: the batch simulator (``core.kernels.batch.simulate_batch``, the numpy loop: ``mpc`` has no compiled
   form) over N copies of the scenario with different seeds, 2 s: scenario-steps/s.

The table goes to stdout, progress to stderr; ``--json`` also writes the numbers.
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np


def _states(values, duration: float):
    from mwip_ros import params as P
    from mwip_ros.core.closed_loop.sim import simulate
    traj = simulate(P.closed_loop(values, controller="mpc", duration=duration))
    return np.column_stack([traj["theta_b"], traj["dtheta_b"], traj["dtheta_w"]])


def _daqp(qp, u_max, free_first=False):
    from mwip_ros.core.laws.mpc import _Qp
    solver = _Qp(qp, u_max, free_first=free_first)

    def solve(z):
        return solver.solve(*z), solver.iterations
    return solve


def _law(qp, u_max):
    return _daqp(qp, u_max, free_first=True)


def _osqp(qp, u_max):
    import osqp
    import scipy.sparse as sp
    N = qp.H.shape[0]
    s = osqp.OSQP()
    s.setup(sp.csc_matrix(np.triu(qp.H)), np.zeros(N), sp.eye(N, format="csc"), np.full(N, -u_max), np.full(N, u_max),
            verbose=False, eps_abs=1e-8, eps_rel=1e-8, polishing=False, adaptive_rho_interval=25, max_iter=4000)
    warm = [None]

    def solve(z):
        s.update(q=qp.F @ np.asarray(z))
        if warm[0] is not None:
            s.warm_start(x=warm[0][0], y=warm[0][1])
        r = s.solve()
        warm[0] = (np.r_[r.x[1:], r.x[-1]], np.r_[r.y[1:], r.y[-1]])
        return min(max(float(r.x[0]), -u_max), u_max), int(r.info.iter)
    return solve


def _proxqp(qp, u_max):
    from proxsuite import proxqp
    N = qp.H.shape[0]
    # n_in = N with C = I and WARM_START by hand: proxsuite 0.8.0 crashes (SIGSEGV) with box constraints
    # warm-started, and with WARM_START_WITH_PREVIOUS_RESULT after update()
    q = proxqp.dense.QP(N, 0, N)
    q.settings.eps_abs, q.settings.verbose = 1e-9, False
    q.settings.initial_guess = proxqp.InitialGuess.WARM_START
    q.init(qp.H, np.zeros(N), None, None, np.eye(N), np.full(N, -u_max), np.full(N, u_max))
    warm = [None]

    def solve(z):
        q.update(g=qp.F @ np.asarray(z))
        if warm[0] is None:
            q.settings.initial_guess = proxqp.InitialGuess.NO_INITIAL_GUESS
            q.solve()
            q.settings.initial_guess = proxqp.InitialGuess.WARM_START
        else:
            q.solve(*warm[0])
        x, y, zz = q.results.x, q.results.y, q.results.z
        warm[0] = (np.r_[x[1:], x[-1]], y.copy(), np.r_[zz[1:], zz[-1]])
        return min(max(float(x[0]), -u_max), u_max), int(q.results.info.iter)
    return solve


SOLVERS = {"daqp": _daqp, "law": _law, "osqp": _osqp, "proxqp": _proxqp}


def _replay(make, qp, u_max, Z, pause: float = 0.0):
    solve = make(qp, u_max)
    times, us, iters = np.empty(len(Z)), np.empty(len(Z)), np.empty(len(Z), dtype=int)
    clock = time.perf_counter
    for k, z in enumerate(Z):
        if pause:
            time.sleep(pause)   # idle between solves, as a node at its rate: the caches go cold
        t0 = clock()
        u, it = solve(tuple(float(c) for c in z))
        times[k] = clock() - t0
        us[k], iters[k] = u, it
    return times, us, iters


def _batch(values, n: int) -> float:
    from mwip_ros import params as P
    from mwip_ros.core.kernels.batch import simulate_batch
    warm = [P.closed_loop(dict(values, seed=i), controller="mpc", duration=0.05) for i in range(2)]
    simulate_batch(warm, (0.0, 0.05))   # the RK4 period compiled or loaded (numba) before the clock starts
    loops = [P.closed_loop(dict(values, seed=i), controller="mpc", duration=2.0) for i in range(n)]
    t0 = time.perf_counter()
    r = simulate_batch(loops, (1.0, 2.0))
    return r.steps / (time.perf_counter() - t0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--horizon", type=int, default=None, help="mpc.horizon (default: the file's, 20)")
    ap.add_argument("--duration", type=float, default=10.0, help="the scenario's length [s] (default 10)")
    ap.add_argument("--solvers", default="daqp,law,osqp,proxqp",
                    help="comma-separated: daqp, law, osqp, proxqp (default: all)")
    ap.add_argument("--repeat", type=int, default=3, help="replays per solver; the fastest per period is kept "
                                                          "(default 3)")
    ap.add_argument("--paced", action="store_true", help="sleep a control period before each solve, as the "
                                                          "controller node runs it: the cold-cache cost")
    ap.add_argument("--batch", type=int, default=0, help="also the batch simulator over N scenarios (0: no)")
    ap.add_argument("--json", default=None, help="write the numbers to this file too")
    args = ap.parse_args(argv)

    from mwip_ros import params as P
    from mwip_ros.core.laws.mpc import SOLVER, qp_matrices
    from mwip_ros.params.paths import default_params_file
    values = P.merged_values(P.load_param_file(default_params_file()))
    if args.horizon is not None:
        values["mpc.horizon"] = args.horizon
    law = P.closed_loop(values, controller="mpc").params
    qp = qp_matrices(P.physical(values, "nominal"), P.period(values), law.horizon,
                     (law.q_theta_b, law.q_dtheta_b, law.q_dtheta_w), law.r)
    print(f"bench_mpc: the paper's scenario with mpc, {args.duration:g} s at {values['control_rate_hz']:g} Hz",
          file=sys.stderr)
    Z = _states(values, args.duration)
    out, ref = {"horizon": law.horizon, "periods": len(Z), "law_solver": SOLVER, "solvers": {}}, None
    print(f"QP: N = {law.horizon} inputs, {law.horizon} box constraints |u_k| <= {law.u_max:g} N m; "
          f"{len(Z)} periods, the same warm-started sequence for every solver"
          + ("; a control period idle before each solve (--paced)" if args.paced else ""))
    print(f"{'solver':8s} {'p50 [us]':>9s} {'p99 [us]':>9s} {'max [us]':>9s} {'iter p50':>8s} {'iter max':>8s} "
          f"{'max |du0| [N m]':>16s}")
    for name in [s.strip() for s in args.solvers.split(",") if s.strip()]:
        try:
            pause = P.period(values) if args.paced else 0.0
            runs = [_replay(SOLVERS[name], qp, law.u_max, Z, pause) for _ in range(max(1, args.repeat))]
        except ImportError as exc:
            print(f"{name:8s} skipped: {exc}")
            continue
        times = np.min([r[0] for r in runs], axis=0) * 1e6
        _, us, iters = runs[0]
        ref = us if ref is None and name == "daqp" else ref
        du = float(np.abs(us - ref).max()) if ref is not None else float("nan")
        p50, p99, mx = (float(np.percentile(times, 50)), float(np.percentile(times, 99)), float(times.max()))
        print(f"{name:8s} {p50:9.1f} {p99:9.1f} {mx:9.1f} {int(np.median(iters)):8d} {int(iters.max()):8d} {du:16.2e}")
        out["solvers"][name] = dict(p50_us=p50, p99_us=p99, max_us=mx, iter_p50=float(np.median(iters)),
                                    iter_max=int(iters.max()), max_du0=du)
    if args.batch:
        print(f"bench_mpc: the batch simulator, {args.batch} scenarios x 2 s", file=sys.stderr)
        rate = _batch(values, args.batch)
        out["batch"] = dict(scenarios=args.batch, scenario_steps_per_s=rate)
        print(f"batch simulator (numpy loop, one DAQP workspace per scenario), {args.batch} scenarios: "
              f"{rate:,.0f} scenario-steps/s")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
