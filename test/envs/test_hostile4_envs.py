"""The Gymnasium environments against a hostile caller (issue 46 items 7, 8): one clear line (ValueError naming the
argument) instead of a traceback, a silent reshape or a silent clip; the vector env's size checked against the memory
budget before anything is allocated (before: num_envs 10^7 allocated until MemoryError at 19.1 GiB)."""
import math

import numpy as np
import pytest

pytest.importorskip("gymnasium")

import gymnasium as gym  # noqa: E402

from mwip_ros.envs import ENV_ID, MwipEnv  # noqa: E402
from mwip_ros.envs.checks import MAX_SEED  # noqa: E402

pytestmark = pytest.mark.unit


@pytest.fixture(scope="module")
def env():
    return MwipEnv(duration=0.1)


@pytest.fixture(scope="module")
def venv():
    pytest.importorskip("numba")
    from mwip_ros.envs import MwipVectorEnv
    return MwipVectorEnv(4, duration=0.1)


@pytest.mark.parametrize("action, words", [(np.ones(5), "one number"), (np.array([0.1, 0.2]), "one number"),
                                           ("x", "not a number")])
def test_a_scalar_action_of_another_shape_is_refused(env, action, words):
    env.reset(seed=0)
    with pytest.raises(ValueError, match=words):   # was: the first entry taken
        env.step(action)


@pytest.mark.parametrize("action", [np.inf, -np.inf, np.nan])
def test_a_non_finite_action_is_refused_by_the_drive_alike(env, action):
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(action)   # inf was clipped to the bound: 256 N m
    assert terminated and info["failure"] == "bad_command" and info["u"] == 0.0


@pytest.mark.parametrize("options, words", [({"initial": (math.nan, 0.0, 0.0, 0.0)}, "initial.theta_w"),
                                            ({"initial": (0.0, 10.0, 0.0, 0.0)}, "initial.theta_b"),
                                            ({"initial": (0.0, 0.0)}, "four numbers"),
                                            ({"start": 1}, "unknown start")])
def test_reset_options_that_are_not_an_initial_state_are_refused(env, options, words):
    with pytest.raises(ValueError, match=words):   # NaN was accepted
        env.reset(seed=0, options=options)
    _, info = env.reset(seed=0, options={"initial": (0.0, 0.1, 0.0, 0.0)})
    assert info["state"][1] == 0.1


@pytest.mark.parametrize("seed", [-1, 1.5, True, MAX_SEED + 1])
def test_a_seed_plant_sim_cannot_hold_is_refused(env, seed):
    with pytest.raises(ValueError, match="seed: a whole number from 0 to 2\\*\\*63 - 1"):
        env.reset(seed=seed)
    assert env.reset(seed=MAX_SEED - 1)[1]["seed"] == MAX_SEED - 1


def test_render_mode_is_one_line():
    with pytest.raises(ValueError, match="render_mode: 'human': the MWIP environments render nothing"):
        gym.make(ENV_ID, render_mode="human")   # was: TypeError from the constructor
    gym.make(ENV_ID, render_mode=None).close()


def test_the_vector_env_refuses_what_it_would_reshape_or_guess(venv):
    with pytest.raises(RuntimeError, match="before reset"):   # was: AttributeError
        type(venv)(2, duration=0.1).step(np.zeros(2))
    venv.reset(seed=0)
    for bad in (np.zeros((2, 2)), np.zeros(5), np.zeros((4, 2))):
        with pytest.raises(ValueError, match=r"one per robot, shape \(4,\) or \(4, 1\)"):   # (2, 2) was reshaped
            venv.step(bad)
    _, _, terminated, _, info = venv.step(np.array([np.inf, np.nan, 0.0, 0.0]))
    assert terminated.tolist() == [True, True, False, False] and info["u"][0] == 0.0
    with pytest.raises(ValueError, match="options"):
        venv.reset(seed=0, options={"initial": (0, 0, 0, 0)})
    with pytest.raises(ValueError, match=r"2\*\*63 - 4"):   # robot 3's seed s + 3 would not fit plant_sim.seed
        venv.reset(seed=MAX_SEED - 1)
    assert venv.reset(seed=MAX_SEED - 3)[1]["seed"][-1] == MAX_SEED


@pytest.mark.parametrize("n", [10 ** 7, 10 ** 6])
def test_a_vector_env_beyond_the_memory_budget_is_refused_before_it_allocates(n, monkeypatch):
    pytest.importorskip("numba")
    import tracemalloc

    from mwip_ros.envs import MwipVectorEnv
    monkeypatch.delenv("MWIP_MEMORY_BUDGET", raising=False)
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match=r"num_envs: .* robots would take about .* more than the memory budget"):
            MwipVectorEnv(n, duration=0.1)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 << 20, peak   # (10^6 took 3.5 GiB and 73 s)
    monkeypatch.setenv("MWIP_MEMORY_BUDGET", "64G")
    from mwip_ros.envs import checks
    assert checks.num_envs(10 ** 6, MwipVectorEnv(2, duration=0.1).setup) == 10 ** 6   # a larger budget takes it
