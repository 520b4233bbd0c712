"""The law ``smc``: sliding-mode control (docs/theory.md 6.5); ``smc_ndo`` is it with DSCNDO's observer term.

The paper names sliding-mode control (Huang et al. 2010: "robust to both parameter variations and noise
disturbances", its drawback "chattering") as the alternative to DSC.  This is the textbook form for the
regulation of an underactuated MWIP, on the states the other laws regulate, z = [theta_b, theta_b', theta_w']:

* a linear sliding surface ``s = c1 theta_b + c2 theta_b' + c3 theta_w'`` designed on the nominal
  linearized model (:func:`mwip_ros.core.control.lqr.linearization`, docs/theory.md 6.1) by Ackermann's formula for
  sliding surfaces (Ackermann & Utkin 1998): ``c^T = e^T (A + p1 I)(A + p2 I)``, ``e^T`` the last row of the
  inverse controllability matrix, so that on ``s = 0`` the linearized motion has the eigenvalues -p1, -p2 and
  ``c^T B = 1`` (``s`` is scaled so that ``s' = ... + u`` near the upright);
* the equivalent control from eq. (1) of the nominal model (no friction, no disturbance): the
  accelerations are affine in u, ``theta_b'' = f_b + g_b u``, ``theta_w'' = f_w + g_w u``;
* the constant-plus-proportional reaching law (Gao & Hung 1993) ``s' = -q s - k sat(s / phi)`` with the
  boundary layer phi (Slotine & Sastry 1983): ``phi = 0`` is the pure sign (chattering);

so that ``u = (-(c1 theta_b' + c2 f_b + c3 f_w) - q s - k sat(s / phi)) / (c2 g_b + c3 g_w)``.
u_taud (eq. 20) is added by :mod:`.ndo`, not here.

In discrete time (the command held over the period h) s_k+1 = (1 - a h) s_k, with a = q outside the layer and
a = q + k / phi inside it (docs/theory.md 6.5): q h >= 2 is refused, (q + k / phi) h >= 2 warned of.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional, Tuple

from .base import Law, LawParam
from .dsc import INTERNALS

__all__ = ["SmcGains", "SmcLaw", "smc_step", "sliding_surface", "sat", "layer_rate", "boundary_layer_warning",
           "DISCRETE_LIMIT", "PARAMETERS"]

DISCRETE_LIMIT = 2.0   # s_k+1 = (1 - a h) s_k is stable for 0 < a h < 2 (a = q outside the layer, q + k/phi inside)

PARAMETERS = (
    LawParam("smc.pole1", "double", 3.0, "sliding-mode control: the linearized motion on s = 0 has the "
             "eigenvalues -pole1, -pole2 (Ackermann's formula for the surface) [1/s]", lo=0.01, hi=1000.0),
    LawParam("smc.pole2", "double", 3.0, "sliding-mode control: second eigenvalue -pole2 of the motion on s = 0 "
             "[1/s]", lo=0.01, hi=1000.0),
    LawParam("smc.k", "double", 40.0, "sliding-mode control: switching gain k of the reaching law "
             "s' = -q s - k sat(s / boundary_layer) [N m] (s' = ... + u)", lo=0.0, hi=1e5),
    LawParam("smc.q", "double", 20.0, "sliding-mode control: proportional rate q of the reaching law [1/s] "
             "(q h below 2 at the control period h, refused otherwise)", lo=0.0, hi=150.0),
    LawParam("smc.boundary_layer", "double", 1.0, "sliding-mode control: boundary-layer width phi of "
             "sat(s / phi) [N m s]; 0 = the pure sign (chattering)", lo=0.0, hi=1e4),
)


class SmcGains(NamedTuple):
    """The surface's coefficients on [theta_b, theta_b', theta_w'] and the reaching law's gains."""

    c1: float     # [N m s/rad]
    c2: float     # [N m s^2/rad]
    c3: float     # [N m s^2/rad]
    q: float      # [1/s]
    k: float      # [N m]
    phi: float    # [N m s]


def sliding_surface(nominal, pole1: float, pole2: float) -> Tuple[float, float, float]:
    """(c1, c2, c3) of s = c1 theta_b + c2 theta_b' + c3 theta_w' by Ackermann's formula for sliding surfaces
    (Ackermann & Utkin 1998) on the nominal linearized model (A, B): c^T = e^T (A + pole1 I)(A + pole2 I),
    e^T = [0, 0, 1] [B, A B, A^2 B]^-1; the motion on s = 0 has the eigenvalues -pole1, -pole2 and c^T B = 1."""
    import numpy as np

    from ..control.lqr import linearization
    A, B = linearization(nominal)
    C = np.hstack([B, A @ B, A @ A @ B])
    e = np.linalg.solve(C.T, np.array([0.0, 0.0, 1.0]))   # e^T C = [0, 0, 1]
    I = np.eye(3)
    c = e @ (A + pole1 * I) @ (A + pole2 * I)
    return float(c[0]), float(c[1]), float(c[2])


def layer_rate(gains: SmcGains, h: float) -> float:
    """(q + k / phi) h: the discrete rate of s inside the boundary layer, s_k+1 = (1 - (q + k / phi) h) s_k
    (docs/theory.md 6.5); inf for phi = 0 (the pure sign: no layer)."""
    return (gains.q + gains.k / gains.phi) * h if gains.phi > 0 else math.inf


def boundary_layer_warning(gains: SmcGains, h: float) -> Optional[str]:
    """One line when the boundary layer is unstable in discrete time, (q + k / phi) h >= 2, naming the keys and
    the rate, and the smallest stable smc.boundary_layer; None when it is stable or phi = 0 (the pure sign)."""
    a = layer_rate(gains, h)
    if gains.phi == 0 or a < DISCRETE_LIMIT:
        return None
    least = gains.k * h / (DISCRETE_LIMIT - gains.q * h)
    return (f"smc: the boundary layer is unstable at control_rate_hz {1.0 / h:g} Hz: (smc.q + smc.k / "
            f"smc.boundary_layer) h = ({gains.q:g} + {gains.k:g} / {gains.phi:g}) x {h:g} s = {a:.3g}, not below "
            f"{DISCRETE_LIMIT:g}; s alternates across the layer and the torque chatters as with the pure sign "
            f"(docs/theory.md 6.5); a stable layer needs smc.boundary_layer > k h / (2 - q h) = {least:.3g} N m s")


def sat(y):
    """clip(y, -1, 1) with abs only (floats, numpy arrays, numba)."""
    return 0.5 * (abs(y + 1.0) - abs(y - 1.0))


def smc_step(P, p, h, x, s, first, m=math):
    """One period of SMC as a pure function (:attr:`~mwip_ros.core.laws.Law.pure_step`): ``P`` = (c1, c2, c3, q, k,
    phi), no state (``s`` is returned as it came).  Returns (u, s, (sigma, u_eq, u_sw, u)): sigma the surface,
    u_eq the equivalent control, u_sw = -(q sigma + k sat(sigma / phi)) / g the reaching law's part."""
    c1, c2, c3, q, k, phi = P[0], P[1], P[2], P[3], P[4], P[5]
    tb, dtw, dtb = x[1], x[2], x[3]
    sigma = c1 * tb + c2 * dtb + c3 * dtw                               # the sliding surface
    sn, mc = m.sin(tb), p.m12 * m.cos(tb)                                # M_C12 = m12 cos theta_b
    det = p.m11 * p.m22 - mc * mc                                        # det M_hat (eq. 4's inertia, nominal)
    r1, r2 = p.m12 * dtb * dtb * sn, p.G_b * sn                           # eq. (1), nominal, u = 0, no friction
    f_w, f_b = (p.m22 * r1 - mc * r2) / det, (p.m11 * r2 - mc * r1) / det
    g_w, g_b = (p.m22 + mc) / det, -(p.m11 + mc) / det                   # d(theta_w'', theta_b'') / du
    g = c2 * g_b + c3 * g_w                                              # s' = F + g u
    u_eq = -(c1 * dtb + c2 * f_b + c3 * f_w) / g
    # sat(sigma / phi) = sigma / max(|sigma|, phi): the sign where |sigma| >= phi (phi = 0: always; 0 at 0)
    a = abs(sigma)
    d = 0.5 * (a + phi + abs(a - phi))                                   # max(|sigma|, phi)
    d = d + (d == 0.0)                                                   # sigma = phi = 0: 0 / 1
    u_sw = -(q * sigma + k * (sigma / d)) / g
    u = u_eq + u_sw
    return u, s, (sigma, u_eq, u_sw, u)


class SmcLaw(Law):
    """SMC: the equivalent control of the nominal eq. (1) plus the reaching law on a linear surface (no state)."""

    name = "smc"
    title = "SMC"
    param_keys = tuple(p.name for p in PARAMETERS)
    parameters = PARAMETERS
    # the layout DSC publishes (as lqr): u_dsc is the law's own command, S1 the surface s; DSC's own are NaN
    internal_names = INTERNALS
    Params = SmcGains
    announce = False

    @classmethod
    def design(cls, values, nominal, h) -> SmcGains:
        """The surface and the reaching law's gains; refused (a ValueError naming ``smc.q``) when q h >= 2, where
        the reaching law's proportional part diverges in discrete time (docs/theory.md 6.5)."""
        q = float(values["smc.q"])
        if not q * h < DISCRETE_LIMIT:
            from ..control.lqr import LqrDesignError
            raise LqrDesignError("smc.q", f"{q:g} /s at control_rate_hz {1.0 / h:g} Hz gives q h = {q * h:.3g}, "
                                          f"not below {DISCRETE_LIMIT:g}: the reaching law diverges in discrete time "
                                          f"(|1 - q h| >= 1); keep smc.q < {DISCRETE_LIMIT / h:.4g} /s at this rate")
        c1, c2, c3 = sliding_surface(nominal, values["smc.pole1"], values["smc.pole2"])
        return SmcGains(c1, c2, c3, q, float(values["smc.k"]), float(values["smc.boundary_layer"]))

    def warnings(self):
        """The boundary layer unstable in discrete time: (q + k / phi) h >= 2 (docs/theory.md 6.5)."""
        text = boundary_layer_warning(self.params, self.h)
        return [text] if text else []

    def step(self, x, tau_hat=None):
        x = self.tracked(x)   # the reference state's error coordinates (docs/theory.md 6.11); x itself without motion
        u, _, (sigma, u_eq, u_sw, u_smc) = smc_step(self.pure_params(self.params), self.nominal, self.h, x, 0.0,
                                                    False, self.m)
        return u, {"S1": sigma, "u_dsc": u_smc, "u_taud": 0.0, "u": u}   # u_taud: 0, the term is off

    pure_step = staticmethod(smc_step)

    @staticmethod
    def pure_params(params: SmcGains):
        return tuple(params)

    def summary(self) -> str:
        g = self.params
        return f"s = {g.c1:.5g} theta_b {g.c2:+.5g} theta_b' {g.c3:+.5g} theta_w', q = {g.q}, k = {g.k}, " \
               f"boundary_layer = {g.phi}"

    def design_text(self, values=None):
        return f"SMC surface {self.summary()}"
