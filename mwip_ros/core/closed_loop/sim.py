"""Offline closed-loop simulator: the discrete-time contract (docs/theory.md), without ROS.

Row k of the result is the state at t_k, the command u_k computed from it, the estimate
tau_hat_k and the true lumped disturbance at t_k (:mod:`.trajectory`).  With sensing or
actuation options on (:mod:`.sensing`), the observer and the law see the measurement, the
table holds the true state and the torque that acted.  A period is :class:`.loop.Period`: the
stages of :data:`.loop.STAGES` in their order; the ``plant_sim`` node runs the plant's stages
with the same :class:`.loop.PlantSide` and the ``disturbance_observer`` and ``dscndo_controller``
nodes the others, so a lockstep graph reproduces these numbers.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Callable, Optional, Tuple, Type

from .. import laws
from ..estimators import EstimatorConfig
from ..identification.excitation import Excitation, ExcitationConfig
from .loop import Period, PlantSide
from ..control.motion import MotionConfig, Shaper
from ..control.observer import DiscreteObserver, gain_matrix
from ..plants.plant import PlantConfig, PlantDiverged
from .trajectory import DIVERGED, FAILURES, Trajectory, TrajectoryTable
from ..control.yaw import YawConfig, YawLoop

__all__ = ["ClosedLoop", "make_period", "simulate", "LAWS", "law_name"]


class _LawsView(Mapping):
    """name -> (family, use_observer) of every registered law (:mod:`.laws`), e.g. 'dscndo' -> ('dsc', True);
    kept for callers of the old table, a live view of the registry."""

    def __getitem__(self, name: str) -> Tuple[str, bool]:
        law = laws.get(name)
        return law.family, law.observer

    def __iter__(self):
        return iter(laws.names())

    def __len__(self) -> int:
        return len(laws.names())


LAWS = _LawsView()


def law_name(law: str, use_observer: bool) -> str:
    """('dsc', True) -> 'dscndo': the registered law of the node's ``law`` and ``use_observer``."""
    return laws.variant(law, use_observer).name


@dataclass(frozen=True)
class ClosedLoop:
    """One closed-loop scenario: the plant, the observer gain X, the law and its parameters, the length."""

    plant: PlantConfig
    X: Tuple[float, float, float, float]   # c1, c2, c3, c4 (eq. 14)
    controller: str                        # a registered law (core.laws): 'dsc', 'dscndo', 'lqr', 'lqr_ndo', ...
    params: Any                            # its Params (core.laws.Law.design): DscGains, LqrGain, ...
    duration_s: float
    estimator: Optional[EstimatorConfig] = None   # the state_estimator of a raw plant (plant.raw), else None
    excitation: Optional[ExcitationConfig] = None   # the controller's excitation (identification), else None
    motion: Optional[MotionConfig] = None   # the references every law tracks (theory 6.11), else None (the paper)
    yaw: Optional[YawConfig] = None   # the yaw-rate loop's gains (theory 6.13; runs on a spatial plant), else None

    @property
    def name(self) -> str:
        return self.controller

    @property
    def law_class(self) -> Type[laws.Law]:
        return laws.get(self.controller)

    @property
    def law(self) -> str:
        """The law's family: the controller node's ``law`` parameter ('dsc' for dsc and dscndo)."""
        return self.law_class.family

    @property
    def use_observer(self) -> bool:
        """True: the law plus the observer term (DSCNDO, LQR+NDO)."""
        return self.law_class.observer


def make_period(loop: ClosedLoop, plant: Optional[PlantConfig] = None, law=None) -> Period:
    """The stages of one period of ``loop`` (:class:`.loop.Period`), built once per run: the plant with its sensors
    and drive, the estimator (a raw plant), the observer, the law, the excitation, the motion references' shaper and,
    on a spatial plant with motion, the yaw stage (theory 6.11, 6.13).

    Parameters
    ----------
    loop : ClosedLoop
        The scenario.
    plant : PlantConfig, optional
        The plant instead of ``loop.plant`` (the env's: its seed, its initial state).
    law : optional
        The law's object instead of ``loop``'s law (the env without a base law: :class:`mwip_ros.envs.NoLaw`).

    Returns
    -------
    Period
        A whole period's stages, at t = 0.
    """
    pc = loop.plant if plant is None else plant
    h = pc.h
    # (a raw plant without an estimator: Period refuses it, ValueError)
    estimator = (loop.estimator.make(h, pc.nominal.r, pc.nominal.g)
                 if pc.raw is not None and loop.estimator is not None else None)
    excitation = Excitation(loop.excitation, h) if loop.excitation is not None else None
    motion = Shaper(loop.motion, h, pc.nominal) if loop.motion is not None else None
    side = PlantSide(pc)
    # the yaw stage (theory 6.13): a spatial plant, its gyro's yaw rate (raw sensors: the IMU's z axis, 6.4)
    yaw = YawLoop(loop.yaw, h) if loop.yaw is not None and motion is not None and side.plant.spatial else None
    law = loop.law_class(loop.params, pc.nominal, h) if law is None else law
    return Period(side, DiscreteObserver(pc.nominal, gain_matrix(loop.X), h), law, estimator, excitation, motion, yaw)


def simulate(loop: ClosedLoop, label: str = "", progress: Optional[Callable[[float], None]] = None,
             diverged_fails: bool = False, on_period: Optional[Callable[[object], None]] = None,
             wrench: Optional[Callable[[float], tuple]] = None) -> Trajectory:
    """Run the closed loop; stops early (``fallen``) when it fails: |theta_b| passes the fall angle, the state is not
    a finite number (diverged), or the law's command is (a ``bad_command``: NaN, infinite, beyond
    :data:`.safety.PLAUSIBLE_TORQUE`).  The trajectory's ``record`` then holds ``t_fall``, ``fall_text`` (the
    line saying when and why) and ``failure`` (the cause, a :data:`.trajectory.FAILURES` name).  A plant whose
    simulation diverges (:class:`~.plant.PlantDiverged`, backend mujoco) raises it, or with ``diverged_fails``
    (a sweep's scenario) ends the run as a ``diverged`` failure at the period it happened in.  ``on_period`` sees
    the plant at t_k each period, once its row is taken (``mwip_sim --render`` draws it); it must not change it.
    ``wrench(t_k)``: the external wrench held over period k (:class:`.loop.Period`; a terrain scan's push)."""
    pc = loop.plant
    h = pc.h
    n_steps = int(round(loop.duration_s / h))
    period = make_period(loop)   # the stages
    period.wrench = wrench
    # the true state: the metrics judge it
    table = TrajectoryTable(internals=True, raw=pc.raw is not None, drive=pc.motor.enabled or pc.raw is not None,
                            excitation=period.excitation is not None, motion=period.motion is not None,
                            pose=period.side.plant.spatial, yaw=period.yaw is not None)
    every = max(1, n_steps // 10)
    try:
        for k in range(n_steps + 1):
            ended = period.run(table)
            if on_period is not None:
                on_period(period.side.plant)
            if ended or k == n_steps or period.advance(table):
                break
            if progress is not None and k % every == 0:
                progress(k / n_steps)
    except PlantDiverged as exc:
        if not diverged_fails:
            raise
        period.failure = (period.side.plant.t, f"FAILED at t = {period.side.plant.t:.3f} s: {exc}",
                          FAILURES[DIVERGED])
    run = table.trajectory(label or loop.name, period.failure is not None, h)
    if period.failure is not None:   # the run's own record of its end (as a bag's plant log): when and why
        run.record.update(t_fall=period.failure[0], fall_text=period.failure[1], failure=period.failure[2])
    return run
