"""The ``upkie.*`` parameters of ``plant_sim``: how the robot side drives Upkie (mwip_ros.robot.upkie, SPEC 16,
docs/hardware-upkie.md).

:func:`specs` gives their :class:`~.spec.ParamSpec` (``params.schema`` lists them with the plant's own);
:func:`upkie_config` makes the :class:`~mwip_ros.robot.upkie.UpkieConfig` of merged values: the period from
``control_rate_hz``, the initial lean from ``initial.theta_b``, the rest from ``upkie.*``. The defaults are
:class:`~mwip_ros.robot.upkie.UpkieConfig`'s (one place); config/upkie.yaml sets the values this stack was measured
with.
"""
from __future__ import annotations

from typing import Any, List, Mapping

from .spec import ParamSpec

__all__ = ["specs", "upkie_config"]


def specs() -> List[ParamSpec]:
    """The ``upkie.*`` ParamSpecs."""
    from mwip_ros.robot.upkie import UpkieConfig
    d = UpkieConfig()
    return [
        ParamSpec("upkie.leg_kp_scale", "double", d.leg_kp_scale, "upkie: kp_scale of the hips' and knees' servo PD "
                  "that holds the legs straight (position 0; PyBullet's kp is 20 N m/rad times it)", lo=0.0, hi=100.0),
        ParamSpec("upkie.leg_kd_scale", "double", d.leg_kd_scale, "upkie: kd_scale of that PD (PyBullet's kd is 1 N m "
                  "s/rad times it)", lo=0.0, hi=100.0),
        ParamSpec("upkie.leg_maximum_torque", "double", d.leg_maximum_torque, "upkie: the legs' maximum_torque [N m] "
                  "(the qdd100's limit: 16)", lo=0.0, hi=100.0, unit="N m"),
        ParamSpec("upkie.wheel_maximum_torque", "double", d.wheel_maximum_torque, "upkie: each wheel's "
                  "maximum_torque [N m], the servo's own clip (the mj5208's limit: 1.7; torque_limit caps the lumped "
                  "u before it)", lo=0.0, hi=100.0, unit="N m"),
        ParamSpec("upkie.substeps", "integer", d.substeps, "upkie, PyBullet: physics steps per control period; 0 = "
                  "1 kHz (int(1000 h))", lo=0, hi=1000),
        ParamSpec("upkie.shm_name", "string", d.shm_name, "upkie, the spine: its shared memory"),
    ]


def upkie_config(values: Mapping[str, Any]):
    """The :class:`~mwip_ros.robot.upkie.UpkieConfig` of merged ``plant_sim`` values (``control_rate_hz``,
    ``initial.theta_b`` and ``upkie.*``), checked (ValueError naming the key)."""
    from mwip_ros.robot.upkie import UpkieConfig
    return UpkieConfig(dt=1.0 / values["control_rate_hz"], leg_kp_scale=values["upkie.leg_kp_scale"],
                       leg_kd_scale=values["upkie.leg_kd_scale"], leg_maximum_torque=values["upkie.leg_maximum_torque"],
                       wheel_maximum_torque=values["upkie.wheel_maximum_torque"],
                       initial_pitch=values["initial.theta_b"], substeps=values["upkie.substeps"],
                       shm_name=values["upkie.shm_name"]).checked()
