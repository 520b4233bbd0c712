"""A law with the observer term: ``u = u_law - u_taud`` (eq. 19), u_taud of eq. (20)-(21).

:func:`with_observer` composes any registered law with the disturbance observer's compensation,
so DSCNDO is DSC plus this term and LQR+NDO is LQR plus the same term; nothing of it is copied
into a law.  The composed law wraps an instance of the law (:meth:`WithObserver.wrap`), so the
controller node switching ``use_observer`` at run time keeps the law's state (the DSC filter).
"""
from __future__ import annotations

import math
from typing import Optional, Type

from ..control.controller import u_taud_of
from .base import Law

__all__ = ["WithObserver", "with_observer"]


class WithObserver(Law):
    """``base`` (a :class:`~mwip_ros.core.laws.Law` class) with the observer term subtracted."""

    base: Type[Law] = Law
    observer = True

    def __init__(self, params, nominal, h: float, m=math):
        self.inner = self.base(params, nominal, h, m)

    @classmethod
    def wrap(cls, inner: Law) -> "WithObserver":
        """The composed law around an existing instance of ``base`` (sharing its state and parameters)."""
        obj = cls.__new__(cls)
        obj.inner = inner
        return obj

    @property
    def params(self):
        return self.inner.params

    @params.setter
    def params(self, value):
        self.inner.params = value

    @property
    def nominal(self):
        return self.inner.nominal

    @classmethod
    def design(cls, values, nominal, h):
        return cls.base.design(values, nominal, h)

    @classmethod
    def stability_margin(cls, nominal, params, X, observer: bool = True) -> float:
        return cls.base.stability_margin(nominal, params, X, observer=True)

    def step(self, x, tau_hat=None):
        """u = u_law - u_taud (eq. 19) with u_taud = tau_hat1 - M_C12 / (m22 + M_C12) tau_hat2 (eq. 20-21); the law
        takes the term in (:meth:`~mwip_ros.core.laws.Law.step_observed`: a law with a limit holds it on u)."""
        p, m = self.inner.nominal, self.inner.m
        u_taud = u_taud_of(p, p.m12 * m.cos(x[1]), tau_hat)   # eq. (20)-(21), M_C12 = m12 cos theta_b
        u, internals = self.inner.step_observed(x, u_taud)     # eq. (19)
        internals["u_taud"], internals["u"] = u_taud, u
        return u, internals

    def track(self, ref) -> None:
        self.inner.track(ref)

    def reset(self) -> None:
        self.inner.reset()

    def elapsed(self, dt: float) -> None:
        self.inner.elapsed(dt)

    def finite(self) -> bool:
        return self.inner.finite()

    def snapshot(self):
        return self.inner.snapshot()

    def restore(self, snap) -> None:
        self.inner.restore(snap)

    def summary(self) -> str:
        return self.inner.summary()

    def design_text(self, values=None) -> Optional[str]:
        return self.inner.design_text(values)

    def warnings(self):
        return self.inner.warnings()


def with_observer(base: Type[Law], name: str, title: Optional[str] = None) -> Type[Law]:
    """The law ``base`` plus the observer term, registered as ``name`` (one class per base and name)."""
    cached = base.__dict__.get("_with_observer")
    if cached is not None and cached.name == name:
        return cached
    extra = tuple(n for n in ("u_taud", "u") if n not in base.internal_names)
    cls = type(f"{base.__name__}WithObserver", (WithObserver,), {
        "base": base, "name": name, "family": base.family or base.name, "title": title or name,
        "param_keys": base.param_keys, "parameters": base.parameters, "Params": base.Params,
        "internal_names": tuple(base.internal_names) + extra, "announce": base.announce,
        "limit_key": base.limit_key,
        "__module__": base.__module__, "__doc__": f"{base.__name__} with the observer term (eq. 19-21)."})
    base._with_observer = cls
    return cls
