"""Theorem 2 stability conditions (eq. 34-35), nominal values throughout."""
from __future__ import annotations

from dataclasses import dataclass

from mwip_ros.controller import DscGains
from mwip_ros.model import PhysicalParams


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
    """a1..a5 of eq. (35) for gains (k1, k2, tau4) and X = [[c1, c2], [c3, c4]]."""
    p = nominal
    (c1, c2), (c3, c4) = X
    r = (p.m11 + p.m12) / p.m22
    return Theorem2(
        a1=gains.k1 - r,
        a2=gains.k2 - gains.k1 / 2 - r / 2,
        a3=1.0 / gains.tau4 - 3 * gains.k1 / 2 - r / 2,
        a4=c1 / p.m11 - (p.m11 + p.m12) * c2 / p.A_bar - 1,
        a5=c4 / p.m22 - p.m12 * c3 / p.A_bar - 1,
    )
