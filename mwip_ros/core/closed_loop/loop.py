"""One closed-loop period: its ordered stages, who runs each, and the offline loop that runs them all.

The discrete-time contract (docs/theory.md, section 4) orders one control period k as

1. ``sensors``   what the robot measures of state k (:mod:`.sensing`: the state, noisy, quantized,
   delayed), with the torque that acted over period k - 1;
2. ``estimator`` the state the loop believes, from the measurement: the identity when the plant
   measures a state (``sensors.model: state``), a ``state_estimator`` (:mod:`.estimators`) when
   it measures the raw IMU and encoder (``raw``, :mod:`.raw_sensors`);
3. ``observer``  tau_hat_k from the measured state and the reported torque (eq. 12-13, :mod:`.observer`);
4. ``law``       u_k from the measured state and tau_hat_k (:mod:`.laws`);
4b. ``yaw``      on a spatial plant with motion references and the yaw loop (:mod:`.yaw`, docs/theory.md 6.13):
   u_psi,k from psi'*_k and the measured yaw rate, and the two wheels' torques u_L, u_R (optional: a planar
   plant, or motion off, has no yaw stage and nothing of it runs);
5. ``drive``     the torque limit, the actuator delay and the driver's state machine (:mod:`.safety`:
   zero torque unless enabled): the command that acts over [t_k, t_{k+1}) (with the motor model,
   :mod:`.drive`, the drive turns it into the torque at every RK4 stage of the plant; not enabled, the
   bridge is open and no current flows, :func:`.plant.gated_drive`);
6. ``plant``     integrate to t_{k+1} (:mod:`.plant`), after recording row k and its true tau_d.

:data:`STAGES` is that order, written once, with the graph node that runs each stage and the
topics it answers on.  Everything that runs a period takes it from here:

* the offline loop (:func:`.sim.simulate`, through :class:`Period`) and the ``plant_sim`` node share
  :class:`PlantSide` (stages 1, 5 and 6: the plant with its sensors and drive); the offline loop runs
  stages 2 to 4 itself (:meth:`Period.decide`), the graph in the nodes :data:`STAGES` names;
* the lockstep driver is told the answering stages (:func:`answering`): the nodes that must be
  there, the topic each answers on, the node to name when an answer is missing; re-simulation
  and the graph tests wait on the same description;
* the batch simulator runs the same stages over arrays (:mod:`.batch`, the same classes with
  numpy) and compiled (:mod:`.compiled`); both mark each stage with a ``# stage: NAME`` comment,
  and a test checks that they hold every stage of :data:`STAGES` in its order, so a stage added
  here and not there fails.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Deque, Optional, Tuple, cast

from ..laws import LawError
from ..plants.plant import Plant, PlantConfig, SpatialPlant, finite_state, make_plant, per_wheel, saturate
from ..plants.raw_sensors import RawSensors, YawGyro
from ..control.safety import PLAUSIBLE_TORQUE, DriverStateMachine
from ..control.yaw import YawLoop, wheel_torques
from .trajectory import BAD_COMMAND, DIVERGED, FAILURES, FALL
from ..plants.sensing import Actuator, Sensors

__all__ = ["Stage", "STAGES", "STAGE_NAMES", "PLANT_NODE", "Answer", "answering", "loop_nodes", "PlantSide",
           "Period", "decide", "command", "fall_text"]

PLANT_NODE = "plant_sim"


@dataclass(frozen=True)
class Stage:
    """One stage of a period: its name, the graph node that runs it, what it reads and answers with there."""

    name: str
    node: str                      # the node (its executable) that runs the stage in the graph
    inputs: Tuple[str, ...]        # topics it reads in the graph
    output: Optional[str]          # the topic it answers with (None: it ends the period, in the plant)
    what: str                      # one line: what the stage does
    optional: bool = False         # True: only some configurations run it
    waits_for: str = ""            # when the lockstep chain waits for it (words, for the wait's log)


STAGES: Tuple[Stage, ...] = (
    Stage("sensors", PLANT_NODE, (), "joint_states",
          "the measurement of state k and the torque that acted over period k - 1 (core.plants.sensing)"),
    Stage("estimator", "state_estimator", ("imu/data_raw", "wheel_encoder"), "joint_states",
          "the state from the measurement: the identity while the plant measures a state", optional=True),
    Stage("observer", "disturbance_observer", ("joint_states",), "disturbance_estimate",
          "tau_hat_k (eq. 12-13)", waits_for="the controller waits for it when use_observer is true"),
    Stage("law", "dscndo_controller", ("joint_states", "disturbance_estimate"), "wheel_torque_cmd",
          "u_k from the state and tau_hat_k (core.laws)"),
    Stage("yaw", "dscndo_controller", ("joint_states",), "wheel_torques_cmd",
          "u_psi_k from psi'*_k and the gyro's yaw rate, the wheels' torques u_L, u_R (core.control.yaw)",
          optional=True,
          waits_for="a spatial plant with motion.enabled and the yaw loop"),
    Stage("drive", PLANT_NODE, ("wheel_torque_cmd",), None,
          "torque_limit and the actuator delay: the torque that acts over [t_k, t_k+1)"),
    Stage("plant", PLANT_NODE, (), None, "record row k and its true tau_d, integrate to t_k+1 (RK4)"),
)
STAGE_NAMES = tuple(s.name for s in STAGES)


@dataclass(frozen=True)
class Answer:
    """A stage another node runs in the lockstep chain: ``node`` answers each state with one message on
    ``topic`` (the last answer of the chain is the command that ends the wait)."""

    stage: str
    node: str
    topic: str
    why: str = ""


def _runs(s: Stage, estimator: bool) -> bool:
    """Whether the stage ``s`` is in a configuration's chain: the estimator only with ``estimator``; the yaw stage
    runs in the law's node after the law, so it adds no node and no answer to wait for."""
    if s.name == "yaw":
        return False
    return estimator or not s.optional


def answering(estimator: bool = False) -> Tuple[Answer, ...]:
    """The answering stages of the lockstep chain, in order: the stages the plant does not run itself
    (``estimator``: whether the configuration has a state estimator)."""
    return tuple(Answer(s.name, s.node, cast(str, s.output), s.waits_for) for s in STAGES   # off the plant: a topic
                 if s.node != PLANT_NODE and _runs(s, estimator))


def loop_nodes(estimator: bool = False) -> Tuple[str, ...]:
    """The nodes of the closed loop (plant first), each once, in the order of their first stage."""
    out = []
    for s in STAGES:
        if s.node not in out and _runs(s, estimator):
            out.append(s.node)
    return tuple(out)


class PlantSide:
    """The stages the plant runs (``sensors``, ``drive``, ``plant``), one object for the offline loop and
    the ``plant_sim`` node, so both take the same steps in the same order.

    :meth:`sense` is stage 1, :meth:`act` stage 5 (the torque that acts, the true tau_d of row k),
    :meth:`advance` stage 6.  ``extra`` is the external wrench held over the period (the node's
    ``external_wrench``; the offline loop has none)."""

    def __init__(self, cfg: PlantConfig):
        self.cfg = cfg
        sc = cfg.sensing
        self.plant: Plant = make_plant(cfg)
        self.raw: Optional[RawSensors] = None
        if cfg.raw is not None:   # docs/theory.md 6.4: the IMU and the relative encoder, delayed as the state would be
            self.raw = RawSensors.for_plant(cfg.raw, cfg.seed, cfg.h, cfg.actual.r, cfg.actual.g)
            self.raw_queue: Deque[Tuple[Any, float]] = deque(maxlen=sc.delay_periods + 1)
        self.sensors = Sensors.for_plant(sc, cfg.seed) if sc.measuring and self.raw is None else None
        self.actuator = Actuator(sc.actuator_delay_periods) if sc.actuator_delay_periods else None
        # the yaw stage's inputs (docs/theory.md 6.13, a spatial plant only): the gyro's yaw rate, delayed as the
        # state is, and the wheels' pair through the actuator's delay
        self.yaw_queue: Deque[float] = deque(maxlen=sc.delay_periods + 1)
        # with raw sensors the IMU's z-axis gyro measures it, with the pitch axis's noise and bias (theory 6.4)
        self.yaw_gyro = (YawGyro.for_plant(cfg.raw, cfg.seed, cfg.h) if cfg.raw is not None and self.plant.spatial
                         else None)
        self.wheel_actuator = (Actuator(sc.actuator_delay_periods, zero=(0.0, 0.0)) if sc.actuator_delay_periods
                               else None)
        # the wheels' torques (u_L, u_R) of the period :meth:`act` decided, None: u / 2 each
        self.wheels: Optional[Tuple[float, float]] = None
        # the driver's state machine (docs/theory.md 6.8): disabled or faulted, the torque that acts is zero; a
        # command that is not a number or beyond PLAUSIBLE_TORQUE is a ``bad_command`` fault (the node's own limit)
        self.safety = DriverStateMachine(require_enable=cfg.require_enable, max_command=PLAUSIBLE_TORQUE)
        self.enabled = self.safety.enabled   # the bridge over the period :meth:`act` decided (closed: enabled)

    def sense(self):
        """Stage ``sensors``: (what is measured of state k, the torque of period k - 1 as reported).  The
        measurement is a state (``sensors.model: state``) or a :class:`~.raw_sensors.RawSample` (``raw``)."""
        p = self.plant
        if self.raw is not None:
            ddq = p.sample_accel()   # a spatial plant: its own accelerometer (MuJoCo's, read at t_k^- after this)
            force = cast(Tuple[float, float], cast(SpatialPlant, p).imu_reading()[1][::2]) if p.spatial else None
            self.raw_queue.append((self.raw.sample(p.x, ddq, force), p.u_prev))
            return self.raw_queue[0]   # the sample of step k - d (or the first one while k < d)
        return self.sensors.sample(p.x, p.u_prev) if self.sensors else (p.x, p.u_prev)

    def sense_yaw_rate(self) -> float:
        """Stage ``sensors`` of a spatial plant (docs/theory.md 6.13): the gyro's yaw rate (the body's z rate) of step
        k - d, as the state is delayed (ideal: no noise, no bias; with raw sensors the IMU's z-axis gyro,
        :class:`~.raw_sensors.YawGyro`).  Called once per period, after :meth:`sense`."""
        w = cast(SpatialPlant, self.plant).yaw_rate   # called for a spatial plant only
        self.yaw_queue.append(w if self.yaw_gyro is None else self.yaw_gyro.sample(w))
        return self.yaw_queue[0]

    def act(self, u_cmd: float, extra=(0.0, 0.0), wheels: Optional[Tuple[float, float]] = None):
        """Stage ``drive``: the torque acting over [t_k, t_k+1) for the command ``u_cmd``, and the true tau_d
        at t_k with it (what row k records).  A command that is not a finite number, or is implausible, faults the
        driver (``bad_command``, before the torque limit, which would clip NaN to a limit): zero torque acts.
        ``wheels`` (the yaw stage's, a spatial plant; docs/theory.md 6.13): the wheels' commands (u/2 - u_psi/2,
        u/2 + u_psi/2), each checked, clipped to half the torque limit, delayed and gated; the torque returned is
        u_L + u_R (``u_cmd`` is not read)."""
        if wheels is not None:
            return self._act_wheels(wheels, extra)
        self.wheels = None
        self.safety.check_command(self.plant.t, u_cmd)
        u = saturate(u_cmd, self.cfg.torque_limit)
        if self.actuator is not None:
            u = self.actuator.apply(u)
        self.enabled = self.safety.enabled   # the gate of this period: not enabled, the bridge is open (no current)
        u = self.safety.torque_gate(u)   # zero unless the driver is enabled; the observer is told what acted
        return u, self.plant.lumped_disturbance(u, extra)

    def _act_wheels(self, wheels, extra):
        t, lim = self.plant.t, per_wheel(self.cfg.torque_limit)
        self.safety.check_command(t, wheels[0])
        self.safety.check_command(t, wheels[1])
        pair = (saturate(wheels[0], lim), saturate(wheels[1], lim))
        if self.wheel_actuator is not None:
            pair = self.wheel_actuator.apply(pair)
        self.enabled = self.safety.enabled
        pair = (self.safety.torque_gate(pair[0]), self.safety.torque_gate(pair[1]))
        self.wheels = pair
        u = pair[0] + pair[1]
        return u, cast(SpatialPlant, self.plant).lumped_disturbance(u, extra, wheels=pair)   # the yaw stage's plant

    def advance(self, u: float, extra=(0.0, 0.0)) -> None:
        """Stage ``plant``: integrate t_k -> t_k+1 with the torque that acts (the bridge as :meth:`act` found it;
        with the yaw stage, the wheels' pair)."""
        if self.wheels is not None:
            cast(SpatialPlant, self.plant).step(u, extra, enabled=self.enabled, wheels=self.wheels)
            return
        self.plant.step(u, extra, enabled=self.enabled)


class Period:
    """A whole period in one process (the offline loop): the plant's stages around the estimator (when the
    plant measures raw: :mod:`.estimators`), the observer and the law (with ``motion``, a :class:`.motion.Shaper`,
    the law tracks its references: :func:`command`); ``wrench``, a function of t_k, the external wrench held over
    each period (what ``plant_sim``'s ``external_wrench`` holds: (tau_ext1, tau_ext2[, force.y, torque.z]))."""

    def __init__(self, side: PlantSide, observer, law, estimator=None, excitation=None, motion=None,
                 yaw: Optional[YawLoop] = None, wrench=None):
        self.side, self.observer, self.law, self.estimator = side, observer, law, estimator
        self.wrench = wrench   # t_k -> the external wrench held over period k (a terrain scan's push); None: none
        self.extra = (0.0, 0.0)
        self.excitation = excitation
        # the references' shaper (core.control.motion.Shaper, theory 6.11), None: none (the paper)
        self.motion = motion
        self.yaw = yaw   # the yaw stage (core.control.yaw, theory 6.13): a spatial plant with motion; None: none
        if yaw is not None and (motion is None or not side.plant.spatial):
            raise ValueError("the yaw stage needs the motion references and a spatial plant (backend mujoco)")
        # (t, one line, cause: a FAILURES name) once the run has failed
        self.failure: Optional[Tuple[float, str, str]] = None
        if (side.raw is None) != (estimator is None):
            raise ValueError("a raw plant needs a state estimator, and only a raw plant has one")

    def decide(self, measured, u_m, k: int = 0):
        """Stages ``estimator`` (the identity when the measurement is a state), ``observer`` and ``law`` (with the
        excitation of period ``k`` added, :func:`command`): (u_k, tau_hat_k, the law's internals, the state the
        loop believes).  A law that raises is a :class:`~.laws.LawError` (the law, t_k, its error)."""
        return decide(self.estimator, self.observer, self.law, measured, u_m, k, self.side.cfg.h, self.excitation,
                      self.motion, self.side.safety.enabled)

    def sense_decide(self):
        """Stages ``sensors`` (with a yaw stage, the gyro's yaw rate too), ``estimator``, ``observer`` and ``law`` of
        period k: (the measurement, the measured yaw rate or None, u_k, tau_hat_k, the law's internals, the state the
        loop believes).  The env (:class:`mwip_ros.envs.MwipEnv`) adds its action to u_k before :meth:`actuate`."""
        side = self.side
        measured, u_m = side.sense()
        dpsi = side.sense_yaw_rate() if self.yaw is not None else None   # the yaw stage's input (theory 6.13)
        u_law, tau_hat, internals, x_m = self.decide(measured, u_m, side.plant.k)
        return measured, dpsi, u_law, tau_hat, internals, x_m

    def actuate(self, u_law: float, dpsi: Optional[float], internals: dict):
        """Stages ``yaw`` (a spatial plant with motion: u_psi from psi'* and the measured yaw rate ``dpsi``, the
        wheels' torques, :func:`.yaw.wheel_torques`) and ``drive`` for the command ``u_law``: (the torque that acts
        over [t_k, t_k+1), the true tau_d at t_k, the internals with the yaw stage's signals).  While no torque acts
        (the driver not enabled) the yaw integral stays zero (:meth:`.yaw.YawLoop.idle`)."""
        wheels = None
        side = self.side
        if self.yaw is not None:   # stage yaw (after the law): u_psi from psi'* and the gyro's yaw rate
            dpsi_ref = self.motion.ref.dpsi
            assert dpsi is not None   # the yaw stage runs with the sensors' yaw rate (Period.run)
            u_psi = self.yaw.step(dpsi_ref, dpsi, u_law) if side.safety.enabled else self.yaw.idle(dpsi)
            internals = {**internals, "dpsi_ref": dpsi_ref, "u_psi": u_psi, "gyro_z": dpsi}
            wheels = wheel_torques(u_law, u_psi, 0.0)   # clipped per wheel in the drive stage
        self.extra = self.wrench(side.plant.t) if self.wrench is not None else (0.0, 0.0)
        u, tau_d = side.act(u_law, self.extra, wheels=wheels)
        return u, tau_d, internals

    def run(self, table) -> bool:
        """Period k up to the integration: sense, decide, act (:meth:`sense_decide`, :meth:`actuate`), and row k
        into ``table`` (true state, the torque that acts, tau_hat, the true tau_d, internals; raw: the sample and the
        estimate).  True when the run fails (:attr:`failure` says when and why; the period ends there): the state is
        not a number (diverged: no row), the robot has fallen, or the law's command was refused; else
        :meth:`advance` integrates it."""
        side = self.side
        p = side.plant
        if not finite_state(p.x):   # diverged: the state is not a number (no row: nothing to sense or record)
            self.failure = (p.t, fall_text(p.t, p.x, p.cfg.fall_angle), FAILURES[DIVERGED])
            return True
        measured, dpsi, u_law, tau_hat, internals, x_m = self.sense_decide()
        u, tau_d, internals = self.actuate(u_law, dpsi, internals)
        table.append(p.t, p.x, u, tau_hat, tau_d, internals, (*measured, *x_m) if self.estimator else (), p.pose)
        self.u = u
        if p.fallen:
            self.failure = (p.t, fall_text(p.t, p.x, p.cfg.fall_angle), FAILURES[FALL])
        elif side.safety.faulted and side.safety.fault_reason == "bad_command":
            why = side.safety.fault_detail
            self.failure = (p.t, f"FAILED at t = {p.t:.3f} s: the law's command is refused ({why})",
                            FAILURES[BAD_COMMAND])
        return self.failure is not None

    def advance(self, table=None) -> bool:
        """Stage ``plant``: integrate period k; ``table`` gets the torque that acted over it (motor model on).  True
        when the model's arithmetic fails on the way (diverged at t_k+1, :attr:`failure`); a state that comes out
        not a number is the next :meth:`run`'s failure."""
        p = self.side.plant
        try:
            self.side.advance(self.u, self.extra)
        except (ArithmeticError, ValueError) as exc:   # e.g. sin of an infinite angle in eq. (1): t_k+1 not reached
            t = p.t + p.cfg.h
            self.failure = (t, f"FAILED at t = {t:.3f} s: the state diverged (the model's arithmetic failed: {exc})",
                            FAILURES[DIVERGED])
            return True
        if table is not None:
            table.set_drive(p.u_prev, p.saturation)
        return False


def decide(estimator, observer, law, measured, u_m: float, k: int, h: float, excitation=None, motion=None,
           driving: bool = True):
    """Stages ``estimator``, ``observer`` and ``law`` of period ``k`` (:meth:`Period.decide`; a robot's own loop, which
    has no :class:`PlantSide`, calls it too: :mod:`mwip_ros.robot.closed_loop`).

    Parameters
    ----------
    estimator : Estimator or None
        The state estimator (:mod:`.estimators`) when ``measured`` is a raw sample, None when it is a state.
    observer, law
        The observer (eq. 12-13) and the law (:mod:`.laws`).
    measured
        The period's measurement: a state, or a :class:`~.raw_sensors.RawSample`.
    u_m : float
        The torque that acted over period k - 1, as reported [N m].
    k : int
        The period; ``h`` its length [s] (for a law's error's time).
    excitation, motion : optional
        The excitation (:mod:`.excitation`) and the references' shaper (:class:`.motion.Shaper`) of :func:`command`.
    driving : bool
        Whether the torque acts (the driver enabled) over the period: :func:`command`'s.

    Returns
    -------
    tuple
        (u_k, tau_hat_k, the law's internals, the state the loop believes); a law that raises is a
        :class:`~.laws.LawError` (the law, t_k, its error).
    """
    x_m = measured if estimator is None else estimator.step(measured)
    tau_hat = observer.update(x_m, u_m)
    try:
        u_law, internals = command(law, x_m, tau_hat, excitation, k, motion, driving)
    except Exception as exc:   # noqa: BLE001 - a law's own error (a plug-in's bug), named as the law's
        raise LawError.of(law.name, k * h, exc) from exc
    return u_law, tau_hat, internals, x_m


def fall_text(t: float, x, fall_angle: float) -> str:
    """The line of a failed state ``x`` at ``t``: a fall, 'FELL at t = ...: |theta_b| = ... > fall_angle ...', or a
    state that diverged (a component not a finite number)."""
    if not finite_state(x):
        return f"FAILED at t = {t:.3f} s: the state diverged (not a finite number: {tuple(float(v) for v in x)})"
    return f"FELL at t = {t:.3f} s: |theta_b| = {abs(x[1]):.4f} > fall_angle {fall_angle:g}"


def command(law, x, tau_hat, excitation, k: int, motion=None, driving: bool = True):
    """Stage ``law``: the references of period ``k`` handed to the law (``motion``, a :class:`.motion.Shaper`;
    None: none, the law regulates as in the paper), the law's command for the state ``x`` and ``tau_hat``, plus the
    excitation of period ``k`` (:mod:`.excitation`; None: none) — the command sent, what the trajectory's ``u``
    records; the excitation and the references (v_ref, theta_w_ref) are in the internals.  While a law with the
    observer term holds (the shaper's :attr:`~.motion.Shaper.hold`, docs/theory.md 6.14) it regulates about the
    hold's equilibrium: it sees theta_b - theta_eq and tau_hat - tau_bar, and -tau_bar_1 is added to its command.
    The controller node calls this too, so the offline loop and the graph take the references in the same place of
    the period.  ``driving`` False: no torque acts (the driver is not enabled, docs/theory.md 6.8): the references
    stay at the measured state, at rest (:meth:`.motion.Shaper.idle`), and start from it when the torque is back."""
    hold = None
    if motion is not None:   # docs/theory.md 6.11: theta_w*(0) is the first state's wheel angle
        if not driving:
            motion.idle()
        ref = motion.reference(k, x=x, tau_hat=tau_hat if law.observer else None)
        law.track(ref)
        hold = motion.hold
    if hold is None:
        u, internals = law.step(x, tau_hat)
    else:   # the hold's equilibrium (docs/theory.md 6.14)
        shifted = type(x)(x[0], x[1] - hold.lean, x[2], x[3])
        u, internals = law.step(shifted, None if tau_hat is None else (tau_hat[0] - hold.tau1, tau_hat[1] - hold.tau2))
        u = u + hold.torque
        if isinstance(internals, dict) and "u" in internals:
            internals = {**internals, "u": u}
    if motion is not None and isinstance(internals, dict):
        internals = {**internals, "v_ref": ref.v, "theta_w_ref": ref.theta_w}
    if excitation is not None:
        e = excitation.at(k)
        u = u + e
        internals = {**internals, "excitation": e} if isinstance(internals, dict) else internals
    return u, internals
