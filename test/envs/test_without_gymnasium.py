"""Gymnasium is optional (mwip_ros.optional): without it mwip_ros.envs refuses in one line naming the package and
its rosdep key, and the rest of mwip_ros runs (a child process whose Python cannot import gymnasium)."""
import subprocess
import sys

import pytest

from without import env_without

pytestmark = pytest.mark.unit


def test_without_gymnasium_the_envs_refuse_in_one_line_and_the_simulator_runs(tmp_path):
    code = ("from mwip_ros.core.sim import simulate\n"
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
