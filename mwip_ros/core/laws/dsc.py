"""The law ``dsc``: the dynamic surface controller (eq. 16-28); ``dscndo`` is it with the observer term.

The equations are :func:`mwip_ros.core.control.controller.dsc_law` (u_DSC of eq. 28, with S1, x4_bar, S2 of
eq. 22-26) and :func:`~mwip_ros.core.control.controller.filter_step` (eq. 25, exact over one period);
this module only holds the filter state x4d between steps.  u_taud (eq. 20) is added by
:mod:`.ndo`, not here.
"""
from __future__ import annotations

import math
from typing import List

from ..control.controller import INTERNALS, DscGains, dsc_terms, dsc_terms_tracking, filter_step
from ..control.motion import rate_reference
from ..control.observer import substeps
from .base import Law

__all__ = ["DscLaw", "INTERNALS", "dsc_step", "dsc_track_step", "lean_reference"]


def dsc_step(P, p, h, x, s, first, m=math):
    """One period of DSC as a pure function (:attr:`~mwip_ros.core.laws.Law.pure_step`): ``P`` = (k1, k2, tau4),
    ``s`` the filter state x4d (ignored when ``first``).  Returns (u, the next x4d, (S1, S2, x4d, x4_bar, u_dsc,
    x1)): u_DSC (eq. 28) with the current x4d, then x4d advanced over one period (eq. 25)."""
    u_dsc, S1, S2, x1, x4_bar, x4d = dsc_terms(p, P[0], P[1], P[2], x, s, first, m)
    return u_dsc, filter_step(x4d, x4_bar, h, P[2], m), (S1, S2, x4d, x4_bar, u_dsc, x1)


def lean_reference(ref, x, m=math):
    """The outer loop's lean reference before its filter, x_d_bar = -k_x e with the wheel error
    e = (theta_w' - theta_w'*) + lambda (theta_w - theta_w*) (docs/theory.md 6.11)."""
    return -ref.lean_gain * (x[2] - rate_reference(ref, x[0]))


def dsc_track_step(P, p, h, x, s, xd, first, ref, m=math):
    """One period of DSC tracking the motion reference ``ref`` as a pure function (:attr:`~mwip_ros.core.laws.Law.
    pure_track`, docs/theory.md 6.11): ``s`` the filter state x4d, ``xd`` the outer loop's filtered lean reference
    x_d (both ignored when ``first``).  x_d_bar = -k_x e (:func:`lean_reference`) through the filter of eq. (25),
    tau4 x_d' + x_d = x_d_bar, so x_d' = (x_d_bar - x_d) / tau4 exactly; then eq. (22)-(28) with S1 = x2 - x_d and
    x4_bar's -x_d', and both filters advanced over the period.  Returns (u, the next x4d, the next x_d, (S1, S2,
    x4d, x4_bar, u, x1))."""
    tau4 = P[2]
    xd_bar = lean_reference(ref, x, m)
    if first:
        xd = xd_bar
    dxd = (xd_bar - xd) / tau4
    u, S1, S2, x1, x4_bar, x4d = dsc_terms_tracking(p, P[0], P[1], tau4, x, s, first, xd, dxd, m)
    return u, filter_step(x4d, x4_bar, h, tau4, m), filter_step(xd, xd_bar, h, tau4, m), (S1, S2, x4d, x4_bar, u,
                                                                                          x1)


class DscLaw(Law):
    """DSC: u = u_DSC (eq. 28) with the filter tau4 x4d' + x4d = x4_bar (eq. 25) stepped once per period."""

    name = "dsc"
    title = "DSC"
    param_keys = ("k1", "k2", "tau4")
    internal_names = INTERNALS
    Params = DscGains

    def __init__(self, params: DscGains, nominal, h: float, m=math):
        super().__init__(params, nominal, h, m)
        self.x4d = None   # None: the next step is the first, x4d(0) = x4_bar(0) (eq. 25)
        self.xd = None    # the outer loop's filtered lean reference x_d (motion only; None: x_d(0) = x_d_bar(0))
        self.last = None  # the state of the last step: held over the periods a gap skipped (:meth:`elapsed`)
        self.skipped = 0  # whole periods the next step comes late by (:meth:`elapsed`)

    @classmethod
    def design(cls, values, nominal, h) -> DscGains:
        return DscGains(k1=values["k1"], k2=values["k2"], tau4=values["tau4"])

    @classmethod
    def stability_margin(cls, nominal, params, X, observer: bool = False) -> float:
        """Theorem 2's gamma (eq. 34-35); without the observer term its controller half min(a1, a2, a3)."""
        from ..control.theorem import controller_conditions, theorem2
        if observer:
            return theorem2(nominal, params, X).gamma
        return min(vars(controller_conditions(nominal, params)).values())

    def reset(self) -> None:
        self.x4d = None
        self.xd = None
        self.last = None
        self.skipped = 0

    def elapsed(self, dt: float) -> None:
        """The next step comes ``dt`` after the last one, not one period: each step advanced its filters over one
        period (eq. 25), so the next one first advances them over the periods the gap skipped, one period at a time
        with the last step's state held (what the law stepped every period would do with that state repeated; DSC's
        x4_bar follows x_d while it tracks, so the cascade is stepped, not solved at once)."""
        self.skipped = substeps(dt, self.h) - 1   # the observer's count of periods (core.control.observer)

    def _catch_up(self) -> None:
        """The filters over the periods :meth:`elapsed` said were skipped (eq. 25; with a reference, x_d's too)."""
        n, self.skipped = self.skipped, 0
        if not n or self.x4d is None or self.last is None:
            return
        P, x = self.pure_params(self.params), self.last
        for _ in range(n):
            if self.ref is not None and self.xd is not None:
                _u, self.x4d, self.xd, _i = dsc_track_step(P, self.nominal, self.h, x, self.x4d, self.xd, False,
                                                            self.ref, self.m)
            else:
                _u, self.x4d, _i = dsc_step(P, self.nominal, self.h, x, self.x4d, False, self.m)

    def step(self, x, tau_hat=None):
        """u_DSC (eq. 28) for ``x`` with the current x4d, then x4d advanced over one period (eq. 25); with a motion
        reference (:meth:`track`) the surfaces track the outer loop's lean x_d (:meth:`_step_tracking`)."""
        self._catch_up()
        first = self.x4d is None
        if self.ref is not None:
            return self._step_tracking(x, first)
        u, self.x4d, (S1, S2, x4d, x4_bar, u_dsc, x1) = dsc_step(self.pure_params(self.params), self.nominal, self.h,
                                                                 x, 0.0 if first else self.x4d, first, self.m)
        self.last = x
        return u, {"S1": S1, "S2": S2, "x4d": x4d, "x4_bar": x4_bar, "u_dsc": u_dsc,
                   "u_taud": 0.0, "u": u, "x1": x1}   # u_taud: 0, the term is off

    def _step_tracking(self, x, first):
        """The surfaces track x_d (docs/theory.md 6.11): :func:`dsc_track_step`, x_d(0) = x_d_bar(0) at the first
        step that has a reference (a first step, or a reference that came later)."""
        xd = lean_reference(self.ref, x, self.m) if self.xd is None else self.xd
        u, self.x4d, self.xd, (S1, S2, x4d, x4_bar, u_dsc, x1) = dsc_track_step(
            self.pure_params(self.params), self.nominal, self.h, x, 0.0 if first else self.x4d, xd, first, self.ref,
            self.m)
        self.last = x
        return u, {"S1": S1, "S2": S2, "x4d": x4d, "x4_bar": x4_bar, "u_dsc": u, "u_taud": 0.0, "u": u, "x1": x1}

    pure_step = staticmethod(dsc_step)
    pure_track = staticmethod(dsc_track_step)
    pure_lanes = 3   # P = (k1, k2, tau4)

    @staticmethod
    def pure_params(params: DscGains):
        return params.k1, params.k2, params.tau4

    def finite(self) -> bool:
        return all(s is None or bool(math.isfinite(s)) for s in (self.x4d, self.xd))

    def summary(self) -> str:
        g = self.params
        return f"k1 = {g.k1}, k2 = {g.k2}, tau4 = {g.tau4}"

    def warnings(self) -> List[str]:
        from ..control.theorem import controller_conditions
        th = controller_conditions(self.nominal, self.params)
        if th.satisfied:
            return []
        return [f"gains break Theorem 2 (eq. 35): a1 = {th.a1:.4f}, a2 = {th.a2:.4f}, a3 = {th.a3:.4f} (all must "
                "be > 0); allowed, but stability is not guaranteed. Run mwip_theorem for a1..a5"]
