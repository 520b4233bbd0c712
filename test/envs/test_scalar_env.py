"""MwipEnv (mwip_ros.envs.scalar): an episode whose actions are a law's own command is mwip_sim's trajectory of that
law bit for bit (the reference computed by core.closed_loop.sim.simulate from the same files, not through the env);
Gymnasium's own checker passes; the spaces, the ends of an episode, the seeds and the refusals."""
import dataclasses
import math

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

from gymnasium.utils.env_checker import check_env  # noqa: E402

from mwip_ros import params as P  # noqa: E402
from mwip_ros.core import laws   # noqa: E402
from mwip_ros.core.control.observer import DiscreteObserver, gain_matrix  # noqa: E402
from mwip_ros.core.closed_loop.sim import simulate  # noqa: E402
from mwip_ros.envs import ENV_ID, MwipEnv, load_values  # noqa: E402
from mwip_ros.params.paths import default_params_file  # noqa: E402

pytestmark = pytest.mark.unit

CONFIG = default_params_file().parent
PAPER = [CONFIG / "paper.yaml"]
REALISTIC = PAPER + [CONFIG / "sensing_realistic.yaml", CONFIG / "motor_realistic.yaml"]
RAW = PAPER + [CONFIG / "sensors_raw_realistic.yaml"]


def reference(files, law, duration, seed):
    """mwip_sim's run of ``law`` on ``files`` with plant_sim.seed ``seed`` (core.closed_loop.sim.simulate, no env)."""
    loop = P.closed_loop(load_values(files), duration=duration, controller=law)
    return simulate(dataclasses.replace(loop, plant=dataclasses.replace(loop.plant, seed=seed))).columns


def episode(env, policy, seed):
    """Run one episode; (true states, torques that acted, rewards, the last step's terminated, truncated)."""
    obs, info = env.reset(seed=seed)
    xs, us, rs = [info["state"]], [], []
    while True:
        obs, r, terminated, truncated, info = env.step(policy(obs, info))
        us.append(info["u"])
        rs.append(r)
        if terminated or truncated:
            return np.array(xs), np.array(us), rs, terminated, truncated, obs
        xs.append(env.unwrapped._period.side.plant.x)


def assert_same_rows(xs, us, ref):
    n = len(us)
    assert n > 100
    for j, c in enumerate(("theta_w", "theta_b", "dtheta_w", "dtheta_b")):
        assert np.array_equal(xs[:n, j], ref[c][:n]), c
    assert np.array_equal(us, ref["u"][:n])


def test_the_laws_own_command_as_a_normalised_action_is_mwip_sims_run_bit_for_bit():
    """The policy is DSCNDO itself, computed here from the observations (the measured state) with the core's observer
    and law, its command divided by the action's scale (256 N m on the paper's robot: exact)."""
    env = MwipEnv(PAPER, duration=3.0)
    assert env.setup.scale == 256.0 and env.action_space.high[0] == 1.0
    loop = env.setup.loop
    pc = loop.plant
    law = laws.get("dscndo")(laws.get("dscndo").design(load_values(PAPER), pc.nominal, pc.h), pc.nominal, pc.h)
    obs_ = DiscreteObserver(pc.nominal, gain_matrix(loop.X), pc.h)
    last = [0.0]

    def dscndo(obs, info):
        u_prev = info.get("u", 0.0)
        tau_hat = obs_.update(tuple(float(v) for v in obs), u_prev)
        u = law.step(tuple(float(v) for v in obs), tau_hat)[0]
        last[0] = u
        return np.array([u / 256.0])

    xs, us, rs, terminated, truncated, _ = episode(env, dscndo, seed=0)
    assert truncated and not terminated and len(us) == 600
    assert_same_rows(xs, us, reference(PAPER, "dscndo", 3.0, 0))


@pytest.mark.parametrize("files, law, seed, duration", [
    (PAPER, "dscndo", 0, 2.0), (REALISTIC, "dscndo", 7, 2.0), (RAW, "lqr_ndo", 3, 2.0), (REALISTIC, "lqr", 11, 2.0),
    # the motion references and the hold (theory 6.11, 6.14) on laws other than DSCNDO, and the paper's file
    (PAPER + [CONFIG / "motion.yaml"], "lqr_ndo", 4, 12.0),
    (PAPER + [CONFIG / "motion.yaml", CONFIG / "sensing_realistic.yaml"], "dsc", 9, 12.0), (PAPER, "dsc", 1, 12.0)])
def test_a_zero_residual_on_a_base_law_is_mwip_sims_run_of_that_law_bit_for_bit(files, law, seed, duration):
    """Sensor noise, encoder, delays, the motor, the raw IMU with the Kalman filter, the motion references: every
    stage of the files."""
    env = MwipEnv(files, duration=duration, base_law=law)
    xs, us, rs, terminated, truncated, _ = episode(env, lambda o, i: np.zeros(1), seed)
    assert truncated and not terminated
    assert_same_rows(xs, us, reference(files, law, duration, seed))


def test_a_zero_residual_with_motion_references_is_mwip_sims_run_bit_for_bit():
    """config/motion.yaml (the references every law tracks, theory 6.11): 1 m/s from 2 s. The env before it ran the
    motion stage regulated to rest instead (theta_w at 12 s: -10.71 rad against mwip_sim's +32.69 rad)."""
    files = PAPER + [CONFIG / "motion.yaml"]
    env = MwipEnv(files, duration=12.0, base_law="dscndo")
    xs, us, rs, terminated, truncated, _ = episode(env, lambda o, i: np.zeros(1), 5)
    assert truncated and not terminated
    ref = reference(files, "dscndo", 12.0, 5)
    assert_same_rows(xs, us, ref)
    assert xs[-1, 0] > 30.0   # it drove: 1 m/s from 2 s on wheels of r = 0.25 m (not regulated to rest)


def test_without_a_base_law_the_action_is_the_whole_command_with_motion_references_too():
    """The files' motion references on (config/motion.yaml) and no base law: the action is the whole command, the
    torque that acts (the env raised AttributeError before: its NoLaw had no ``observer``, which the law stage reads
    with the references)."""
    env = MwipEnv(PAPER + [CONFIG / "motion.yaml"], duration=1.0, normalize_action=False)
    obs, info = env.reset(seed=3)
    obs, r, terminated, truncated, info = env.step(np.array([5.0]))
    assert info["u"] == 5.0 and info["v_ref"] == 0.0 and not terminated


def test_the_yaw_stage_of_a_spatial_plant_is_mwip_sims_bit_for_bit():
    """The MuJoCo plant with motion and the yaw stage (theory 6.13: u_psi, the wheels' pair), a turn in place of
    0.5 rad/s from 0.5 s: the env runs the period's yaw stage as mwip_sim does (the residual adds to the law's
    command, the yaw stage splits it)."""
    pytest.importorskip("mujoco")
    values = {**load_values(PAPER + [CONFIG / "square.yaml"]), "mujoco.timestep": 0.005,
              "motion.profile": [0.0, 0.0], "motion.yaw_profile": [0.0, 0.0, 0.5, 0.5]}
    env = MwipEnv(values, duration=1.5, base_law="dscndo")
    xs, us, rs, terminated, truncated, _ = episode(env, lambda o, i: np.zeros(1), 2)
    assert truncated and not terminated
    loop = P.closed_loop(values, duration=1.5, controller="dscndo")
    ref = simulate(dataclasses.replace(loop, plant=dataclasses.replace(loop.plant, seed=2))).columns
    assert_same_rows(xs, us, ref)
    obs, info = env.reset(seed=2)
    for _ in range(250):
        obs, r, terminated, truncated, info = env.step(np.zeros(1))
    assert info["dpsi_ref"] == pytest.approx(0.5) and info["u_psi"] == ref["u_psi"][249] != 0.0   # it turns


def test_the_torque_in_newton_metres_passes_exactly_through_a_torque_limit():
    """normalize_action False: the action is the torque; the law's command beyond the limit is clipped to it as
    mwip_sim's drive clips it."""
    values = {**load_values(PAPER), "torque_limit": 150.0}
    env = MwipEnv(values, duration=1.0, normalize_action=False)
    assert env.setup.scale == 150.0 and env.action_space.high[0] == 150.0
    loop = env.setup.loop
    pc = loop.plant
    law = laws.get("dsc")(laws.get("dsc").design(values, pc.nominal, pc.h), pc.nominal, pc.h)
    xs, us, *_ = episode(env, lambda o, i: np.array([law.step(tuple(map(float, o)))[0]]), 0)
    ref = reference(values, "dsc", 1.0, 0)
    assert np.abs(ref["u"]).max() == 150.0   # the limit is reached
    assert_same_rows(xs, us, ref)


@pytest.mark.parametrize("kwargs", [{}, {"base_law": "dscndo"}, {"params": RAW, "observation": "raw"},
                                    {"params": RAW}])
def test_gymnasiums_env_checker_passes(kwargs):
    import warnings
    env = MwipEnv(**{"duration": 1.0, **kwargs})
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    # only the advice on the unbounded observation (theta_w is an angle without bounds)
    assert all("infinity" in str(w.message) for w in said), [str(w.message) for w in said]
    assert env.observation_space.shape == ((5,) if kwargs.get("observation") == "raw" else (4,))


def test_registered_ids_make_the_env_and_by_module_prefix():
    env = gym.make(ENV_ID, duration=0.5)
    assert isinstance(env.unwrapped, MwipEnv)
    env2 = gym.make("mwip_ros.envs:" + ENV_ID, duration=0.5, base_law="lqr")
    assert env2.unwrapped.setup.base_law == "lqr"


def test_a_full_torque_push_falls_terminates_with_the_fall_penalty():
    env = MwipEnv(PAPER, duration=5.0)
    xs, us, rs, terminated, truncated, obs = episode(env, lambda o, i: np.array([1.0]), 0)
    assert terminated and not truncated
    x_end = env.unwrapped._period.side.plant.x
    assert abs(x_end[1]) > 1.0472 and all(abs(x[1]) <= 1.0472 for x in xs)
    assert rs[-1] == -100.0 and all(-100.0 < r <= 1.0 for r in rs[:-1])
    assert np.all(us == 256.0)


def test_the_default_reward_is_the_documented_sum():
    env = MwipEnv(PAPER, duration=0.1, base_law="dscndo")
    obs, info = env.reset(seed=0)
    obs, r, *_ , info = env.step(np.array([0.5]))
    x1 = env._period.side.plant.x
    u = info["u"]
    want = 1.0 - (x1[1] / 1.0472) ** 2 - 0.01 * x1[3] ** 2 - 0.01 * (u / 256.0) ** 2
    assert math.isclose(r, want, rel_tol=1e-12) and r < 1.0


def test_a_reward_callable_replaces_the_default():
    seen = []

    def mine(x, u, x_next, fell):
        seen.append((x[1], u))
        return -abs(x_next[1])

    env = MwipEnv(PAPER, duration=0.1, reward=mine)
    env.reset(seed=0)
    _, r, *_ = env.step(np.array([0.0]))
    assert r == -abs(env._period.side.plant.x[1]) and seen == [(-0.1745, 0.0)]


def test_the_seed_is_the_plants_noise_seed():
    def thetas(seed):
        env = MwipEnv(REALISTIC, duration=0.5, base_law="dscndo")
        xs, *_ = episode(env, lambda o, i: np.zeros(1), seed)
        return xs[:, 1]
    a, b, c = thetas(1), thetas(1), thetas(2)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_reset_options_set_the_initial_state():
    env = MwipEnv(PAPER, duration=0.1)
    obs, info = env.reset(seed=0, options={"initial": (0.0, 0.05, 0.0, 0.0)})
    assert obs[1] == 0.05 and info["state"][1] == 0.05


@pytest.mark.parametrize("kwargs, key", [
    ({"base_law": "nope"}, "base_law"), ({"observation": "pixels"}, "observation"),
    ({"observation": "raw"}, "observation"), ({"torque_scale": -1.0}, "torque_scale"), ({"duration": 0.0}, "duration")])
def test_a_wrong_argument_is_refused_naming_it(kwargs, key):
    with pytest.raises(ValueError) as err:
        MwipEnv(PAPER, **kwargs)
    assert str(err.value).startswith(f"{key}:"), err.value


def test_a_wrong_parameter_file_is_refused_naming_the_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("plant_sim:\n  ros__parameters:\n    fall_angle: -1.0\n")
    with pytest.raises(P.ParamError) as err:
        MwipEnv(PAPER + [bad])
    assert "fall_angle" in str(err.value)


def test_a_sweep_spec_draws_a_robot_per_episode_and_the_episode_is_mwip_sims_of_that_robot():
    """sweep=mass_mismatch.yaml: each reset draws m_b, I_b and l from [0.7, 1.3] x the paper's true values, seeded
    by the episode's seed; the episode (a zero residual on DSCNDO) is mwip_sim's run of that robot bit for bit."""
    from mwip_ros.sweep.spec import load_spec
    path = CONFIG / "sweeps" / "mass_mismatch.yaml"
    base = load_spec(path).base_values
    env = MwipEnv(sweep=path, duration=1.0, base_law="dscndo")
    drawn = {}
    for seed in (5, 6, 5):
        obs, info = env.reset(seed=seed)
        robot = info["robot"]
        assert set(robot) == {"actual.m_b", "actual.I_b", "actual.l"}
        for key, value in robot.items():
            assert 0.7 * base[key] <= value <= 1.3 * base[key] and value != base[key], key
        drawn.setdefault(seed, robot)
        assert drawn[seed] == robot   # the same seed, the same robot
    assert drawn[5] != drawn[6]
    xs, us, *_ = episode(env, lambda o, i: np.zeros(1), 6)
    assert_same_rows(xs, us, reference({**base, **drawn[6]}, "dscndo", 1.0, 6))


def test_sweep_and_params_together_are_refused():
    with pytest.raises(ValueError) as err:
        MwipEnv(PAPER, sweep=CONFIG / "sweeps" / "mass_mismatch.yaml")
    assert str(err.value).startswith("sweep:")
