"""Dynamic surface controller (eq. 16-28) and the DSCNDO law (eq. 19-21).

All model terms use the *nominal* parameters.  ``dsc_law`` is a pure function of
one :class:`~mwip_ros.core.plants.model.State`; ``DscController`` adds the first-order
filter (eq. 25) advanced exactly once per control period (docs/theory.md).
The law every caller steps is :class:`mwip_ros.core.laws.dsc.DscLaw` (these functions, and the
observer term composed by :mod:`mwip_ros.core.laws.ndo`); ``DscController`` and
``ControlOutput`` stay for the tests of the equations.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

from ..plants.model import PhysicalParams

__all__ = ["INTERNALS", "DscGains", "ControlOutput", "u_taud_of", "x4_bar_of", "dsc_law", "dsc_terms",
           "dsc_terms_tracking", "filter_step", "DscController"]

# The names of controller_internals (its JointState's joints, docs/graph.md) of DSC and DSCNDO, LQR, SMC and MPC:
# fields of :class:`ControlOutput`
INTERNALS = ("S1", "S2", "x4d", "x4_bar", "u_dsc", "u_taud", "u", "x1")


@dataclass(frozen=True)
class DscGains:
    """The DSC gains; their values (the paper's 6, 6, 0.1) live in the parameter schema."""

    k1: float     # first surface gain, eq. (24)
    k2: float     # second surface gain, eq. (28)
    tau4: float   # filter time constant [s], eq. (25)


@dataclass(frozen=True)
class ControlOutput:
    """Everything the law computed for one state (published as controller internals)."""

    u: float        # applied command, eq. (19)
    u_dsc: float    # the law's own command before the observer term: eq. (28) for DSC, -K x for LQR
    u_taud: float   # observer compensation, eq. (20)-(21); 0 for plain DSC
    S1: float       # eq. (22)
    S2: float       # eq. (26)
    x1: float       # eq. (16)
    x4_bar: float   # virtual control, eq. (24)
    x4d: float      # filtered virtual control used at this step, eq. (25)


def u_taud_of(nominal: PhysicalParams, mc, tau_hat):
    """The observer's compensation u_taud for M_C12 = ``mc`` (m12 cos theta_b) and the estimate ``tau_hat``."""
    return tau_hat[0] - mc / (nominal.m22 + mc) * tau_hat[1]  # eq. (20)-(21), fix: uses tau_hat1


def x4_bar_of(nominal: PhysicalParams, k1: float, S1: float, x1: float, mc: float, dxd: float) -> float:
    """Virtual control x4_bar (eq. 24) for the surface S1 = x2 - x_d (eq. 22; x_d = 0 in the paper) and M_C12 = ``mc``
    (m12 cos theta_b); ``dxd`` is x_d' (0 in the paper; - 0.0 changes no bit): S1' = -k1 S1 when x4 = x4_bar
    (docs/theory.md 6.11)."""
    return (nominal.m22 + mc) / (nominal.m11 + mc) * (x1 / (nominal.m22 + mc) + k1 * S1 - dxd)


def dsc_law(nominal: PhysicalParams, gains: DscGains, x, x4d: Optional[float], tau_hat=None,
            m=math) -> ControlOutput:
    """u = u_DSC - u_taud for the state ``x``; ``x4d=None`` means the first step (x4d(0) = x4_bar(0)).

    ``tau_hat=None`` is plain DSC (observer term off); ``m`` the math namespace (``numpy``
    for arrays of scenarios).
    """
    first = x4d is None
    u_dsc, S1, S2, x1, x4_bar, x4d = dsc_terms(nominal, gains.k1, gains.k2, gains.tau4, x, 0.0 if first else x4d,
                                               first, m)
    u_taud = 0.0 if tau_hat is None else u_taud_of(nominal, nominal.m12 * m.cos(x[1]), tau_hat)
    return ControlOutput(u=u_dsc - u_taud, u_dsc=u_dsc, u_taud=u_taud, S1=S1, S2=S2,
                         x1=x1, x4_bar=x4_bar, x4d=x4d)     # eq. (19)


def dsc_terms(nominal, k1, k2, tau4, x, x4d, first, m=math):
    """(u_DSC, S1, S2, x1, x4_bar, x4d) of eq. (16)-(28) for the state ``x``; ``first``: x4d(0) = x4_bar(0)
    (``x4d`` is then ignored).  A pure function of numbers (``core.kernels.compiled`` compiles it for the batch): the
    paper's surfaces, :func:`dsc_terms_tracking` with x_d = x_d' = 0 (the same bits: x2 - 0.0 is x2)."""
    return dsc_terms_tracking(nominal, k1, k2, tau4, x, x4d, first, 0.0, 0.0, m)


def dsc_terms_tracking(nominal, k1, k2, tau4, x, x4d, first, xd, dxd, m=math):
    """:func:`dsc_terms` with the first surface tracking the lean reference ``xd`` (x_d' = ``dxd``): S1 = x2 - x_d
    (eq. 22 with a reference, docs/theory.md 6.11) and x4_bar with -x_d' (eq. 24); the rest is eq. (25)-(28)."""
    p = nominal
    _, x2, x4, x3 = x                            # x2 = theta_b, x3 = theta_b', x4 = theta_w' (eq. 16)
    mc = p.m12 * m.cos(x2)                       # M_C12
    sb = m.sin(x2)
    gs = p.G_b * sb                              # G_S2
    A = p.m11 * p.m22 - mc ** 2
    x1 = (p.m11 + mc) * x4 + (p.m22 + mc) * x3   # eq. (16)
    S1 = x2 - xd                                 # eq. (22); x_d = 0 in the paper
    x4_bar = x4_bar_of(p, k1, S1, x1, mc, dxd)   # eq. (24)
    if first:
        x4d = x4_bar                             # eq. (25) initial condition
    S2 = x4 - x4d                                # eq. (26)
    u_dsc = (A / (p.m22 + mc) * ((x4_bar - x4d) / tau4 - k2 * S2)
             - p.m12 * p.m22 * sb * (x1 - (p.m11 + mc) * x4) ** 2 / (p.m22 + mc) ** 3
             + mc * gs / (p.m22 + mc))           # eq. (28)
    return u_dsc, S1, S2, x1, x4_bar, x4d


def filter_step(x4d: float, x4_bar: float, h: float, tau4: float, m=math) -> float:
    """Exact discretisation of tau4 x4d' + x4d = x4_bar over one period with x4_bar held."""
    return x4_bar + (x4d - x4_bar) * m.exp(-h / tau4)


@dataclass
class DscController:
    """DSC (``use_observer=False``) or DSCNDO, stepping the filter once per call."""

    nominal: PhysicalParams
    gains: DscGains
    h: float
    use_observer: bool = True
    x4d: Optional[float] = None
    m: object = math     # numpy to step a batch of scenarios (array gains and states)

    def step(self, x, tau_hat=None) -> ControlOutput:
        out = dsc_law(self.nominal, self.gains, x, self.x4d, tau_hat if self.use_observer else None, self.m)
        self.x4d = filter_step(out.x4d, out.x4_bar, self.h, self.gains.tau4, self.m)
        return out
