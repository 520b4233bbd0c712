"""Theorem 2 stability conditions (eq. 34-35), nominal values throughout.

The conditions fall in two halves: a1..a3 constrain the controller's gains
(k1, k2, tau4) and a4, a5 the observer's gain X.  Each node checks its own half
(:func:`controller_conditions`, :func:`observer_conditions`); the offline tools
check both (:func:`theorem2`).
"""
from __future__ import annotations

from dataclasses import dataclass

from .controller import DscGains
from ..plants.model import PhysicalParams

__all__ = ["ControllerConditions", "ObserverConditions", "Theorem2", "controller_conditions",
           "observer_conditions", "theorem2"]


def _ratio(p: PhysicalParams) -> float:
    return (p.m11 + p.m12) / p.m22


@dataclass(frozen=True)
class ControllerConditions:
    """a1..a3 of eq. (35): the DSC gains' half of Theorem 2."""

    a1: float
    a2: float
    a3: float

    @property
    def satisfied(self) -> bool:
        return min(self.a1, self.a2, self.a3) > 0.0


@dataclass(frozen=True)
class ObserverConditions:
    """a4, a5 of eq. (35): the observer gain's half of Theorem 2."""

    a4: float
    a5: float

    @property
    def satisfied(self) -> bool:
        return min(self.a4, self.a5) > 0.0


def controller_conditions(nominal: PhysicalParams, gains: DscGains) -> ControllerConditions:
    """a1, a2, a3 of eq. (35) for the gains (k1, k2, tau4)."""
    r = _ratio(nominal)
    return ControllerConditions(
        a1=gains.k1 - r,                                   # eq. (35)
        a2=gains.k2 - gains.k1 / 2 - r / 2,                # eq. (35)
        a3=1.0 / gains.tau4 - 3 * gains.k1 / 2 - r / 2)    # eq. (35)


def observer_conditions(nominal: PhysicalParams, X) -> ObserverConditions:
    """a4, a5 of eq. (35) for X = [[c1, c2], [c3, c4]]."""
    p = nominal
    (c1, c2), (c3, c4) = X
    return ObserverConditions(
        a4=c1 / p.m11 - (p.m11 + p.m12) * c2 / p.A_bar - 1,  # eq. (35)
        a5=c4 / p.m22 - p.m12 * c3 / p.A_bar - 1)            # eq. (35)


@dataclass(frozen=True)
class Theorem2:
    a1: float
    a2: float
    a3: float
    a4: float
    a5: float

    @property
    def gamma(self) -> float:
        return min(self.a1, self.a2, self.a3, self.a4, self.a5)  # eq. (34)

    @property
    def satisfied(self) -> bool:
        return self.gamma > 0.0

    def as_dict(self) -> dict:
        return {"a1": self.a1, "a2": self.a2, "a3": self.a3, "a4": self.a4, "a5": self.a5,
                "gamma": self.gamma}


def theorem2(nominal: PhysicalParams, gains: DscGains, X) -> Theorem2:
    """a1..a5 of eq. (35): both halves, for gains (k1, k2, tau4) and X."""
    c, o = controller_conditions(nominal, gains), observer_conditions(nominal, X)
    return Theorem2(a1=c.a1, a2=c.a2, a3=c.a3, a4=o.a4, a5=o.a5)
