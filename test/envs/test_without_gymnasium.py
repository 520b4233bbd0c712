"""Gymnasium is optional (mwip_ros.optional): without it mwip_ros.envs refuses in one line naming the package and
its rosdep key, and the rest of mwip_ros runs (a child process whose Python cannot import gymnasium); without numba
the scalar env runs and the vector env refuses in one line."""
import subprocess
import sys

import pytest

from without import env_without

pytestmark = pytest.mark.unit


@pytest.mark.cli
def test_without_gymnasium_the_envs_refuse_in_one_line_and_the_simulator_runs(tmp_path):
    code = ("from mwip_ros.core.closed_loop.sim import simulate\n"
            "from mwip_ros import params as P\n"
            "from mwip_ros.params.paths import default_params_file\n"
            "v = P.merged_values(P.load_param_files([default_params_file()]))\n"
            "print(simulate(P.closed_loop(v, duration=0.5)).fallen)\n"
            "try:\n"
            "    import mwip_ros.envs\n"
            "except ImportError as exc:\n"
            "    print(type(exc).__name__, exc)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env=env_without(tmp_path, "gymnasium"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    fallen, refusal = r.stdout.strip().splitlines()
    assert fallen == "False"
    assert refusal.startswith("MissingPackage mwip_ros.envs (the Gymnasium environments) needs the Python package "
                              "gymnasium"), refusal
    assert "pip install 'gymnasium'" in refusal and "python3-gymnasium-pip" in refusal


@pytest.mark.cli
def test_without_numba_the_scalar_env_runs_and_the_vector_env_refuses_in_one_line(tmp_path):
    code = ("import numpy as np\n"
            "from mwip_ros.envs import MwipEnv\n"
            "env = MwipEnv(duration=0.1, base_law='dscndo')\n"
            "env.reset(seed=0)\n"
            "print(env.step(np.zeros(1))[3] is False)\n"
            "try:\n"
            "    from mwip_ros.envs import MwipVectorEnv\n"
            "except ImportError as exc:\n"
            "    print(type(exc).__name__, exc)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env=env_without(tmp_path, "numba"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    stepped, refusal = r.stdout.strip().splitlines()
    assert stepped == "True"
    assert refusal.startswith("MissingPackage MwipVectorEnv (its compiled RK4) needs the Python package numba"), refusal
