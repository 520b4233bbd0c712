"""``MwipVectorEnv``: N robots of the parameter files as one ``gymnasium.vector.VectorEnv``, one call of the array
stepper (:class:`~mwip_ros.envs.lanes.Lanes`) per step for all of them.

The spaces, the action's scale, the reward and the ends of an episode are :class:`~mwip_ros.envs.scalar.MwipEnv`'s.
Autoreset is Gymnasium's ``NEXT_STEP`` mode: the step after a robot's episode ended restarts it (its action is
ignored, its reward 0, its observation the first of the new episode); the restart sets that robot's entries of the
arrays, nothing is built again, and the robot's noise streams go on.  ``reset(seed=s)`` seeds robot i's plant with
s + i (its D_w and sensor noise, as ``plant_sim.seed``), so its first episode is ``mwip_sim``'s with that seed.
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from mwip_ros.optional import required

from . import checks
from .common import SEED_RANGE, ParamsArg, setup

with required("numba", "MwipVectorEnv (its compiled RK4)"):
    from .lanes import Lanes

__all__ = ["MwipVectorEnv"]



class MwipVectorEnv(VectorEnv):
    """``num_envs`` robots of the parameter files (the arguments as :class:`~mwip_ros.envs.scalar.MwipEnv`'s).  The
    files may set the state sensors (noise, encoder, delay) or raw sensors with their estimator (``observation``:
    ``state`` the estimate, ``raw`` the raw samples), the torque limit, the actuator delay, the motor, D_w, tau_ext,
    the model error, the excitation, the driver nobody enables (``require_enable``) and the motion references
    (``motion.enabled``, docs/theory.md 6.11: the base law tracks them as in ``mwip_sim``); another plant backend,
    and the motion references with ``require_enable``, are refused naming the key (``MwipEnv`` runs them).  Each
    step runs the stages of :data:`mwip_ros.core.closed_loop.loop.STAGES` with the compiled loop's own stage functions
    (:class:`~mwip_ros.envs.lanes.Lanes`); the action, a residual torque, is added to the base law's command (the
    stage ``law``, where the excitation is added) before the stage ``drive``.
    ``sweep``: a sweep spec instead of ``params``
    (:class:`~mwip_ros.envs.robots.SpecRobots`: it may vary the true robot only): ``reset(seed=s)`` gives robot i
    scenario i of the spec with ``seed: s`` and ``samples: num_envs`` (its true robot and its noise seed); a restarted
    robot takes the next scenario, then those of the spec with seed s + 1, s + 2, ...  ``infos``: ``u`` (the torque
    after the drive's limit and delay, as ``MwipEnv``'s ``info["u"]``), ``failure`` (0, or the
    :data:`mwip_ros.core.closed_loop.trajectory.FAILURES` index of why the episode ended)."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, params: ParamsArg = None, duration: Optional[float] = None,
                 base_law: Optional[str] = None, observation: str = "state", reward: Optional[Callable] = None,
                 torque_scale: Optional[float] = None, normalize_action: bool = True, sweep=None,
                 render_mode: Optional[str] = None):
        checks.render_mode(render_mode)
        self.render_mode = None
        self.num_envs = n = checks.num_envs(num_envs)
        self.robots = None
        if sweep is not None:
            if params is not None:
                raise ValueError("sweep: a sweep spec names its own base file; give params or sweep, not both")
            from mwip_ros.sweep.spec import load_spec
            from .robots import SpecRobots
            spec = load_spec(sweep)
            self.robots = SpecRobots(spec, n)
            params = spec.base_values
            duration = spec.duration_s if duration is None else duration
        self.setup = s = setup(params, duration, base_law, observation, reward, torque_scale, normalize_action)
        checks.num_envs(n, s)   # the robots' memory, estimated before any is allocated: within the budget
        self.lanes = Lanes(s, n)
        self.single_action_space = spaces.Box(-s.bound, s.bound, (1,), np.float64)
        width = 5 if observation == "raw" else 4
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (width,), np.float64)
        self.action_space = batch_space(self.single_action_space, n)
        self.observation_space = batch_space(self.single_observation_space, n)
        self._restart = np.zeros(n, dtype=bool)
        self._obs = np.zeros((n, width))
        self._ready = False   # reset() first

    def _observation(self) -> np.ndarray:
        xm = self.lanes.observe()
        if self.setup.observation == "raw":   # the raw samples (delayed, as the estimator got them)
            return self.lanes.sample.copy()
        for j in range(4):
            self._obs[:, j] = xm[j]
        return self._obs.copy()

    def reset(self, *, seed=None, options: Optional[dict] = None):
        """Every robot at t = 0; ``seed``: an int s (robot i: s + i), a list of one per robot, or None (drawn).
        With a sweep spec, an int or None: the spec's seed (robot i: its scenario i, its noise seed too)."""
        n = self.num_envs
        if options is not None:
            raise ValueError("options: MwipVectorEnv takes none (every robot starts in the files' initial state)")
        if seed is None or checks.whole(seed):
            seed = checks.seed(seed, 1 if self.robots is not None else n)
        super().reset(seed=seed if isinstance(seed, int) else None)
        if self.robots is not None:
            if not (seed is None or isinstance(seed, (int, np.integer))):
                raise ValueError("seed: with a sweep spec, one seed (the spec's) or None")
            self._pool_seed = int(seed) if seed is not None else int(self.np_random.integers(SEED_RANGE))
            self._pool, seeds = self.robots.pool(self._pool_seed)
            self._pool_next = n
            self.lanes.robot[:] = self._pool[:n].T
            seeds = seeds[:n]
        elif seed is None:
            seeds = self.np_random.integers(SEED_RANGE, size=n)
        elif isinstance(seed, (int, np.integer)):
            seeds = int(seed) + np.arange(n)
        else:
            seeds = checks.seeds(seed, n)
        self.lanes.restart(np.ones(n, dtype=bool), seeds)
        self._restart[:] = False
        self._ready = True
        return self._observation(), {"seed": np.asarray(seeds)}

    def step(self, actions):
        if not self._ready:
            raise RuntimeError("MwipVectorEnv.step before reset")
        s, lanes = self.setup, self.lanes
        a = checks.actions(actions, self.num_envs)   # one per robot (beyond the bound: clipped)
        go = ~self._restart
        x_k = lanes.x
        u, code = lanes.advance(lanes.u_base + s.torque(a), go)
        terminated = code > 0
        truncated = go & ~terminated & (lanes.k >= s.n_steps)
        reward = np.asarray(s.reward(x_k, u, lanes.x, terminated), dtype=float)
        if self._restart.any():   # NEXT_STEP autoreset: these robots start again instead of stepping
            reward = np.where(go, reward, 0.0)
            if self.robots is not None:
                self._next_robots(self._restart)
            lanes.restart(self._restart)
        obs = self._observation()
        self._restart = terminated | truncated
        return obs, reward, terminated, truncated, {"u": u, "failure": code}

    def _next_robots(self, mask: np.ndarray) -> None:
        """The robots of ``mask`` take the next robots of the pool (then of the spec with the next seed)."""
        idx = np.flatnonzero(mask)
        rows = []
        while len(rows) < len(idx):
            if self._pool_next == len(self._pool):
                self._pool_seed += 1
                self._pool, _ = self.robots.pool(self._pool_seed)
                self._pool_next = 0
            take = min(len(idx) - len(rows), len(self._pool) - self._pool_next)
            rows.extend(self._pool[self._pool_next:self._pool_next + take])
            self._pool_next += take
        self.lanes.robot[:, idx] = np.array(rows).T
