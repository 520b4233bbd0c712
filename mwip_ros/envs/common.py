"""What the scalar and the vector environment share: the parameter files, the action's scale, the reward.

The environments are configured as ``mwip_sim`` is (:func:`mwip_ros.params.closed_loop` of the merged parameter
files): the robot, its model error, the disturbances, the sensors (the state, or raw with an estimator), the drive
and the delays all come from the files.  Nothing here is an equation of the loop; the loop's own stages
(:mod:`mwip_ros.core.closed_loop.loop`) run the robot.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence, Union

import numpy as np

from mwip_ros import params as P
from mwip_ros.core import laws
from mwip_ros.core.closed_loop.sim import ClosedLoop
from mwip_ros.params.paths import default_params_file

__all__ = ["DEFAULT_TORQUE_SCALE", "OBSERVATIONS", "SEED_RANGE", "Reward", "EnvSetup", "load_values", "setup"]

SEED_RANGE = 2 ** 31   # a robot's plant seed, when reset is given none, is drawn from [0, 2^31)

# the action's scale [N m] when the files set neither a torque limit nor the motor (the paper's robot): a power of
# two (a * 256 and u / 256 are exact), above the paper's largest DSCNDO command (212 N m at t = 0)
DEFAULT_TORQUE_SCALE = 256.0
OBSERVATIONS = ("state", "raw")   # what the policy sees: the state the law sees, or the raw sample (sensors raw)

ParamsArg = Union[None, str, Path, Sequence[Union[str, Path]], Mapping[str, Any]]


def load_values(params: ParamsArg) -> dict:
    """The merged values (:func:`mwip_ros.params.merged_values`) of ``params``: None (the package's
    ``config/paper.yaml``), a parameter file, a list of them (merged in order, as ``mwip_sim --params``), or a dict
    of merged values already loaded.  A bad file raises :class:`mwip_ros.params.ParamError` naming the key."""
    if isinstance(params, Mapping):
        return dict(params)
    if params is None:
        paths = [default_params_file()]
    elif isinstance(params, (str, Path)):
        paths = [Path(params)]
    else:
        paths = [Path(p) for p in params]
    return P.merged_values(P.load_param_files(paths, option="params"))


@dataclass(frozen=True)
class Reward:
    """The default reward of one period k (the true state, not the measurement; every term dimensionless)::

        r_k = alive - pitch (theta_b / fall_angle)^2 - rate theta_b'^2 - torque (u_k / S)^2     (upright at t_k+1)
        r_k = -fall                                                                               (fallen: terminated)

    with theta_b, theta_b' of the state at t_k+1, u_k the drive's torque over the period (after its limit and delay;
    with the motor model, the motor's command) and S the action's
    scale.  Called with floats (the scalar env) or arrays (the vector env, one entry per robot).  Any callable
    ``reward(x, u, x_next, fell) -> float`` replaces it (``MwipEnv(reward=...)``)."""

    fall_angle: float
    scale: float
    alive: float = 1.0
    pitch: float = 1.0
    rate: float = 0.01
    torque: float = 0.01
    fall: float = 100.0

    def __call__(self, x, u, x_next, fell):
        b, db = x_next[1], x_next[3]
        with np.errstate(invalid="ignore", over="ignore"):
            r = (self.alive - self.pitch * (b / self.fall_angle) ** 2 - self.rate * db * db
                 - self.torque * (u / self.scale) ** 2)
        return np.where(fell, -self.fall, r) if isinstance(r, np.ndarray) else (-self.fall if fell else float(r))


@dataclass(frozen=True)
class EnvSetup:
    """One environment's configuration: the closed loop of the files (the plant, the observer, the law), the
    base law (None: the action is the whole command), the action's scale S [N m], the number of periods."""

    loop: ClosedLoop
    base_law: Optional[str]
    scale: float
    normalize: bool
    observation: str
    n_steps: int
    reward: Callable

    @property
    def bound(self) -> float:
        """The action space's bound: 1 (normalised) or S [N m]."""
        return 1.0 if self.normalize else self.scale

    def torque(self, a):
        """The torque [N m] of the action ``a`` (clipped to the action space): a S, or a itself.  An action that is
        not finite stays so, NaN and infinite alike: the drive refuses it (``bad_command``), it is never a torque at
        the bound."""
        a = np.where(np.isfinite(a), np.clip(a, -self.bound, self.bound), a)
        return a * self.scale if self.normalize else a


def _scale(plant, torque_scale: Optional[float]) -> float:
    """S: ``torque_scale``, else the drive's torque limit, else the motor's peak, else DEFAULT_TORQUE_SCALE."""
    if torque_scale is not None:
        if not (math.isfinite(torque_scale) and torque_scale > 0):
            raise ValueError(f"torque_scale: must be a finite number > 0 [N m], got {torque_scale!r}")
        return float(torque_scale)
    if plant.torque_limit > 0:
        return float(plant.torque_limit)
    if plant.motor.enabled:
        return float(plant.motor.peak_torque)
    return DEFAULT_TORQUE_SCALE


def setup(params: ParamsArg = None, duration: Optional[float] = None, base_law: Optional[str] = None,
          observation: str = "state", reward: Optional[Callable] = None, torque_scale: Optional[float] = None,
          normalize_action: bool = True) -> EnvSetup:
    """The :class:`EnvSetup` of the environments' arguments; a wrong one raises ValueError naming it (a wrong
    parameter file: :class:`mwip_ros.params.ParamError` naming the key)."""
    values = load_values(params)
    if base_law is not None and base_law not in laws.names():
        raise ValueError(f"base_law: {base_law!r} is not a registered law ({', '.join(laws.names())})")
    if base_law is not None and laws.unavailable(laws.get(base_law)):
        raise ValueError(f"base_law: {laws.unavailable(laws.get(base_law))}")
    if observation not in OBSERVATIONS:
        raise ValueError(f"observation: {observation!r} is not one of {', '.join(OBSERVATIONS)}")
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration: must be a finite number > 0 [s], got {duration!r}")
    loop = P.closed_loop(values, duration=duration, controller=base_law)
    if observation == "raw" and loop.plant.raw is None:
        raise ValueError("observation: 'raw' needs raw sensors in the parameter files (plant_sim sensors.model: raw)")
    n_steps = int(round(loop.duration_s / loop.plant.h))
    if n_steps < 1:
        raise ValueError(f"duration: {loop.duration_s:g} s is less than one control period")
    scale = _scale(loop.plant, torque_scale)
    return EnvSetup(loop, base_law, scale, bool(normalize_action), observation, n_steps,
                    reward if reward is not None else Reward(loop.plant.fall_angle, scale))
