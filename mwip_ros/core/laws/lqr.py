"""The law ``lqr``: u = -K [theta_b, theta_b', theta_w'] (the baseline, docs/theory.md 6.1); ``lqr_ndo`` adds
the observer term (:mod:`.ndo`).  The gain is :func:`mwip_ros.core.control.lqr.lqr_gain` of ``lqr.Q``, ``lqr.R``."""
from __future__ import annotations

import math
from typing import NamedTuple, Optional

from ..control.lqr import lqr_gain, lqr_u
from .base import Law
from .dsc import INTERNALS

__all__ = ["LqrGain", "LqrLaw", "lqr_step"]


class LqrGain(NamedTuple):
    """K on [theta_b, theta_b', theta_w']."""

    k_theta_b: float
    k_dtheta_b: float
    k_dtheta_w: float


def lqr_step(P, p, h, x, s, first, m=math):
    """One period of LQR as a pure function (:attr:`~mwip_ros.core.laws.Law.pure_step`): ``P`` = K; no state
    (``s`` is returned as it came).  Returns (u, s, (u, S1 = theta_b))."""
    u = lqr_u(P, x)
    return u, s, (u, x[1])


class LqrLaw(Law):
    """u = -K x (no state)."""

    name = "lqr"
    title = "LQR"
    param_keys = ("lqr.Q", "lqr.R")
    # the layout DSC publishes, so a plot of controller_internals works for every built-in law: u_dsc is
    # -K x, S1 theta_b; S2, x1, x4_bar, x4d (DSC's own) are NaN
    internal_names = INTERNALS
    Params = LqrGain
    announce = True

    @classmethod
    def design(cls, values, nominal, h) -> LqrGain:
        """K for the nominal model at period ``h``; :class:`~mwip_ros.core.control.lqr.LqrDesignError` names lqr.Q or
        lqr.R when there is none."""
        return LqrGain(*lqr_gain(nominal, h, values["lqr.Q"], values["lqr.R"]))

    def step(self, x, tau_hat=None):
        x = self.tracked(x)   # the reference state's error coordinates (docs/theory.md 6.11); x itself without motion
        u, _, (u_lqr, S1) = lqr_step(self.params, self.nominal, self.h, x, 0.0, False, self.m)
        return u, {"u_dsc": u_lqr, "u_taud": 0.0, "S1": S1, "u": u}   # u_taud: 0, off

    pure_step = staticmethod(lqr_step)
    pure_lanes = 3   # P = K

    @staticmethod
    def pure_params(params: LqrGain):
        return tuple(params)

    def design_text(self, values=None) -> Optional[str]:
        K = self.params
        text = f"LQR gain K = [{K[0]:.6g}, {K[1]:.6g}, {K[2]:.6g}] on [theta_b, theta_b', theta_w']"
        if values is None:
            return text
        return f"{text} (lqr.Q = {values['lqr.Q']}, lqr.R = {values['lqr.R']:g})"
