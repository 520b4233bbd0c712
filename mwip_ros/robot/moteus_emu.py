"""An emulated moteus robot, without ROS: an fdcanusb's line protocol, two moteus controllers' register machines,
and the project's plant under them (:class:`~.sim.SimBackend`), on a clock the caller gives.

``mwip_moteus_emulator`` (:mod:`mwip_ros.cli.moteus_emulator`) serves it on a pseudo-terminal in its own process
(:func:`serve`); the tests drive it in-process.  The protocol is the one mjbots' ``moteus`` package writes, decoded
and encoded with that package's own functions:

**The fdcanusb's lines** (``moteus.fdcanusb_device``): the host writes ``can send ID HEX [FLAGS] [*CC]`` (the
arbitration id and the payload in hex, padded with 0x50 to a CAN-FD length, ``B``/``b`` bit-rate switch, ``F``
CAN-FD, and a CRC-8 checksum on a serial port that is not an fdcanusb by its USB ids); the fdcanusb answers ``OK``
once the frame is on the bus, and ``rcv ID HEX [E] [B] [F]`` for each frame that comes back (checksummed when the
request was; a bad checksum is answered ``ERR checksum mismatch``, an unknown command ``ERR unknown command``).
The checksum and hex helpers are the library's (``_append_checksum``, ``_strip_and_validate_checksum``,
``_hexify``, ``_dehexify``, ``TransportDevice._round_up_dlc``: private names of ``moteus`` 1.1.1, pinned).

**A moteus frame** (moteus's register reference, "A1 subframes"): the arbitration id is ``prefix << 16 | 0x8000
(reply wanted) | source << 8 | destination`` (0x7f: every controller); the payload is multiplex subframes, decoded
by ``moteus.protocol.parse_registers`` (writes scaled to revolutions, rev/s, N m, s; the reads asked) and answered
by ``moteus.multiplex.WriteCombiner`` with base 0x20 and ``moteus.protocol.Writer``'s mapped writers at the
resolution each read asked; a register the emulator does not have is answered with a read error (0x31).  The reply
goes from ``controller << 8 | source`` with the request's prefix.

**A controller** (:class:`Servo`) as moteus's firmware behaves (its register reference and configuration):

- mode 0 *stopped* (no torque; writing it clears a fault and the timeout mode), 10 *position*, 12 *zero velocity*,
  11 *timeout*, 1 *fault*;
- position mode (SPEC 16): ``tau = feedforward_torque + kd_scale kd (velocity - v) + kp_scale kp (position - p)``
  (the position term dropped when ``position`` is NaN, a NaN velocity taken as 0), clipped to
  +-``maximum_torque`` (NaN: the system's, ``max_torque``), and never beyond ``max_torque``; writing the mode
  starts a new command (unwritten registers at their defaults: ``kp_scale`` = ``kd_scale`` = 1, ``position`` 0,
  ``maximum_torque`` NaN, ``watchdog_timeout`` 0);
- the watchdog: a position command is valid for its ``watchdog_timeout`` (0: ``servo.default_timeout_s``, NaN:
  forever); with no command after that the controller enters mode 11 by itself and does what
  ``servo.timeout_mode`` says (0: disengaged, no torque; 12: a damper, -kd v within +-``timeout_max_torque``); it
  leaves mode 11 (and mode 1) only on a stop command, ignoring any other;
- a fault: mode 1 with its code in register 0x00f; an over-temperature (board temperature above
  ``servo.fault_temperature``) faults a controller that drives (code 38), and a command to drive faults it again
  while the temperature stays up.

**The wheels and the plant.**  Each controller's shaft is one wheel with its ``sign`` (+1: the shaft's positive
sense rolls the wheel forward): it reads position = sign phi / 2 pi [rev] and velocity = sign phi' / 2 pi [rev/s]
from the plant's read of the wheel (phi relative to the body, as a servo measures it), and its torque tau drives
the wheel with sign tau [N m].  :meth:`EmulatedRobot.advance_to` steps the plant in periods of its ``h``, each
with the torques the controllers apply at its start (held over it, as the plant's drive stage holds a command).

**Held until driven** (``hold``): a robot is held upright by hand until its driver drives it.  A held
:class:`EmulatedRobot` keeps its plant at the initial state (its clock goes on) until a controller first takes a
command in position mode; from then on the physics runs.  Held, it is at rest: its IMU reads no rotation and the
specific force of a body at rest at the initial pitch (:func:`mwip_ros.core.plants.raw_sensors.specific_force` with no
acceleration; the plant's own first read has the accelerations of a robot let go at that instant).  So a graph
that takes seconds to come up meets the robot where the parameter file starts it.

**Faults on demand** (:class:`Injection`): an added latency and a uniform jitter on every answer of the fdcanusb
(in order: a serial line does not reorder), a fraction of the frames lost on the bus (the fdcanusb still says
``OK``; the controller never sees the frame), a controller that stops answering from a time (or when told: the
emulator's SIGUSR1) as if unplugged from the bus (it neither hears nor answers, and its watchdog stops it), and an
over-temperature on a controller from a time.
"""
from __future__ import annotations

import errno
import io
import math
import os
import random
import select
import time
from collections import deque
from dataclasses import dataclass, field
from dataclasses import replace as _replace
from typing import Callable, Deque, Dict, List, Optional, Sequence, Tuple

from mwip_ros.core.plants.raw_sensors import specific_force
from mwip_ros.optional import required

from .backend import Command, Imu, Observation
from .moteus_backend import MODE_FAULT, MODE_TIMEOUT, TWO_PI

with required("moteus"):
    from moteus import multiplex as mp
    from moteus.fdcanusb_device import _append_checksum, _dehexify, _hexify, _strip_and_validate_checksum
    from moteus.protocol import Register as R
    from moteus.protocol import Writer, scale_register
    from moteus.transport_device import TransportDevice

__all__ = ["ServoConfig", "Servo", "Injection", "EmulatedRobot", "serve", "decode", "reply_layout", "scaled",
           "MODE_STOPPED", "MODE_POSITION", "MODE_ZERO_VELOCITY", "OVER_TEMPERATURE"]

MODE_STOPPED, MODE_POSITION, MODE_ZERO_VELOCITY = 0, 10, 12
OVER_TEMPERATURE = 38          # moteus's fault code for an over-temperature
BROADCAST = 0x7f
_DLC = TransportDevice()       # the library's CAN-FD length rounding (_round_up_dlc)
_PAD = 0x50                    # the multiplex NOP: what the library pads a frame with

# a command's registers and their values until written (moteus's register reference: "if unspecified")
COMMAND_DEFAULTS: Dict[int, float] = {
    R.COMMAND_POSITION: 0.0, R.COMMAND_VELOCITY: 0.0, R.COMMAND_FEEDFORWARD_TORQUE: 0.0, R.COMMAND_KP_SCALE: 1.0,
    R.COMMAND_KD_SCALE: 1.0, R.COMMAND_POSITION_MAX_TORQUE: math.nan, R.COMMAND_STOP_POSITION: math.nan,
    R.COMMAND_TIMEOUT: 0.0, R.COMMAND_VELOCITY_LIMIT: math.nan, R.COMMAND_ACCEL_LIMIT: math.nan,
    R.COMMAND_FIXED_VOLTAGE_OVERRIDE: math.nan, R.COMMAND_ILIMIT_SCALE: 1.0,
    R.COMMAND_FIXED_CURRENT_OVERRIDE: math.nan, R.COMMAND_IGNORE_POSITION_BOUNDS: 0.0}

# the Writer method that encodes each readable register in its units (moteus.protocol.scale_register's mapping)
_ENCODING: Dict[int, str] = {
    **{r: "write_int" for r in (R.MODE, R.FAULT, R.TRAJECTORY_COMPLETE, R.HOME_STATE, R.MILLISECOND_COUNTER,
                                R.UUID1, R.UUID2, R.UUID3, R.UUID4, R.UUID_MASK_CAPABLE, R.MODEL_NUMBER)},
    **{r: "write_position" for r in (R.POSITION, R.ABS_POSITION, R.COMMAND_POSITION, R.COMMAND_STOP_POSITION,
                                     R.CONTROL_POSITION)},
    **{r: "write_velocity" for r in (R.VELOCITY, R.COMMAND_VELOCITY, R.COMMAND_VELOCITY_LIMIT, R.CONTROL_VELOCITY)},
    **{r: "write_torque" for r in (R.TORQUE, R.COMMAND_FEEDFORWARD_TORQUE, R.COMMAND_POSITION_MAX_TORQUE,
                                   R.POSITION_COMMAND, R.CONTROL_TORQUE)},
    **{r: "write_current" for r in (R.Q_CURRENT, R.D_CURRENT)},
    **{r: "write_pwm" for r in (R.COMMAND_KP_SCALE, R.COMMAND_KD_SCALE, R.COMMAND_ILIMIT_SCALE)},
    R.COMMAND_TIMEOUT: "write_time", R.COMMAND_ACCEL_LIMIT: "write_accel", R.VOLTAGE: "write_voltage",
    R.TEMPERATURE: "write_temperature", R.MOTOR_TEMPERATURE: "write_temperature", R.POWER: "write_power"}
READ_ERROR_UNKNOWN = 1   # the error code of a read of a register the emulator does not have


@dataclass(frozen=True)
class ServoConfig:
    """One controller's configuration (moteus's configuration keys in its own units).

    Parameters
    ----------
    can_id : int
        Its CAN id (``id.id``, 1..126).
    sign : int
        +1 or -1: the shaft's positive sense rolls its wheel forward (+1) or back (-1).
    kp, kd : float
        ``servo.pid_position.kp`` [N m/rev] and ``kd`` [N m s/rev].
    max_torque : float
        The most torque it gives (what ``servo.max_current_A`` allows) [N m].
    default_timeout : float
        ``servo.default_timeout_s`` [s] (NaN: none).
    timeout_mode : int
        ``servo.timeout_mode``: 0 (disengaged) or 12 (zero velocity, a damper).
    timeout_max_torque : float
        ``servo.timeout_max_torque_Nm`` [N m].
    fault_temperature : float
        ``servo.fault_temperature`` [C].
    temperature : float
        The board's temperature when nothing is injected [C].
    voltage : float
        The supply [V].
    """

    can_id: int
    sign: int = 1
    kp: float = 4.0
    kd: float = 0.1
    max_torque: float = math.inf
    default_timeout: float = 0.1
    timeout_mode: int = MODE_ZERO_VELOCITY
    timeout_max_torque: float = 5.0
    fault_temperature: float = 75.0
    temperature: float = 30.0
    voltage: float = 24.0

    def __post_init__(self):
        if not (isinstance(self.can_id, int) and 1 <= self.can_id <= 126):
            raise ValueError(f"moteus emulator: can_id must be in 1..126, got {self.can_id!r}")
        if self.sign not in (1, -1):
            raise ValueError(f"moteus emulator: sign must be +1 or -1, got {self.sign!r}")
        if self.timeout_mode not in (MODE_STOPPED, MODE_ZERO_VELOCITY):
            raise ValueError(f"moteus emulator: timeout_mode must be 0 (stopped) or 12 (zero velocity), got "
                             f"{self.timeout_mode!r}")
        if not self.max_torque > 0:
            raise ValueError(f"moteus emulator: max_torque must be > 0 N m, got {self.max_torque!r}")


class Servo:
    """One moteus controller's register machine (module docstring); its clock is the caller's ``now`` [s].

    Parameters
    ----------
    cfg : ServoConfig
        Its configuration.
    """

    def __init__(self, cfg: ServoConfig):
        self.cfg = cfg
        self.mode = MODE_STOPPED
        self.fault = 0
        self.command: Dict[int, float] = dict(COMMAND_DEFAULTS)
        self.deadline: Optional[float] = None     # the watchdog's expiry [s], None: not armed
        self.position = 0.0                        # [rev] of the shaft
        self.velocity = 0.0                        # [rev/s]
        self.torque = 0.0                          # [N m] the torque it applies now (shaft sense)
        self.temperature = cfg.temperature
        self.hot = False                           # an over-temperature is injected
        self.watchdog_trips = 0
        self.frames = 0
        self.t0 = None                             # its clock's start (the millisecond counter)
        self.commanded_at: Optional[float] = None  # the time of the command in force [s]
        self.events: List[str] = []                # what happened to it, one line each (the emulator prints them)

    # -- the shaft -------------------------------------------------------------------------------------------

    def measure(self, phi: float, phi_rate: float) -> None:
        """Its shaft's reading from its wheel's.

        Parameters
        ----------
        phi, phi_rate : float
            The wheel's angle relative to the body [rad] and its rate [rad/s], in the robot's forward sense.
        """
        s = self.cfg.sign
        self.position, self.velocity = s * phi / TWO_PI, s * phi_rate / TWO_PI

    def wheel_torque(self) -> float:
        """The torque it applies in the wheel's forward sense [N m]."""
        return self.cfg.sign * self.torque

    def overheat(self, hot: bool) -> None:
        """Inject (True) or remove an over-temperature: the board's temperature beyond ``fault_temperature``."""
        self.hot = bool(hot)
        self.temperature = self.cfg.fault_temperature + 10.0 if hot else self.cfg.temperature

    # -- a frame ---------------------------------------------------------------------------------------------

    def frame(self, data: bytes, now: float) -> Optional[bytes]:
        """Take one frame: its writes (a new command when the mode is written), then its reads.

        Parameters
        ----------
        data : bytes
            The frame's multiplex payload (padding included).
        now : float
            The time it arrives [s].

        Returns
        -------
        bytes or None
            The reply's payload, None when the frame reads nothing.
        """
        self.frames += 1
        if self.t0 is None:
            self.t0 = now
        self._check(now, watch=False)   # the watchdog is the physics' (EmulatedRobot.advance_to): see serve()
        writes, query = decode(data)
        if writes:
            self._write(writes, now)
        if not query:
            return None
        return self._reply(query, now)

    def _write(self, writes: Dict[int, float], now: float) -> None:
        mode = writes.get(R.MODE)
        if mode is None:   # command registers without a mode: they change the command in force
            if self.mode in (MODE_POSITION, MODE_ZERO_VELOCITY):
                self.command.update({r: v for r, v in writes.items() if r in COMMAND_DEFAULTS})
            return
        mode = int(mode)
        if mode == MODE_STOPPED:   # a stop: disengaged, and the one way out of a fault or of the timeout mode
            self.mode, self.fault, self.deadline = MODE_STOPPED, 0, None
            self.command = dict(COMMAND_DEFAULTS)
            return
        if self.mode in (MODE_FAULT, MODE_TIMEOUT) or mode not in (MODE_POSITION, MODE_ZERO_VELOCITY):
            return   # only a stop leaves a fault or the timeout mode; modes it does not emulate are ignored
        self.command = {**COMMAND_DEFAULTS, **{r: v for r, v in writes.items() if r in COMMAND_DEFAULTS}}
        if self.hot:
            self._overheated()
            return
        self.mode, self.commanded_at = mode, now
        timeout = self.command[R.COMMAND_TIMEOUT]
        if timeout == 0.0:
            timeout = self.cfg.default_timeout
        self.deadline = None if (mode != MODE_POSITION or math.isnan(timeout)) else now + timeout

    # -- what it does ------------------------------------------------------------------------------------------

    def _check(self, now: float, watch: bool = True) -> None:
        """The transitions due at ``now``: the watchdog's expiry (mode 11; ``watch`` False: not checked), an
        over-temperature (mode 1)."""
        if watch and self.mode == MODE_POSITION and self.deadline is not None and now >= self.deadline:
            self.events.append(f"CAN id {self.cfg.can_id}: watchdog timeout (mode 11), {now - self.commanded_at:.4f} s "
                               f"after its last command (its watchdog_timeout {self.deadline - self.commanded_at:.4f} "
                               "s)")
            self.mode, self.deadline = MODE_TIMEOUT, None
            self.watchdog_trips += 1
        if self.hot and self.mode in (MODE_POSITION, MODE_ZERO_VELOCITY, MODE_TIMEOUT):
            self._overheated()

    def _overheated(self) -> None:
        self.mode, self.fault, self.deadline = MODE_FAULT, OVER_TEMPERATURE, None
        self.events.append(f"CAN id {self.cfg.can_id}: fault {OVER_TEMPERATURE} (over temperature, "
                           f"{self.temperature:g} C)")

    def update(self, now: float, watch: bool = True) -> float:
        """Its state at ``now`` and the torque it applies from then on, kept in :attr:`torque`.

        Parameters
        ----------
        now : float
            The time [s].
        watch : bool
            Whether its watchdog is checked (an over-temperature always is).

        Returns
        -------
        float
            The torque [N m] on its shaft (its own sense).
        """
        c = self.cfg
        self._check(now, watch)
        if self.mode == MODE_POSITION:
            cmd = self.command
            v_ref = cmd[R.COMMAND_VELOCITY]
            tau = (cmd[R.COMMAND_FEEDFORWARD_TORQUE]
                   + cmd[R.COMMAND_KD_SCALE] * c.kd * ((0.0 if math.isnan(v_ref) else v_ref) - self.velocity))
            if not math.isnan(cmd[R.COMMAND_POSITION]):
                tau += cmd[R.COMMAND_KP_SCALE] * c.kp * (cmd[R.COMMAND_POSITION] - self.position)
            limit = cmd[R.COMMAND_POSITION_MAX_TORQUE]
            limit = c.max_torque if math.isnan(limit) else min(abs(limit), c.max_torque)
        elif self.mode == MODE_ZERO_VELOCITY or (self.mode == MODE_TIMEOUT and c.timeout_mode == MODE_ZERO_VELOCITY):
            kd_scale = self.command[R.COMMAND_KD_SCALE] if self.mode == MODE_ZERO_VELOCITY else 1.0
            tau, limit = -kd_scale * c.kd * self.velocity, min(c.timeout_max_torque, c.max_torque)
        else:   # stopped, fault, timeout disengaged: the bridge is off
            tau, limit = 0.0, 0.0
        self.torque = max(-limit, min(limit, tau)) if math.isfinite(tau) else 0.0
        return self.torque

    def registers(self, now: float) -> Dict[int, float]:
        """Every register it has, in moteus's units, at ``now``."""
        uuid = (self.cfg.can_id, 0x6d77, 0x6970, 0x656d)   # 16 bytes, unique per CAN id
        return {
            **self.command,
            R.MODE: self.mode, R.POSITION: self.position, R.VELOCITY: self.velocity, R.TORQUE: self.torque,
            R.Q_CURRENT: 0.0, R.D_CURRENT: 0.0, R.ABS_POSITION: math.nan, R.POWER: 0.0,
            R.MOTOR_TEMPERATURE: math.nan, R.TRAJECTORY_COMPLETE: 1, R.HOME_STATE: 0, R.VOLTAGE: self.cfg.voltage,
            R.TEMPERATURE: self.temperature, R.FAULT: self.fault if self.mode == MODE_FAULT else 0,
            R.CONTROL_POSITION: math.nan, R.CONTROL_VELOCITY: 0.0, R.CONTROL_TORQUE: self.torque,
            R.POSITION_COMMAND: self.torque, R.MODEL_NUMBER: 0,
            R.MILLISECOND_COUNTER: int(round((now - (self.t0 or now)) * 1e3)) & 0x7fffffff,
            R.UUID1: uuid[0], R.UUID2: uuid[1], R.UUID3: uuid[2], R.UUID4: uuid[3], R.UUID_MASK_CAPABLE: 1}

    def _reply(self, query: Sequence[Tuple[int, int]], now: float) -> bytes:
        """The reply to the reads ``query`` [(register, resolution)]: the values it has (one combiner over the span
        with base 0x20, gaps ignored; :func:`reply_layout`), then a read error for each register it does not
        have."""
        values = self.registers(now)
        layout, unknown = reply_layout(tuple(query), frozenset(values))
        buf = io.BytesIO()
        writer = Writer(buf)
        for header, reg, res in layout:
            buf.write(header)
            getattr(writer, _ENCODING[reg])(values[reg], res)
        for reg in unknown:
            writer.write_int8(mp.READ_ERROR)
            writer.write_varuint(reg)
            writer.write_varuint(READ_ERROR_UNKNOWN)
        return buf.getvalue()


_SCALES: Dict[Tuple[int, int], Optional[float]] = {}


def scaled(register: int, resolution: int, raw):
    """A register's raw value as moteus's units: ``moteus.protocol.scale_register``'s mapping, with the scale of a
    mapped register looked up once per (register, resolution) (an integer register's value is the library's own)."""
    key = (register, resolution)
    scale = _SCALES.get(key, 0.0)
    if scale == 0.0:
        probe = scale_register(register, resolution, 1)
        scale = _SCALES[key] = None if isinstance(probe, int) else float(probe)
    if scale is None:
        return scale_register(register, resolution, raw)
    if resolution != mp.F32 and raw == (-128, -32768, -2147483648)[resolution]:
        return math.nan
    return raw * scale


def decode(data: bytes) -> Tuple[Dict[int, float], List[Tuple[int, int]]]:
    """A frame's multiplex payload as (its writes {register: value in moteus's units}, in order; its reads
    [(register, resolution)]), by ``moteus.multiplex.parse_frame`` (what ``moteus.protocol.parse_registers``
    does, with the scales looked up once: :func:`scaled`)."""
    writes: Dict[int, float] = {}
    reads: List[Tuple[int, int]] = []
    for sub in mp.parse_frame(data):
        if isinstance(sub, mp.RegisterSubframe):
            if sub.type is mp.SubframeType.WRITE:
                writes[sub.register] = scaled(sub.register, sub.resolution, sub.value)
            elif sub.type is mp.SubframeType.READ:
                reads.append((sub.register, sub.resolution))
    return writes, reads


_LAYOUTS: Dict[tuple, tuple] = {}


def reply_layout(query: Tuple[Tuple[int, int], ...], have: frozenset) -> Tuple[list, List[int]]:
    """How a reply to ``query`` is framed: ([(the subframe header written before the value, or b"", register,
    resolution)], the registers it does not have), from ``moteus.multiplex.WriteCombiner`` with base 0x20 over the
    span of the registers it has (the reads it has not: ignored there, and answered with a read error).  A layout
    depends on the query only: computed once per query."""
    key = (query, have)
    found = _LAYOUTS.get(key)
    if found is not None:
        return found
    known = {reg: res for reg, res in query if reg in have and reg in _ENCODING}
    unknown = [reg for reg, _ in query if reg not in known]
    layout = []
    if known:
        lo, hi = min(known), max(known)
        buf = io.BytesIO()
        combiner = mp.WriteCombiner(Writer(buf), mp.REPLY_BASE, lo,
                                    [known.get(r, mp.IGNORE) for r in range(lo, hi + 1)])
        for reg in range(lo, hi + 1):
            start = buf.tell()
            if combiner.maybe_write():
                layout.append((buf.getvalue()[start:], reg, known[reg]))
    _LAYOUTS[key] = found = (layout, unknown)
    return found


@dataclass
class Injection:
    """Faults on demand (module docstring); times are seconds from the emulator's start.

    Parameters
    ----------
    latency : float
        Added to every answer of the fdcanusb [s].
    jitter : float
        A uniform random delay in [0, jitter] on top [s].
    loss : float
        The fraction of frames lost on the bus (0..1).
    silent : dict
        CAN id -> the time it stops answering [s] (0: from the start).
    overheat : dict
        CAN id -> the time its over-temperature starts [s].
    seed : int
        Of the loss and jitter draws.
    """

    latency: float = 0.0
    jitter: float = 0.0
    loss: float = 0.0
    silent: Dict[int, float] = field(default_factory=dict)
    overheat: Dict[int, float] = field(default_factory=dict)
    seed: int = 0

    def __post_init__(self):
        for key in ("latency", "jitter"):
            v = getattr(self, key)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"moteus emulator: {key} must be a finite number of seconds >= 0, got {v!r}")
        if not 0.0 <= self.loss <= 1.0:
            raise ValueError(f"moteus emulator: loss must be a fraction in [0, 1], got {self.loss!r}")


@dataclass
class Counters:
    """What the emulator did (its shutdown line and the tests)."""

    lines: int = 0
    frames: int = 0
    lost: int = 0
    unheard: int = 0       # frames a silent controller did not hear
    replies: int = 0
    errors: int = 0
    steps: int = 0
    stalls: int = 0        # wake-ups more than 5 ms after their time (the process was not scheduled)
    held: int = 0          # periods the robot was held (hold: before the first command to drive)
    worst_stall: float = 0.0   # how late the latest wake-up was [s]


class EmulatedRobot:
    """The fdcanusb, its controllers and the plant (module docstring).

    Parameters
    ----------
    backend : SimBackend
        The plant (a simulated :class:`~.backend.Backend` with ``cfg.h``), its period ``cfg.h`` the physics step.
    servos : sequence of Servo
        The left wheel's controller, then the right one's.
    injection : Injection or None
        Faults on demand (None: none).
    hold : bool
        Hold the plant at its initial state until a controller first drives (module docstring).
    """

    def __init__(self, backend, servos: Sequence[Servo], injection: Optional[Injection] = None, hold: bool = False):
        injection = injection if injection is not None else Injection()
        if len(servos) != 2 or servos[0].cfg.can_id == servos[1].cfg.can_id:
            raise ValueError("moteus emulator: two controllers with distinct CAN ids (left, right)")
        self.backend = backend
        self.h = backend.cfg.h
        self.servos = list(servos)
        self.by_id = {s.cfg.can_id: s for s in self.servos}
        self.injection = injection
        self.rng = random.Random(injection.seed)
        self.silenced: Dict[int, bool] = {s.cfg.can_id: False for s in self.servos}
        unknown = [cid for cid in (*injection.silent, *injection.overheat) if cid not in self.by_id]
        if unknown:
            raise ValueError(f"moteus emulator: no controller with CAN id {unknown[0]} to inject a fault into")
        self._due_silent, self._due_overheat = dict(injection.silent), dict(injection.overheat)
        self.counters = Counters()
        self.t0: Optional[float] = None
        self.t_next = 0.0
        self.obs: Observation = backend.observe()
        self.obs_t = 0.0                           # the clock's time of that read [s]
        self.imu_period: Optional[float] = None
        self.next_imu: Optional[float] = None      # the time of the next IMU sample [s]
        self.imu_samples: List[Tuple[float, Observation]] = []   # (its time [s], the read) not yet taken
        self.events: List[str] = []                # the plant's own events (its driver refused a torque), one line
        self._last_due = 0.0
        self.held = bool(hold)                     # the plant held at its initial state (until a controller drives)
        if self.held:   # at rest in a hand: no rotation, gravity's specific force alone (module docstring)
            c = backend.cfg
            fx, fz = specific_force(backend.plant.x, (0.0, 0.0), c.actual.r, c.raw.offset, c.actual.g)
            self.obs = _replace(self.obs, imu=Imu((0.0, 0.0, 0.0), (fx, 0.0, fz)))
        self._measure()

    def start(self, now: float, imu_period: Optional[float] = None) -> None:
        """Start the clock at ``now`` [s]: the plant's time 0, the injections' times counted from here; an IMU
        sample every ``imu_period`` [s] (None: no IMU) into :attr:`imu_samples`."""
        self.t0 = self.t_next = self.obs_t = now
        self.imu_period = imu_period
        self.next_imu = None if imu_period is None else now + imu_period

    def next_sample(self) -> Optional[float]:
        """When the physics period that holds the next IMU sample ends [s] (None: no IMU)."""
        if self.next_imu is None:
            return None
        return self.t_next + self.h * max(1, math.ceil((self.next_imu - self.t_next) / self.h - 1e-9))

    def _measure(self) -> None:
        for servo, wheel in zip(self.servos, (self.obs.left, self.obs.right)):
            servo.measure(wheel.position, wheel.velocity)

    def _injections(self, now: float) -> None:
        """The injections due at ``now``, each once (SIGUSR1 may plug a controller back afterwards)."""
        if not self._due_silent and not self._due_overheat:
            return
        t = now - self.t0
        for cid, at in list(self._due_silent.items()):
            if t >= at:
                self.silenced[cid] = True
                del self._due_silent[cid]
        for cid, at in list(self._due_overheat.items()):
            if t >= at:
                self.by_id[cid].overheat(True)
                del self._due_overheat[cid]

    def silence(self, can_id: int, silent: bool) -> None:
        """Unplug (True) or plug back a controller: it neither hears nor answers while unplugged."""
        self.silenced[can_id] = bool(silent)

    # -- the physics -------------------------------------------------------------------------------------------

    def advance_to(self, now: float, watch_until: Optional[float] = None, commanded: Optional[set] = None) -> int:
        """Step the plant through every period that has ended by ``now``, each with the torques the controllers
        apply at its start.  Their watchdogs are checked at each start, but a controller in ``commanded`` (None: all)
        only at the starts up to ``watch_until`` (None: all), the time up to which no command to it can have come
        unseen (:func:`serve`).  Returns the number of periods stepped."""
        n = 0
        while self.t_next + self.h <= now:
            start = self.t_next
            self._injections(start)
            watch = watch_until is None or start <= watch_until
            torques = [s.update(start, watch or (commanded is not None and s.cfg.can_id not in commanded)) * s.cfg.sign
                       for s in self.servos]
            if self.held and any(s.mode == MODE_POSITION for s in self.servos):
                self.held = False
                self.events.append(f"the robot is let go at t = {start - self.t0:.3f} s: a controller drives")
            if self.held:   # a hand holds it: the period passes, the plant stays at its initial state
                self.counters.held += 1
            else:
                fault = self.obs.fault
                self.obs = self.backend.step(Command(*torques))
                if self.obs.fault and not fault:
                    self.events.append(f"the plant: {self.obs.fault} (no torque acts on it from now on)")
                self._measure()
                n += 1
            self.t_next = self.obs_t = start + self.h
            if self.next_imu is not None and self.obs_t >= self.next_imu - 1e-9:
                # the IMU's own clock: the read of the period its sample time falls in, once per sample time
                self.imu_samples.append((self.obs_t, self.obs))
                while self.next_imu <= self.obs_t + 1e-9:
                    self.next_imu += self.imu_period
        self.counters.steps += n
        return n

    def deadline(self) -> Optional[float]:
        """The earliest watchdog expiry of the controllers [s], None when none is armed."""
        armed = [s.deadline for s in self.servos if s.deadline is not None]
        return min(armed) if armed else None

    # -- the fdcanusb ------------------------------------------------------------------------------------------

    def commanded(self, lines: Sequence[bytes]) -> set:
        """The CAN ids the host's ``lines`` write a command to (a frame with register writes; a query is none), read
        without checking their checksums: what :func:`serve` may not watch the watchdog of before it takes them."""
        ids = set()
        for line in lines:
            fields = line.split()
            if len(fields) < 4 or fields[0] != b"can" or fields[1] != b"send":
                continue
            try:
                arb, data = int(fields[2], 16), _dehexify(fields[3])
                writes, _ = decode(data)
            except (ValueError, RuntimeError, IndexError):
                continue
            if writes:
                dest = arb & 0x7f
                ids |= set(self.by_id) if dest == BROADCAST else {dest}
        return ids

    def receive(self, line: bytes, now: float) -> Tuple[float, List[bytes]]:
        """One line from the host, as the fdcanusb and its controllers take it.

        Parameters
        ----------
        line : bytes
            The line without its end.
        now : float
            When it came [s].

        Returns
        -------
        tuple
            (when its answers are due [s], the answer lines, each with its end).
        """
        c = self.counters
        c.lines += 1
        self._injections(now)
        stripped, had_checksum, valid = _strip_and_validate_checksum(line.strip())
        if had_checksum and not valid:
            c.errors += 1
            return self._due(now), [self._line(b"ERR checksum mismatch", True)]
        fields = stripped.split()
        if len(fields) < 4 or fields[0] != b"can" or fields[1] != b"send":
            c.errors += 1
            return self._due(now), [self._line(b"ERR unknown command", had_checksum)]
        try:
            arb = int(fields[2], 16)
            data = _dehexify(fields[3])
        except ValueError:
            c.errors += 1
            return self._due(now), [self._line(b"ERR malformed frame", had_checksum)]
        c.frames += 1
        out = [self._line(b"OK", had_checksum)]
        if self.injection.loss and self.rng.random() < self.injection.loss:
            c.lost += 1
            return self._due(now), out
        dest, source = arb & 0x7f, (arb >> 8) & 0x7f
        prefix, wants_reply = (arb >> 16) & 0x1fff, bool(arb & 0x8000)
        for servo in self.servos:
            cid = servo.cfg.can_id
            if dest not in (cid, BROADCAST):
                continue
            if self.silenced[cid]:
                c.unheard += 1
                continue
            reply = servo.frame(data, now)
            if wants_reply and reply is not None:
                c.replies += 1
                out.append(self._rcv((prefix << 16) | (cid << 8) | source, reply, had_checksum))
        return self._due(now), out

    def _due(self, now: float) -> float:
        """When answers taken at ``now`` leave: the latency and a jitter draw later, never before the previous
        ones (a serial line keeps its order)."""
        inj = self.injection
        due = now + inj.latency + (self.rng.uniform(0.0, inj.jitter) if inj.jitter else 0.0)
        self._last_due = max(due, self._last_due)
        return self._last_due

    @staticmethod
    def _line(text: bytes, checksum: bool) -> bytes:
        return (_append_checksum(text) if checksum else text) + b"\n"

    def _rcv(self, arb: int, payload: bytes, checksum: bool) -> bytes:
        size = _DLC._round_up_dlc(len(payload))
        data = payload + bytes([_PAD]) * (size - len(payload))
        flags = " E" if arb > 0x7ff else ""
        return self._line(f"rcv {arb:04X} {_hexify(data)}{flags} B F".encode("latin1"), checksum)


def serve(robot: EmulatedRobot, fd: int, running: Callable[[], bool], clock: Callable[[], float] = time.monotonic,
          on_imu: Optional[Callable[[int, Observation], None]] = None, imu_period: float = 0.0025,
          max_line: int = 512, tick: float = 0.005, on_event: Optional[Callable[[str], None]] = None,
          eager: bool = True) -> None:
    """Run ``robot`` on the master side ``fd`` of a pseudo-terminal (non-blocking) in real time until ``running()``
    is false: one thread, one ``select`` that wakes for the host's bytes, the next IMU sample, the next answer due,
    the next watchdog expiry, and at least every ``tick``.

    The plant is stepped through every period that has ended at each look (the end of a period with ``eager``, a
    frame, an IMU sample, a watchdog), each period with the torques applied at its start, as stepping each on time.
    The host's lines are taken after the periods that ended before them, and a controller they command has its
    watchdog checked over those periods only up to the previous look (the command may have come any time after it:
    a frame in the pty's buffer while this process was not scheduled is not a driver that went silent; a query
    feeds no watchdog and delays none).
    The IMU is sampled on its own clock as the plant passes each sample time (:meth:`EmulatedRobot.advance_to`), so
    its stamps keep their rate when this process is late, which only delays their publication.

    Parameters
    ----------
    robot : EmulatedRobot
        The robot (started here).
    fd : int
        The pty's master side, non-blocking.
    running : callable
        Checked at every wake-up; False ends the loop.
    clock : callable
        The monotonic clock [s].
    on_imu : callable or None
        Called with each IMU sample: (its time on the wall clock [ns], the plant's read then); None: no IMU.
    imu_period : float
        The IMU's period [s] (its own rate, not the host's).
    max_line : int
        A host line longer than this is dropped (a garbled stream).
    tick : float
        The longest sleep [s].
    on_event : callable or None
        Called with each controller event (a watchdog timeout, a fault), one line.
    eager : bool
        Wake up at the end of every period to step it (True), so that a frame finds at most one period to step
        before its answer; False: only when looked at (fewer wake-ups, the periods since stepped before the answer).
    """
    now = clock()
    robot.start(now, imu_period if on_imu is not None else None)
    pending: Deque[Tuple[float, bytes]] = deque()
    buf = b""
    out = b""
    last_wake = now
    c = robot.counters
    while running():
        now = clock()
        deadline = robot.deadline()
        times = (now + tick, robot.t_next + robot.h if eager else robot.next_sample(),
                 pending[0][0] if pending else None,
                 None if deadline is None else deadline + robot.h)   # a watchdog is looked at the period after
        wake = min(t for t in times if t is not None)
        readable, _, _ = select.select([fd], [fd] if out else [], [], max(0.0, wake - now))
        now = clock()
        if not readable:
            if now - wake > 0.005:
                c.stalls += 1
                c.worst_stall = max(c.worst_stall, now - wake)
            # nothing was waiting when select returned; bytes that came before ``now`` (this thread was not
            # scheduled in between) are waiting now: the periods up to ``now`` are watched only without them
            readable = select.select([fd], [], [], 0.0)[0]
        lines: List[bytes] = []
        if readable:
            try:
                chunk = os.read(fd, 65536)
            except OSError as exc:   # EIO: no process has the slave side open; EAGAIN: nothing after all
                if exc.errno not in (errno.EIO, errno.EAGAIN):
                    raise
                chunk = b""
                if exc.errno == errno.EIO:
                    time.sleep(0.001)
            buf += chunk
            while True:
                cut = min((i for i in (buf.find(b"\n"), buf.find(b"\r")) if i >= 0), default=-1)
                if cut < 0:
                    if len(buf) > max_line:
                        buf = b""
                    break
                line, buf = buf[:cut], buf[cut + 1:]
                if line.strip():
                    lines.append(line)
        # the periods that ended before the host's lines are taken; a controller they command (or any, while a line
        # is still coming) is watched only up to the previous look: its command may have come any time after it
        commanded = robot.commanded(lines) | (set(robot.by_id) if buf else set())
        robot.advance_to(now, watch_until=last_wake, commanded=commanded)
        last_wake = now
        for line in lines:
            due, answers = robot.receive(line, now)
            pending.extend((due, a) for a in answers)
        while pending and pending[0][0] <= now:
            out += pending.popleft()[1]
        if out:
            try:
                written = os.write(fd, out)
                out = out[written:]
            except OSError as exc:
                if exc.errno not in (errno.EAGAIN, errno.EIO):
                    raise
        for source in (robot, *robot.servos):
            while source.events:
                text = source.events.pop(0)
                if on_event is not None:
                    on_event(text)
        if robot.imu_samples:
            wall = time.time_ns() - int(round(clock() * 1e9))   # the wall clock's offset from the monotonic one
            for t, obs in robot.imu_samples:
                on_imu(wall + int(round(t * 1e9)), obs)
            robot.imu_samples.clear()
