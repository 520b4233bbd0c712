"""State estimators: the raw sensors (:mod:`..raw_sensors`) to the state the observer and the law consume.

docs/theory.md 6.4.  An estimator is a class (:class:`Estimator`) with its own
parameters, a ``reset`` and a ``step`` from one :class:`~..raw_sensors.RawSample` to the estimated
:class:`~..model.State`; its period is one pure function of numbers (:attr:`Estimator.pure_step`), which
``step`` calls and the batch simulator can compile with numba.  ``theta_b`` and ``theta_b'`` come from the
IMU; ``theta_w = phi + theta_b`` and ``theta_w' = phi' + theta_b'`` from the encoder.

* :func:`get` returns an estimator class by its name (the ``state_estimator`` parameter ``method``),
  :func:`names` lists them; :func:`register` adds one.

Today's estimators: ``complementary`` (:mod:`.complementary`) and ``kalman`` (:mod:`.kalman`).
"""
from __future__ import annotations

from typing import Any, Dict, NamedTuple, Tuple, Type, TypeVar

from . import complementary, kalman
from .base import NIS_WINDOW_S, Estimator, EstimatorParam, Health

__all__ = ["EstimatorParam", "Health", "Estimator", "EstimatorConfig", "register", "get", "names", "NIS_WINDOW_S"]

class EstimatorConfig(NamedTuple):
    """The ``state_estimator``'s choice, as plain data: its ``method``, its parameter values (``(name, value)``
    pairs, every method's: :meth:`Estimator.checked` takes its own) and the IMU offset it believes [m]."""

    method: str
    values: Tuple[Tuple[str, Any], ...]
    imu_offset: float

    def make(self, h: float, r: float, g: float) -> "Estimator":
        """The estimator for period ``h``, the nominal wheel radius ``r`` and gravity ``g``."""
        return get(self.method)(dict(self.values), h, r, self.imu_offset, g)


_ESTIMATORS: Dict[str, Type[Estimator]] = {}
_E = TypeVar("_E", bound=Type[Estimator])


def register(cls: _E) -> _E:
    """Register ``cls`` under ``cls.name`` (the same class again is allowed, another under a taken name not)."""
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no name")
    old = _ESTIMATORS.get(cls.name)
    if old is not None and old is not cls:
        raise ValueError(f"an estimator named {cls.name!r} is registered already ({old.__module__}.{old.__name__})")
    cls.title = cls.title or cls.name
    _ESTIMATORS[cls.name] = cls
    return cls


def get(method: str) -> Type[Estimator]:
    """The estimator registered as ``method``; KeyError naming the known ones."""
    try:
        return _ESTIMATORS[method]
    except KeyError:
        raise KeyError(f"unknown state estimator {method!r}; known: {', '.join(names())}") from None


def names() -> Tuple[str, ...]:
    """Every registered estimator's name, in registration order."""
    return tuple(_ESTIMATORS)


def _builtins() -> None:
    register(complementary.ComplementaryFilter)
    register(kalman.KalmanFilter)


_builtins()
