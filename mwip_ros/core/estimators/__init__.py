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

import math
from typing import Any, Callable, Dict, Mapping, NamedTuple, Optional, Tuple, Type, TypeVar

from ..model import State

__all__ = ["EstimatorParam", "Health", "Estimator", "EstimatorConfig", "register", "get", "names", "NIS_WINDOW_S"]

NIS_WINDOW_S = 1.0   # time constant [s] of the running mean of the normalized innovation squared (health)


class EstimatorParam(NamedTuple):
    """A ``state_estimator`` parameter an estimator declares (plain data, the fields of
    :class:`mwip_ros.core.laws.LawParam`)."""

    name: str                     # dotted parameter name, e.g. 'complementary.tau'
    type: str                     # ROS type: 'double', 'integer', 'bool', 'string'
    default: Any
    description: str
    lo: Optional[float] = None    # lo <= value (numbers), None: unbounded
    hi: Optional[float] = None    # value <= hi


class EstimatorConfig(NamedTuple):
    """The ``state_estimator``'s choice, as plain data: its ``method``, its parameter values (``(name, value)``
    pairs, every method's: :meth:`Estimator.checked` takes its own) and the IMU offset it believes [m]."""

    method: str
    values: Tuple[Tuple[str, Any], ...]
    imu_offset: float

    def make(self, h: float, r: float, g: float) -> "Estimator":
        """The estimator for period ``h``, the nominal wheel radius ``r`` and gravity ``g``."""
        return get(self.method)(dict(self.values), h, r, self.imu_offset, g)


class Health(NamedTuple):
    """How an estimator's last step went (the pure step's health tuple)."""

    innovation: float   # the measurement minus its prediction (complementary: accelerometer pitch [rad];
                        # kalman: encoder angle [rad])
    nis: float          # its normalized innovation squared (about 1 when the filter's statistics hold)
    nis_mean: float     # the running mean of ``nis`` over NIS_WINDOW_S (exponential)
    diverged: bool      # the estimate is not to be trusted (each estimator's criteria, docs/theory.md 6.4)


class Estimator:
    """One state estimator: its parameters, its state, one step per raw sample.

    Attributes
    ----------
    name : str
        The registered name (the ``state_estimator`` parameter ``method``).
    title : str
        The name in log lines.
    parameters : tuple of EstimatorParam
        Its ``state_estimator`` parameters, named ``<name>.<key>``.
    pure_step : function
        The period as a pure function, ``pure_step(P, dt, sample, s, first, m=math)`` -> ``(estimate, s_next,
        health)``: ``P`` the numbers :meth:`pure_params` makes, ``dt`` the time since the last sample [s] (the
        period h, or a multiple of it when samples were lost), ``sample`` the 5 floats of a
        :class:`~..raw_sensors.RawSample`, ``s`` the flat tuple of floats of the state (ignored when ``first``,
        the first sample), ``estimate`` (theta_w, theta_b, theta_w', theta_b'), ``health`` the fields of
        :class:`Health`.  numba compiles it as is (``numba.njit(error_model="numpy")``).
    state_size : int
        The length of the state tuple ``s``.
    """

    name: str = ""
    title: str = ""
    parameters: Tuple[EstimatorParam, ...] = ()
    pure_step: Optional[Callable[..., Any]] = None
    state_size: int = 0

    def __init__(self, params: Optional[Mapping[str, Any]], h: float, r: float, d: float, g: float):
        """``params``: parameter values by name (``<name>.<key>``; a missing one takes its default, an unknown
        or out-of-range one is a ValueError naming it); ``h`` the period [s]; ``r`` the nominal wheel radius
        [m], ``d`` the IMU offset [m], ``g`` gravity [m/s^2]."""
        self.values = self.checked(params or {})
        self.h, self.r, self.d, self.g = float(h), float(r), float(d), float(g)
        self.P = self.pure_params(self.values, self.r, self.d, self.g)
        self.reset()

    @classmethod
    def defaults(cls) -> Dict[str, Any]:
        return {p.name: p.default for p in cls.parameters}

    @classmethod
    def checked(cls, params: Mapping[str, Any]) -> Dict[str, Any]:
        """Every parameter's value: ``params`` over the defaults; ValueError names an unknown key or a value
        outside its range."""
        known = {p.name: p for p in cls.parameters}
        prefix = f"{cls.name}."
        out = cls.defaults()
        for key, value in params.items():
            if not key.startswith(prefix):
                continue   # another method's parameter (the node declares them all)
            if key not in known:
                raise ValueError(f"unknown {cls.name} parameter {key!r}; known: {', '.join(known)}")
            spec = known[key]
            if spec.type in ("double", "integer"):
                value = float(value) if spec.type == "double" else int(value)
                if not math.isfinite(value) or (spec.lo is not None and value < spec.lo) or \
                        (spec.hi is not None and value > spec.hi):
                    raise ValueError(f"{key} = {value!r} is outside [{spec.lo}, {spec.hi}]")
            out[key] = value
        return out

    @staticmethod
    def pure_params(values: Mapping[str, Any], r: float, d: float, g: float) -> tuple:
        """The numbers ``pure_step`` reads as ``P`` (floats, in a fixed order) from the parameter values."""
        raise NotImplementedError

    def reset(self) -> None:
        """Forget the past: the next sample is a first sample."""
        self.s = (0.0,) * self.state_size
        self.first = True
        self.health = Health(0.0, 0.0, 0.0, False)

    def step(self, sample, dt: Optional[float] = None) -> State:
        """The estimated state at the sample's instant, ``dt`` [s] after the last sample (the period ``h`` when
        None: no sample lost between them); :attr:`health` tells how the step went."""
        pure_step = type(self).pure_step
        if pure_step is None:   # the same TypeError as calling None, naming the class
            raise TypeError(f"{type(self).__name__} has no pure_step")
        est, self.s, health = pure_step(self.P, self.h if dt is None else dt, tuple(sample), self.s, self.first)
        self.first = False
        self.health = Health(*health)
        return State(*est)

    @property
    def diverged(self) -> bool:
        return self.health.diverged

    def snapshot(self):
        return self.s, self.first, self.health

    def restore(self, snap) -> None:
        self.s, self.first, self.health = snap


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
    from . import complementary, kalman
    register(complementary.ComplementaryFilter)
    register(kalman.KalmanFilter)


_builtins()
