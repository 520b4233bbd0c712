"""The control laws and their one registry.

A law is a class (:class:`Law`) with its own parameters, a ``reset`` and a ``step`` from the
measured state and the observer's estimate to a command and its internal signals.  Every
caller picks laws here: ``mwip_sim --controller``, a sweep's and a tuning's ``controllers``,
the offline loop (:mod:`..sim`), the batch simulator (:mod:`..batch`) and the controller node
(its ``law`` parameter is a law's :attr:`Law.family`, ``use_observer`` picks the variant with
the observer term).

* :func:`register` adds a law, and with ``with_observer=`` its variant that subtracts the
  observer term u_taud of eq. (20) (:class:`~.ndo.WithObserver`: composed, not copied).
* :func:`get` returns a law by its name, :func:`names` lists them, :func:`families` lists the
  values of the node's ``law`` parameter, :func:`variant` maps (family, use_observer) to a law.
* Plug-ins: the environment variable ``MWIP_ROS_LAWS`` (``module[:module...]``, importable
  module names) is read when this package is first imported; each module registers its laws
  with :func:`register`.  So a process started with it (a node, ``mwip_sim``) knows them.  A module
  that cannot be imported, or raises while importing, is kept as a :class:`PluginError` that
  :func:`check_plugins` raises: the tools and the nodes stop at start-up with its one line, exit 2.
* A law's step that raises is a :class:`LawError` in the loops that run it (:mod:`..loop`, :mod:`..batch`):
  the law, when, the error, and in a batch the scenario.

Today's laws: ``dsc`` and ``dscndo`` (:mod:`.dsc`, eq. 16-28 and 19-21), ``lqr`` and
``lqr_ndo`` (:mod:`.lqr`, the baseline), ``smc`` and ``smc_ndo`` (:mod:`.smc`, sliding-mode control),
``mpc`` and ``mpc_ndo`` (:mod:`.mpc`, model predictive control with the torque limit as a constraint).
"""
from __future__ import annotations

import importlib
import os
from typing import Any, Dict, List, Mapping, Optional, Tuple, Type, TypeVar

from . import dsc, lqr, mpc, smc
from .base import Law, LawError, LawParam, PluginError
from .ndo import with_observer as _compose

__all__ = ["Law", "LawParam", "register", "get", "names", "families", "variant", "lookup", "PLUGINS_ENV",
           "load_plugins", "unavailable", "instances", "check_plugins", "LawError", "PluginError"]

PLUGINS_ENV = "MWIP_ROS_LAWS"


_LAWS: Dict[str, Type[Law]] = {}
_L = TypeVar("_L", bound=Type[Law])


def register(cls: _L, with_observer: Optional[str] = None, title: Optional[str] = None) -> _L:
    """Register the law ``cls`` under ``cls.name``; ``with_observer`` also registers, under that name, its
    variant with the observer term (eq. 19-21, :func:`.ndo.with_observer`), titled ``title``.

    Registering the same class again is allowed (a module imported twice); another class under a taken
    name is refused."""
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no name")
    cls.family = cls.family or cls.name
    cls.title = cls.title or cls.name
    for law in (cls, _compose(cls, with_observer, title) if with_observer else None):
        if law is None:
            continue
        old = _LAWS.get(law.name)
        if old is not None and old is not law and not _same_law(old, law):
            raise ValueError(f"a law named {law.name!r} is registered already ({old.__module__}.{old.__name__})")
        if old is None:
            _LAWS[law.name] = law
    return cls


def _same_law(a: type, b: type) -> bool:
    """The observer variant of one base class, composed twice."""
    return getattr(a, "base", None) is not None and getattr(a, "base", None) is getattr(b, "base", None)


def get(name: str) -> Type[Law]:
    """The law registered as ``name``; KeyError naming the known ones."""
    try:
        return _LAWS[name]
    except KeyError:
        why = f" ({_PLUGIN_FAILURE})" if _PLUGIN_FAILURE is not None else ""
        raise KeyError(f"unknown law {name!r}; known: {', '.join(names())}{why}") from None


def names() -> Tuple[str, ...]:
    """Every registered law's name, in registration order."""
    return tuple(_LAWS)


def families() -> Tuple[str, ...]:
    """The values of the controller node's ``law`` parameter, in registration order."""
    return tuple(dict.fromkeys(law.family for law in _LAWS.values()))


def lookup(family: str, use_observer: bool) -> Optional[Type[Law]]:
    """The law of ``family`` with (``use_observer``) or without the observer term, or None."""
    for law in _LAWS.values():
        if law.family == family and law.observer == bool(use_observer):
            return law
    return None


def variant(family: str, use_observer: bool) -> Type[Law]:
    """:func:`lookup`, or ValueError naming what is missing."""
    law = lookup(family, use_observer)
    if law is None:
        if family not in families():
            raise ValueError(f"unknown law {family!r}; known: {', '.join(families())}")
        raise ValueError(f"the law {family!r} has no variant {'with' if use_observer else 'without'} the "
                         f"observer term (use_observer: {str(bool(use_observer)).lower()})")
    return law


def unavailable(law: Type[Law]) -> Optional[str]:
    """None when the optional packages ``law`` needs (:attr:`Law.requires`, its base's for an observer variant) can
    be imported, else the one line naming the first missing one and how to install it."""
    from mwip_ros.optional import missing
    for module in getattr(law, "base", law).requires:
        text = missing(module, f"the law {law.name}")
        if text:
            return text
    return None


def instances(values: Mapping[str, Any], nominal, h: float) -> Dict[str, "Law"]:
    """{family: its law without the observer term, designed from ``values``} for every family that has one and
    whose optional packages are installed (:func:`unavailable`): what the controller node builds at start-up."""
    plain = (lookup(family, False) for family in families())
    return {law.family: law.from_params(values, nominal, h) for law in plain
            if law is not None and unavailable(law) is None}


def load_plugins(spec: Optional[str] = None) -> List[str]:
    """Import the modules named in ``spec`` (default: ``$MWIP_ROS_LAWS``, ``module[:module...]``); returns
    their names.  Each registers its laws when imported."""
    spec = os.environ.get(PLUGINS_ENV, "") if spec is None else spec
    mods = [s.strip() for s in spec.split(":") if s.strip()]
    for mod in mods:
        try:
            importlib.import_module(mod)
        except ImportError as exc:
            raise PluginError(f"{PLUGINS_ENV}={spec!r}: cannot import the law module {mod!r} ({exc}); name "
                              f"importable modules (on PYTHONPATH), separated by ':'") from exc
        except Exception as exc:   # noqa: BLE001 - whatever a plug-in raises while importing, said in one line
            raise PluginError(f"{PLUGINS_ENV}={spec!r}: the law module {mod!r} raised while importing: "
                              f"{type(exc).__name__}: {exc}") from exc
    return mods


def _builtins() -> None:
    register(dsc.DscLaw, with_observer="dscndo", title="DSCNDO")   # eq. 16-28; eq. 19-21
    register(lqr.LqrLaw, with_observer="lqr_ndo", title="LQR+NDO")  # the baseline (docs/theory.md 6.1)
    register(smc.SmcLaw, with_observer="smc_ndo", title="SMC+NDO")  # sliding-mode control (docs/theory.md 6.5)
    register(mpc.MpcLaw, with_observer="mpc_ndo", title="MPC+NDO")  # model predictive control (docs/theory.md 6.6)


def check_plugins() -> None:
    """Raise the :class:`PluginError` of the plug-ins of ``$MWIP_ROS_LAWS`` imported with this package, if any: the
    tools (``mwip_sim``, ``mwip_sweep``, ...: ``cli.interrupts.run_main``) and the nodes (``run_node``) call it at
    start-up and stop with its one line, exit 2.  Importing this package does not raise it (a tool's module
    imports the package before its ``main`` could say anything in one line)."""
    if _PLUGIN_FAILURE is not None:
        raise _PLUGIN_FAILURE


_builtins()
_PLUGIN_FAILURE: Optional[PluginError] = None
try:
    load_plugins()
except PluginError as _exc:
    _PLUGIN_FAILURE = _exc
