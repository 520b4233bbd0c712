"""MwipVectorEnv (mwip_ros.envs.vector over envs.lanes): a law's own command as the actions equals the batch
simulator (core.kernels.batch.simulate_batch: its trajectories and the compiled loop's metrics, computed here from the
same files, not through the env) to 1e-9; autoreset restarts a robot in place; the refusals."""
import dataclasses

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

from mwip_ros import params as P  # noqa: E402
from mwip_ros.core import laws   # noqa: E402
from mwip_ros.core.kernels.batch import simulate_batch  # noqa: E402
from mwip_ros.core.kernels.budget import window_samples  # noqa: E402
from mwip_ros.core.control.observer import DiscreteObserver  # noqa: E402
from mwip_ros.envs import ENV_ID, MwipVectorEnv, load_values  # noqa: E402
from mwip_ros.params.paths import default_params_file  # noqa: E402

pytestmark = pytest.mark.unit

CONFIG = default_params_file().parent
PAPER = [CONFIG / "paper.yaml"]
SENSING = PAPER + [CONFIG / "sensing_realistic.yaml"]
MOTOR = SENSING + [CONFIG / "motor_realistic.yaml"]
CHIRP = PAPER + [CONFIG / "identify.yaml"]   # the identification's chirp added to the law's command
RAW = PAPER + [CONFIG / "sensors_raw_realistic.yaml"]   # raw sensors, the kalman estimator
MOTION = PAPER + [CONFIG / "motion.yaml"]   # the motion references every law tracks (theory 6.11)
N, SEED, DURATION, WINDOW = 6, 40, 2.0, (1.0, 2.0)


def batch(files, law):
    """simulate_batch of robots SEED + i: (its trajectories, the compiled loop's metrics)."""
    loop = P.closed_loop(load_values(files), duration=DURATION, controller=law)
    loops = [dataclasses.replace(loop, plant=dataclasses.replace(loop.plant, seed=SEED + i)) for i in range(N)]
    recorded = simulate_batch(loops, WINDOW, record=True)
    compiled = simulate_batch(loops, WINDOW, compiled=True)
    return recorded.trajectories, compiled.metrics


def run(env, policy):
    """One episode of every robot: true states (steps + 1, N, 4), torques (steps, N); every robot truncated."""
    obs, _ = env.reset(seed=SEED)
    xs, us = [np.stack(env.lanes.x, 1)], []
    while True:
        obs, r, terminated, truncated, info = env.step(policy(obs, us[-1] if us else np.zeros(N)))
        us.append(info["u"])
        xs.append(np.stack(env.lanes.x, 1))
        assert not terminated.any()
        if truncated.any():
            assert truncated.all()
            return np.array(xs), np.array(us)


def check_against_batch(xs, us, trajectories, metrics, h):
    n_steps = us.shape[0]
    for i, tr in enumerate(trajectories):
        c = tr.columns
        assert len(c["u"]) == n_steps + 1
        for j, name in enumerate(("theta_w", "theta_b", "dtheta_w", "dtheta_b")):
            assert np.allclose(xs[:, i, j], c[name], rtol=0, atol=1e-9), (i, name)
        assert np.allclose(us[:, i], c["u"][:-1], rtol=0, atol=1e-9), i
    first, count = window_samples(n_steps, h, WINDOW)
    rows = slice(first, first + count)
    theta_rms = np.sqrt(np.mean(xs[rows, :, 1] ** 2, axis=0))
    assert np.allclose(theta_rms, metrics["theta_b_rms"], rtol=1e-9, atol=0)
    if first + count <= n_steps:   # u of the window's rows (the last row's command is not integrated)
        assert np.allclose(np.sqrt(np.mean(us[rows] ** 2, axis=0)), metrics["u_rms"], rtol=1e-9, atol=0)


@pytest.mark.parametrize("files, law", [(PAPER, "dscndo"), (SENSING, "dscndo"), (SENSING, "lqr_ndo"), (PAPER, "dsc"),
                                        (MOTOR, "dscndo"), (CHIRP, "dscndo")])
def test_a_zero_residual_on_a_base_law_equals_the_batch_simulator(files, law):
    env = MwipVectorEnv(N, files, duration=DURATION, base_law=law)
    xs, us = run(env, lambda obs, u: np.zeros((N, 1)))
    trajectories, metrics = batch(files, law)
    check_against_batch(xs, us, trajectories, metrics, env.setup.loop.plant.h)


def test_the_laws_command_computed_over_the_observations_equals_the_batch_simulator():
    """The policy is DSCNDO over arrays (the core's observer and law with numpy, as the batch builds them), its command
    divided by the action's scale (256 N m)."""
    env = MwipVectorEnv(N, PAPER, duration=DURATION)
    loop = env.setup.loop
    pc = loop.plant
    law = laws.get("dscndo")(loop.params if loop.controller == "dscndo" else
                             laws.get("dscndo").design(load_values(PAPER), pc.nominal, pc.h), pc.nominal, pc.h, np)
    obs_ = DiscreteObserver(pc.nominal, tuple(loop.X), pc.h, m=np)

    def dscndo(obs, u_prev):
        x = tuple(obs[:, j] for j in range(4))
        u = law.step(x, obs_.update(x, u_prev))[0]
        return (u / 256.0)[:, None]

    xs, us = run(env, dscndo)
    check_against_batch(xs, us, *batch(PAPER, "dscndo"), pc.h)


def deterministic():
    """The paper's robot with deterministic friction, delays and an encoder: a restarted episode repeats the first."""
    return {**load_values(PAPER), "actual.D_w_variance": 0.0, "sensors.delay_periods": 2,
            "actuator.delay_periods": 1, "sensors.encoder_counts_per_rev": 1024}


def test_autoreset_restarts_a_robot_in_place_and_its_next_episode_repeats_the_first():
    env = MwipVectorEnv(3, deterministic(), duration=0.5, base_law="dscndo", torque_scale=4096.0)
    obs0, _ = env.reset(seed=1)
    lanes, x_arr, gens = env.lanes, env.lanes.x[0], list(env.lanes.zs.gens if env.lanes.zs else [])
    push = np.array([[0.0], [1.0], [0.0]])   # robot 1 is pushed over
    first, second, ends = [], [], []
    for step in range(400):
        obs, r, term, trunc, info = env.step(push if step < 200 else np.zeros((3, 1)))
        ends.append((term.copy(), trunc.copy(), r.copy()))
        (first if step < 100 else second).append(obs[0].copy())
        if step == 99:
            assert trunc[0] and trunc[2] and not term[0]
        if step == 100:   # the step after the end: robots 0 and 2 start again, their reward 0
            assert np.array_equal(obs[0], obs0[0]) and np.array_equal(obs[2], obs0[2]) and r[0] == 0.0
    fell = [s for s, (t, _, _) in enumerate(ends) if t[1]]
    assert fell and all(ends[s][2][1] == -100.0 for s in fell)
    assert np.array_equal(np.array(first), np.array(second[1:101]))   # the second episode repeats the first
    assert env.lanes is lanes and env.lanes.x[0] is not x_arr   # the same stepper, no rebuild
    assert list(env.lanes.zs.gens if env.lanes.zs else []) == gens


def test_a_restarted_robot_keeps_its_noise_streams():
    env = MwipVectorEnv(2, SENSING, duration=0.1, base_law="dscndo")
    env.reset(seed=3)
    gens = list(env.lanes.dw.gens)
    for _ in range(25):
        env.step(np.zeros((2, 1)))
    assert env.lanes.k.tolist() == [4, 4] and all(a is b for a, b in zip(env.lanes.dw.gens, gens))


def test_make_vec_of_the_registered_id_runs_the_vector_env():
    envs = gym.make_vec(ENV_ID, num_envs=4, vectorization_mode="vector_entry_point", duration=0.2)
    assert isinstance(envs.unwrapped, MwipVectorEnv) and envs.num_envs == 4
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (4, 4) and envs.action_space.shape == (4, 1)
    assert envs.observation_space.contains(obs)
    obs, r, term, trunc, info = envs.step(envs.action_space.sample())
    assert r.shape == (4,) and r.dtype == np.float64 and envs.observation_space.contains(obs)
    assert term.dtype == trunc.dtype == np.bool_


def raw(method, **more):
    """The raw sensors of sensors_raw_realistic.yaml with the estimator ``method``."""
    return {**load_values(RAW), "method": method, **more}


@pytest.mark.parametrize("method", ["kalman", "complementary"])
@pytest.mark.parametrize("law", ["dscndo", "lqr"])
def test_raw_sensors_and_the_estimator_with_a_zero_residual_equal_the_batch_simulator(method, law):
    """The raw samples per robot, the estimator's pure step per robot, the estimate the law sees: simulate_batch's
    trajectories (the scalar loop's) and the compiled loop's metrics, to 1e-9; the estimate is the batch's
    theta_b_hat (its estimate-error metric)."""
    files = raw(method)
    env = MwipVectorEnv(N, files, duration=DURATION, base_law=law)
    obs, _ = env.reset(seed=SEED)
    xs, us, est = [np.stack(env.lanes.x, 1)], [], [obs[:, 1]]
    while True:
        obs, r, terminated, truncated, info = env.step(np.zeros((N, 1)))
        us.append(info["u"])
        xs.append(np.stack(env.lanes.x, 1))
        est.append(obs[:, 1])
        assert not terminated.any()
        if truncated.any():
            assert truncated.all()
            break
    xs, us, est = np.array(xs), np.array(us), np.array(est)
    trajectories, metrics = batch(files, law)
    check_against_batch(xs, us, trajectories, metrics, env.setup.loop.plant.h)
    first, count = window_samples(us.shape[0], env.setup.loop.plant.h, WINDOW)
    rows = slice(first, first + count)
    err = np.sqrt(np.mean((est[rows] - xs[rows, :, 1]) ** 2, axis=0))
    key = next(k for k in metrics if "theta_b" in k and "err" in k and "rms" in k)
    assert np.allclose(err, metrics[key], rtol=1e-9, atol=0), key
    assert np.all(err > 0)   # the estimate is not the true state


def test_the_raw_observation_is_the_scalar_envs_raw_sample():
    """observation='raw': (gyro, accel_x, accel_z, encoder, encoder_rate) delayed, robot i's those of MwipEnv's
    episode with seed SEED + i (the scalar loop's own sensors), to 1e-9."""
    from mwip_ros.envs import MwipEnv
    files = raw("kalman", **{"sensors.delay_periods": 2})
    env = MwipVectorEnv(2, files, duration=0.3, base_law="dscndo", observation="raw")
    assert env.observation_space.shape == (2, 5)
    obs = [env.reset(seed=SEED)[0]]
    for _ in range(30):
        obs.append(env.step(np.zeros((2, 1)))[0])
    obs = np.array(obs)
    for i in range(2):
        one = MwipEnv(files, duration=0.3, base_law="dscndo", observation="raw")
        want = [one.reset(seed=SEED + i)[0]] + [one.step(np.zeros(1))[0] for _ in range(30)]
        assert np.allclose(obs[:, i], np.array(want), rtol=0, atol=1e-9), i
    assert np.ptp(obs[:, 0, 0]) > 0 and np.all(obs[1:3, :, 4] == 0.0)   # the encoder rate: 0 at k = 0 (delayed 2)


def test_autoreset_restarts_the_estimator_of_a_done_robot_in_place():
    """A robot pushed over restarts with a first estimator step, in the same arrays: with deterministic sensors and
    friction, robot 0's second episode repeats its first (the estimate, bit for bit)."""
    values = raw("kalman", **{"actual.D_w_variance": 0.0, "sensors.imu.gyro_noise_std": 0.0,
                              "sensors.imu.gyro_bias_walk": 0.0, "sensors.imu.accel_noise_std": 0.0,
                              "sensors.delay_periods": 1})
    env = MwipVectorEnv(2, values, duration=0.3, base_law="dscndo", torque_scale=4096.0)
    env.reset(seed=1)
    ES, first, second, fell = env.lanes.ES, [], [], False
    push = np.array([[0.0], [1.0]])
    n = env.setup.n_steps   # 60 periods of 5 ms
    for step in range(2 * n + 1):
        obs, r, term, trunc, info = env.step(push if step < n else np.zeros((2, 1)))
        (first if step < n else second).append(obs[0].copy())
        fell |= bool(term[1])
        if step == n - 1:
            assert trunc[0] and not term[0]
    assert fell and env.lanes.ES is ES   # robot 1 fell and restarted; no array built again
    assert np.array_equal(np.array(first), np.array(second[1:n + 1]))   # robot 0's second episode repeats its first


@pytest.mark.parametrize("files", [MOTOR, RAW])
def test_require_enable_a_driver_nobody_enables_equals_the_batch_simulator(files):
    """require_enable: true, nobody enables the driver (as mwip_sim): no torque acts, the motor carries no current,
    the robots fall; each one's trajectory and the time it fell are the batch simulator's (its scalar loop, 1e-9)."""
    values = {**load_values(files), "require_enable": True}
    env = MwipVectorEnv(N, values, duration=DURATION, base_law="dscndo")
    env.reset(seed=SEED)
    xs, us, fell = [np.stack(env.lanes.x, 1)], [], np.full(N, -1)
    for step in range(env.setup.n_steps):
        obs, r, term, trunc, info = env.step(np.zeros((N, 1)))
        live = fell < 0
        us.append(np.where(live, info["u"], np.nan))
        xs.append(np.where(live[:, None], np.stack(env.lanes.x, 1), np.nan))
        fell[term & live] = step
        assert not trunc.any() and np.all(info["failure"][term] == 1)   # FALL
        if (fell >= 0).all():
            break
    assert (fell >= 0).all() and np.all(np.array(us)[~np.isnan(us)] == 0.0)
    trajectories, _ = batch(values, "dscndo")
    xs = np.array(xs)
    for i, tr in enumerate(trajectories):
        c = tr.columns
        rows = fell[i] + 2   # the states x_0 .. x_(fall period + 1): the batch records the fallen state too
        assert len(c["theta_b"]) == rows, (i, len(c["theta_b"]), rows)
        for j, name in enumerate(("theta_w", "theta_b", "dtheta_w", "dtheta_b")):
            assert np.allclose(xs[:rows, i, j], c[name], rtol=0, atol=1e-9), (i, name)
        assert np.all(c["u"] == 0.0)


@pytest.mark.parametrize("files, key", [
    ({**load_values(PAPER), "backend": "mujoco"}, "plant_sim.backend"),
    # the compiled loop's motion stage does not idle the references while the driver is disabled (the batch runs
    # such a loop in the scalar loop only)
    ({**load_values(PAPER + [CONFIG / "motion.yaml"]), "require_enable": True}, "require_enable"),
])
def test_what_the_vector_env_does_not_run_is_refused_naming_the_key(files, key):
    with pytest.raises(ValueError) as err:
        MwipVectorEnv(2, files)
    assert str(err.value).startswith(f"{key}:"), err.value


@pytest.mark.parametrize("files, law", [(PAPER, "mpc"), (SENSING, "mpc_ndo")])
def test_mpc_a_law_without_a_pure_step_with_a_zero_residual_equals_the_batch_simulator(files, law):
    """MPC's QP per robot (the law's own object each); the batch runs it over arrays (its QPs one by one)."""
    pytest.importorskip("daqp")
    env = MwipVectorEnv(N, files, duration=DURATION, base_law=law)
    assert env.lanes.law is None and len(env.lanes.laws) == N
    xs, us = run(env, lambda obs, u: np.zeros((N, 1)))
    trajectories, metrics = batch(files, law)
    check_against_batch(xs, us, trajectories, metrics, env.setup.loop.plant.h)
    assert np.max(np.abs(us)) > 0.9 * env.setup.loop.params.u_max   # the bound was reached: the QP's, not free


def test_autoreset_gives_mpc_a_cold_start_of_the_restarted_robot_only():
    """Robot 1's command is not a number in step 2 (the drive refuses it, its episode ends): its law's reset (a cold
    start, no active set) is called in the step that restarts it, robot 0's not; robot 0's second episode repeats its
    first."""
    pytest.importorskip("daqp")
    env = MwipVectorEnv(2, deterministic(), duration=0.05, base_law="mpc", torque_scale=4096.0)
    env.reset(seed=1)
    resets = [0, 0]
    for i, lw in enumerate(env.lanes.laws):
        lw.reset = (lambda i, old: lambda: (resets.__setitem__(i, resets[i] + 1), old())[1])(i, lw.reset)
    n, first, second = env.setup.n_steps, [], []
    nan = np.array([[0.0], [np.nan]])
    for step in range(2 * n + 1):
        restart = env._restart.copy()
        before = list(resets)
        obs, r, term, trunc, info = env.step(nan if step == 2 else np.zeros((2, 1)))
        assert term[1] == (step == 2)
        assert [resets[i] - before[i] for i in range(2)] == restart.astype(int).tolist(), step
        (first if step < n else second).append(obs[0].copy())
        if step == n - 1:
            assert not env.lanes.laws[0]._qps[0].cold   # robot 0's QP holds an active set when it restarts
    assert resets == [1, 2]   # robot 0 at its end (0.05 s); robot 1 in step 3, then at its end
    assert np.array_equal(np.array(first), np.array(second[1:n + 1]))


def test_the_stepper_holds_every_stage_of_the_loop_in_its_order():
    """envs/lanes.py marks each stage as the batch's forms do (core.closed_loop.loop.STAGES;
    test/core/closed_loop/test_loop.py)."""
    import re
    from pathlib import Path

    import mwip_ros.envs.lanes as lanes_module
    from mwip_ros.core.closed_loop.loop import STAGE_NAMES
    marks = re.findall(r"# stage: (\w+)", Path(lanes_module.__file__).read_text())
    assert tuple(marks) == STAGE_NAMES


def test_the_stepper_calls_the_compiled_loops_own_stage_functions():
    """The stages sensors (state, raw with its estimator), law with the motion references and drive are the compiled
    loop's own functions (core.kernels.compiled), the very objects its kernel binds: the env writes none of them
    again."""
    from mwip_ros.core.kernels import compiled
    from mwip_ros.core.estimators import kalman
    from mwip_ros.envs import kernels
    law = laws.get("dscndo")
    assert kernels.sense.py_func.__globals__["sense_state"].py_func.__code__ is compiled.sense_state.__code__
    assert kernels.drive.py_func.__globals__["drive_stage"].py_func.__code__ is compiled.drive_stage.__code__
    stage = kernels.track_kernel(law).py_func.__globals__["law_track"]
    assert stage is compiled.track_for(law) is compiled.kernel_for(law).py_func.__globals__["law_track"]
    raw = kernels.raw_kernel(kalman.KalmanFilter).py_func.__globals__["sense_raw"].py_func
    assert raw.__code__ is compiled.sense_raw.__code__
    assert raw.__globals__["est_step"].py_func.__code__ is kalman.kalman_step.__code__
    source = open(kernels.__file__).read() + open(lanes_file()).read()
    assert "PLAUSIBLE_TORQUE" not in source and "raw_sample(" not in source   # no drive gate, no raw sample of its own


def lanes_file():
    import mwip_ros.envs.lanes as lanes_module
    return lanes_module.__file__


def test_a_sweep_spec_gives_robot_i_the_specs_scenario_i_equal_to_the_batch_and_restarts_draw_the_next():
    """sweep=mass_mismatch.yaml, reset(seed=7): robot i is scenario i of the spec with seed 7 and samples N (its true
    m_b, I_b, l and its noise seed), its episode the batch simulator's run of that scenario (1e-9)."""
    from mwip_ros.sweep.scenarios import expand
    from mwip_ros.sweep.spec import load_spec
    path = CONFIG / "sweeps" / "mass_mismatch.yaml"
    spec = dataclasses.replace(load_spec(path), seed=7, samples=N)
    sc = expand(spec)
    loops = [P.closed_loop({**spec.base_values, **sc.overrides(i)}, duration=DURATION, controller="dscndo")
             for i in range(N)]
    env = MwipVectorEnv(N, sweep=path, duration=DURATION, base_law="dscndo")
    obs, _ = env.reset(seed=7)
    m11 = [lp.plant.actual.m11 for lp in loops]
    assert np.array_equal(env.lanes.robot[0], m11) and len(set(m11)) == N
    xs, us = [np.stack(env.lanes.x, 1)], []
    for _ in range(int(round(DURATION / loops[0].plant.h))):
        obs, r, term, trunc, info = env.step(np.zeros((N, 1)))
        xs.append(np.stack(env.lanes.x, 1))
        us.append(info["u"])
    assert trunc.all()
    recorded = simulate_batch(loops, WINDOW, record=True)
    check_against_batch(np.array(xs), np.array(us), recorded.trajectories,
                        simulate_batch(loops, WINDOW, compiled=True).metrics, loops[0].plant.h)
    env.step(np.zeros((N, 1)))   # the restart: the next robots, the spec with seed 8's first N
    nxt = expand(dataclasses.replace(spec, seed=8))
    want = [P.closed_loop({**spec.base_values, **nxt.overrides(i)}, duration=DURATION).plant.actual.m11
            for i in range(N)]
    assert np.array_equal(env.lanes.robot[0], want)


def test_a_sweep_spec_that_varies_more_than_the_true_robot_is_refused_naming_the_axis(tmp_path):
    spec = tmp_path / "s.yaml"
    spec.write_text(f"base: {CONFIG / 'paper.yaml'}\ncontrollers: [dscndo]\nduration_s: 1.0\n"
                    "metrics_window_s: [0.5, 1.0]\nsamples: 2\nvary:\n  dscndo_controller.k1: {scale: [0.9, 1.1]}\n")
    with pytest.raises(ValueError) as err:
        MwipVectorEnv(2, sweep=spec)
    assert str(err.value).startswith("sweep:") and "dscndo_controller.k1" in str(err.value), err.value


def motion_run(files, law, duration):
    """(the vector env's run of N robots with a zero residual, simulate_batch's trajectories (the scalar loop, as
    mwip_sim) and the compiled loop's metrics) of ``law`` on ``files`` for ``duration``."""
    env = MwipVectorEnv(N, files, duration=duration, base_law=law)
    xs, us = run(env, lambda obs, u: np.zeros((N, 1)))
    loop = P.closed_loop(load_values(files), duration=duration, controller=law)
    loops = [dataclasses.replace(loop, plant=dataclasses.replace(loop.plant, seed=SEED + i)) for i in range(N)]
    window = (duration / 2, duration)
    return (env, xs, us, simulate_batch(loops, window, record=True).trajectories,
            simulate_batch(loops, window, compiled=True).metrics)


@pytest.mark.slow   # 12 s of 6 robots and of mwip_sim's 6 runs; the law's motion kernel compiled into an empty cache
@pytest.mark.parametrize("files, law, exact", [(MOTION, "dscndo", True), (MOTION, "lqr_ndo", True),
                                               (MOTION + [CONFIG / "sensing_realistic.yaml"], "dsc", False)])
def test_motion_references_with_a_zero_residual_equal_mwip_sims_run_bit_for_bit(files, law, exact):
    """config/motion.yaml (1 m/s from 2 s, -0.5 m/s from 10 s): the vector env runs the compiled loop's motion stage
    (core.kernels.compiled_motion.law_track), every robot equal to mwip_sim's run of it (the batch's record: the scalar
    loop) to the bit, and to the compiled batch's metrics; it drove.  DSC's tracking step compiled is the scalar one's
    within an ulp (one command of robot 1's 2,400 differed by 1 ulp, its states not at all): 1e-9 there, as the
    other vector env tests.  Before, the vector env refused motion.enabled."""
    env, xs, us, trajectories, metrics = motion_run(files, law, 12.0)
    for i, tr in enumerate(trajectories):
        c = tr.columns
        for j, name in enumerate(("theta_w", "theta_b", "dtheta_w", "dtheta_b")):
            if exact:
                assert np.array_equal(xs[:, i, j], c[name]), (i, name, np.max(np.abs(xs[:, i, j] - c[name])))
            else:
                assert np.allclose(xs[:, i, j], c[name], rtol=0, atol=1e-9), (i, name)
        if exact:
            assert np.array_equal(us[:, i], c["u"][:-1]), i
        else:
            assert np.allclose(us[:, i], c["u"][:-1], rtol=0, atol=1e-9), i
    h = env.setup.loop.plant.h
    first, count = window_samples(us.shape[0], h, (6.0, 12.0))
    theta_rms = np.sqrt(np.mean(xs[first:first + count, :, 1] ** 2, axis=0))
    assert np.allclose(theta_rms, metrics["theta_b_rms"], rtol=1e-9, atol=0)
    assert np.all(xs[int(round(10.0 / h)), :, 0] > 20.0)   # 1 m/s from 2 s on wheels of r = 0.25 m: it drove


def test_motion_references_track_per_robot_after_an_autoreset():
    """A robot restarted in place (NEXT_STEP) takes the references from t = 0 again (its own references' state reset):
    its second episode repeats its first while the other robot's goes on."""
    values = {**load_values(MOTION), "actual.D_w_variance": 0.0}
    env = MwipVectorEnv(2, values, duration=3.0, base_law="dscndo", torque_scale=4096.0)
    env.reset(seed=1)
    n, first, second = env.setup.n_steps, [], []
    nan = np.array([[0.0], [np.nan]])
    for step in range(n + 4 + n):
        obs, r, term, trunc, info = env.step(nan if step == 3 else np.zeros((2, 1)))
        if step < n:
            first.append(obs[0].copy())
        elif step > n:
            second.append(obs[0].copy())
    assert np.array_equal(np.array(first[:n - 1]), np.array(second[:n - 1]))
    assert abs(first[-1][0]) > 1.0   # robot 0 drove in its first episode


def test_mpc_tracks_the_motion_references_through_the_scalar_loops_command_equal_to_mwip_sim():
    """A law without a pure step (mpc) with motion: the vector env calls core.closed_loop.loop.command with a Shaper per
    robot, the scalar loop's own law stage; each robot equals mwip_sim's run (the batch's record) to the bit."""
    pytest.importorskip("daqp")
    duration, n = 3.0, 2
    env = MwipVectorEnv(n, MOTION, duration=duration, base_law="mpc")
    assert env.lanes.shapers is not None and env.lanes.track is None
    obs, _ = env.reset(seed=SEED)
    xs, us = [np.stack(env.lanes.x, 1)], []
    for _ in range(env.setup.n_steps):
        obs, r, term, trunc, info = env.step(np.zeros((n, 1)))
        us.append(info["u"])
        xs.append(np.stack(env.lanes.x, 1))
    assert trunc.all() and not term.any()
    loop = P.closed_loop(load_values(MOTION), duration=duration, controller="mpc")
    loops = [dataclasses.replace(loop, plant=dataclasses.replace(loop.plant, seed=SEED + i)) for i in range(n)]
    for i, tr in enumerate(simulate_batch(loops, (1.0, duration), record=True).trajectories):
        for j, name in enumerate(("theta_w", "theta_b", "dtheta_w", "dtheta_b")):
            assert np.array_equal(np.array(xs)[:, i, j], tr.columns[name]), (i, name)
        assert np.array_equal(np.array(us)[:, i], tr.columns["u"][:-1]), i
    assert np.all(np.array(xs)[-1, :, 2] > 0.5)   # the wheels turn forward: v* = 0.5 m/s at 3 s
