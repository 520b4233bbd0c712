"""The ``motion.*`` parameters of ``dscndo_controller`` (docs/theory.md 6.11): the references a law tracks.

:func:`specs` gives their :class:`~.spec.ParamSpec` (``params.schema`` lists them with the controller's own);
:func:`motion` makes the :class:`mwip_ros.core.control.motion.MotionConfig` of merged values, None while
``motion.enabled`` is false (the default, and config/paper.yaml's: every law regulates, as in the paper).
"""
from __future__ import annotations

from typing import Any, Dict, List, Mapping, Optional

from mwip_ros.core.control.motion import ABSURD_SPEED
from mwip_ros.core.plants.plant_base import per_wheel

from .drive import motor
from .spec import ParamSpec

__all__ = ["specs", "motion", "yaw", "profile_rule", "yaw_profile_rule", "PROFILE_MAX_POINTS", "ABSURD_SPEED",
           "DRIVE_KEYS", "drive_wheel_limit", "wheel_limit", "wheel_limit_warning"]

PROFILE_MAX_POINTS = 10000
# plant_sim's drive (docs/theory.md 6.7): what the yaw stage's wheel limit is derived from (:func:`drive_wheel_limit`)
DRIVE_KEYS = ("torque_limit", "motor.enabled", "motor.torque_constant", "motor.resistance", "motor.voltage_limit",
              "motor.current_limit")


def _timed_pairs_rule(v, what: str, unit: str) -> Optional[str]:
    """None when ``v`` is a profile [t0, a0, t1, a1, ...] of ``what`` [``unit``]: pairs, times from 0 increasing,
    values within +/-:data:`ABSURD_SPEED`."""
    if len(v) % 2:
        return f"give pairs [t0, v0, t1, v1, ...] (time [s], {what} [{unit}]), got {len(v)} entries"
    if len(v) > 2 * PROFILE_MAX_POINTS:
        return f"at most {PROFILE_MAX_POINTS} points, got {len(v) // 2}"
    times, values = v[0::2], v[1::2]
    if any(t < 0 for t in times) or any(b <= a for a, b in zip(times, times[1:])):
        return f"the times must be >= 0 and increase, got {list(times)!r}"
    if any(abs(a) > ABSURD_SPEED for a in values):
        return f"{what}s must be within +/-{ABSURD_SPEED:g} {unit}, got {list(values)!r}"
    return None


def profile_rule(v) -> Optional[str]:
    """None when ``v`` is a speed profile [t0, v0, t1, v1, ...]: pairs, times from 0 increasing, finite speeds."""
    return _timed_pairs_rule(v, "speed", "m/s")


def yaw_profile_rule(v) -> Optional[str]:
    """None when ``v`` is a yaw-rate profile [t0, w0, t1, w1, ...]: pairs, times from 0 increasing, finite rates."""
    return _timed_pairs_rule(v, "yaw rate", "rad/s")


def specs() -> List[ParamSpec]:
    """The ``motion.*`` ParamSpecs."""
    pos: Dict[str, Any] = dict(lo=0.0, lo_open=True)
    return [
        ParamSpec("motion.enabled", "bool", False, "track references from cmd_vel (or motion.profile): every law "
                  "tracks the wheel's reference angle and rate (docs/theory.md 6.11); false = balance only, "
                  "as in the paper"),
        ParamSpec("motion.max_speed", "double", 1.5, "motion: |v*| at most this [m/s]; a faster cmd_vel is clipped",
                  hi=100.0, **pos, unit="m/s"),
        ParamSpec("motion.max_accel", "double", 0.5, "motion: the reference speed changes at most this fast [m/s^2]",
                  hi=100.0, **pos, unit="m/s^2"),
        ParamSpec("motion.max_yaw_rate", "double", 1.0, "motion: |psi'*| at most this [rad/s]; it changes at most "
                  "max_yaw_rate per second", hi=100.0, **pos, unit="rad/s"),
        ParamSpec("motion.cmd_vel_timeout_s", "double", 0.5, "motion: with no cmd_vel for this long the references "
                  "ramp to zero (max_accel) and the robot holds its position", hi=3600.0, **pos, unit="s"),
        ParamSpec("motion.position_gain", "double", 0.2, "motion: lambda of the wheel error e = (theta_w' - "
                  "theta_w'*) + lambda (theta_w - theta_w*) every law drives to zero [1/s]; 0 = speed only, no "
                  "position hold", lo=0.0, hi=100.0, unit="1/s"),
        ParamSpec("motion.lean_gain", "double", 0.03, "motion, DSC/DSCNDO: k_x of the outer loop's lean reference "
                  "x_d = -k_x e, tracked by the surfaces (eq. 22) [rad per rad/s]", lo=0.0, hi=10.0,
                  unit="rad s/rad"),
        ParamSpec("motion.hold_settle_s", "double", 5.0, "motion: the hold, where the robot comes to rest: for this "
                  "long after v* reaches 0 (and from the start) the wheel's reference angle moves to the wheel's "
                  "angle whenever its rate reaches zero, then stays (docs/theory.md 6.14); 0 = it stays where the "
                  "references stopped", lo=0.0, hi=3600.0, unit="s"),
        ParamSpec("motion.hold_filter_s", "double", 1.0, "motion: the hold's equilibrium: the time constant of "
                  "the filter of the constant disturbance the law regulates about while v* = 0 (the lean and "
                  "torque that hold the robot on a slope; docs/theory.md 6.14); 0 = none, the law's own",
                  lo=0.0, hi=3600.0, unit="s"),
        ParamSpec("motion.profile", "double_array", [], "motion: a speed profile for offline and lockstep runs, "
                  "[t0, v0, t1, v1, ...] (time [s], v* [m/s] from then on); empty = follow cmd_vel",
                  rule=profile_rule, words="pairs [t0, v0, t1, v1, ...], times from 0 increasing"),
        ParamSpec("motion.yaw_profile", "double_array", [], "motion: a yaw-rate profile for offline and lockstep "
                  "runs, [t0, w0, t1, w1, ...] (time [s], psi'* [rad/s] from then on), beside motion.profile; "
                  "empty = psi'* 0 with a profile, else cmd_vel's angular.z", rule=yaw_profile_rule,
                  words="pairs [t0, w0, t1, w1, ...], times from 0 increasing"),
        ParamSpec("motion.yaw_kp", "double", 400.0, "motion, a spatial plant (backend mujoco): the yaw-rate loop's "
                  "proportional gain, u_psi = kp e + ki integral(e), e = psi'* - the gyro's yaw rate "
                  "(docs/theory.md 6.13) [N m per rad/s]", lo=0.0, hi=1e4, unit="N m s/rad"),
        ParamSpec("motion.yaw_ki", "double", 4000.0, "motion, a spatial plant: the yaw-rate loop's integral gain "
                  "[N m per rad]", lo=0.0, hi=1e5, unit="N m/rad"),
        ParamSpec("motion.yaw_gyro_calibration_s", "double", 0.0, "motion, a spatial plant: the yaw stage first "
                  "averages the gyro's yaw rate for this long, u_psi = 0, and subtracts the mean from then on (its "
                  "bias at start-up, the robot not turning; docs/theory.md 6.13); 0 = none (an ideal gyro)",
                  lo=0.0, hi=60.0, unit="s"),
        ParamSpec("motion.yaw_wheel_limit", "double", 0.0, "motion, a spatial plant: the torque one wheel's drive "
                  "gives [N m]; balance first: the yaw pair uses only what the law's u leaves of it, |u_psi| <= "
                  "2 limit - |u| (docs/theory.md 6.13); 0 = the drive's own (plant_sim's torque_limit / 2 and the "
                  "motor's peak / 2, the smaller; none without either); never more than the drive's",
                  lo=0.0, hi=1e6, unit="N m"),
    ]


def motion(v: Mapping[str, Any]):
    """The :class:`~mwip_ros.core.control.motion.MotionConfig` of merged values, or None while ``motion.enabled`` is
    false."""
    if not v.get("motion.enabled", False):
        return None
    from mwip_ros.core.control.motion import MotionConfig
    prof = [float(x) for x in v["motion.profile"]]
    return MotionConfig(max_speed=v["motion.max_speed"], max_accel=v["motion.max_accel"],
                        max_yaw_rate=v["motion.max_yaw_rate"], timeout_s=v["motion.cmd_vel_timeout_s"],
                        position_gain=v["motion.position_gain"], lean_gain=v["motion.lean_gain"],
                        profile=tuple(zip(prof[0::2], prof[1::2])), r=v["nominal.r"],
                        yaw_profile=_pairs(v.get("motion.yaw_profile", ())),
                        hold_settle_s=v.get("motion.hold_settle_s", 5.0),
                        hold_filter_s=v.get("motion.hold_filter_s", 1.0))


def _pairs(flat):
    f = [float(x) for x in flat]
    return tuple(zip(f[0::2], f[1::2]))


def drive_wheel_limit(v: Mapping[str, Any]) -> float:
    """The torque one wheel's drive gives [N m] (plant_sim's :data:`DRIVE_KEYS`, docs/theory.md 6.7 and 6.13): half of
    ``torque_limit`` (the drive stage clips each wheel there), half of the motor's peak torque at rest (each wheel has
    half the lumped motor), the smaller of the two; 0 when the drive has neither (no limit: the paper's robot)."""
    limits = []
    if v.get("torque_limit", 0.0) > 0.0:
        limits.append(per_wheel(float(v["torque_limit"])))
    m = motor(v)
    if m.enabled:
        limits.append(per_wheel(m.peak_torque))
    return min(limits) if limits else 0.0


def wheel_limit(v: Mapping[str, Any]) -> float:
    """The yaw stage's wheel limit L (balance first, docs/theory.md 6.13): the drive's own (:func:`drive_wheel_limit`),
    or ``motion.yaw_wheel_limit`` when it is less: the yaw pair never counts on torque the wheels do not have (a
    larger one is taken down to the drive's, :func:`wheel_limit_warning` says so)."""
    given, drive = float(v.get("motion.yaw_wheel_limit", 0.0)), drive_wheel_limit(v)
    if given > 0.0 and drive > 0.0:
        return min(given, drive)
    return given if given > 0.0 else drive


def wheel_limit_warning(v: Mapping[str, Any]) -> Optional[str]:
    """The line that says ``motion.yaw_wheel_limit`` is more than the drive gives a wheel (and the drive's is used),
    None otherwise."""
    given, drive = float(v.get("motion.yaw_wheel_limit", 0.0)), drive_wheel_limit(v)
    if given > 0.0 and drive > 0.0 and given > drive:
        return (f"motion.yaw_wheel_limit: {given:g} N m is more than the drive gives a wheel ({drive:.6g} N m: "
                f"plant_sim's torque_limit / 2 and the motor's peak / 2, the smaller); the yaw stage uses the drive's")
    return None


def yaw(v: Mapping[str, Any]):
    """The :class:`~mwip_ros.core.control.yaw.YawConfig` of merged values (the yaw stage runs on a spatial plant), or
    None while ``motion.enabled`` is false.  Its wheel limit is :func:`wheel_limit`'s (the values include plant_sim's
    drive: merged files, or a node's values with the drive's from the plant_sim sections)."""
    if not v.get("motion.enabled", False):
        return None
    from mwip_ros.core.control.yaw import YawConfig
    return YawConfig(kp=v["motion.yaw_kp"], ki=v["motion.yaw_ki"],
                     calibration_s=v.get("motion.yaw_gyro_calibration_s", 0.0), wheel_limit=wheel_limit(v))
