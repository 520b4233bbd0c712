"""Many scenarios at once: the closed loop of :mod:`.sim` over numpy arrays, one entry per scenario.

Every equation is the scalar loop's own (``model.accel``, ``plant.rk4_period``,
``DiscreteObserver``, the law's ``step`` (:mod:`.laws`), ``model.lumped_disturbance``), so the batch and the
scalar loop cannot drift apart; a test checks each batch trajectory against :func:`.sim.simulate`.
Two forms of the one loop (:mod:`.batch_compiled`, :mod:`.batch_numpy`; this module picks one, and
:mod:`.batch_scenarios` holds what they share and the scalar loop they fall back to):

* compiled (the default for a law with a pure form, ``Law.pure_step``: dsc, dscndo, lqr, lqr_ndo): the
  whole period, sensors to RK4, runs as one numba kernel built from those same functions
  (:func:`.compiled.kernel_for`), scenario by scenario; the normal draws are numpy's, made here a
  block at a time and handed in; the metrics come from the window's running sums
  (:func:`.batch_compiled.window_sums_metrics`, the arithmetic of :func:`.metrics.window_metrics`).
  ``MWIP_BATCH_COMPILED=0`` (or ``compiled=False``) turns it off.  The raw sensors with their estimator, the
  motor and the excitation run there too (the scenarios sharing whether they measure raw and the estimator's
  method); with ``record``, or a law without a pure form, those loops run the scalar loop per scenario
  (:func:`.batch_scenarios._simulate_each`).
* over numpy arrays (a law without a pure form, a plug-in; ``record=True``): the observer, the law and
  the true tau_d are called with the math namespace ``numpy`` and parameters whose fields are arrays;
  the plant's RK4 period runs as the same ``plant.rk4_period`` compiled by numba (:mod:`.compiled`).
  A law whose step raises over arrays (its own error, or numpy's for a law written for one scenario,
  ``if x[1] > a``) runs scenario by scenario instead (:func:`.batch_scenarios._simulate_each`): the same numbers,
  or the law's own error as a :class:`~.laws.LawError` naming the scenario.

* Each scenario has its own parameters and its own seeded D_w stream (the scalar plant's
  generator, drawn in the same order).
* A scenario that fails is marked with the time it failed and why (:data:`FAILURES`, as the scalar loop,
  :class:`.loop.Period`): it falls (|theta_b| > its fall angle, or theta_b not a number), the law's command is
  refused (not a finite number, or beyond :data:`.safety.PLAUSIBLE_TORQUE`: the driver's ``bad_command``, zero
  torque acts in that row), or its state diverges (a component not a finite number after a period: no row).
  Its row at that instant is the last it records, and from then on its state is frozen, so a
  fallen or diverging scenario never poisons the others, and is never upright.
* The metrics over the window come from :func:`.metrics.window_metrics`, the function the
  single-run metrics use.

The scenarios of one batch must share the control period, the RK4 sub-steps, the duration and
the law's family (a sweep groups them so); with and without the observer term may mix (the
law's observer variant runs, with tau_hat = 0 for the scenarios without it).
"""
from __future__ import annotations

import functools
import os
from typing import Optional, Sequence

from .. import laws
from ..closed_loop.sim import ClosedLoop
from ..closed_loop.trajectory import BAD_COMMAND, DIVERGED, FAILURES, FALL
from .batch_compiled import _simulate_compiled
from .batch_numpy import _simulate_numpy
from .batch_scenarios import BatchResult, _same, _simulate_each

__all__ = ["BatchResult", "simulate_batch", "compiled_form", "COMPILED_ENV", "compiled_default", "FAILURES", "FALL",
           "BAD_COMMAND", "DIVERGED"]

COMPILED_ENV = "MWIP_BATCH_COMPILED"   # "0": the numpy loop even for a law with a compiled form


def compiled_default() -> bool:
    """Whether :func:`simulate_batch` runs the compiled loop by default (``$MWIP_BATCH_COMPILED``, default on)."""
    return os.environ.get(COMPILED_ENV, "1").strip() not in ("0", "false", "no", "off", "")


@functools.lru_cache(maxsize=None)
def numba_missing() -> Optional[str]:
    """None when numba (optional, :mod:`mwip_ros.optional`) is installed, else the line naming it: without it
    :func:`simulate_batch` runs the scalar loop scenario by scenario (:func:`.batch_scenarios._simulate_each`), slower,
    the same numbers."""
    from mwip_ros.optional import missing
    return missing("numba")


def simulate_batch(loops: Sequence[ClosedLoop], window: Sequence[float], record: bool = False,
                   compiled: Optional[bool] = None) -> BatchResult:
    """Run every scenario of ``loops`` for its ``duration_s``; ``record`` keeps each one's trajectory.

    ``compiled`` (default :func:`compiled_default`): without ``record``, a law with a pure form
    (``Law.pure_step``) runs as one compiled loop (:func:`.batch_compiled._simulate_compiled`); else, and for every
    other law, the loop runs over numpy arrays with the plant's RK4 compiled.  Without numba (:func:`numba_missing`),
    the scalar loop scenario by scenario.  The raw sensors and their estimator, the motor
    and the excitation (:func:`_beyond_arrays`) run compiled too when the scenarios share whether they have raw
    sensors and the estimator's method (:func:`_raw_stage`); else, with ``record`` or a law without a pure form,
    the scalar loop scenario by scenario (:func:`.batch_scenarios._simulate_each`).  The array and compiled forms have
    no driver state machine (docs/theory.md 6.8): they always run enabled, so scenarios with ``require_enable: true`` (a
    driver nobody enables: its bridge open, no torque) run the scalar loop, which has it; so do scenarios with
    another plant backend (``mujoco``: a simulation that diverges is the scenario's ``diverged`` failure).  Motion
    references (``motion``, theory 6.11) run compiled (:mod:`.compiled_motion`), else the scalar loop."""
    if _scalar_only(loops):   # both array forms need numba, a driver and eq. (1)
        return _simulate_each(loops, window, record)
    beyond = any(_beyond_arrays(lp) for lp in loops)
    form = compiled_form(loops, record, compiled)
    if form is not None:
        kernel, law, stage = form
        return _simulate_compiled(loops, window, law, kernel, *stage)   # raw, the estimator
    if beyond:
        return _simulate_each(loops, window, record)
    return _simulate_numpy(loops, window, record)


def _scalar_only(loops: Sequence[ClosedLoop]) -> bool:
    """Whether only the scalar loop runs ``loops``: no numba, a driver nobody enables, another plant backend."""
    return bool(numba_missing()) or any(lp.plant.require_enable or lp.plant.backend != "rk4" for lp in loops)


def compiled_form(loops: Sequence[ClosedLoop], record: bool = False, compiled: Optional[bool] = None):
    """(the compiled loop, the law class, (raw, the estimator class)) that :func:`simulate_batch` runs ``loops``
    with, or None when it runs another form (see there).  Getting it compiles nothing: numba compiles (or loads
    from its cache) at the first call."""
    if compiled is None:
        compiled = compiled_default()
    if not compiled or record or _scalar_only(loops):
        return None
    from .compiled import kernel_for
    family = _same((lp.law for lp in loops), "the law")
    use_obs = [lp.use_observer for lp in loops]
    law = laws.lookup(family, any(use_obs)) or laws.lookup(family, not any(use_obs))
    stage = _raw_stage(loops) if any(_beyond_arrays(lp) for lp in loops) else (False, None)
    if law is None or (any(use_obs) and not law.observer) or stage is None:
        return None
    kernel = kernel_for(law, stage[1])
    return None if kernel is None else (kernel, law, stage)


def _raw_stage(loops: Sequence[ClosedLoop]):
    """(raw sensors or not, the estimator class or None) when the scenarios share both (the compiled loop is
    specialised per estimator); None when they do not, or the estimator has no pure step."""
    from .. import estimators
    raws = {lp.plant.raw is not None for lp in loops}
    if len(raws) != 1:
        return None
    if not raws.pop():
        return False, None
    methods = {lp.estimator.method if lp.estimator is not None else None for lp in loops}
    method = methods.pop() if len(methods) == 1 else None
    if method is None:
        return None
    cls = estimators.get(method)
    return (True, cls) if getattr(cls, "pure_step", None) is not None else None


def _beyond_arrays(loop: ClosedLoop) -> bool:
    """Stages the numpy form does not run: the raw sensors and their estimator, the motor, the excitation, motion."""
    pc = loop.plant
    return pc.raw is not None or pc.motor.enabled or loop.excitation is not None or loop.motion is not None


