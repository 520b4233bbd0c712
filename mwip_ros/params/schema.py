"""The parameter schema: every parameter of every node, its type, default, range and description.

This is the one place the paper's values live (the defaults below; ``config/paper.yaml``
repeats them as a file a user copies and edits).  One schema serves the offline tools
(which read the YAML file directly) and the nodes (which declare every parameter from
it, with its description and range, and validate start-up values and run-time updates
with the same checks).

Types follow ROS 2 exactly: a ``double`` parameter written as ``200`` is an integer to
ROS and is refused (write ``200.0``).
"""
from __future__ import annotations

import difflib
import math
from typing import Any, Dict, Iterable, List, Mapping, Optional

from mwip_ros.core.control.safety import PLAUSIBLE_STATE
from . import driver, ground, motion, upkie
from .errors import ParamError
from .spec import HI_WHY, INT32_MAX, ParamSpec

__all__ = ["SHARED", "ParamSpec", "INT32_MAX", "HI_WHY", "PAPER_NOMINAL", "PAPER_ACTUAL", "SHARED_SPECS",
           "NODE_SPECS", "ROS_OWN", "ROS_OWN_PREFIXES", "QOS_OVERRIDES", "QOS_OVERRIDES_REFUSED", "specs_for",
           "defaults_for", "spelling_hint", "check_derived", "check_geometry"]

SHARED = "/**"

# What a published measurement may read: mwip_ros.core.control.safety.PLAUSIBLE_STATE (msgs.layouts.LIMITS: the observer
# and the controller reject a joint_states message beyond them as implausible).  A noise standard deviation is
# at most NOISE_LIMIT_FRACTION of the limit, and theta_b's noise must leave NOISE_SIGMAS standard deviations
# between the fall angle and the limit (check_derived): noise that makes a measurement implausible is a
# configuration error, refused at start-up, not a fault of the observer found during the run.
MEASURED_LIMITS = PLAUSIBLE_STATE
NOISE_LIMIT_FRACTION = 10.0
NOISE_SIGMAS = 8.0

# --- ranges and choices, as data: ParamSpec(**_positive()) ----------------------------------------
# Each helper gives ParamSpec fields; the start-up and run-time check (ParamSpec.check), the ROS parameter
# descriptor (nodes.runtime.params) and the --help text (nodes.runtime.params.range_text) are all derived from them.

def _bounds(lo: float, hi: float, lo_open: bool = False) -> Dict[str, Any]:
    """lo < v <= hi (``lo_open``) or lo <= v <= hi."""
    return dict(lo=lo, hi=hi, lo_open=lo_open)


def _positive(hi: float = 1e6) -> Dict[str, Any]:
    return _bounds(0.0, hi, lo_open=True)


def _non_negative(hi: float = 1e6) -> Dict[str, Any]:
    return _bounds(0.0, hi)


def _symmetric(hi: float) -> Dict[str, Any]:
    return _bounds(-hi, hi)


def _positive_from(floor: float, hi: float, why: str) -> Dict[str, Any]:
    """v > 0 (the descriptor's range starts at 0), and v >= ``floor`` (``why``), and v <= hi."""
    return dict(lo=0.0, hi=hi, lo_open=True, floor=floor, floor_why=why, hi_why="")


# tau4 so small that (x4_bar - x4d) / tau4 overflows is no filter; a rate below 1 mHz has no nanosecond period
_tau4 = _positive_from(1e-6, 1e6, "a filter faster than a microsecond is no filter")
_rate = _positive_from(1e-3, 1e5, "a control period of at most 1000 s")
_at_least_zero: Dict[str, Any] = dict(lo=0)     # an integer: its descriptor's range ends at INT32_MAX
_at_least_one: Dict[str, Any] = dict(lo=1)


def _count_range(lo: int, hi: int) -> Dict[str, Any]:
    return dict(lo=lo, hi=hi)


_priority: Dict[str, Any] = dict(lo=0, hi=99, words="0 (normal scheduling) or a SCHED_FIFO priority 1..99")


def _one_of(*choices) -> Dict[str, Any]:
    return dict(choices=tuple(choices))


# --- what is not a range: the arrays' shapes (a rule, and its words for --help) --------------------

def _four_finite_rule(v):
    if len(v) != 4:
        return f"must have 4 entries [c1, c2, c3, c4], got {len(v)}"
    if any(abs(c) > 1e9 for c in v):
        return f"entries must be within +/-1e9, got {v!r}"
    return None


def _lqr_q_rule(v):
    if len(v) not in (3, 9):
        return f"give the diagonal (3 entries) or the 3x3 matrix row by row (9), got {len(v)} entries"
    if any(abs(c) > 1e12 for c in v):
        return f"entries must be within +/-1e12, got {v!r}"
    return None


_four_finite: Dict[str, Any] = dict(rule=_four_finite_rule, words="must have 4 entries [c1, c2, c3, c4]")
_lqr_q: Dict[str, Any] = dict(rule=_lqr_q_rule, words="give the diagonal (3 entries) or the 3x3 matrix row by row (9)")

# The robot's physical values: each > 0 with a floor (a value below it is no robot of this kind, and a model built
# from it has inertia terms that round away: test/params/test_physical_ranges.py runs the model at every range end).
BODY_FLOORS = {"m_b": (1e-3, "a body lighter than a gram"), "m_w": (1e-3, "wheels lighter than a gram"),
               "I_b": (1e-6, "a body inertia below 1e-6 kg m^2"), "I_w": (1e-6, "a wheel inertia below 1e-6 kg m^2"),
               "l": (1e-3, "a centre of gravity within a millimetre of the axle"),
               "r": (1e-3, "a wheel radius below a millimetre"), "g": (1e-3, "gravity below 1e-3 m/s^2")}


def _body(prefix: str, values: Mapping[str, float], what: str) -> List[ParamSpec]:
    units = {"m_b": "kg", "m_w": "kg", "I_b": "kg m^2", "I_w": "kg m^2", "l": "m", "r": "m", "g": "m/s^2"}
    text = {"m_b": "body mass", "m_w": "wheel mass", "I_b": "body moment of inertia",
            "I_w": "wheel moment of inertia", "l": "axle to body centre of gravity",
            "r": "wheel radius", "g": "gravitational acceleration"}
    return [ParamSpec(f"{prefix}.{k}", "double", v, f"{what} {text[k]} [{units[k]}]",
                      **_positive_from(BODY_FLOORS[k][0], 1e6, f"{BODY_FLOORS[k][1]} is no robot of this kind"),
                      unit=units[k])
            for k, v in values.items()]


PAPER_NOMINAL = dict(m_b=210.6, m_w=29.0, I_b=55.0, I_w=0.6, l=0.267, r=0.254, g=9.81)
PAPER_ACTUAL = dict(m_b=310.6, m_w=29.0, I_b=65.0, I_w=0.6, l=0.317, r=0.254, g=9.81)

SHARED_SPECS: List[ParamSpec] = [
    ParamSpec("control_rate_hz", "double", 200.0, "control rate 1/h [Hz] of plant, observer and controller",
              **_rate, unit="Hz"),
    *_body("nominal", PAPER_NOMINAL, "nominal (hatted)"),
    ParamSpec("realtime_priority", "integer", 0, "SCHED_FIFO priority 1..99 of the node's threads, for realtime "
              "runs (needs root or CAP_SYS_NICE; else a warning); 0 = normal scheduling", **_priority),
]

# The observer's and the controller's QoS follow the loop's mode (msgs.qos): give them the plant's.
_LOOP_MODE = ParamSpec("mode", "string", "lockstep", "the plant's mode, for the QoS: lockstep (nothing lost) or "
                       "realtime (the newest state only)", **_one_of("lockstep", "realtime"))

def _registry():
    """The control laws' registry (core.laws; its plug-ins, $MWIP_ROS_LAWS, are imported with it)."""
    from mwip_ros.core import laws
    return laws


def _law_parameters() -> List[ParamSpec]:
    """The dscndo_controller parameters the registered laws declare themselves (all changeable at run time)."""
    laws, seen, out = _registry(), set(), []
    for name in laws.names():
        for p in laws.get(name).parameters:
            if p.name not in seen:
                seen.add(p.name)
                out.append(ParamSpec(p.name, p.type, p.default, p.description, lo=p.lo, hi=p.hi, dynamic=True))
    return out


def _estimator_parameters() -> List[ParamSpec]:
    """The state_estimator parameters the registered estimators declare (core.estimators)."""
    from mwip_ros.core import estimators
    return [ParamSpec(p.name, p.type, p.default, p.description, lo=p.lo, hi=p.hi)
            for name in estimators.names() for p in estimators.get(name).parameters]


def _estimator_names() -> tuple:
    from mwip_ros.core import estimators
    return estimators.names()


NODE_SPECS: Dict[str, List[ParamSpec]] = {
    "plant_sim": [
        ParamSpec("mode", "string", "lockstep", "lockstep (deterministic, waits for each command) or realtime "
                  "(wall-clock timer, zero-order hold)", **_one_of("lockstep", "realtime")),
        ParamSpec("duration_s", "double", 10.0, "simulated time to run [s]; 0 = until stopped",
                  **_non_negative(1e7)),
        ParamSpec("substeps", "integer", 5, "RK4 sub-steps per control period", **_at_least_one),
        ParamSpec("backend", "string", "rk4", "the physics: rk4 (eq. 1, RK4) or mujoco (a 3D model with two wheels "
                  "in MuJoCo, docs/theory.md 6.10)", **_one_of("rk4", "mujoco")),
        ParamSpec("mujoco.timestep", "double", 0.005, "mujoco: the largest physics step [s]; a control period is "
                  "ceil(h / timestep) equal steps", **_positive_from(1e-5, 1.0, "a step below 10 us"), unit="s"),
        ParamSpec("actual.track_width", "double", 0.5, "mujoco: distance between the two wheels [m]",
                  **_positive_from(1e-3, 100.0, "wheels closer than a millimetre"), unit="m"),
        *[ParamSpec(f"actual.I_b_{ax}", "double", v, f"mujoco: true body moment of inertia about its {ax} axis "
                    "through the centre of gravity [kg m^2] (actual.I_b is the pitch axis)",
                    **_positive_from(1e-6, 1e6, "a body inertia below 1e-6 kg m^2"), unit="kg m^2")
          for ax, v in (("roll", 65.0), ("yaw", 20.0))],
        *ground.specs(),   # ground.*: friction, slope, bumps (params.ground)
        *upkie.specs(),   # upkie.*: how the robot side drives Upkie (params.upkie, mwip_ros.robot.upkie)
        ParamSpec("seed", "integer", 0, "seed of the D_w friction noise", **_at_least_zero),
        *_body("actual", PAPER_ACTUAL, "true"),
        ParamSpec("actual.D_b", "double", 0.1, "true drive viscous friction D_b [N m s/rad]", **_non_negative()),
        ParamSpec("actual.D_w_mean", "double", 0.5, "mean of the ground friction D_w [N m s/rad]", **_non_negative()),
        ParamSpec("actual.D_w_variance", "double", 0.2, "variance of D_w, drawn once per period; 0 = deterministic",
                  **_non_negative()),
        ParamSpec("initial.theta_w", "double", 0.0, "initial wheel angle [rad]",
                  **_symmetric(MEASURED_LIMITS["theta_w"])),
        ParamSpec("initial.theta_b", "double", -0.1745, "initial body pitch [rad]",
                  **_symmetric(MEASURED_LIMITS["theta_b"])),
        ParamSpec("initial.dtheta_w", "double", 0.0, "initial wheel rate [rad/s]",
                  **_symmetric(MEASURED_LIMITS["rate"])),
        ParamSpec("initial.dtheta_b", "double", 0.0, "initial body pitch rate [rad/s]",
                  **_symmetric(MEASURED_LIMITS["rate"])),
        ParamSpec("tau_ext1.amplitude", "double", 30.0, "tau_ext1 amplitude [N m] (wheel row)", **_symmetric(1e6)),
        ParamSpec("tau_ext1.omega", "double", 2.0, "tau_ext1 angular frequency [rad/s]", **_symmetric(1e6)),
        ParamSpec("tau_ext1.phase", "double", math.pi / 2, "tau_ext1 phase [rad]", **_symmetric(1e6)),
        ParamSpec("tau_ext2.amplitude", "double", 0.2, "tau_ext2 amplitude [N m] (sum of rows)", **_symmetric(1e6)),
        ParamSpec("tau_ext2.omega", "double", 1.0, "tau_ext2 angular frequency [rad/s]", **_symmetric(1e6)),
        ParamSpec("tau_ext2.phase", "double", 0.0, "tau_ext2 phase [rad]", **_symmetric(1e6)),
        ParamSpec("torque_limit", "double", 0.0, "|u| cap [N m]; 0 = none", **_non_negative()),
        ParamSpec("fall_angle", "double", 1.0472, "|theta_b| beyond this ends the run as fallen [rad]",
                  **_positive(MEASURED_LIMITS["theta_b"])),
        ParamSpec("lockstep_timeout_s", "double", 10.0, "wall time [s] to wait for the graph (the controller and "
                  "expected_subscribers) before the first state, and in lockstep for each command; lockstep gives "
                  "up after it, realtime starts without the missing nodes", **_positive()),
        ParamSpec("stale_command_periods", "integer", 4, "realtime: a command older than this many periods "
                  "is replaced by zero torque", **_at_least_one),
        ParamSpec("csv", "string", "", "write the trajectory (mwip_sim CSV columns) to this file; '' = none"),
        ParamSpec("summary_json", "string", "", "write the run's summary (steps/s, realtime loop periods, missed "
                  "deadlines, stale commands, metrics) to this JSON file; '' = none"),
        *[ParamSpec(f"sensors.noise_std.{ch}", "double", 0.0, f"standard deviation of the zero-mean Gaussian noise on "
                    f"the published {ch} [{unit}], drawn once per period (its own seeded stream); 0 = none; at most "
                    f"a tenth of what a measurement may read (|{ch}| <= {limit:g}: the observer and the controller "
                    f"refuse a message beyond it)", **_non_negative(limit / NOISE_LIMIT_FRACTION), unit=unit)
          for ch, unit, limit in (("theta_w", "rad", MEASURED_LIMITS["theta_w"]),
                                  ("theta_b", "rad", MEASURED_LIMITS["theta_b"]),
                                  ("dtheta_w", "rad/s", MEASURED_LIMITS["rate"]),
                                  ("dtheta_b", "rad/s", MEASURED_LIMITS["rate"]))],
        ParamSpec("sensors.model", "string", "state", "what the plant publishes: state (joint_states, the state "
                  "itself, noisy with sensors.noise_std) or raw (imu/data_raw and wheel_encoder, what an IMU on the "
                  "body and a motor encoder measure; a state_estimator publishes joint_states)",
                  **_one_of("state", "raw")),
        ParamSpec("sensors.encoder_counts_per_rev", "integer", 0, "wheel encoder resolution: the published theta_w "
                  "(raw: the wheel's angle relative to the body) is quantized to 2 pi / counts; 0 = ideal",
                  **_count_range(0, 1 << 30)),
        ParamSpec("sensors.imu.offset", "double", 0.3, "raw: the IMU's distance from the axle along the body "
                  "[m]", **_non_negative(100.0), unit="m"),
        ParamSpec("sensors.imu.gyro_noise_std", "double", 0.0, "raw: white noise of the pitch rate per sample "
                  "[rad/s]", **_non_negative(10.0), unit="rad/s"),
        ParamSpec("sensors.imu.gyro_bias", "double", 0.0, "raw: the gyro's bias at the start [rad/s]",
                  **_symmetric(10.0), unit="rad/s"),
        ParamSpec("sensors.imu.gyro_bias_walk", "double", 0.0, "raw: random walk of the gyro's bias "
                  "[rad/s/sqrt(s)]", **_non_negative(10.0)),
        ParamSpec("sensors.imu.accel_noise_std", "double", 0.0, "raw: white noise of each accelerometer axis per "
                  "sample [m/s^2]", **_non_negative(100.0), unit="m/s^2"),
        ParamSpec("sensors.delay_periods", "integer", 0, "measurement delay: the state published at step k is the "
                  "measurement of step k - d (the first d steps publish the first one)", **_count_range(0, 100000)),
        ParamSpec("actuator.delay_periods", "integer", 0, "actuator delay: the command answering state k acts "
                  "over [t_(k+d), t_(k+d+1)); zero torque before the first one", **_count_range(0, 100000)),
        ParamSpec("motor.enabled", "bool", False, "a DC motor and its driver between the command and the wheel "
                  "(theory.md 6.7: back-EMF, voltage and current limits, evaluated at every RK4 stage); false = the "
                  "torque is the command"),
        ParamSpec("motor.torque_constant", "double", 2.0, "K_t at the wheel [N m/A], also the back-EMF constant "
                  "[V s/rad]", **_positive_from(1e-3, 1e4, "a motor of less than 1 mN m per ampere"),
                  unit="N m/A"),
        ParamSpec("motor.resistance", "double", 0.15, "winding resistance R [ohm]",
                  **_positive_from(1e-3, 1e4, "a winding below a milliohm: R i* rounds away against the back-EMF "
                                   "and the drive gives no torque at speed"), unit="ohm"),
        ParamSpec("motor.voltage_limit", "double", 48.0, "the driver's voltage limit V_max (battery) [V]",
                  **_positive_from(0.1, 1e5, "a battery below 0.1 V"), unit="V"),
        ParamSpec("motor.current_limit", "double", 60.0, "the driver's current limit I_max [A]",
                  **_positive_from(1e-3, 1e5, "a current limit below a milliampere"), unit="A"),
        ParamSpec("require_enable", "bool", False, "the driver starts disabled (zero torque) until ~/enable "
                  "(docs/theory.md 6.8); false: enabled at once, as the paper's run"),
        ParamSpec("watchdog_s", "double", 0.5, "realtime: no new wheel_torque_cmd for this long is a fault (zero "
                  "torque, latched until ~/reset; checked every period, counted from the first state published, "
                  "so a controller that never answers faults too); lockstep: lockstep_timeout_s is the watchdog",
                  **_positive_from(1e-3, 1e4, "a watchdog faster than a millisecond would fire between commands"),
                  unit="s"),
        ParamSpec("exit_on_fall", "bool", True, "end the process (exit code 3) when the robot falls; false: the "
                  "process stays up, the robot lying where it fell and the driver holding zero torque in fault "
                  "until ~/reset (exit code 3 only if duration_s ends the run with it down)"),
        ParamSpec("expected_subscribers", "integer", 2, "lockstep: matched subscriptions the plant's first "
                  "published topic needs before the first state (joint_states, or imu/data_raw with sensors.model "
                  "raw), counted as without an estimator: 2 = observer + controller, +1 per recorder; with raw "
                  "sensors the state_estimator alone listens, so the floor is this - 1", **_at_least_zero),
    ],
    "disturbance_observer": [
        _LOOP_MODE,
        ParamSpec("X", "double_array", [100.0, 0.0, 0.0, 100.0], "observer gain X = [c1, c2, c3, c4] (eq. 14)",
                  **_four_finite, dynamic=True),
        ParamSpec("csv", "string", "", "write the estimates (t, tau_hat1, tau_hat2) to this file at the end; "
                  "'' = none"),
    ],
    "dscndo_controller": [
        _LOOP_MODE,
        ParamSpec("k1", "double", 6.0, "first surface gain k1 (eq. 24)", **_positive(), dynamic=True),
        ParamSpec("k2", "double", 6.0, "second surface gain k2 (eq. 28)", **_positive(), dynamic=True),
        ParamSpec("tau4", "double", 0.1, "filter time constant tau4 [s] (eq. 25)", **_tau4, dynamic=True),
        ParamSpec("use_observer", "bool", True, "true: add the observer term u_taud (eq. 20) to the law: DSCNDO "
                  "(eq. 19) or LQR+NDO; false: the law alone (DSC or LQR)", dynamic=True),
        ParamSpec("law", "string", "dsc", "dsc (dynamic surface control, eq. 16-28) or lqr (the baseline: discrete "
                  "LQR on the nominal model's linearization, gain K from lqr.Q and lqr.R)",
                  **_one_of(*_registry().families()), dynamic=True),   # the laws' registry (core.laws)
        ParamSpec("lqr.Q", "double_array", [100.0, 10.0, 1.0], "LQR state weight on [theta_b, theta_b', theta_w']: "
                  "the diagonal (3 entries) or the 3x3 matrix row by row (9); symmetric positive semidefinite",
                  **_lqr_q, dynamic=True),
        ParamSpec("lqr.R", "double", 0.01, "LQR input weight (> 0)", **_positive(), dynamic=True),
        *_law_parameters(),   # what a plug-in law declares itself (core.laws.Law.parameters)
        *motion.specs(),   # motion.*: the references the laws track (params.motion, docs/theory.md 6.11)
        ParamSpec("excitation.type", "string", "none", "a known torque added to the law's command, recorded, for "
                  "identification (mwip_identify): none, chirp (a linear sweep f0 -> f1) or prbs (+-amplitude, "
                  "random bits)", **_one_of("none", "chirp", "prbs")),
        ParamSpec("excitation.amplitude", "double", 0.0, "the excitation's amplitude [N m]", **_non_negative(1e5),
                  unit="N m"),
        ParamSpec("excitation.f0", "double", 0.1, "chirp: start frequency [Hz] (<= excitation.f1)",
                  **_non_negative(1e4), unit="Hz"),
        ParamSpec("excitation.f1", "double", 5.0, "chirp: end frequency; prbs: the band edge [Hz]", **_positive(1e4),
                  unit="Hz"),
        ParamSpec("excitation.duration_s", "double", 10.0, "the excitation lasts this long from t = 0 [s]",
                  **_positive(1e7), unit="s"),
        ParamSpec("excitation.bit_periods", "integer", 0, "prbs: control periods a bit is held; 0 = from f1 "
                  "(round(0.443 / (f1 h)))", **_at_least_zero),
        ParamSpec("excitation.seed", "integer", 0, "prbs: seed of the bits (stream [seed, 3])", **_at_least_zero),
    ],
    "state_estimator": [
        _LOOP_MODE,
        ParamSpec("method", "string", "kalman", "how the raw IMU and encoder become the state: complementary (the "
                  "gyro integrated, blended with the accelerometer's pitch) or kalman (pitch, gyro bias and the "
                  "IMU's horizontal motion; docs/theory.md 6.4)", **_one_of(*_estimator_names())),
        ParamSpec("imu_offset", "double", 0.3, "the IMU's distance from the axle along the body as the estimator "
                  "believes it [m] (the plant's sensors.imu.offset is the truth)", **_non_negative(100.0), unit="m"),
        ParamSpec("csv", "string", "", "write the estimates (t, theta_w_hat, theta_b_hat, dtheta_w_hat, "
                  "dtheta_b_hat) to this file at the end; '' = none"),
        ParamSpec("imu_sync", "string", "stamp", "how an IMU sample meets an encoder sample: stamp (the two of one "
                  "stamp, as plant_sim and a driver whose backend reads both at once publish them) or latest (the "
                  "IMU has its own driver and rate: each encoder sample takes the newest IMU sample, held)",
                  **_one_of("stamp", "latest")),
        ParamSpec("imu_max_age_s", "double", 0.05, "imu_sync latest: an IMU sample further than this from the "
                  "encoder sample's stamp (older, or ahead) is not used: that encoder sample is dropped, counted "
                  "(an IMU that stopped publishing stops the estimates)", **_positive(10.0), unit="s"),
        *_estimator_parameters(),
    ],
    "mcap_recorder": [
        ParamSpec("output", "string", "", "bag directory to create (refuses an existing one)"),
        ParamSpec("topics", "string_array", [], "topics to record; empty = every topic of the graph"),
        ParamSpec("compression", "string", "", "'' or 'zstd' (MCAP chunk compression)", **_one_of("", "zstd")),
        ParamSpec("chunk_size", "integer", 1 << 20, "MCAP chunk size [bytes]", **_at_least_one),
        ParamSpec("max_bagfile_size", "integer", 0, "split the bag: start the next file <bag>_<n>.mcap once the "
                  "current one holds more than this many bytes (rosbag2's max_bagfile_size); 0 = no limit",
                  **_count_range(0, 1 << 50), unit="B"),
        ParamSpec("max_bagfile_duration", "integer", 0, "split the bag: start the next file once a message is "
                  "more than this many seconds of log time after the current file's first (rosbag2's "
                  "max_bagfile_duration, whole seconds as there); 0 = no limit", **_count_range(0, 1 << 40),
                  unit="s"),
    ],
    "foxglove_server": [
        ParamSpec("host", "string", "127.0.0.1", "address the WebSocket server listens on (0.0.0.0: every "
                  "interface; the server has no authentication)"),
        ParamSpec("port", "integer", 8765, "TCP port of the WebSocket server (Foxglove: ws://host:port)",
                  **_count_range(1, 65535)),
        ParamSpec("topics", "string_array", [], "topics to serve; empty = every topic of the graph"),
        ParamSpec("nice", "integer", 10, "nice value of the server's threads, 0 (normal) .. 19 (lowest): a viewer "
                  "yields the CPU to the control loop", **_count_range(0, 19)),
        ParamSpec("max_clients", "integer", 32, "most TCP connections the WebSocket server keeps open; one beyond "
                  "them is closed at once and logged (and refused at start-up if the descriptor limit leaves no "
                  "room for it)", **_count_range(1, 100000)),
        ParamSpec("idle_timeout_s", "double", 60.0, "a connection that subscribes to nothing and sends nothing for "
                  "this long is closed (also one that never completes the WebSocket handshake, and a subscribed one "
                  "that reads nothing that long while data waits for it)",
                  **_positive_from(0.5, 86400.0, "a client needs a moment to subscribe once it connected"), unit="s"),
    ],
    "robot_markers": [],   # the shared section only (the nominal model sizes the robot)
    "bag_replay": [
        ParamSpec("bag", "string", "", "bag directory to replay"),
        ParamSpec("rate", "double", 1.0, "playback rate factor", **_positive()),
        ParamSpec("loop", "bool", False, "start again at the end"),
        ParamSpec("topics", "string_array", [], "topics to replay; empty = all"),
        ParamSpec("publish_clock", "bool", False, "publish /clock from the bag's time"),
        ParamSpec("mode", "string", "replay", "replay (republish) or resim (feed joint_states through a running "
                  "observer and controller and compare)", **_one_of("replay", "resim")),
        ParamSpec("tolerance", "double", 1e-9, "resim: largest absolute difference still counted as equal",
                  **_non_negative()),
        ParamSpec("parameter_events", "bool", True, "resim: apply the recorded changes of the observer's and "
                  "the controller's parameters (/parameter_events) before the state they first applied to"),
        ParamSpec("timeout_s", "double", 10.0, "resim: give up when the graph is not ready or a command does "
                  "not come within this wall time [s]; replay: how long to wait for subscribers", **_positive()),
        ParamSpec("wait_for_subscribers", "integer", 0, "matched subscriptions to wait for before the first "
                  "message: replay: on every replayed topic (0 = start at once); resim: on joint_states "
                  "(0 = automatic: the controller, plus the observer when the bag has disturbance_estimate)",
                  **_at_least_zero),
    ],
}

# robot_state (odometry, URDF, TF; docs/theory.md 6.12): the robot's geometry and sensors, plant_sim's specs
NODE_SPECS["robot_state"] = [s for s in NODE_SPECS["plant_sim"] if s.name in (
    "actual.m_b", "actual.m_w", "actual.I_b", "actual.I_w", "actual.l", "actual.r", "actual.g", "actual.I_b_roll",
    "actual.I_b_yaw",
    "actual.track_width", "sensors.model", "sensors.imu.offset", "sensors.encoder_counts_per_rev",
    "sensors.imu.gyro_noise_std")]
# wheel_driver (docs/hardware.md): the node that owns a robot's clock; its settings and its backends' (params.driver)
NODE_SPECS["wheel_driver"] = driver.specs()

# Parameters ROS itself declares on every node; allowed anywhere in the file.
ROS_OWN = {"use_sim_time": ParamSpec("use_sim_time", "bool", False, "use /clock"),
           "start_type_description_service": ParamSpec("start_type_description_service", "bool", True, "ROS")}
ROS_OWN_PREFIXES = ()
# rclpy applies qos_overrides.* only to publishers and subscriptions created with QoSOverridingOptions; the
# nodes set each topic's QoS themselves (msgs.qos: lockstep must lose nothing), so such a key is refused,
# never silently ignored.
QOS_OVERRIDES = "qos_overrides."
QOS_OVERRIDES_REFUSED = ("QoS overrides are not supported: mwip_ros chooses each topic's QoS itself (docs/graph.md: "
                         "QoS; lockstep must lose nothing); remove the key")


def specs_for(node: str) -> Dict[str, ParamSpec]:
    """Every parameter ``node`` declares (the shared ones first)."""
    if node not in NODE_SPECS:
        raise KeyError(node)
    return {s.name: s for s in (*SHARED_SPECS, *NODE_SPECS[node])}


def defaults_for(node: str) -> Dict[str, Any]:
    return {name: s.default for name, s in specs_for(node).items()}


def spelling_hint(name: str, names: Iterable[str]) -> str:
    """' (did you mean 'x'?)' for the closest of ``names``, else ''; when ``names`` maps each name to the section
    it goes under (a string), ' (did you mean 'x' under section:?)'."""
    close = difflib.get_close_matches(name, list(names), n=1)
    if not close:
        return ""
    where = names.get(close[0]) if isinstance(names, Mapping) else None
    return (f" (did you mean '{close[0]}' under {where}:?)" if isinstance(where, str)
            else f" (did you mean '{close[0]}'?)")


def _check_designs(values: Mapping[str, Any], nominal, source: Optional[str]) -> None:
    """Each registered law's :meth:`~mwip_ros.core.laws.Law.design` from ``values`` (those whose parameters are
    all in ``values``); its error becomes a ParamError naming its key (``LqrDesignError.key``), or the law's first
    parameter when it names none (a plug-in's)."""
    laws, h = _registry(), 1.0 / values["control_rate_hz"]
    for family in laws.families():
        cls = laws.lookup(family, False) or laws.lookup(family, True)
        if not cls.param_keys or not all(k in values for k in cls.param_keys):
            continue
        try:
            cls.design(values, nominal, h)
        except (ArithmeticError, ValueError) as exc:
            key = getattr(exc, "key", None)
            if key is None:
                key, reason = cls.param_keys[0], f"the law {cls.name!r} has no design from its parameters ({exc})"
            else:
                reason = getattr(exc, "reason", str(exc))
            raise ParamError(key, reason, source) from None


def check_geometry(values: Mapping[str, Any], source: Optional[str] = None) -> None:
    """The 3D robot (``actual.*``: what ``backend: mujoco`` builds, docs/theory.md 6.10, and what ``robot_state``'s
    URDF describes): a body inertia a rigid body can have (each principal moment at most the sum of the other two)
    and wheels that do not overlap; ParamError naming the key, else."""
    moments = {"actual.I_b_roll": values["actual.I_b_roll"], "actual.I_b": values["actual.I_b"],
               "actual.I_b_yaw": values["actual.I_b_yaw"]}
    for key, v in moments.items():
        rest = sum(moments.values()) - v
        if v > rest:
            raise ParamError(key, f"{v:g} kg m^2 is more than the other two principal moments of the body together "
                                  f"({rest:g}); no rigid body has it", source)
    from mwip_ros.core.plants.mujoco_plant import wheel_width
    width = wheel_width(values["actual.r"])   # each wheel's cylinder is r / 5 wide (core.plants.mujoco_plant.mjcf)
    if values["actual.track_width"] <= width:
        raise ParamError("actual.track_width", f"{values['actual.track_width']:g} m: the wheels (each "
                                               f"actual.r / 5 = {width:g} m wide) would overlap", source)


def _check_mujoco(values: Mapping[str, Any], source: Optional[str]) -> None:
    """The 3D model of ``backend: mujoco`` (docs/theory.md 6.10): :func:`check_geometry`, and the package."""
    check_geometry(values, source)
    from mwip_ros.optional import missing
    why = missing("mujoco")
    if why is not None:
        raise ParamError("backend", why, source)


def check_derived(values: Mapping[str, Any], source: Optional[str] = None) -> None:
    """Raise ParamError when values that pass their own checks give a model no arithmetic can run:
    inertia terms that are not finite or an A_bar that is not positive (eq. 2, 38); or a law's parameters
    that give it no design (LQR or MPC weights with no stabilizing gain for the nominal model, ...: every
    registered law's design, whatever the law in use, so a switch of law at run time cannot fail).  The
    inertia terms are the model's (:class:`mwip_ros.core.plants.model.PhysicalParams`)."""
    from mwip_ros.core.plants.model import PhysicalParams

    for prefix in ("nominal", "actual"):
        if f"{prefix}.m_b" not in values:
            continue
        model = PhysicalParams(**{k: values[f"{prefix}.{k}"] for k in PAPER_NOMINAL})
        m11, m12, m22, G_b, a_bar = model.m11, model.m12, model.m22, model.G_b, model.A_bar   # eq. (2), (38)
        if not all(math.isfinite(x) for x in (m11, m12, m22, G_b, a_bar)) or not a_bar > 0:
            raise ParamError(f"{prefix}.m_b", f"the {prefix} model's inertia terms are not usable (m11 = {m11:g}, "
                                              f"m12 = {m12:g}, m22 = {m22:g}, A_bar = {a_bar:g}); check "
                                              f"{prefix}.{{m_b, m_w, I_b, I_w, l, r, g}}", source)
    if values.get("backend") == "mujoco":
        _check_mujoco(values, source)
        ground.check(values, source)
    if values.get("excitation.f0", 0.0) > values.get("excitation.f1", math.inf):
        raise ParamError("excitation.f0", f"must be <= excitation.f1 ({values['excitation.f1']:g} Hz), got "
                                          f"{values['excitation.f0']:g}", source)
    if values.get("excitation.type", "none") != "none" and "control_rate_hz" in values:
        nyquist = values["control_rate_hz"] / 2.0   # the command is sampled at the control rate (held over h)
        if not values["excitation.f1"] < nyquist:
            raise ParamError("excitation.f1", f"{values['excitation.f1']:g} Hz is at or above the Nyquist frequency "
                                              f"control_rate_hz / 2 = {nyquist:g} Hz: the {values['excitation.type']} "
                                              f"would come out aliased; keep excitation.f0 <= excitation.f1 below "
                                              f"it", source)
    if values.get("sensors.model") == "raw":
        for ch in ("theta_w", "theta_b", "dtheta_w", "dtheta_b"):
            if values.get(f"sensors.noise_std.{ch}"):
                raise ParamError(f"sensors.noise_std.{ch}", "applies to sensors.model: state only; a raw plant's "
                                                            "noise is sensors.imu.* (set it to 0.0)", source)
    sd = values.get("sensors.noise_std.theta_b")
    if sd and "fall_angle" in values and values["fall_angle"] + NOISE_SIGMAS * sd > MEASURED_LIMITS["theta_b"]:
        most = (MEASURED_LIMITS["theta_b"] - values["fall_angle"]) / NOISE_SIGMAS
        raise ParamError("sensors.noise_std.theta_b", f"{sd:g} rad would publish implausible pitches: a pitch near "
                                                      f"fall_angle ({values['fall_angle']:g} rad) plus "
                                                      f"{NOISE_SIGMAS:g} standard deviations passes |theta_b| <= pi, "
                                                      f"which the observer refuses; at most {most:.4g} rad with this "
                                                      f"fall_angle", source)
    if "nominal.m_b" in values and "control_rate_hz" in values:
        _check_designs(values, PhysicalParams(**{k: values[f"nominal.{k}"] for k in PAPER_NOMINAL}), source)
    if isinstance(values.get("law"), str) and isinstance(values.get("use_observer"), bool):
        laws = _registry()   # a law registered without its observer variant cannot take use_observer: true
        if values["law"] in laws.families() and laws.lookup(values["law"], values["use_observer"]) is None:
            raise ParamError("use_observer", f"the law {values['law']!r} has no variant "
                                             f"{'with' if values['use_observer'] else 'without'} the observer term",
                             source)
