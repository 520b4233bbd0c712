"""What a state estimator is (:class:`Estimator`, its parameters :class:`EstimatorParam`, its :class:`Health`):
below the estimators (:mod:`.complementary`, :mod:`.kalman`) and
the registry (the package, :mod:`mwip_ros.core.estimators`, which re-exports these names), so the estimators import
this module and the registry imports them, and nothing imports back.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Dict, Mapping, NamedTuple, Optional, Tuple

from ..plants.model import State

__all__ = ["EstimatorParam", "Health", "Estimator", "NIS_WINDOW_S"]

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
