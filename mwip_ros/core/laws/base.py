"""What a control law is (:class:`Law`, its parameters :class:`LawParam`) and the errors of running one
(:class:`LawError`, :class:`PluginError`): below the laws (:mod:`.dsc`, :mod:`.lqr`, :mod:`.smc`, :mod:`.mpc`,
:mod:`.ndo`) and the registry (the package, :mod:`mwip_ros.core.laws`, which re-exports these names), so the laws
import this module and the registry imports the laws, and nothing imports back.
"""
from __future__ import annotations

import math
from typing import Any, Callable, List, Mapping, NamedTuple, Optional, Tuple, Type

from ..control.motion import error_state

__all__ = ["Law", "LawParam", "LawError", "PluginError"]


class LawParam(NamedTuple):
    """A ``dscndo_controller`` parameter a law declares itself (plain data: ``params.schema`` makes its
    ParamSpec).  The built-in laws' parameters are in the schema already and only named in ``param_keys``."""

    name: str                     # dotted parameter name, e.g. 'trivial.k'
    type: str                     # ROS type: 'double', 'integer', 'bool', 'string', 'double_array'
    default: Any
    description: str
    lo: Optional[float] = None    # lo <= value (numbers), None: unbounded
    hi: Optional[float] = None    # value <= hi


class Law:
    """One control law: its parameters, its state, and one step per control period.

    A subclass sets the class attributes and implements :meth:`design`, :meth:`__init__` (when it keeps
    state), :meth:`reset` and :meth:`step`; the rest has defaults.  ``m`` is the math namespace: ``math``
    for one scenario, ``numpy`` (the batch's) for arrays of scenarios, whose parameters then hold arrays.

    Attributes
    ----------
    name : str
        The registered name (``mwip_sim --controller``, a sweep's ``controllers``).
    family : str
        The node's ``law`` parameter value; the law and its observer variant share it.
    observer : bool
        True when the law uses the estimate tau_hat (the node then waits for it).
    title : str
        The name in log lines ('DSCNDO').
    param_keys : tuple of str
        The ``dscndo_controller`` parameters :meth:`design` reads (a change re-designs the law at run time).
    parameters : tuple of LawParam
        The parameters the law declares itself (a plug-in's own keys); the schema adds them to the node.
    internal_names : tuple of str
        The names on ``controller_internals`` in order; a name the step's internals lack is published NaN.
    Params : type
        A frozen dataclass of numbers, what :meth:`design` returns (the batch stacks its fields).
    announce : bool
        Log :meth:`design_text` at start-up even when the law is not in use.
    pure_step : function or None
        The law's period as a pure function of numbers, ``pure_step(P, nominal, h, x, s, first, m=math)`` ->
        ``(u, s_next, internals tuple)``: ``P`` the numbers :meth:`pure_params` makes of the parameters,
        ``nominal`` anything with ``m11``, ``m12``, ``m22``, ``G_b``, ``s`` one float of state (ignored when
        ``first``, the first step).  When a law has one, its :meth:`step` calls it, and the batch simulator runs
        it compiled by numba inside one compiled loop (``core.kernels.compiled``); None: the batch runs :meth:`step`
        over numpy arrays.
    pure_track : function or None
        The law's period tracking a motion reference (docs/theory.md 6.11) as a pure function, ``pure_track(P,
        nominal, h, x, s, s2, first, ref, m=math)`` -> ``(u, s_next, s2_next, internals tuple)`` with a second float
        of state ``s2`` (DSC's x_d); None (the default): ``pure_step`` on the error state (:meth:`tracked`), as
        :meth:`step` does.  The compiled batch runs it (``core.kernels.compiled_motion``).
    limit_key : str or None
        The parameter of the law's own torque limit, when it has one (``mpc.u_max``): its command, the observer
        term included, holds |u| <= that value at every step (:meth:`step_observed`); None: no limit.
    requires : tuple of str
        Optional packages the law needs (:mod:`mwip_ros.optional`: ``("daqp",)`` for mpc); without one the law is
        refused in one line (:func:`unavailable`), and the other laws run.
    pure_lanes : int
        3 when ``pure_step`` is plain arithmetic and ``m``'s functions on its numbers, with ``P`` three numbers:
        the compiled loop then runs it for several scenarios at once (``core.kernels.simd``); 0 (the default): one
        scenario after another.
    """

    name: str = ""
    family: str = ""
    observer: bool = False
    title: str = ""
    param_keys: Tuple[str, ...] = ()
    parameters: Tuple[LawParam, ...] = ()
    internal_names: Tuple[str, ...] = ("u",)
    Params: type = type(None)
    announce: bool = False
    pure_step: Optional[Callable[..., Any]] = None
    pure_track: Optional[Callable[..., Any]] = None
    pure_lanes = 0
    limit_key: Optional[str] = None
    requires: Tuple[str, ...] = ()
    _with_observer: Type[Law]   # set by .ndo.with_observer on the base class it composes (annotation only)
    # the motion reference (core.control.motion.Reference) of this period; None: regulation, as in the paper
    ref = None

    @staticmethod
    def pure_params(params) -> tuple:
        """The numbers ``pure_step`` reads as ``P`` (floats, in a fixed order)."""
        raise NotImplementedError

    def __init__(self, params, nominal, h: float, m=math):
        self.params, self.nominal, self.h, self.m = params, nominal, h, m

    # --- parameters -------------------------------------------------------------------------------

    @classmethod
    def design(cls, values: Mapping[str, Any], nominal, h: float):
        """The law's :attr:`Params` from parameter ``values`` (one scenario), the nominal model and the period.

        Raises ValueError (or a subclass naming the key) when the values give no law."""
        raise NotImplementedError

    @classmethod
    def from_params(cls, values: Mapping[str, Any], nominal, h: float, m=math) -> "Law":
        """The law ready to step, designed from parameter ``values``."""
        return cls(cls.design(values, nominal, h), nominal, h, m)

    @classmethod
    def stability_margin(cls, nominal, params, X, observer: bool = False) -> float:
        """How far the gains satisfy the law's stability condition (> 0: satisfied; math.inf: it has none),
        with (``observer``) or without the observer term; ``X`` is the observer gain matrix (eq. 14)."""
        return math.inf

    # --- state --------------------------------------------------------------------------------------

    def track(self, ref) -> None:
        """The references of the coming step (:class:`~mwip_ros.core.control.motion.Reference`, theory 6.11; None: none,
        the law regulates to the upright at rest as in the paper).  The loop calls it once per period before
        :meth:`step` (:meth:`mwip_ros.core.closed_loop.loop.Period.decide`, the controller node); a law tracks it in
        error coordinates (:meth:`tracked`), DSC through its outer loop (docs/theory.md 6.11)."""
        self.ref = ref

    def tracked(self, x):
        """``x`` in the error coordinates of the reference (theta_w - theta_w*, theta_b, theta_w' - theta_w'* +
        lambda (theta_w - theta_w*), theta_b'): :func:`mwip_ros.core.control.motion.error_state`; ``x`` itself without
        one."""
        return x if self.ref is None else error_state(x, self.ref)

    def reset(self) -> None:
        """Forget the state: the next step is a first step."""

    def elapsed(self, dt: float) -> None:
        """The time since the previous step when it is not the period ``h`` [s]: a realtime controller that lost
        states (n periods apart: n h) says so before :meth:`step`, and that step advances the law's own filters over
        ``dt`` instead of one period.  Only that one step; a law without a state in time ignores it."""

    def step(self, x, tau_hat=None):
        """``(u, internals)`` for the measured state ``x`` and the estimate ``tau_hat`` (None: none).

        ``internals`` is a dict of the law's own signals (names from :attr:`internal_names`)."""
        raise NotImplementedError

    def step_observed(self, x, u_taud):
        """``(u, internals)`` with the observer term ``u_taud`` of eq. (20) taken in: ``u = u_law - u_taud``
        (eq. 19), ``internals["u_dsc"]`` the law's own u_law.  The default subtracts it from :meth:`step`'s
        command; a law with a torque limit overrides it to hold the limit on u itself (``mpc``: the QP's bounds
        shifted by u_taud, docs/theory.md 6.6).  :class:`~.ndo.WithObserver` calls it."""
        u_law, internals = self.step(x, None)
        return u_law - u_taud, internals

    def finite(self) -> bool:
        """False when the law's state went non-finite (the node then undoes the step)."""
        return True

    def snapshot(self):
        """The state as it is now, for :meth:`restore` (a step that gave no finite command is undone)."""
        return dict(self.__dict__)

    def restore(self, snap) -> None:
        self.__dict__.update(snap)

    # --- text ---------------------------------------------------------------------------------------

    def summary(self) -> str:
        """The gains in a few words for status lines ('k1 = 6.0, ...'), '' for none."""
        return ""

    def design_text(self, values: Optional[Mapping[str, Any]] = None) -> Optional[str]:
        """A line logged at start-up and whenever the law's parameters change (the LQR gain), or None;
        ``values`` are the parameter values it was designed from."""
        return None

    def warnings(self) -> List[str]:
        """Warnings about the current parameters (gains that break a stability condition)."""
        return []


class LawError(RuntimeError):
    """A law's step raised: names the law, when (``t``, None: unknown), the error (its type and text) and, in a
    batch or a sweep, the scenario (None: unknown).  Plain arguments, so it crosses processes (a sweep's workers)."""

    def __init__(self, law: str, t: Optional[float], error: str, scenario: Optional[int] = None):
        super().__init__(law, t, error, scenario)
        self.law, self.t, self.error, self.scenario = law, t, error, scenario

    @classmethod
    def of(cls, law: str, t: Optional[float], exc: BaseException) -> "LawError":
        return cls(law, t, f"{type(exc).__name__}: {exc}")

    def in_scenario(self, scenario: int) -> "LawError":
        return LawError(self.law, self.t, self.error, scenario)

    def __str__(self) -> str:
        where = [f"at t = {self.t:.3f} s" if self.t is not None else "",
                 f"in scenario {self.scenario}" if self.scenario is not None else ""]
        return f"the law {self.law!r} raised {' '.join(w for w in where if w)}: {self.error}".replace("  ", " ")


class PluginError(ImportError):
    """A law plug-in module (``$MWIP_ROS_LAWS``) that cannot be imported or raised while importing: one line naming
    the module and the error."""
