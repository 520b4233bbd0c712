"""Laws that go wrong, registered by tests as test/trivial_law.py is (imported, or ``MWIP_ROS_LAWS=bad_laws`` with
this directory on ``PYTHONPATH``): what a verdict must never score as upright.

Each is ``u = k theta_b`` (:mod:`trivial_law`'s law, which balances the paper's robot) until step ``AFTER``, then:

* ``nan_cmd``: u = NaN;
* ``huge_cmd``: u = 1e300 (finite, absurd: no drive has it, and eq. 1 overflows on it in a period or two);
* ``raising``: its step raises ``RuntimeError("raising law's own error")`` (a bug in a plug-in); written for one
  scenario (``if ... abs(x[1]) < 10``), so over a batch's arrays numpy raises first (an ambiguous truth value).

``nan_cmd`` and ``huge_cmd`` have a pure form (``pure_step``), so the batch runs them compiled too; ``raising``
has none (the batch runs it over numpy arrays).
"""
from __future__ import annotations

import math
from typing import NamedTuple

from mwip_ros.core.laws import Law, register

AFTER = 100   # the first step that goes wrong: t = AFTER h (0.5 s at the paper's 200 Hz)
K = 2000.0    # N m/rad, trivial_law's default


class BadParams(NamedTuple):
    k: float
    after: float
    value: float


def bad_step(P, p, h, x, s, first, m=math):
    """The period as a pure function: ``s`` counts the steps taken; from step ``P[1]`` on the command is ``P[2]``."""
    n = 0.0 if first else s
    u = P[2] if n >= P[1] else P[0] * x[1]
    return u, n + 1.0, (u,)


class _BadLaw(Law):
    value = math.nan
    internal_names = ("u",)
    Params = BadParams

    @classmethod
    def design(cls, values, nominal, h):
        return BadParams(K, float(AFTER), cls.value)

    def __init__(self, params, nominal, h, m=math):
        super().__init__(params, nominal, h, m)
        self.s, self.first = 0.0, True

    def reset(self):
        self.s, self.first = 0.0, True

    def step(self, x, tau_hat=None):
        u, self.s, _ = bad_step(self.params, self.nominal, self.h, x, self.s, self.first, self.m)
        self.first = False
        return u, {"u": u}

    pure_step = staticmethod(bad_step)

    @staticmethod
    def pure_params(params):
        return tuple(params)


class NanLaw(_BadLaw):
    name = "nan_cmd"
    value = math.nan


class HugeLaw(_BadLaw):
    name = "huge_cmd"
    value = 1e300


class RaisingLaw(Law):
    name = "raising"
    internal_names = ("u",)
    Params = BadParams

    @classmethod
    def design(cls, values, nominal, h):
        return BadParams(K, float(AFTER), 0.0)

    def __init__(self, params, nominal, h, m=math):
        super().__init__(params, nominal, h, m)
        self.n = 0

    def step(self, x, tau_hat=None):
        self.n += 1
        if self.n > AFTER and abs(x[1]) < 10.0:   # written for one scenario: over arrays, numpy's ValueError
            raise RuntimeError("raising law's own error")
        u = self.params.k * x[1]
        return u, {"u": u}


register(NanLaw)
register(HugeLaw)
register(RaisingLaw)
