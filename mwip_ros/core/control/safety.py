"""The driver's state machine (docs/theory.md 6.8): what stands between a controller and the motor.

States:

=============  ==============================================================================
``disabled``   no torque (the bridge open, no current); the start state when ``require_enable`` is true
``enabled``    the command acts; the start state when ``require_enable`` is false
``fault``      no torque (the bridge open, no current), latched with its reason until ``reset``
=============  ==============================================================================

Events and their answers (every call answers, none raises; a call that changes the state returns
and records a :class:`Transition`):

==============  =============  ============================  ==================================
event           disabled       enabled                       fault
==============  =============  ============================  ==================================
``enable``      -> enabled     ok, already enabled           refused: reset first (names the fault)
``disable``     ok, already    -> disabled                   ok, torque already zero; stays latched
``reset``       -> start       -> start                      -> start, refused while a level is held
``fault(r)``    -> fault(r)    -> fault(r)                   kept: the first reason stays
==============  =============  ============================  ==================================

Fault reasons (:data:`FAULT_REASONS`): ``watchdog`` (no new command for ``watchdog_s``; lockstep: the
lockstep timeout), ``bad_command`` (non-finite or implausible, :meth:`DriverStateMachine.check_command`),
``fall`` (|theta_b| > fall_angle), ``emergency_stop`` (std_msgs/Bool true), ``estimator_unhealthy``
(raw mode: the state estimator reports ERROR), ``diverged`` (the plant's simulation diverged,
:class:`~mwip_ros.core.plants.plant.PlantDiverged`: the run ends there) and ``device`` (a robot's device reported its
own fault: a moteus fault code, a controller that stopped answering, a transport that failed; the detail is the
backend's one line naming it, :attr:`mwip_ros.robot.backend.Observation.fault`).  A fault is a fault whatever the enable
state (a fall while disabled is latched too).

**Levels.** ``emergency_stop`` and ``estimator_unhealthy`` are inputs with a level (:data:`LEVEL_INPUTS`,
:meth:`DriverStateMachine.set_level`), not events: the e-stop is pressed (true) until it is released
(false), the estimator unhealthy while its latest status is ERROR (OK or WARN clears it).  Asserting one
latches the fault (as :meth:`~DriverStateMachine.fault`), and the machine remembers that it is held
(``held``): while any level is held, ``reset`` is refused, naming it (the state stays ``fault``), and so
``enable`` is too (it is refused in fault).  Releasing a level does not clear the fault: it makes the
next ``reset`` possible.  So no reset and no enable brings torque back while the e-stop is pressed or the
estimator's fault condition holds.  A level asserted during another fault is held the same way: the
fault keeps its first reason, and the reset is still refused until the level is released.

**Latch**: while in fault, a later fault keeps the first reason and its detail, the cause (a watchdog
expiry is typically followed by a fall, and the fall is not what went wrong).  Later faults are counted
(``suppressed``) and the last one kept (``last_suppressed``) for diagnostics; they make no transition.  An
event fault (``watchdog``, ``bad_command``, ``fall``) that comes during another fault needs no memory: its
condition is checked again after the reset (the watchdog counts again from the reset, a fall is checked
every period) and faults again if it still holds.

**Reset policy** (stop first, as Upkie's spine and ros2_control's lifecycle do): ``reset`` restores the
start state, never more.  With ``require_enable: true`` (a robot's setting) that is ``disabled``: a reset
from a fault brings no torque back, an explicit ``enable`` must follow.  With ``require_enable: false``
(the paper's runs and the simulations: nobody to enable the driver) the start state is ``enabled``, and the
reset itself is the explicit act that brings the torque back; it is refused while a level is held.

:meth:`DriverStateMachine.torque_gate` is the command that acts: the command when enabled, else 0.0
(which is also what the observer must be told acted); :attr:`DriverStateMachine.enabled` is the bridge:
disabled or in fault it is open and no current flows, so the torque is exactly zero also with the motor
model and the wheel spinning faster than V_max / K_t (:func:`mwip_ros.core.plants.plant.gated_drive`).
Pure Python, no ROS: the ``plant_sim`` node maps the answers onto std_srvs/Trigger (``success``,
``message``) and the transitions onto ``/diagnostics`` and the log.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Deque, Dict, Optional, Tuple

__all__ = ["DISABLED", "ENABLED", "FAULT", "STATES", "FAULT_REASONS", "LEVEL_INPUTS", "EVENTS", "Transition",
           "Answer", "DriverStateMachine", "Watchdog", "HISTORY", "PLAUSIBLE_TORQUE", "PLAUSIBLE_STATE"]

DISABLED, ENABLED, FAULT = "disabled", "enabled", "fault"
STATES = (DISABLED, ENABLED, FAULT)
FAULT_REASONS = ("watchdog", "bad_command", "fall", "emergency_stop", "estimator_unhealthy", "diverged", "device")
LEVEL_INPUTS = ("emergency_stop", "estimator_unhealthy")   # faults that are held while their input is asserted
# how a refused reset names a held level, and what releases it
_HELD_TEXT = {"emergency_stop": ("the emergency stop is still asserted",
                                 "release it (std_msgs/Bool false on emergency_stop: mwip_ctl estop --release)"),
              "estimator_unhealthy": ("the state estimator still reports ERROR",
                                      "wait for its status to return to OK or WARN")}
EVENTS = ("enable", "disable", "reset") + FAULT_REASONS   # the ``reason`` a Transition can carry
# A command beyond this [N m] is implausible (a ``bad_command``): far beyond any drive of this robot (the paper's
# run stays below 150 N m) and far inside what the model's arithmetic survives (1e300 overflows eq. 1 in a period).
# The plant node's driver refuses such a message, the offline loop's driver the law's command (core.closed_loop.loop).
PLAUSIBLE_TORQUE = 1e6
# What a measured state may read (|value| at most), far beyond anything the robot reaches (the paper's run: |theta_b|
# below 0.2 rad, the rates below 5 rad/s) and far inside what the arithmetic survives (a rate of 1e160 overflows the
# law): a joint_states message beyond it is rejected like a NaN (msgs.layouts.LIMITS), and a plant's measurement
# noise must stay well inside it (params.schema).
PLAUSIBLE_STATE = {
    "theta_b": math.pi,        # body pitch [rad]: beyond it the body is upside down
    "theta_w": 1e9,            # wheel angle [rad]: 250,000 km of travel
    "rate": 1e3,               # theta_w', theta_b' [rad/s]
}
HISTORY = 1000     # transitions kept by a machine (older ones drop: a node that runs for days stays bounded)

# /diagnostics levels (diagnostic_msgs/DiagnosticStatus): OK, WARN, ERROR
_LEVEL = {ENABLED: 0, DISABLED: 1, FAULT: 2}


@dataclass(frozen=True)
class Transition:
    """One change of state at time ``t`` [s]: ``reason`` is the event (``enable``, ``disable``, ``reset``) or
    the fault's reason (:data:`FAULT_REASONS`); ``detail`` says more (a fault's figures), may be ''."""

    t: float
    from_state: str
    to_state: str
    reason: str
    detail: str = ""

    def text(self) -> str:
        """One line for the log and /diagnostics, e.g. ``t = 1.250 s: enabled -> fault (fall: |theta_b| = ...)``."""
        more = f": {self.detail}" if self.detail else ""
        return f"t = {self.t:.3f} s: {self.from_state} -> {self.to_state} ({self.reason}{more})"


@dataclass(frozen=True)
class Answer:
    """The answer to a service call (std_srvs/Trigger's ``success`` and ``message``) and the transition it
    made, if any."""

    success: bool
    message: str
    transition: Optional[Transition] = None


class DriverStateMachine:
    """The driver's state, fault latch and history (module doc).

    Parameters
    ----------
    require_enable : bool
        True: start (and reset to) ``disabled``, the torque acting only after ``enable``; False: ``enabled``.
    max_command : float
        A command whose magnitude passes this [N m] is implausible (:meth:`check_command`: a ``bad_command``
        fault); 0 = only non-finite commands are bad.
    """

    def __init__(self, require_enable: bool = False, max_command: float = 0.0):
        if not (isinstance(max_command, (int, float)) and math.isfinite(max_command) and max_command >= 0):
            raise ValueError(f"max_command: must be finite and >= 0, got {max_command!r}")
        self.require_enable = bool(require_enable)
        self.max_command = float(max_command)
        self.state = self.start_state
        self.fault_reason: Optional[str] = None
        self.fault_detail = ""
        self.fault_t: Optional[float] = None
        self.suppressed = 0                                    # faults raised while already in fault
        self.last_suppressed: Optional[Tuple[float, str, str]] = None   # (t, reason, detail) of the last one
        self.history: Deque[Transition] = deque(maxlen=HISTORY)
        self.held: Dict[str, Tuple[float, str]] = {}          # level input -> (t asserted, detail) while asserted

    @property
    def start_state(self) -> str:
        return DISABLED if self.require_enable else ENABLED

    @property
    def enabled(self) -> bool:
        return self.state == ENABLED

    @property
    def faulted(self) -> bool:
        return self.state == FAULT

    def _go(self, t: float, to: str, reason: str, detail: str = "") -> Transition:
        tr = Transition(float(t), self.state, to, reason, detail)
        self.state = to
        self.history.append(tr)
        return tr

    def _fault_text(self) -> str:
        more = f": {self.fault_detail}" if self.fault_detail else ""
        return f"{self.fault_reason}{more}, since t = {self.fault_t:.3f} s"

    # -- services -------------------------------------------------------------------------------------------

    def enable(self, t: float) -> Answer:
        """``~/enable``: disabled -> enabled; refused in fault (reset first)."""
        if self.state == FAULT:
            return Answer(False, f"refused: the driver is in fault ({self._fault_text()}); call ~/reset first")
        if self.state == ENABLED:
            return Answer(True, "already enabled")
        return Answer(True, "enabled", self._go(t, ENABLED, "enable"))

    def disable(self, t: float) -> Answer:
        """``~/disable``: enabled -> disabled; in fault the torque is zero already and the fault stays latched."""
        if self.state == FAULT:
            return Answer(True, f"in fault ({self._fault_text()}): the torque is zero already; the fault stays "
                                f"latched until ~/reset")
        if self.state == DISABLED:
            return Answer(True, "already disabled")
        return Answer(True, "disabled", self._go(t, DISABLED, "disable"))

    def reset(self, t: float) -> Answer:
        """``~/reset``: clear any fault and return to the start state (from any state); refused, the state unchanged,
        while a level input is held (:meth:`set_level`), naming it."""
        if self.held:
            why = "; ".join(f"{_HELD_TEXT[r][0]} (since t = {since:.3f} s{': ' + d if d else ''}): {_HELD_TEXT[r][1]}"
                            for r, (since, d) in self.held.items())
            where = f" ({self._fault_text()})" if self.state == FAULT else ""
            return Answer(False, f"refused: {why}; the driver stays in {self.state}{where}")
        was = self._fault_text() if self.state == FAULT else None
        self.fault_reason, self.fault_detail, self.fault_t = None, "", None
        self.suppressed, self.last_suppressed = 0, None
        text = f"fault cleared ({was}); " if was else ""
        if self.state == self.start_state:
            return Answer(True, f"{text}{self.state} (the start state)")
        return Answer(True, f"{text}{self.start_state} (the start state)", self._go(t, self.start_state, "reset"))

    # -- faults ---------------------------------------------------------------------------------------------

    def fault(self, t: float, reason: str, detail: str = "") -> Optional[Transition]:
        """Latch a fault with ``reason`` (one of :data:`FAULT_REASONS`; anything else is a programming error:
        ValueError naming it).  Returns the transition, or None when already in fault (the first reason stays;
        this one is counted in ``suppressed``)."""
        if reason not in FAULT_REASONS:
            raise ValueError(f"fault reason {reason!r}: not one of {', '.join(FAULT_REASONS)}")
        if self.state == FAULT:
            self.suppressed += 1
            self.last_suppressed = (float(t), reason, detail)
            return None
        self.fault_reason, self.fault_detail, self.fault_t = reason, detail, float(t)
        return self._go(t, FAULT, reason, detail)

    def set_level(self, t: float, reason: str, asserted: bool, detail: str = "") -> Optional[Transition]:
        """A level input (:data:`LEVEL_INPUTS`; anything else: ValueError) is asserted or released (module doc).
        Asserted: held, and the fault latched (its transition, or None when already in fault: counted as a later
        fault, unless it was held already: a repeat of the same level is no new fault).  Released: no longer
        held; the fault stays latched until :meth:`reset`.  Returns the transition, if any."""
        if reason not in LEVEL_INPUTS:
            raise ValueError(f"level input {reason!r}: not one of {', '.join(LEVEL_INPUTS)}")
        if not asserted:
            self.held.pop(reason, None)
            return None
        if reason in self.held:
            return None
        self.held[reason] = (float(t), detail)
        return self.fault(t, reason, detail)

    def check_command(self, t: float, u) -> Optional[Transition]:
        """A ``bad_command`` fault when ``u`` is not a finite number or (``max_command`` > 0) passes it in
        magnitude; the transition, or None (a good command, or already in fault)."""
        try:
            v = float(u)
        except (TypeError, ValueError):
            return self.fault(t, "bad_command", f"not a number: {u!r}")
        if not math.isfinite(v):
            return self.fault(t, "bad_command", f"u = {v!r} is not finite")
        if self.max_command > 0 and abs(v) > self.max_command:
            return self.fault(t, "bad_command", f"|u| = {abs(v):.6g} N m > {self.max_command:g} N m, implausible")
        return None

    def check_fall(self, t: float, theta_b: float, fall_angle: float) -> Optional[Transition]:
        """A ``fall`` fault when |theta_b| > ``fall_angle`` (or theta_b is not finite)."""
        if not abs(theta_b) <= fall_angle:
            return self.fault(t, "fall", f"|theta_b| = {abs(theta_b):.4f} rad > fall_angle {fall_angle:g} rad")
        return None

    # -- what acts ------------------------------------------------------------------------------------------

    def torque_gate(self, u: float) -> float:
        """The torque that acts: ``u`` when enabled, else 0.0."""
        return u if self.state == ENABLED else 0.0

    def diagnostic(self) -> Tuple[int, str]:
        """(level, message) for /diagnostics: 0 OK (enabled), 1 WARN (disabled), 2 ERROR (fault, with its reason)."""
        if self.state == FAULT:
            last = self.last_suppressed   # set with every suppressed fault
            extra = f" (+{self.suppressed} later fault(s), last: {last[1]})" if self.suppressed and last else ""
            held = f"; held: {', '.join(self.held)} (reset refused until released)" if self.held else ""
            return _LEVEL[FAULT], f"fault: {self._fault_text()}{extra}{held}"
        return _LEVEL[self.state], self.state


@dataclass
class Watchdog:
    """The command watchdog: expired when no command came for more than ``timeout`` [s] (0 = off).

    It counts from the first state the plant publishes (:meth:`arm`, at the start of a run and again after a
    reset): a controller that never answers (not started, its input remapped away) is a fault within
    ``timeout`` of that state, not an open loop that runs until the robot falls.  Before the first state it is
    not armed (the plant waits for its graph).  ``feed(now)`` at every command; ``expired(now)`` at every
    period; ``answered`` says whether a command came since it was armed (the fault then names the stage that
    never answered)."""

    timeout: float
    last: Optional[float] = None
    answered: bool = False

    def __post_init__(self):
        if not (isinstance(self.timeout, (int, float)) and math.isfinite(self.timeout) and self.timeout >= 0):
            raise ValueError(f"watchdog_s: must be finite and >= 0, got {self.timeout!r}")

    def arm(self, now: float) -> None:
        """The first state of a run is out: count from ``now`` unless already armed."""
        if self.last is None:
            self.last, self.answered = float(now), False

    def feed(self, now: float) -> None:
        self.last, self.answered = float(now), True

    def reset(self) -> None:
        """Disarm (until the next :meth:`arm` or command)."""
        self.last, self.answered = None, False

    def expired(self, now: float) -> bool:
        return self.timeout > 0 and self.last is not None and now - self.last > self.timeout

    def silence(self, now: float) -> float:
        """Seconds since the last command, or since it was armed when none came (0 when not armed)."""
        return 0.0 if self.last is None else now - self.last
