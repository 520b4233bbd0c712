"""The ``motion.*`` keys of dscndo_controller (theory 6.11): defaults off, out of range is one line naming the key, and
the typed config."""
import subprocess
import sys

import pytest

from mwip_ros import params as P
from mwip_ros.params.motion import motion
from mwip_ros.params.paths import default_params_file

pytestmark = pytest.mark.unit


def _file(tmp_path, lines, name="m.yaml"):
    f = tmp_path / name
    f.write_text("dscndo_controller:\n  ros__parameters:\n" + "".join(f"    {line}\n" for line in lines))
    return f


def test_off_by_default_and_in_paper_yaml():
    assert P.defaults_for("dscndo_controller")["motion.enabled"] is False
    v = P.merged_values(P.load_param_file(default_params_file()))
    assert v["motion.enabled"] is False and motion(v) is None


@pytest.mark.parametrize("line, key", [
    ("motion: {max_speed: 0.0}", "motion.max_speed"),
    ("motion: {max_speed: 1.0e3}", "motion.max_speed"),
    ("motion: {max_accel: -1.0}", "motion.max_accel"),
    ("motion: {max_yaw_rate: 0.0}", "motion.max_yaw_rate"),
    ("motion: {cmd_vel_timeout_s: 0.0}", "motion.cmd_vel_timeout_s"),
    ("motion: {position_gain: -0.1}", "motion.position_gain"),
    ("motion: {lean_gain: 11.0}", "motion.lean_gain"),
    ("motion: {profile: [0.0, 1.0, 2.0]}", "motion.profile"),
    ("motion: {profile: [1.0, 1.0, 0.5, 0.0]}", "motion.profile"),
    ("motion: {profile: [0.0, 1.0e4]}", "motion.profile"),
    ("motion: {enabled: 1}", "motion.enabled"),
    ("motion: {yaw_kp: -1.0}", "motion.yaw_kp"),
    ("motion: {yaw_ki: 1.0e9}", "motion.yaw_ki"),
    ("motion: {yaw_profile: [0.0, 1.0, 2.0]}", "motion.yaw_profile"),
    ("motion: {yaw_profile: [1.0, 1.0, 0.5, 0.0]}", "motion.yaw_profile"),
    ("motion: {yaw_profile: [0.0, 1.0e4]}", "motion.yaw_profile"),
])
def test_out_of_range_is_one_line_naming_the_key(tmp_path, line, key):
    with pytest.raises(P.ParamError) as ei:
        P.load_param_files([default_params_file(), _file(tmp_path, [line])])
    assert key in str(ei.value) and "\n" not in str(ei.value)


@pytest.mark.cli
def test_mwip_sim_exits_2_naming_the_key(tmp_path):
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", "--params", str(default_params_file()),
                        str(_file(tmp_path, ["motion: {max_accel: 0.0}"])), "-q"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and "motion.max_accel" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_typed_config(tmp_path):
    pf = P.load_param_files([default_params_file(), _file(tmp_path, [
        "motion: {enabled: true, max_speed: 2.0, profile: [0.0, 0.0, 1.0, 1.0]}"])])
    cfg = motion(P.merged_values(pf))
    assert cfg.max_speed == 2.0 and cfg.max_accel == 0.5 and cfg.profile == ((0.0, 0.0), (1.0, 1.0))
    assert cfg.r == 0.254 and cfg.position_gain == 0.2 and cfg.lean_gain == 0.03
