"""Typed configurations of the core, built from a node's (or a merged) parameter dict."""
from __future__ import annotations

from typing import Any, Iterable, List, Mapping, Optional, Tuple, cast

from mwip_ros.core import laws
from mwip_ros.core.control.controller import DscGains
from mwip_ros.core.plants.drive import limit_warning, torque_warning
from mwip_ros.core.estimators import EstimatorConfig
from mwip_ros.core.identification.excitation import ExcitationConfig
from mwip_ros.core.plants.model import PhysicalParams, Sinusoid, State
from mwip_ros.core.plants.plant import MujocoConfig, PlantConfig
from mwip_ros.core.plants.raw_sensors import RawSensorConfig
from mwip_ros.core.plants.sensing import SensingConfig
from mwip_ros.core.closed_loop.sim import ClosedLoop

from .drive import motor
from .motion import motion as motion_config, wheel_limit_warning, yaw as yaw_config

from .schema import PAPER_NOMINAL

__all__ = ["physical", "sinusoid", "gains", "period", "observer_gain", "plant_config", "sensing", "raw_sensors",
           "estimator", "motor", "excitation", "lqr_gain", "closed_loop", "limit_warnings", "observer_warnings",
           "design_warnings"]


def physical(values: Mapping[str, Any], prefix: str) -> PhysicalParams:
    """``nominal.*`` or ``actual.*`` as PhysicalParams."""
    return PhysicalParams(**{k: values[f"{prefix}.{k}"] for k in PAPER_NOMINAL})


def sinusoid(values: Mapping[str, Any], prefix: str) -> Sinusoid:
    return Sinusoid(values[f"{prefix}.amplitude"], values[f"{prefix}.omega"], values[f"{prefix}.phase"])


def gains(values: Mapping[str, Any]) -> DscGains:
    return DscGains(k1=values["k1"], k2=values["k2"], tau4=values["tau4"])


def period(values: Mapping[str, Any]) -> float:
    """The control period h = 1 / control_rate_hz [s]."""
    return 1.0 / values["control_rate_hz"]


def observer_gain(values: Mapping[str, Any]):
    """X as the 2x2 matrix (eq. 14)."""
    from mwip_ros.core.control.observer import gain_matrix
    return gain_matrix(values["X"])


def plant_config(v: Mapping[str, Any]) -> PlantConfig:
    """PlantConfig from a plant_sim parameter dict."""
    return PlantConfig(
        actual=physical(v, "actual"), nominal=physical(v, "nominal"),
        D_b=v["actual.D_b"], D_w_mean=v["actual.D_w_mean"], D_w_variance=v["actual.D_w_variance"],
        tau_ext1=sinusoid(v, "tau_ext1"), tau_ext2=sinusoid(v, "tau_ext2"),
        h=period(v), substeps=v["substeps"], seed=v["seed"],
        initial=State(v["initial.theta_w"], v["initial.theta_b"], v["initial.dtheta_w"], v["initial.dtheta_b"]),
        torque_limit=v["torque_limit"], fall_angle=v["fall_angle"], sensing=sensing(v), raw=raw_sensors(v),
        motor=motor(v), require_enable=v.get("require_enable", False), backend=v.get("backend", "rk4"),
        mujoco=mujoco(v))


def mujoco(v: Mapping[str, Any]) -> Optional[MujocoConfig]:
    """The MuJoCo model's own values and its ground (``backend: mujoco``, docs/theory.md 6.10); None with the rk4
    backend."""
    if v.get("backend", "rk4") != "mujoco":
        return None
    return MujocoConfig(track_width=v["actual.track_width"], I_b_roll=v["actual.I_b_roll"],
                        I_b_yaw=v["actual.I_b_yaw"], friction=v["ground.friction"], timestep=v["mujoco.timestep"],
                        slope=v.get("ground.slope", 0.0), bumps=tuple(float(x) for x in v.get("ground.bumps", ())))


def excitation(v: Mapping[str, Any]) -> Optional[ExcitationConfig]:
    """The controller's excitation (``excitation.*``), None when it is off (type none or amplitude 0)."""
    if v.get("excitation.type", "none") == "none":
        return None
    cfg = ExcitationConfig(**{k: v[f"excitation.{k}"] for k in ("type", "amplitude", "f0", "f1", "duration_s",
                                                                 "bit_periods", "seed")})
    return cfg if cfg.active else None


def limit_warnings(v: Mapping[str, Any], law_names: Iterable[str] = ()) -> List[str]:
    """The torque limits too weak for the true robot (:func:`mwip_ros.core.plants.drive.limit_warning`, one line each):
    the motor's peak torque at ``fall_angle`` (:func:`~mwip_ros.core.plants.drive.torque_warning`); ``torque_limit``
    (when > 0) and the own limit of each law of ``law_names`` (``Law.limit_key``: ``mpc.u_max``) at the initial
    tilt, where a limit below the holding torque starts the run beyond what it can turn back; and a yaw wheel limit
    above the drive's (:func:`.motion.wheel_limit_warning`: the drive's is used)."""
    actual = physical(v, "actual")
    out = [torque_warning(motor(v), actual, v["fall_angle"])]
    limits = {"torque_limit": v["torque_limit"]} if v.get("torque_limit", 0.0) > 0.0 else {}
    for name in law_names:
        key = laws.get(name).limit_key
        if key and key in v:
            limits[key] = v[key]
    tilt = abs(v["initial.theta_b"])
    out += [limit_warning(key, lim, actual, tilt, f"the initial tilt |initial.theta_b| = {tilt:g} rad")
            for key, lim in limits.items()]
    if v.get("motion.enabled"):   # the yaw stage's wheel limit above the drive's (the drive's is used)
        out.append(wheel_limit_warning(v))
    return [w for w in out if w]


def observer_warnings(v: Mapping[str, Any]) -> List[str]:
    """The observer gain X against Theorem 2 (eq. 35: a4, a5 > 0,
    :func:`mwip_ros.core.control.theorem.observer_conditions`) on the nominal model: one line when it breaks it, else
    none."""
    from mwip_ros.core.control.theorem import observer_conditions
    th = observer_conditions(physical(v, "nominal"), observer_gain(v))
    if th.satisfied:
        return []
    return [f"observer gains break Theorem 2 (eq. 35): a4 = {th.a4:.4f}, a5 = {th.a5:.4f} (must be > 0); run "
            "mwip_theorem for the full table"]


def design_warnings(node: str, v: Mapping[str, Any], changed: Optional[Iterable[str]] = None) -> List[str]:
    """What the node ``node`` warns about its parameter values ``v`` (what it logs at start-up and after a change):
    ``dscndo_controller``: each law's own warnings (``Law.warnings``: DSC's gains against Theorem 2, ...) of the laws
    whose parameters include one of ``changed`` (None: every law); ``disturbance_observer``: the observer's
    (:func:`observer_warnings`) when ``X`` or the nominal model changed.  Other nodes: none.

    Parameters
    ----------
    node : str
        The node's name (its last component: a namespace is left out).
    v : mapping
        Every parameter value of the node.
    changed : iterable of str, optional
        The parameters just changed (None: all of them, at start-up).

    Returns
    -------
    list of str
        One line per warning.
    """
    node = node.rstrip("/").rsplit("/", 1)[-1]
    touched = None if changed is None else set(changed)
    if node == "dscndo_controller":
        nominal, h = physical(v, "nominal"), period(v)
        plain = [law for law in (laws.lookup(f, False) for f in laws.families()) if law is not None]
        in_use = touched is not None and bool(touched & {"law", "use_observer"})   # the law switched to
        out = []
        for law in plain:
            if laws.unavailable(law) is not None or not (touched is None or touched & set(law.param_keys)
                                                         or (in_use and law.family == v.get("law"))):
                continue
            try:
                out += law.from_params(v, nominal, h).warnings()
            except (KeyError, ArithmeticError, ValueError):   # no design from these values: the node refuses them
                continue
        return out
    if node == "disturbance_observer" and (touched is None or any(k == "X" or k.startswith("nominal.")
                                                                   for k in touched)):
        return observer_warnings(v)
    return []


def raw_sensors(v: Mapping[str, Any]) -> Optional[RawSensorConfig]:
    """The IMU and the relative encoder of ``sensors.model: raw`` (docs/theory.md 6.4); None for ``state``."""
    if v.get("sensors.model", "state") != "raw":
        return None
    return RawSensorConfig(offset=v["sensors.imu.offset"], gyro_noise_std=v["sensors.imu.gyro_noise_std"],
                           gyro_bias=v["sensors.imu.gyro_bias"], gyro_bias_walk=v["sensors.imu.gyro_bias_walk"],
                           accel_noise_std=v["sensors.imu.accel_noise_std"],
                           encoder_counts_per_rev=v["sensors.encoder_counts_per_rev"])


def estimator(v: Mapping[str, Any]) -> EstimatorConfig:
    """The state_estimator's method, its parameters (every method's) and the IMU offset it believes."""
    from mwip_ros.core import estimators
    names = [p.name for m in estimators.names() for p in estimators.get(m).parameters]
    return EstimatorConfig(v["method"], tuple((n, v[n]) for n in names if n in v), v["imu_offset"])


def sensing(v: Mapping[str, Any]) -> SensingConfig:
    """The plant's sensing and actuation options (all off by default); with raw sensors only the delays (the
    encoder's counts quantize the relative angle: :func:`raw_sensors`)."""
    if v.get("sensors.model", "state") == "raw":
        return SensingConfig(delay_periods=v["sensors.delay_periods"],
                             actuator_delay_periods=v["actuator.delay_periods"])
    return SensingConfig(noise_std=tuple(v[f"sensors.noise_std.{c}"] for c in ("theta_w", "theta_b", "dtheta_w",
                                                                                "dtheta_b")),
                         encoder_counts_per_rev=v["sensors.encoder_counts_per_rev"],
                         delay_periods=v["sensors.delay_periods"], actuator_delay_periods=v["actuator.delay_periods"])


def lqr_gain(v: Mapping[str, Any]):
    """K of the LQR baseline for these values (nominal model, period, lqr.Q, lqr.R)."""
    from mwip_ros.core.control.lqr import lqr_gain as design
    return design(physical(v, "nominal"), period(v), v["lqr.Q"], v["lqr.R"])


def closed_loop(v: Mapping[str, Any], use_observer: Optional[bool] = None,
                duration: Optional[float] = None, law: Optional[str] = None,
                controller: Optional[str] = None) -> ClosedLoop:
    """The offline scenario of a merged parameter dict (``merged_values``).

    Parameters
    ----------
    v : mapping
        The merged values.
    use_observer, duration, law : optional
        Override the file's ``use_observer``, ``duration_s`` and ``law`` (the controller node's: a law's
        family, core.laws.families()).
    controller : str, optional
        A registered law by name (core.laws.names(): 'dscndo', ...), instead of ``law`` and ``use_observer``.
    """
    if controller is None:
        controller = laws.variant(v["law"] if law is None else law,
                                  v["use_observer"] if use_observer is None else use_observer).name
    cls = laws.get(controller)
    plant = plant_config(v)
    X = cast(Tuple[float, float, float, float], tuple(float(c) for c in v["X"]))   # 4 entries: the schema's rule
    return ClosedLoop(plant=plant, X=X, controller=controller,
                      params=cls.design(v, plant.nominal, plant.h),
                      duration_s=v["duration_s"] if duration is None else duration,
                      estimator=estimator(v) if plant.raw is not None else None, excitation=excitation(v),
                      motion=motion_config(v), yaw=yaw_config(v))
