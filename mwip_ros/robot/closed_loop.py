"""The closed loop over a robot's :class:`~mwip_ros.robot.backend.Backend`, in one process, without ROS: the project's
stages (:func:`mwip_ros.core.closed_loop.loop.decide`: state estimator, observer, law) between a backend's reads and
writes.

Period k (docs/theory.md section 4's contract, the robot's side of it as SPEC section 16 has it):

1. the read of t_k (the previous step's answer; at k = 0 the reset's);
2. the raw sample the state estimator takes (SPEC 10): the gyro's pitch rate ``imu.angular_velocity[1]`` and the
   specific force ``imu.linear_acceleration[0]``, ``[2]`` (both in ``imu_link`` axes), the lumped wheel angle
   relative to the body ``phi = (phi_L + phi_R) / 2`` with both wheels in the forward sense (on Upkie the backend
   has turned the right servo's ``-phi_R`` into ``+phi_R``: ``(phi_L - phi_R_servo) / 2``) and its rate as the
   servos report it; the torque that acted over period k - 1, ``u_L + u_R`` as the servos report it. With
   ``measure="truth"`` the simulator's true planar state instead (the estimator bypassed, for comparison);
3. :func:`~mwip_ros.core.closed_loop.loop.decide`: the estimate, tau_hat_k, u_k (with the excitation and the
   references);
4. the drive: ``torque_limit`` (the lumped |u|, ``saturate``), a command that is not finite ends the run
   (``bad_command``), u split over the wheels by :meth:`~mwip_ros.robot.backend.Command.lumped`;
5. the write and the next read: :meth:`~mwip_ros.robot.backend.Backend.step`.

Row k of the :class:`~mwip_ros.core.closed_loop.trajectory.Trajectory` holds the true state where the backend has one
(NaN else), the command u_k after the torque limit, tau_hat_k, the raw sample and the estimate, the torque that acted
over [t_k, t_k+1) (``u_applied``: the next read's report), and the pose (the axle's x, y where the backend knows it: an
:class:`~mwip_ros.robot.upkie.UpkieBackend` on PyBullet). The true lumped disturbance is not known (NaN).

A run ends early when the robot falls (|theta_b| beyond ``fall_angle``: the true one where there is one, else the
estimate), when a command is refused, or when the backend reports a fault; ``record`` says when and why, as
:func:`mwip_ros.core.closed_loop.sim.simulate`'s does. ``realtime`` paces the periods to the wall clock (a simulated
backend is stepped on demand otherwise: lockstep) and records the timing: the periods, the late ones (a write more than
one period behind its slot), the lateness's 99th percentile and the worst, and each period's own work (its stages, the
write and the next read: a simulator's physics included): its median, 99th percentile and worst.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from ..core.identification.excitation import Excitation
from ..core.closed_loop.loop import decide, fall_text
from ..core.control.motion import Shaper
from ..core.control.observer import DiscreteObserver, gain_matrix
from ..core.plants.plant import Pose, saturate
from ..core.plants.raw_sensors import RawSample
from ..core.closed_loop.sim import ClosedLoop
from ..core.closed_loop.trajectory import BAD_COMMAND, FAILURES, FALL, Trajectory, TrajectoryTable
from .backend import Backend, Command, Observation

__all__ = ["Push", "raw_sample", "run", "summary", "MEASURES"]

MEASURES = ("raw", "truth")
DEVICE_FAULT = "device_fault"   # a run ended by the backend's own fault (Observation.fault)


@dataclass(frozen=True)
class Push:
    """A horizontal push held on the robot's body: ``force`` [N] forward (world x), from ``t`` [s] for ``duration``
    [s] (a backend with a ``push`` method: Upkie on PyBullet)."""

    t: float
    duration: float
    force: float


def raw_sample(obs: Observation) -> RawSample:
    """The raw sample of one read (module docstring, step 2): gyro pitch rate, specific force along x_b and z_b, the
    lumped wheel angle relative to the body and its rate.

    Parameters
    ----------
    obs : Observation
        A read with an IMU.

    Returns
    -------
    RawSample
        What the state estimator takes (:mod:`mwip_ros.core.plants.raw_sensors`).
    """
    if obs.imu is None:
        raise ValueError("this backend's read has no IMU: the state estimator needs one (imu/data_raw)")
    w, f = obs.imu.angular_velocity, obs.imu.linear_acceleration
    return RawSample(float(w[1]), float(f[0]), float(f[2]), obs.phi, obs.phi_rate)


def _pose(backend: Backend, obs: Observation) -> Optional[Pose]:
    where = getattr(backend, "axle_position", None)
    if where is None or not getattr(backend, "simulated", False):
        return None
    x, y = where()
    th = obs.truth[1] if obs.truth is not None else math.nan
    return Pose(x, y, math.nan, math.nan, th, math.nan, obs.left.position + th, obs.right.position + th)


def run(backend: Backend, loop: ClosedLoop, duration: float, measure: str = "raw", push: Optional[Push] = None,
        realtime: bool = False, on_period: Optional[Callable[[int, Observation], None]] = None) -> Trajectory:
    """Run ``loop``'s estimator, observer and law on ``backend`` for ``duration`` seconds (module docstring).

    Parameters
    ----------
    backend : Backend
        The robot side; it is reset first and left as the run ends (the caller closes it).
    loop : ClosedLoop
        The law, its gains, the observer gain X, the estimator, the excitation and the references, from a parameter
        file (:func:`mwip_ros.params.typed.closed_loop`); of its plant only ``h``, ``nominal``, ``torque_limit`` and
        ``fall_angle`` are read.
    duration : float
        Simulated (or wall-clock) seconds [s].
    measure : str
        ``raw``: the IMU and the encoders through ``loop.estimator`` (which must be set); ``truth``: the simulator's
        true planar state.
    push : Push, optional
        A push during the run.
    realtime : bool
        Pace the periods to the wall clock.
    on_period : callable, optional
        Called with (k, the read of t_k) every period.

    Returns
    -------
    Trajectory
        One row per period; ``record`` holds ``failure``, ``t_fall``, ``fall_text`` of a failed run and, realtime,
        ``timing``.
    """
    if measure not in MEASURES:
        raise ValueError(f"measure {measure!r}: one of {', '.join(MEASURES)}")
    pc = loop.plant
    h = pc.h
    if measure == "raw" and loop.estimator is None:
        raise ValueError("measure 'raw' needs a state estimator (sensors.model: raw and the state_estimator's method)")
    estimator = loop.estimator.make(h, pc.nominal.r, pc.nominal.g) if measure == "raw" else None
    observer = DiscreteObserver(pc.nominal, gain_matrix(loop.X), h)
    law = loop.law_class(loop.params, pc.nominal, h)
    excitation = Excitation(loop.excitation, h) if loop.excitation is not None else None
    motion = Shaper(loop.motion, h) if loop.motion is not None else None
    table = TrajectoryTable(internals=True, raw=True, drive=True, excitation=excitation is not None,
                            motion=motion is not None, pose=True)
    n_steps = int(round(duration / h))
    failure = None
    nan4 = (math.nan,) * 4
    late, lateness, work = 0, [], []
    obs = backend.reset()
    t0 = time.monotonic()
    pushing = False
    for k in range(n_steps + 1):
        started = time.monotonic()
        if on_period is not None:
            on_period(k, obs)
        t = k * h
        truth = obs.truth if obs.truth is not None else nan4
        if obs.fault is not None:
            failure = (t, f"FAILED at t = {t:.3f} s: {obs.fault}", DEVICE_FAULT)
            break
        sample = raw_sample(obs) if obs.imu is not None else None
        if measure == "truth":
            if obs.truth is None:
                raise ValueError(f"measure 'truth': the backend {backend.name!r} has no true state")
            measured = obs.truth
        else:
            if sample is None:
                raise ValueError(raw_sample.__doc__.splitlines()[0] + f": the backend {backend.name!r} has no IMU")
            measured = sample
        u_law, tau_hat, internals, x_m = decide(estimator, observer, law, measured, obs.torque, k, h, excitation,
                                                motion)
        u = saturate(u_law, pc.torque_limit)
        extra = (*(sample if sample is not None else (math.nan,) * 5), *x_m)
        table.append(t, truth, u, tau_hat, (math.nan, math.nan), internals, extra, _pose(backend, obs))
        judged = truth[1] if obs.truth is not None else x_m[1]
        if not abs(judged) <= pc.fall_angle:
            failure = (t, fall_text(t, truth if obs.truth is not None else x_m, pc.fall_angle), FAILURES[FALL])
            break
        if not math.isfinite(u):
            failure = (t, f"FAILED at t = {t:.3f} s: the law's command is refused (not a finite number: {u})",
                       FAILURES[BAD_COMMAND])
            break
        if k == n_steps:
            break
        decided = time.monotonic()
        if push is not None:
            on = push.t - 1e-9 <= t < push.t + push.duration - 1e-9
            if on != pushing:
                backend.push(push.force if on else 0.0)
                pushing = on
        if realtime:
            slot = t0 + (k + 1) * h
            now = time.monotonic()
            if now < slot:
                time.sleep(slot - now)
            behind = time.monotonic() - slot
            lateness.append(behind)
            if behind > h:
                late += 1
        before = time.monotonic()
        obs = backend.step(Command.lumped(u))
        if realtime:   # the period's own work: its stages, and the write and the next read
            work.append(decided - started + time.monotonic() - before)
        table.set_drive(obs.torque, 0)
    table.flush()
    traj = table.trajectory(backend.name, failure is not None, h)
    if failure is not None:
        traj.record.update(t_fall=failure[0], fall_text=failure[1], failure=failure[2])
    if realtime:
        lat = np.asarray(lateness) if lateness else np.zeros(1)
        busy = np.asarray(work) if work else np.zeros(1)
        traj.record["timing"] = {"periods": len(lateness), "late": late, "lateness_p99_ms": float(
            np.percentile(lat, 99) * 1e3), "lateness_max_ms": float(lat.max() * 1e3),
            "work_p50_ms": float(np.percentile(busy, 50) * 1e3), "work_p99_ms": float(np.percentile(busy, 99) * 1e3),
            "work_max_ms": float(busy.max() * 1e3),
            "wall_s": time.monotonic() - t0}
    return traj


def summary(traj: Trajectory, window=(5.0, 60.0)) -> dict:
    """A run's numbers against the goals (docs/hardware-upkie.md): over ``window`` [s] theta_b's RMS and worst, the
    estimator's pitch error's RMS, u's RMS; over the whole run whether it stayed up, the axle's largest distance from
    where it started [m] and where it ended [m]. Values that the run lacks are NaN (a window the run does not cover, a
    column the run does not have: never a verdict).

    theta_b is the truth where the run has one (a simulator's). A robot has none: its pitch is the state estimator's
    estimate, and ``judged_on`` says so (``"estimate"``): a run of :func:`run` whose backend has no truth (its truth
    columns NaN, its ``theta_b_hat`` the estimate), or a bag whose ``joint_states`` is the estimator's with no
    ``true_joint_states`` (:func:`mwip_ros.runs.read_bag_run`'s ``record["states_from"]``). The estimator's error
    then is unknown (NaN), and so is the drift without a pose.

    Parameters
    ----------
    traj : Trajectory
        A run of :func:`run`, or a bag's (:func:`mwip_ros.runs.read_bag_run`).
    window : pair of float
        The metrics window [s].

    Returns
    -------
    dict
        ``upright``, ``covers_window``, ``judged_on`` (``truth`` or ``estimate``), ``theta_b_rms``,
        ``theta_b_max_abs``, ``theta_b_est_err_rms``, ``u_rms``, ``max_drift``, ``final_drift``, ``t_end``,
        ``failure``.
    """
    c = traj.columns
    t = c["t"]
    n = len(t)
    nan = np.full(n, np.nan)
    sel = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    covers = (not traj.fallen) and bool(sel.any()) and t[-1] >= window[1] - 1e-9

    def col(name):
        return np.asarray(c[name], dtype=float) if name in c else nan

    def rms(x):
        x = np.asarray(x, dtype=float)[sel]
        return float(np.sqrt(np.mean(x ** 2))) if covers and len(x) and np.all(np.isfinite(x)) else math.nan

    th, th_hat = col("theta_b"), col("theta_b_hat")
    if traj.record.get("states_from") == "estimate":   # a bag's joint_states: the estimator's, no truth
        judged_on, err = "estimate", nan
    elif n and not np.any(np.isfinite(th)) and np.any(np.isfinite(th_hat)):   # a backend without truth
        judged_on, th, err = "estimate", th_hat, nan
    else:
        judged_on, err = "truth", th_hat - th
    x, y = col("x"), col("y")
    d = np.hypot(x - x[0], y - y[0]) if n else nan
    return {"upright": not traj.fallen, "covers_window": bool(covers), "judged_on": judged_on,
            "theta_b_rms": rms(th),
            "theta_b_max_abs": float(np.max(np.abs(th[sel]))) if covers and np.all(np.isfinite(th[sel])) else math.nan,
            "theta_b_est_err_rms": rms(err), "u_rms": rms(col("u")),
            "max_drift": float(np.max(d)) if n and np.all(np.isfinite(d)) else math.nan,
            "final_drift": float(d[-1]) if n and np.isfinite(d[-1]) else math.nan,
            "t_end": float(t[-1]) if n else math.nan, "failure": traj.record.get("fall_text", "")}
