"""``MwipEnv``: one robot as a Gymnasium environment, a period of the offline loop per step.

An adapter over :class:`mwip_ros.core.closed_loop.loop.Period` (the stages of
:data:`mwip_ros.core.closed_loop.loop.STAGES`, built by
:func:`mwip_ros.core.closed_loop.sim.make_period` as :func:`mwip_ros.core.closed_loop.sim.simulate` builds them):
``reset`` builds the plant with its sensors and drive (:class:`~mwip_ros.core.closed_loop.loop.PlantSide`), the
observer, the estimator (raw sensors), the base law, the motion references (``motion.enabled``) and the yaw stage (a
spatial plant with motion), and runs the stages ``sensors`` to ``law`` of period 0
(:meth:`~mwip_ros.core.closed_loop.loop.Period.sense_decide`; the observation is what the law sees); ``step(a)`` adds
the action to the base law's command (the stage ``law``), runs ``yaw`` and ``drive``
(:meth:`~mwip_ros.core.closed_loop.loop.Period.actuate`) and ``plant`` of period k, then the stages up to the law of
period k + 1.  Actions equal to the law's own command give ``mwip_sim``'s trajectory of that law bit for bit
(``test/envs``, with motion references and the yaw stage too).
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable, Optional

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from mwip_ros.core.closed_loop.loop import Period
from mwip_ros.core.plants.plant import finite_state
from mwip_ros.core.closed_loop.sim import make_period
from mwip_ros.core.closed_loop.trajectory import BAD_COMMAND, DIVERGED, FAILURES, FALL

from . import checks
from .common import SEED_RANGE, ParamsArg, setup

__all__ = ["MwipEnv", "NoLaw"]

# with motion.enabled, what ``info`` adds of the period's references and the yaw stage (the trajectory's columns)
REFERENCES = ("v_ref", "theta_w_ref", "dpsi_ref", "u_psi")


class NoLaw:
    """The law stage without a law (the action is the whole command): u = 0, to which the action is added."""

    name = "none"
    # no observer term: core.closed_loop.loop.command hands the references without tau_hat (motion on)
    observer = False

    def track(self, ref) -> None:
        """The motion references (core.closed_loop.loop.command hands them to every law): nothing to track."""

    def step(self, x, tau_hat=None):
        return 0.0, {}


class MwipEnv(gym.Env):
    """The MWIP of the parameter files as a Gymnasium environment.

    Parameters
    ----------
    params : path, list of paths, dict or None
        The parameter files, merged in order as ``mwip_sim --params`` (None: the package's ``config/paper.yaml``),
        or merged values (``mwip_ros.params.merged_values``).
    duration : float, optional
        The episode's length [s] (default: ``plant_sim.duration_s``); the episode is truncated there.
    base_law : str, optional
        A registered law (``dscndo``, ``lqr``, ...): the action is a residual added to its command.  None: the
        action is the whole command.
    observation : {'state', 'raw'}
        ``state``: the state the law sees (the measurement, noisy, quantized, delayed as the files say; with raw
        sensors the estimator's state), (theta_w, theta_b, theta_w', theta_b').  ``raw``: the raw sample (gyro,
        accel_x, accel_z, encoder, encoder_rate; ``sensors.model: raw`` only).
    reward : callable, optional
        ``reward(x, u, x_next, fell) -> float`` (true states at t_k and t_k+1, the drive's torque); default
        :class:`~mwip_ros.envs.common.Reward`.
    torque_scale : float, optional
        S [N m]: the action a in [-1, 1] is the torque a S.  Default: the drive's ``torque_limit``, else the motor's
        peak torque, else :data:`~mwip_ros.envs.common.DEFAULT_TORQUE_SCALE` (256 N m).
    normalize_action : bool
        False: the action is the torque in N m, in [-S, S].
    sweep : path, optional
        A sweep spec (``mwip_sweep``'s, e.g. ``config/sweeps/mass_mismatch.yaml``) instead of ``params``: its base
        file, its duration (unless ``duration``), and on every reset one robot drawn from its ``vary`` axes as the
        sweep draws them (:func:`mwip_ros.sweep.scenarios.expand` with the episode's seed as the spec's seed; a grid
        point drawn too), ``info["robot"]`` its values.  The action's scale is the base file's.

    The episode is terminated when the robot falls (|theta_b| > ``fall_angle``), its state diverges or the drive
    refuses the command; truncated after ``duration`` / h periods.  ``reset(seed=s)`` seeds the episode's plant with
    s (its D_w noise and sensor noise, as ``plant_sim.seed: s``); without a seed, a seed drawn from the env's
    generator.  ``reset(options={"initial": (theta_w, theta_b, theta_w', theta_b')})`` sets the initial state.
    ``info``: ``t`` (t_k), ``state`` (the true state at t_k), ``u`` (the drive's torque over period k, after its limit
    and delay: the trajectory's ``u``), ``tau_hat`` and ``tau_d`` (the observer's estimate and the true lumped
    disturbance at t_k), ``failure``.
    """

    metadata = {"render_modes": []}

    def __init__(self, params: ParamsArg = None, duration: Optional[float] = None, base_law: Optional[str] = None,
                 observation: str = "state", reward: Optional[Callable] = None, torque_scale: Optional[float] = None,
                 normalize_action: bool = True, sweep=None, render_mode: Optional[str] = None):
        checks.render_mode(render_mode)   # gymnasium.make passes it: None, or one line (the env renders nothing)
        self.render_mode = None
        self._spec = None
        if sweep is not None:
            if params is not None:
                raise ValueError("sweep: a sweep spec names its own base file; give params or sweep, not both")
            from mwip_ros.sweep.spec import load_spec
            self._spec = load_spec(sweep)
            params = self._spec.base_values
            duration = self._spec.duration_s if duration is None else duration
        self._duration = duration
        self.setup = s = setup(params, duration, base_law, observation, reward, torque_scale, normalize_action)
        self.action_space = spaces.Box(-s.bound, s.bound, (1,), np.float64)
        self.observation_space = spaces.Box(-np.inf, np.inf, (5 if observation == "raw" else 4,), np.float64)
        self._period: Optional[Period] = None

    # --- the loop's stages ----------------------------------------------------------------------------------------

    def _robot(self, seed: int):
        """(the closed loop of the episode with ``seed``, the values a sweep spec drew for it or None)."""
        if self._spec is None:
            return self.setup.loop, None
        from mwip_ros import params as P
        from mwip_ros.sweep.scenarios import expand
        sc = expand(dataclasses.replace(self._spec, seed=int(seed), samples=1))
        i = int(np.random.default_rng(int(seed)).integers(len(sc)))   # a grid point, when the spec has a grid
        drawn = {k: v for k, v in sc.overrides(i).items() if k != "seed"}   # the noise seed is the episode's
        return P.closed_loop({**self._spec.base_values, **drawn}, duration=self._duration,
                             controller=self.setup.base_law), drawn

    def _build(self, loop, seed: int, initial=None) -> Period:
        pc = dataclasses.replace(loop.plant, seed=int(seed))
        if initial is not None:
            pc = dataclasses.replace(pc, initial=type(pc.initial)(*(float(v) for v in initial)))
        return make_period(loop, pc, None if self.setup.base_law else NoLaw())   # mwip_sim's stages, motion and yaw

    def _observe(self) -> np.ndarray:
        """Stages ``sensors``, ``estimator``, ``observer`` and ``law`` (the base law's command) of period k."""
        period = self._period
        p = period.side.plant
        if not finite_state(p.x):   # diverged (the episode has ended): nothing to sense, zeros
            self._u_base, self._tau_hat, self._dpsi, self._internals = 0.0, (0.0, 0.0), None, {}
            return np.zeros(self.observation_space.shape)
        measured, self._dpsi, self._u_base, self._tau_hat, self._internals, x_m = period.sense_decide()
        return np.array(measured if self.setup.observation == "raw" else x_m, dtype=np.float64)

    # --- gymnasium ------------------------------------------------------------------------------------------------

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        seed, initial = checks.seed(seed), checks.options(options)   # one line each for a wrong one
        super().reset(seed=seed)
        plant_seed = seed if seed is not None else int(self.np_random.integers(SEED_RANGE))
        loop, drawn = self._robot(plant_seed)
        self._period = self._build(loop, plant_seed, initial)
        p = self._period.side.plant
        obs = self._observe()
        info = {"t": p.t, "state": np.array(p.x, dtype=float), "seed": plant_seed}
        if drawn is not None:
            info["robot"] = drawn
        return obs, info

    def step(self, action) -> tuple:
        if self._period is None:
            raise RuntimeError("MwipEnv.step before reset")
        period, s = self._period, self.setup
        side = period.side
        p = side.plant
        t, x = p.t, p.x
        a = checks.action(action)   # one number (beyond the bound: clipped; not finite: the drive refuses it)
        u_cmd = self._u_base + float(s.torque(a))           # stage law: the base law's command plus the action
        u, tau_d, internals = period.actuate(u_cmd, self._dpsi, self._internals)   # stages yaw and drive
        failure = None
        if side.safety.faulted and side.safety.fault_reason == "bad_command":
            failure = FAILURES[BAD_COMMAND]
        else:
            period.u = u
            if period.advance():                             # stage plant (RK4); True: the arithmetic failed
                failure = FAILURES[DIVERGED]
            elif p.fallen:
                failure = FAILURES[FALL] if finite_state(p.x) else FAILURES[DIVERGED]
        terminated = failure is not None
        truncated = not terminated and p.k >= s.n_steps
        reward = float(s.reward(x, u, p.x, terminated))
        info: dict[str, Any] = {"t": t, "state": np.array(x, dtype=float), "u": u, "tau_hat": self._tau_hat,
                                "tau_d": tau_d, "failure": failure}
        info.update({k: internals[k] for k in REFERENCES if k in internals})   # motion on: the references, yaw
        obs = self._observe()
        return obs, reward, terminated, truncated, info
