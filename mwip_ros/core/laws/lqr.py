"""The law ``lqr``: u = -K [theta_b, theta_b', theta_w'] (the baseline, docs/theory.md 6.1); ``lqr_ndo`` adds
the observer term (:mod:`.ndo`).  The gain is :func:`mwip_ros.core.lqr.lqr_gain` of ``lqr.Q``, ``lqr.R``."""
from __future__ import annotations

from typing import NamedTuple, Optional

from ..lqr import lqr_gain, lqr_law
from . import Law
from .dsc import INTERNALS

__all__ = ["LqrGain", "LqrLaw"]


class LqrGain(NamedTuple):
    """K on [theta_b, theta_b', theta_w']."""

    k_theta_b: float
    k_dtheta_b: float
    k_dtheta_w: float


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
        """K for the nominal model at period ``h``; :class:`~mwip_ros.core.lqr.LqrDesignError` names lqr.Q or
        lqr.R when there is none."""
        return LqrGain(*lqr_gain(nominal, h, values["lqr.Q"], values["lqr.R"]))

    def step(self, x, tau_hat=None):
        out = lqr_law(self.nominal, self.params, x, None, self.m)
        return out.u, {"u_dsc": out.u_dsc, "u_taud": out.u_taud, "S1": out.S1, "u": out.u}   # u_taud: 0, off

    def design_text(self, values=None) -> Optional[str]:
        K = self.params
        text = f"LQR gain K = [{K[0]:.6g}, {K[1]:.6g}, {K[2]:.6g}] on [theta_b, theta_b', theta_w']"
        if values is None:
            return text
        return f"{text} (lqr.Q = {values['lqr.Q']}, lqr.R = {values['lqr.R']:g})"
