"""The law ``policy`` (mwip_ros/policy_law.py, a plug-in: MWIP_ROS_LAWS=mwip_ros.policy_law) runs a learned policy's
file: ``mwip_sim --controller policy`` repeats MwipEnv's episode of that policy bit for bit, and a bad file is refused
naming policy.file.  mwip_sim runs in a child process (this process never registers the law: other tests enumerate
the registry)."""
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("gymnasium")

from mwip_ros.envs import MwipEnv  # noqa: E402
from mwip_ros.params.paths import default_params_file  # noqa: E402
from mwip_ros.policy import LinearPolicy  # noqa: E402
from mwip_ros.runs import read_csv  # noqa: E402

pytestmark = pytest.mark.unit

POLICY = LinearPolicy((9.609, 1.246, -0.0438), 256.0)   # about what the cross-entropy example learns
PAPER = default_params_file()


def overlay(tmp_path, policy_file) -> "os.PathLike":
    out = tmp_path / "policy.yaml"
    out.write_text(f"dscndo_controller:\n  ros__parameters:\n    law: policy\n    use_observer: false\n"
                   f"    policy:\n      file: {policy_file}\n")
    return out


def mwip_sim(tmp_path, *args):
    env = dict(os.environ, MWIP_ROS_LAWS="mwip_ros.policy_law")
    return subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", *map(str, args)], capture_output=True,
                          text=True, timeout=120, env=env, cwd=tmp_path)


def env_episode(duration):
    """MwipEnv with the policy's actions: the true states and torques of every row."""
    env = MwipEnv(duration=duration)
    obs, info = env.reset(seed=0)
    xs, us = [info["state"]], []
    while True:
        obs, _, terminated, truncated, info = env.step(POLICY(obs[None, :])[0])
        us.append(info["u"])
        if terminated or truncated:
            return np.array(xs), np.array(us), env._period.side.plant.x
        xs.append(np.array(env._period.side.plant.x))


@pytest.mark.cli
def test_mwip_sim_with_the_law_policy_repeats_the_envs_episode_bit_for_bit(tmp_path):
    POLICY.save(tmp_path / "p.json")
    r = mwip_sim(tmp_path, "--params", PAPER, overlay(tmp_path, tmp_path / "p.json"), "--duration", "3", "--csv",
                 tmp_path / "run.csv", "-q")
    assert r.returncode == 0, r.stderr
    run = read_csv(tmp_path / "run.csv")
    xs, us, last = env_episode(3.0)
    assert len(run["u"]) == len(us) + 1 == 601
    for j, c in enumerate(("theta_w", "theta_b", "dtheta_w", "dtheta_b")):
        np.testing.assert_array_equal(run[c][:-1], xs[:, j], err_msg=c)
        assert run[c][-1] == last[j]
    np.testing.assert_array_equal(run["u"][:-1], us)
    assert np.abs(run["u"]).max() == 256.0   # the policy's clip is the law's


@pytest.mark.cli
@pytest.mark.parametrize("content", ["not json", '{"policy": "linear", "w": [1, 2], "scale": 256}'])
def test_a_bad_policy_file_is_refused_naming_policy_file(tmp_path, content):
    (tmp_path / "p.json").write_text(content)
    r = mwip_sim(tmp_path, "--params", PAPER, overlay(tmp_path, tmp_path / "p.json"), "--duration", "1", "-q")
    assert r.returncode == 2 and "parameter 'policy.file'" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
