"""The law ``mpc``: linear model predictive control with the torque limit as a hard constraint (docs/theory.md
6.6); ``mpc_ndo`` is it with DSCNDO's observer term (composed by :mod:`.ndo`, eq. 19-21).

The model is the LQR baseline's (docs/theory.md 6.1, :mod:`mwip_ros.core.control.lqr`): the nominal linearization at the
upright, z = [theta_b, theta_b', theta_w'], held over the control period h (zero-order hold), ``z+ = A_d z + B_d u``.
Each period, from the measured z_0, the law solves

    minimize    sum_{k=0}^{N-1} (z_k^T Q z_k + R u_k^2) + z_N^T P z_N
    subject to  z_{k+1} = A_d z_k + B_d u_k,     -u_max <= u_k <= u_max   (k = 0 .. N-1)

with P the discrete Riccati solution of (A_d, B_d, Q, R), the LQR's, so that when no constraint binds u_0 is the
LQR command -K z_0 (the finite-horizon Riccati recursion started at P stays at P), and applies u_0.  The states
are eliminated (condensed form): with Z = [z_1; ...; z_N] = Phi z_0 + Gamma U, the QP in U = [u_0 .. u_{N-1}] is

    minimize 1/2 U^T H U + (F z_0)^T U   s.t.  -u_max <= U <= u_max,
    H = Gamma^T Qbar Gamma + R I,   F = Gamma^T Qbar Phi,   Qbar = blkdiag(Q, ..., Q, P)

(the cost halved; N box constraints, no other).  Always feasible: only the input is constrained.

The solver is DAQP (the dual active-set solver of Arnstroem, Bemporad and Axehill, 2022; ``daqp`` on PyPI): an
active-set method ends on the solution of its final active set, to rounding, so ``mpc`` equals ``lqr`` when no
constraint binds and the command sits exactly on the bound when u_0's constraint is active; its warm start is
plain data (the active set) that the law keeps, shifts, snapshots and restores.  (Its timings, and why not OSQP or
ProxQP: BENCHMARKS.md, "MPC's QP solver".)

Determinism.  A solve is a pure function of (H, f = F z_0, the bounds, the starting active set): the law passes the
starting active set explicitly at every solve (``Model.update(f=..., sense=...)``, the bounds when they moved), so
nothing of the workspace's history counts.  Settings: ``iter_limit = ITER_LIMIT`` (a fixed cap on active-set
changes, no time limit: ``time_limit = 0``), ``eps_prox = 0`` (H is positive definite: no proximal
regularization), the rest DAQP's defaults.  The same
states give the same commands bit for bit in the offline loop, the batch simulator and the lockstep graph.

Warm start.  The active set of the previous solution shifted by one period (u_1 .. u_{N-1} become u_0 .. u_{N-2};
the last keeps u_{N-1}'s): usually the optimal one, one iteration.  :meth:`MpcLaw.reset` clears it (cold start:
no constraint active); :meth:`MpcLaw.snapshot` / :meth:`MpcLaw.restore` copy it (the node undoes a step whose
command is not finite).  A solve that ends without a solution (the cap hit, a numerical failure) gives
clip(-K z_0, +-u_max), the saturated LQR command, and a cold start next period.

The limit.  ``mpc.u_max`` [N m] is the law's own parameter: the law does not see the plant's ``torque_limit``
nor the motor model.  With the motor model on (docs/theory.md 6.7) the torque is capped at I_max K_t
(``motor.current_limit`` times ``motor.torque_constant``); set ``mpc.u_max`` to it.  The back-EMF's lower limit at
speed (V_max - K_t w) K_t / R is not modelled.  ``mpc_ndo`` takes the observer term u_taud (eq. 20) into the QP
as a known input offset held over the horizon: the command is u_0 - u_taud and the bounds are shifted,
``-u_max + u_taud <= u_k <= u_max + u_taud`` (docs/theory.md 6.6), so |u| <= u_max holds with the term too.

No pure form (``pure_step`` is None: a QP solver does not run inside numba): in the batch simulator :meth:`step`
gets arrays of scenarios and solves them one by one, each scenario with its own DAQP workspace and warm start.
"""
from __future__ import annotations

import functools
import math
from typing import NamedTuple, Optional, Tuple

import numpy as np

from .base import Law, LawParam
from .dsc import INTERNALS

__all__ = ["MpcParams", "MpcLaw", "QpMatrices", "qp_matrices", "PARAMETERS", "ITER_LIMIT", "SOLVER"]

SOLVER = "daqp"
ITER_LIMIT = 1000      # DAQP's cap on active-set changes per solve (2 N would do)
# DAQP's sense flags: ACTIVE (1) | LOWER (2) for u = -u_max (lam < 0), ACTIVE for u = +u_max (lam > 0), else none
_AT_LOWER, _AT_UPPER = 3, 1
Q_MAX = 1e12           # mpc.Q's entries at most this (lqr.Q's bound): beyond, the Riccati solution overflows

PARAMETERS = (
    LawParam("mpc.horizon", "integer", 20, "model predictive control: prediction horizon N [control periods] "
             "(the QP has N inputs; at 200 Hz, N = 20 looks 0.1 s ahead, the terminal weight covers the rest)",
             lo=1, hi=200),
    LawParam("mpc.Q", "double_array", [100.0, 10.0, 1.0], "model predictive control: state weight on [theta_b, "
             "theta_b', theta_w'], the diagonal (3 entries, 0 .. 1e12); the terminal weight is the Riccati solution of "
             "mpc.Q and mpc.R (as lqr.Q)"),
    LawParam("mpc.R", "double", 0.01, "model predictive control: input weight R (> 0), as lqr.R",
             lo=1e-6, hi=1e6),
    LawParam("mpc.u_max", "double", 120.0, "model predictive control: torque limit |u_k| <= u_max [N m], a hard "
             "constraint of the QP; with the motor model on, set it to motor.current_limit x "
             "motor.torque_constant (I_max K_t)", lo=0.1, hi=1e5),
)


class MpcParams(NamedTuple):
    """The law's parameters (numbers: the batch stacks them); the QP is built from them, the nominal model and h."""

    horizon: int
    q_theta_b: float
    q_dtheta_b: float
    q_dtheta_w: float
    r: float
    u_max: float


class QpMatrices(NamedTuple):
    """The condensed QP of one design: 1/2 U^T H U + (F z_0)^T U, and the model and LQR behind it."""

    Ad: np.ndarray     # 3x3
    Bd: np.ndarray     # 3x1
    P: np.ndarray      # 3x3, the terminal weight (DARE)
    K: np.ndarray      # (3,), the LQR gain of (A_d, B_d, Q, R)
    H: np.ndarray      # N x N
    F: np.ndarray      # N x 3


def _design_error(key: str, reason: str) -> ValueError:
    from ..control.lqr import LqrDesignError
    return LqrDesignError(key, reason)


@functools.lru_cache(maxsize=64)
def qp_matrices(nominal, h: float, horizon: int, Q: Tuple[float, float, float], R: float) -> QpMatrices:
    """The condensed QP of the horizon ``horizon`` on the ZOH model of the nominal linearization at period ``h``
    (remembered: a sweep asks for the same one many times)."""
    from scipy.linalg import expm, solve_discrete_are

    from ..control.lqr import _zoh, linearization, weights
    Qm, Rm = weights(Q, R)
    A, B = linearization(nominal)
    Ad, Bd = _zoh(A, B, float(h), expm)
    P = solve_discrete_are(Ad, Bd, Qm, Rm)
    K = np.linalg.solve(Rm + Bd.T @ P @ Bd, Bd.T @ P @ Ad)[0]
    N = int(horizon)
    powers = [np.eye(3)]
    for _ in range(N):
        powers.append(Ad @ powers[-1])
    Phi = np.vstack(powers[1:])                                   # z_k = A_d^k z_0 + ...
    Gamma = np.zeros((3 * N, N))
    for k in range(N):                                            # z_{k+1} = ... + sum_j A_d^(k-j) B_d u_j
        for j in range(k + 1):
            Gamma[3 * k:3 * k + 3, j] = (powers[k - j] @ Bd)[:, 0]
    Qbar = np.kron(np.eye(N), Qm)
    Qbar[-3:, -3:] = P
    H = Gamma.T @ Qbar @ Gamma + Rm[0, 0] * np.eye(N)
    H = 0.5 * (H + H.T)
    F = Gamma.T @ Qbar @ Phi
    for a in (Ad, Bd, P, K, H, F):
        a.setflags(write=False)
    return QpMatrices(Ad, Bd, P, K, np.ascontiguousarray(H), np.ascontiguousarray(F))


class _Qp:
    """One scenario's QP: a DAQP workspace and the warm start (the starting active set, DAQP's sense flags)."""

    def __init__(self, qp: QpMatrices, u_max: float, free_first: bool = True):
        """``free_first``: try the unconstrained optimum before DAQP (the law always does; False makes every
        period a DAQP solve, as ``scripts/bench_mpc.py`` times the solvers)."""
        from mwip_ros.optional import required
        with required("daqp", "the law mpc"):
            import daqp
        self.qp, self.u_max, self.N = qp, float(u_max), qp.H.shape[0]
        self.model = daqp.Model()
        # DAQP may keep pointers to the arrays it is given: they are this object's, kept alive with the workspace
        self._H, self._A = qp.H.copy(), np.zeros((0, self.N))
        self._f, self._hi, self._lo = np.zeros(self.N), np.full(self.N, self.u_max), np.full(self.N, -self.u_max)
        self._z = np.zeros(3)
        self._offset = 0.0                                          # the bounds' shift the workspace holds
        self.sense = np.zeros(self.N, dtype=np.int32)               # the warm start: the active set to start from
        self.model.setup(self._H, self._f, self._A, self._hi, self._lo, self.sense)
        self.model.settings = dict(iter_limit=ITER_LIMIT, time_limit=0.0, eps_prox=0.0)
        self.iterations = 0
        # the unconstrained optimum U = -H^-1 F z_0, row by row (Python floats): where it is within the bounds it
        # is the QP's optimum (H is positive definite), with no constraint active, and DAQP is not called
        self._free = [tuple(row) for row in (-np.linalg.solve(qp.H, qp.F)).tolist()] if free_first else []
        self.cold = True                                            # the warm start is empty (sense all 0)

    def warm(self, sense=None) -> None:
        """Set the warm start to ``sense`` (None: empty, a cold start), in place: DAQP may hold the array it was
        set up with.  ``cold`` follows it, so a period within the bounds writes nothing when it is empty."""
        if sense is None:
            self.sense[:] = 0
            self.cold = True
        else:
            self.sense[:] = sense
            self.cold = not any(sense)

    def solve(self, theta_b: float, dtheta_b: float, dtheta_w: float, offset: float = 0.0) -> float:
        """u_0 for the state z = (theta_b, theta_b', theta_w') with the bounds ``offset`` -+ u_max (the observer
        term taken in: |u_0 - offset| <= u_max, docs/theory.md 6.6), warm-started; the warm start moves on.

        Few calls into numpy and DAQP, the rest on Python floats (a node calls it once a period, on cold
        caches): the unconstrained optimum is tried first, on floats; DAQP only when it leaves the bounds, and
        the shift of the active set is a list."""
        u_max = self.u_max
        if not (math.isfinite(theta_b) and math.isfinite(dtheta_b) and math.isfinite(dtheta_w)
                and math.isfinite(offset)):
            return math.nan                                          # nothing solved, the warm start stays
        if self._free:
            for g0, g1, g2 in self._free:                            # a plain loop: cheaper than all() over a generator
                if abs(g0 * theta_b + g1 * dtheta_b + g2 * dtheta_w - offset) > u_max:
                    break
            else:                                                    # within the bounds: the optimum, none active
                if not self.cold:
                    self.warm()
                self.iterations = 0
                g0, g1, g2 = self._free[0]
                return g0 * theta_b + g1 * dtheta_b + g2 * dtheta_w
        return self._daqp(theta_b, dtheta_b, dtheta_w, offset)

    def _daqp(self, theta_b: float, dtheta_b: float, dtheta_w: float, offset: float) -> float:
        """DAQP's solve from the warm start, the bounds ``offset`` -+ u_max; the warm start moves on."""
        lo, hi = offset - self.u_max, offset + self.u_max
        z = self._z
        z[0], z[1], z[2] = theta_b, dtheta_b, dtheta_w
        np.dot(self.qp.F, z, out=self._f)                            # the QP's linear term F z_0
        if offset != self._offset:                                   # the bounds shifted by the observer term
            self._offset = offset
            self._hi[:], self._lo[:] = hi, lo
            self.model.update(f=self._f, bupper=self._hi, blower=self._lo, sense=self.sense)
        else:
            self.model.update(f=self._f, sense=self.sense)
        U, _, flag, info = self.model.solve()
        self.iterations = int(info["iterations"])
        u0 = float(U[0])
        if flag <= 0 or not math.isfinite(u0):                      # the cap, or no solution: saturated LQR
            self.warm()
            K = self.qp.K
            return min(max(-float(K[0] * theta_b + K[1] * dtheta_b + K[2] * dtheta_w), lo), hi)
        # the active set (lam < 0: the lower bound, > 0: the upper), shifted by one period
        active = [(_AT_LOWER if lam < 0.0 else _AT_UPPER) if lam != 0.0 else 0 for lam in info["lam"].tolist()]
        self.warm(active[1:] + active[-1:])
        if active[0]:                                                # u_0 on its bound: the bound exactly
            return lo if active[0] == _AT_LOWER else hi
        return min(max(u0, lo), hi)                                  # (DAQP's primal_tol is 1e-6)


def _at(v, i):
    return v if np.ndim(v) == 0 else v[i]


_NOMINAL = ("m_b", "m_w", "I_b", "I_w", "l", "r", "g")   # the nominal model's fields (one value or one per scenario)


class MpcLaw(Law):
    """Linear MPC on the LQR baseline's ZOH model; the torque limit a hard constraint (state: the warm start)."""

    name = "mpc"
    title = "MPC"
    param_keys = tuple(p.name for p in PARAMETERS)
    parameters = PARAMETERS
    # the layout DSC publishes (as lqr): u_dsc is the law's own command, S1 theta_b; DSC's own are NaN
    internal_names = INTERNALS
    Params = MpcParams
    announce = False
    limit_key = "mpc.u_max"
    requires = ("daqp",)   # optional (mwip_ros.optional): without it this law is refused, the others run

    def __init__(self, params, nominal, h: float, m=math):
        self.nominal, self.h, self.m = nominal, h, m
        self.params = params                 # the property: one scenario's QP is built here

    @property
    def params(self) -> MpcParams:
        return self._params

    @params.setter
    def params(self, value) -> None:
        """New parameters (the node re-designs at run time): a new QP, a cold start.  One scenario's QP (the
        node's) is built now, not in the first step (building it, the Riccati terminal weight and DAQP's
        workspace, takes longer than a control period); the batch's (one per scenario) on its first step."""
        self._params = value
        self._qps = None
        nominal = self.nominal
        if all(np.ndim(v) == 0 for v in (*value, *(getattr(nominal, f) for f in _NOMINAL))):
            self._qps = [self._scenario_qp(None)]

    @classmethod
    def design(cls, values, nominal, h) -> MpcParams:
        """The parameters, checked: ``mpc.Q`` 3 entries >= 0, a stabilizing Riccati solution; a
        :class:`~mwip_ros.core.control.lqr.LqrDesignError` names the key."""
        from ..control.lqr import LqrDesignError, lqr_gain
        Q = values["mpc.Q"]
        if len(Q) != 3:
            raise _design_error("mpc.Q", f"give the diagonal (3 entries), got {len(Q)} entries")
        if not all(isinstance(q, (int, float)) and math.isfinite(q) and 0 <= q <= Q_MAX for q in Q):
            raise _design_error("mpc.Q", f"entries must be >= 0 and <= {Q_MAX:g} (as lqr.Q's), got {list(Q)}")
        N, R, u_max = values["mpc.horizon"], values["mpc.R"], values["mpc.u_max"]
        if not (isinstance(N, (int, np.integer)) and not isinstance(N, bool) and N >= 1):
            raise _design_error("mpc.horizon", f"must be an integer >= 1, got {N!r}")
        if not (isinstance(R, (int, float)) and math.isfinite(R) and R > 0):
            raise _design_error("mpc.R", f"must be > 0, got {R!r}")
        if not (isinstance(u_max, (int, float)) and math.isfinite(u_max) and u_max > 0):
            raise _design_error("mpc.u_max", f"must be > 0, got {u_max!r}")
        try:
            lqr_gain(nominal, h, Q, R)      # the terminal weight exists (the same checks as the LQR's)
        except LqrDesignError as exc:
            raise _design_error("mpc.Q" if exc.key == "lqr.Q" else "mpc.R", exc.reason) from None
        return MpcParams(int(N), float(Q[0]), float(Q[1]), float(Q[2]), float(R), float(u_max))

    # --- the QPs ----------------------------------------------------------------------------------------------

    def _scenario_qp(self, i: Optional[int]) -> _Qp:
        """Scenario i's QP (None: the one scenario) from its parameters and nominal model."""
        p, nom = self._params, self.nominal
        if i is not None:                    # the batch: a field holds one value for all or one per scenario
            p = MpcParams(*(_at(v, i) for v in p))
            nom = type(nom)(**{f: float(_at(getattr(nom, f), i)) for f in _NOMINAL})
        qp = qp_matrices(nom, float(self.h), int(round(p.horizon)),
                         (float(p.q_theta_b), float(p.q_dtheta_b), float(p.q_dtheta_w)), float(p.r))
        return _Qp(qp, p.u_max)

    # --- state ------------------------------------------------------------------------------------------------

    def reset(self) -> None:
        """A cold start: no constraint assumed active."""
        for qp in self._qps or ():
            qp.warm()

    def snapshot(self):
        return None if self._qps is None else [qp.sense.copy() for qp in self._qps]

    def restore(self, snap) -> None:
        if snap is None:
            self._qps = None
            return
        if self._qps is not None and len(self._qps) == len(snap):
            for qp, sense in zip(self._qps, snap):
                qp.warm(sense)

    def finite(self) -> bool:
        return True                          # the warm start is an active set: always valid

    def step(self, x, tau_hat=None):
        u = self._solve(x, 0.0)
        return u, {"u_dsc": u, "u_taud": 0.0, "S1": x[1], "u": u}   # u_taud: 0, the term is off

    def step_observed(self, x, u_taud):
        """``mpc_ndo``: u = u_0 - u_taud (eq. 19) with the observer term inside the QP, the bounds shifted by it
        (-u_max <= u_k - u_taud <= u_max, u_taud held over the horizon; docs/theory.md 6.6): |u| <= u_max holds
        (clamped to it against rounding; NaN stays NaN)."""
        u0 = self._solve(x, u_taud)
        u_max = self._params.u_max
        if np.ndim(u0) == 0:
            u = u0 - u_taud
            u = u if not math.isfinite(u) else min(max(u, -u_max), u_max)
        else:
            u = np.clip(u0 - u_taud, -u_max, u_max)
        return u, {"u_dsc": u0, "S1": x[1]}

    def _solve(self, x, offset):
        """u_0 of the QP (bounds ``offset`` -+ u_max) for the state ``x``: one scenario, or arrays of them."""
        x = self.tracked(x)   # the reference state's error coordinates (docs/theory.md 6.11); x itself without motion
        theta_b, dtheta_w, dtheta_b = x[1], x[2], x[3]
        if np.ndim(theta_b) == 0:            # one scenario
            if self._qps is None or len(self._qps) != 1:
                self._qps = [self._scenario_qp(None)]
            return self._qps[0].solve(float(theta_b), float(dtheta_b), float(dtheta_w), float(offset))
        n = len(theta_b)                     # the batch: arrays of scenarios, solved one by one
        if self._qps is None or len(self._qps) != n:
            self._qps = [self._scenario_qp(i) for i in range(n)]
        tb, dtb, dtw, off = (np.broadcast_to(np.asarray(a, dtype=float), (n,)).tolist()
                             for a in (theta_b, dtheta_b, dtheta_w, offset))
        return np.array([qp.solve(tb[i], dtb[i], dtw[i], off[i]) for i, qp in enumerate(self._qps)])

    # --- text -------------------------------------------------------------------------------------------------

    def summary(self) -> str:
        p = self._params
        if np.ndim(p.horizon) != 0:
            return "a batch"
        return (f"N = {int(p.horizon)}, Q = diag({p.q_theta_b:g}, {p.q_dtheta_b:g}, {p.q_dtheta_w:g}), "
                f"R = {p.r:g}, |u| <= {p.u_max:g} N m")

    def design_text(self, values=None) -> Optional[str]:
        return f"MPC {self.summary()} ({SOLVER}, terminal weight: the Riccati solution)"
