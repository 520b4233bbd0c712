"""Limits of one robot that two keys give: a file whose limits disagree is refused in one line naming both keys; a
limit left 0 is derived from the other (the wheel_driver's wheel limit from plant_sim's ``torque_limit``)."""
import pytest

from mwip_ros import params as P
from mwip_ros.params import driver as D
from mwip_ros.params.file import robot_values

pytestmark = pytest.mark.unit


def _driver_values(tmp_path, torque_limit: float, wheel_torque_limit: float):
    f = tmp_path / "robot.yaml"
    f.write_text(f"plant_sim:\n  ros__parameters:\n    torque_limit: {torque_limit!r}\n"
                 f"wheel_driver:\n  ros__parameters:\n    wheel_torque_limit: {wheel_torque_limit!r}\n")
    values = P.load_param_file(f).for_node("wheel_driver")
    return values, robot_values([f], values["control_rate_hz"])


def test_a_wheel_limit_above_plant_sims_torque_limit_share_is_refused_naming_both_keys(tmp_path):
    values, robot = _driver_values(tmp_path, 1.8, 1.0)   # plant_sim gives a wheel 0.9 N m, the driver 1.0
    with pytest.raises(P.ParamError) as exc:
        D.driver_config(values, robot)
    line = str(exc.value)
    assert exc.value.key == "wheel_torque_limit" and "\n" not in line, line
    assert "torque_limit / 2 = 0.9 N m" in line and "plant_sim's torque_limit" in line, line
    with pytest.raises(P.ParamError, match="wheel_torque_limit"):
        D.moteus_config({**values, "moteus.path": "/dev/null"}, robot)


@pytest.mark.parametrize("torque_limit, wheel_torque_limit, expected", [
    (1.8, 0.9, 0.9),     # the share itself
    (1.8, 0.05, 0.05),   # less (a robot on a stand): the driver's own
    (1.8, 0.0, 0.9),     # 0: derived, the torque_limit's share
    (0.0, 1.0, 1.0),     # plant_sim has none: the driver's own
    (0.0, 0.0, 0.0),     # neither: no limit
])
def test_a_wheel_limit_within_the_share_or_derived_from_it_is_taken(tmp_path, torque_limit, wheel_torque_limit,
                                                                     expected):
    values, robot = _driver_values(tmp_path, torque_limit, wheel_torque_limit)
    assert D.driver_config(values, robot).wheel_torque_limit == expected
