"""The compiled loop's stages that are one scenario's period each, and how the scalar loop's own functions are
compiled (docs/architecture.md, the batch simulator).

The stages ``sensors`` (:func:`sense_state`; raw: :func:`sense_raw`, with the estimator), ``law`` with the motion
references (:func:`track_for`: :func:`.compiled_motion.law_track` per law) and ``drive`` (:func:`drive_stage`) are
functions of their own, one scenario's period each: the compiled batch loop (:func:`.compiled.kernel_for`) calls them,
and so does the vector env (:mod:`mwip_ros.envs.kernels`, robot by robot at each robot's own period), so the stages are
written once for both.

Every function here and in the loop is compiled from its own code object: :func:`_compiled` (the scalar plant's
``accel``, ``motor_torque``, ``rk4_driven``, ``rk4_period``), :func:`_deep` (a function and, recursively, every plain
Python function it calls by a global name) and :func:`_lanes_of` (the same code on :data:`.simd.lanes`, a lane a
scenario).  numba caches the machine code (:mod:`.jitcache`: stamped with everything it is made of, so an edit to
any of it is compiled afresh).
"""
from __future__ import annotations

import types

from . import compiled_motion, simd
from ..plants import drive, model, plant
from ..plants.drive import motor_torque
from ..plants.model import accel
from ..plants.plant import saturate
from ..plants.raw_sensors import raw_sample
from ..plants.sensing import quantize
from ..control.safety import PLAUSIBLE_TORQUE
from .jitcache import jit as _jit

__all__ = ["sense_state", "sense_raw", "raw_stage", "drive_stage", "track_for", "pure_form"]


def _compiled(fn, **calls):
    """``fn``'s own code compiled by numba, with the global names in ``calls`` bound to compiled functions."""
    same = types.FunctionType(fn.__code__, {**fn.__globals__, **calls}, fn.__name__, fn.__defaults__)
    same.__qualname__ = fn.__qualname__
    return _jit(same)


_accel = _compiled(model.accel)
_motor_torque = _compiled(drive.motor_torque)
_rk4_driven = _compiled(plant.rk4_driven, accel=_accel, motor_torque=_motor_torque)
_rk4_period = _compiled(plant.rk4_period, rk4_driven=_rk4_driven)


_DONE: dict = {}   # code object -> its compiled function


def _lanes_tag() -> str:
    return f"lanes{simd.WIDTH}"   # a kernel per lane width


def _deep(fn, suffix: str = "", **calls):
    """``fn``'s own code compiled by numba (as :func:`_compiled`), every plain Python function it calls by a global
    name compiled alike, recursively: the scalar loop's own functions, no copy.  Cached under the stamp of what it
    is made of (:func:`made_of`: the functions bound in ``calls`` included)."""
    key = (fn.__code__, suffix)
    if key in _DONE:
        return _DONE[key]
    bound = dict(calls)
    for name in fn.__code__.co_names:
        g = fn.__globals__.get(name)
        if name not in bound and isinstance(g, types.FunctionType):
            bound[name] = _deep(g)
    same = types.FunctionType(fn.__code__, {**fn.__globals__, **bound}, fn.__name__, fn.__defaults__)
    same.__qualname__ = fn.__qualname__ + suffix
    _DONE[key] = out = _jit(same, _lanes_tag())
    return out


def _lanes_of(fn, **calls):
    """``fn``'s own code compiled by numba with ``m`` (its math namespace, the last default) :mod:`.simd`: called with
    :data:`.simd.lanes` for the per-scenario values, it runs :data:`.simd.WIDTH` scenarios at once."""
    bound = dict(calls)
    for name in fn.__code__.co_names:
        g = fn.__globals__.get(name)
        if name not in bound and isinstance(g, types.FunctionType):
            bound[name] = _deep(g)
    same = types.FunctionType(fn.__code__, {**fn.__globals__, **bound}, fn.__name__, fn.__defaults__[:-1] + (simd,))
    same.__qualname__ = fn.__qualname__ + "__lanes"
    return _jit(same, _lanes_tag())


def _no_est(P, h, sample, s, first):   # pragma: no cover
    """The estimator of a loop without raw sensors: never called (``raw`` is False)."""
    return (0.0, 0.0, 0.0, 0.0), (0.0,), (0.0, 0.0, 0.0, False)


est_step = _no_est   # the estimator's pure_step (core.estimators): bound per estimator by raw_stage


# tau_ext's values at a period's RK4 stage times: ``Sinusoid.at``, bound to its compiled form by kernel_for
at = model.Sinusoid.at


def _stage(tau1, tau2, f1, f2, t, dt, substeps):   # pragma: no cover
    """:func:`.plant.stage_torques` into ``tau1``, ``tau2`` (2 substeps + 1 each), the same times and values."""
    tau1[0] = at(f1, t) + 0.0
    tau2[0] = at(f2, t) + 0.0
    for j in range(substeps):
        ta, tb = t + (j + 0.5) * dt, t + (j + 1) * dt
        tau1[2 * j + 1] = at(f1, ta) + 0.0
        tau2[2 * j + 1] = at(f2, ta) + 0.0
        tau1[2 * j + 2] = at(f1, tb) + 0.0
        tau2[2 * j + 2] = at(f2, tb) + 0.0


def sense_state(xt, zk, noisy, std, counts, q, k, delay, u_prev):   # pragma: no cover - compiled
    """Stage ``sensors`` of one scenario that measures the state (:meth:`.sensing.Sensors.sample`): the true state
    ``xt`` plus ``std`` times the period's normals ``zk`` (``noisy``), the wheel angle quantized by the encoder
    (:func:`.sensing.quantize`, ``counts`` > 0), put with ``u_prev`` (the torque of period k - 1) into slot
    k % (delay + 1) of the queue ``q`` (delay + 1, >= 5; in place); returns the sample of step k - ``delay`` (the
    first one while k < delay): (the measured state, the torque reported with it).  The compiled loop
    (:func:`_loop`) and the vector env (:mod:`mwip_ros.envs.kernels`) both run it."""
    w, b, dw, db = xt
    if noisy:
        w, b, dw, db = w + std[0] * zk[0], b + std[1] * zk[1], dw + std[2] * zk[2], db + std[3] * zk[3]
    if counts > 0:
        w = quantize(w, counts)
    slot = k % (delay + 1)
    q[slot, 0], q[slot, 1], q[slot, 2], q[slot, 3], q[slot, 4] = w, b, dw, db, u_prev
    r = (k - delay) % (delay + 1) if k >= delay else 0
    return (q[r, 0], q[r, 1], q[r, 2], q[r, 3]), q[r, 4]


def sense_raw(pa, D_b, xt, u_prev, MC, e1, e2, zr, RS, RW, k, h, delay, q, PE, ES):   # pragma: no cover - compiled
    """Stages ``sensors`` and ``estimator`` of one scenario with raw sensors (docs/theory.md 6.4,
    :meth:`.loop.PlantSide.sense` with :meth:`.plant.PlantSim.sample_accel`): the accelerations at t_k^- of eq. (1)
    (:func:`.model.accel` of the true robot ``pa``, ``D_b``, the state ``xt``, with what acted over the previous
    period: ``u_prev``, or with the motor (``MC``: K_t, R, V_max, I_max; K_t = 0: none) its torque at x_k for the
    previous command, its D_w, and tau_ext ``e1``, ``e2`` at t_k), the raw sample (:func:`.raw_sensors.raw_sample`
    with the normals ``zr``; ``RW``: r, d, g, gyro_noise_std, gyro_bias_walk, accel_noise_std, counts), put with
    ``u_prev`` into slot k % (delay + 1) of the queue ``q`` (delay + 1, 6), and the estimator's ``pure_step``
    (``est_step``, bound per estimator; ``PE`` its numbers, ``ES`` its state, in place) on the sample of step
    k - ``delay``.  ``RS`` (in place): the gyro's bias, the previous phi, D_w and the drive's command of the previous
    period.  Returns (the estimate, the torque reported with the sample, the sample's slot in ``q``).  The compiled
    loop (:func:`_loop`) and the vector env (:mod:`mwip_ros.envs.kernels`) both run it."""
    ua = u_prev
    if MC[0] > 0.0 and k > 0:   # the motor's torque at x_k for the previous command
        ua = motor_torque(RS[3], xt[2] - xt[3], MC[0], MC[1], MC[2], MC[3])[0]
    ddq = accel(pa, RS[2], D_b, xt, ua, e1, e2)
    gy, fx, fz, phi, rate, bias = raw_sample(xt, ddq, zr, RS[0], RS[1], k == 0, h, RW[0], RW[1], RW[2], RW[3],
                                             RW[4], RW[5], int(RW[6]))
    RS[0], RS[1] = bias, phi
    slot = k % (delay + 1)
    q[slot, 0], q[slot, 1], q[slot, 2], q[slot, 3], q[slot, 4] = gy, fx, fz, phi, rate
    q[slot, 5] = u_prev
    r = (k - delay) % (delay + 1) if k >= delay else 0
    # the estimator (the delayed raw sample to a state, core.estimators: its pure_step)
    est, sn, _ = est_step(PE, h, (q[r, 0], q[r, 1], q[r, 2], q[r, 3], q[r, 4]), ES, k == 0)
    for j in range(len(sn)):
        ES[j] = sn[j]
    return est, q[r, 5], r


def raw_stage(estimator_step, suffix: str = ""):
    """:func:`sense_raw` compiled with the estimator's ``pure_step`` ``estimator_step`` (the compiled functions of the
    scalar loop for the rest)."""
    return _deep(sense_raw, suffix, est_step=_deep(estimator_step) if estimator_step is not _no_est
                 else _jit(_no_est, _lanes_tag()), accel=_accel, raw_sample=_deep(raw_sample),
                 motor_torque=_motor_torque)


def drive_stage(u, limit, qa, k, act_delay):   # pragma: no cover - compiled
    """Stage ``drive`` of one scenario's period k (:meth:`.loop.PlantSide.act`): the driver's ``bad_command`` (a
    command not a number or beyond :data:`.safety.PLAUSIBLE_TORQUE`), the torque limit (:func:`.plant.saturate`,
    ``limit`` 0: none), the actuator delay (:class:`.sensing.Actuator`: the queue ``qa`` of act_delay + 1 slots, in
    place); returns (the torque that acts over [t_k, t_k+1): zero in fault, whether the command was refused).  The
    compiled loop (:func:`_loop`) and the vector env (:mod:`mwip_ros.envs.kernels`) both run it."""
    bad = not abs(u) <= PLAUSIBLE_TORQUE
    u = saturate(u, limit)
    if act_delay > 0:
        qa[k % (act_delay + 1)] = u
        u = qa[(k - act_delay) % (act_delay + 1)] if k >= act_delay else 0.0
    if bad:
        u = 0.0   # in fault: zero torque acts
    return u, bad


def _owner(cls: type, name: str):
    """The class of ``cls``' MRO that defines ``name``."""
    return next((c for c in cls.__mro__ if name in c.__dict__), None)


def pure_form(law: type):
    """The pure step the compiled loop runs for the law class ``law`` (its ``pure_step``, or its base's for an
    observer variant), or None: it has none, or it is a subclass that steps otherwise than the form it inherits."""
    core = getattr(law, "base", law)
    fn = getattr(core, "pure_step", None)
    return None if fn is None or _owner(core, "step") is not _owner(core, "pure_step") else fn


def track_for(law: type):
    """Stage ``law`` with the motion references (docs/theory.md 6.11, 6.14), compiled for the law class ``law``:
    :func:`.compiled_motion.law_track` with the law's ``pure_track`` (or its ``pure_step`` on the error state,
    :func:`.compiled_motion.tracked_step`), the one the compiled loop calls and the vector env too; None when the law
    has no pure form (:func:`pure_form`)."""
    fn = pure_form(law)
    if fn is None:
        return None
    own = getattr(getattr(law, "base", law), "pure_track", None)
    suffix = f"__{fn.__module__}.{fn.__qualname__}".replace(".", "_")
    track = _deep(own) if own is not None else _deep(compiled_motion.tracked_step, suffix, law_step=_deep(fn))
    return _deep(compiled_motion.law_track, suffix, track_step=track)
