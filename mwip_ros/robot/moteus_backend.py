"""Two moteus controllers through mjbots' ``moteus`` package and its fdcanusb transport: :class:`MoteusBackend`.

**Torque control as moteus does it** (SPEC 16).  Each period every wheel gets a position-mode command
(``Controller.make_position``) with ``position`` NaN (no position term), ``velocity`` 0, ``kp_scale`` =
``kd_scale`` = 0, ``feedforward_torque`` the wheel's torque, ``maximum_torque`` the configured limit and
``watchdog_timeout``: the controller applies

    tau = feedforward_torque, clipped to +-maximum_torque

and, when no command follows within ``watchdog_timeout``, enters its timeout mode (mode 11) by itself and stops
driving (what its ``servo.timeout_mode`` says: disengaged, or a damper), which it leaves only on a stop command.
So the motors stop if this process dies.  ``step(None)``, :meth:`MoteusBackend.close` and every step after a fault
send ``Controller.make_stop`` (mode 0, which also clears a controller's fault) instead.

**Units and signs.**  moteus reports its output shaft in revolutions and rev/s, and torque in N m; a wheel's angle
relative to the body is phi = sign 2 pi position (its stator is on the body), its rate sign 2 pi velocity, its torque
sign torque, and a wheel's torque command goes out as sign tau, ``sign`` being +1 or -1 per wheel (+1: the shaft's
positive sense rolls that wheel forward; mirrored motors have one of each).

**One round trip per period.**  :meth:`MoteusBackend.step` is one ``transport.cycle`` carrying both controllers'
commands, each with ``query=True``: the controller applies the newest command on receipt and answers with its
state as of that instant (position, velocity, the torque it applied until then, mode, fault, temperature).  So a
period is "read, then the newest command" in one exchange: the read is the state before the new torque acts,
and the command is the newest one the node has (computed from the previous period's read: its age is one period
plus the compute).  A separate query cycle before the command would double the bus traffic and the latency per
period for no fresher command (the command answering this read cannot exist before the read is published);
:meth:`MoteusBackend.observe` is that query alone (no command: it does not feed the watchdog).  An observation's
``time`` is the middle of its exchange on ``time.monotonic()`` (when the controllers answered, on a link as slow
both ways).

**Faults** come back in :attr:`Observation.fault` as one line naming the wheel, its CAN id and the fault, and latch
(every later step sends stops) until :meth:`MoteusBackend.reset`:

- a controller in mode 1 (fault) with its code (:data:`FAULT_CODES`: 38 over temperature, 33 motor driver, ...);
- a controller in mode 11 (its watchdog expired: it went without a command for ``watchdog_timeout``);
- a controller that has not answered for ``silence_limit`` seconds (a reply lost now and then is not a fault: the
  wheel reads its last answer, counted in :attr:`MoteusBackend.missed`, and the read is :attr:`Observation.stale`,
  no new sample); one that never answered reads NaN;
- a transport that fails (the serial device gone, an ``ERR`` line, a reader that died, a write it does not take):
  then nothing more is sent until :meth:`MoteusBackend.reset` (each step returns the latched read at once), and the
  controllers stop by their own watchdogs.

**A synchronous face.**  The ``moteus`` library is asyncio; the backend owns one event loop and runs each call to
completion on it (one thread uses a backend).  One cycle waits at most ``reply_timeout`` for the replies
(``asyncio.wait_for`` around ``transport.cycle``; the library itself waits without a bound on an fdcanusb), and
keeps each reply as it arrives (through the command's ``reply_filter``), so a controller that does not answer
costs ``reply_timeout`` and is named alone.  A reply later than that is missed, and if it arrives during the next
cycle it is taken as that one's (moteus replies carry no sequence number), so ``reply_timeout`` must exceed the
transport's latency and jitter.  After a cycle that missed a reply, what arrived late is flushed before the next
one.  A serial write that the device does not take within ``silence_limit`` (it stopped reading) fails, and is the
transport's fault: the library itself would wait for it without a bound.  :attr:`MoteusBackend.round_trips` keeps
the cycles' durations.

No IMU: on a moteus robot the IMU has its own driver (``imu/data_raw``).  No ROS here.
"""
from __future__ import annotations

import asyncio
import collections
import math
import time
from dataclasses import dataclass
from typing import Deque, Dict, List, Optional, Tuple

from mwip_ros.optional import required

from .backend import Backend, BackendError, Command, Observation, Wheel

__all__ = ["FAULT_CODES", "MODE_NAMES", "MoteusConfig", "MoteusBackend", "fault_text"]

TWO_PI = 2.0 * math.pi

# moteus's fault codes (register 0x00f, mode 1), from its register reference
FAULT_CODES: Dict[int, str] = {
    32: "calibration fault", 33: "motor driver fault", 34: "over voltage", 35: "encoder fault",
    36: "motor not configured", 37: "pwm cycle overrun", 38: "over temperature", 39: "outside limit",
    40: "under voltage", 41: "config changed", 42: "theta invalid", 43: "position invalid",
    44: "driver enable fault", 45: "stop position deprecated", 46: "timing violation",
    47: "bemf feedforward no accel", 48: "invalid limits"}
# moteus's modes (register 0x000) by number
MODE_NAMES: Dict[int, str] = {
    0: "stopped", 1: "fault", 2: "enabling", 3: "calibrating", 4: "calibration complete", 5: "pwm", 6: "voltage",
    7: "voltage foc", 8: "voltage dq", 9: "current", 10: "position", 11: "timeout", 12: "zero velocity",
    13: "stay within", 14: "measure inductance", 15: "brake"}
MODE_FAULT, MODE_TIMEOUT = 1, 11


def fault_text(code: int) -> str:
    """A moteus fault code as words: '38 (over temperature)'."""
    return f"{code} ({FAULT_CODES.get(int(code), 'unknown')})"


@dataclass(frozen=True)
class MoteusConfig:
    """The moteus backend's settings (per wheel: (left, right)).

    Parameters
    ----------
    path : str
        The fdcanusb's serial device (``/dev/fdcanusb``, ``/dev/serial/by-id/...``, a pty).
    maximum_torque : float
        Each wheel's torque limit, sent with every command [N m] (> 0).
    ids : tuple of 2 ints
        The controllers' CAN ids (1..126, distinct).
    signs : tuple of 2 ints
        +1 or -1: the sign from the shaft's positive sense to the wheel's forward rolling.
    watchdog_timeout : float
        moteus's per-command watchdog [s]: without a new command for this long a controller stops by itself.
    reply_timeout : float
        How long one cycle waits for the replies [s].
    silence_limit : float
        A controller that has not answered for this long is a fault [s].
    """

    path: str
    maximum_torque: float
    ids: Tuple[int, int] = (1, 2)
    signs: Tuple[int, int] = (1, -1)
    watchdog_timeout: float = 0.05
    reply_timeout: float = 0.004
    silence_limit: float = 0.05

    def __post_init__(self):
        def bad(key: str, why: str):
            raise ValueError(f"moteus: {key}: {why}")
        if not isinstance(self.path, str) or not self.path:
            bad("path", f"the fdcanusb's serial device is needed, got {self.path!r}")
        for key in ("maximum_torque", "watchdog_timeout", "reply_timeout", "silence_limit"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                bad(key, f"must be a finite number > 0, got {v!r}")
        if self.reply_timeout > 0.5 * self.watchdog_timeout:
            bad("reply_timeout", f"{self.reply_timeout:g} s is more than half of watchdog_timeout "
                                 f"{self.watchdog_timeout:g} s: a controller that does not answer would hold the cycle "
                                 "long enough for the other one's watchdog to stop it")
        if (len(self.ids) != 2 or len(set(self.ids)) != 2
                or not all(isinstance(i, int) and 1 <= i <= 126 for i in self.ids)):
            bad("ids", f"two distinct CAN ids in 1..126 (left, right), got {self.ids!r}")
        if len(self.signs) != 2 or not all(s in (1, -1) for s in self.signs):
            bad("signs", f"two signs, each +1 or -1 (left, right), got {self.signs!r}")


WHEELS = ("left", "right")
NO_READ = Wheel(math.nan, math.nan, math.nan)


class MoteusBackend(Backend):
    """Two moteus controllers behind :class:`~.backend.Backend` (module docstring).

    Parameters
    ----------
    cfg : MoteusConfig
        The serial path, the CAN ids, signs, torque limit and the time bounds.

    Raises
    ------
    BackendError
        The ``moteus`` package is missing, or the serial device does not open.
    """

    name = "moteus"
    simulated = False

    def __init__(self, cfg: MoteusConfig):
        with required("moteus"):
            import moteus
        self.cfg = cfg
        self._moteus = moteus
        self._loop = asyncio.new_event_loop()
        self._loop.set_exception_handler(self._loop_error)
        self._transport_error: Optional[str] = None
        self.transport = None
        self.closed = False
        self.fault: Optional[str] = None          # the latched fault (one line) until reset()
        self.missed = [0, 0]                      # replies missed per wheel (left, right)
        self.round_trips: Deque[float] = collections.deque(maxlen=100_000)   # each cycle's duration [s]
        self._flush = False                       # a reply was missed: flush what arrives late before the next cycle
        self._last: List[Wheel] = [NO_READ, NO_READ]
        self._last_obs: Optional[Observation] = None
        try:
            self._loop.run_until_complete(self._open())
        except Exception as exc:   # noqa: BLE001 - whatever the serial layer raises, as one line
            self._loop.close()
            raise BackendError(f"moteus: cannot open the fdcanusb at {cfg.path!r}: {exc}") from exc
        self._heard = [time.monotonic()] * 2     # a controller that never answers is silent from the start

    async def _open(self) -> None:
        m, c = self._moteus, self.cfg
        # moteus.Fdcanusb(path) is this device in this transport.  The cycle's bound is asyncio.wait_for's (_cycle);
        # the library's own waits (on a serial port that is not an fdcanusb by its USB ids, a pty) are made longer:
        # its wait for the OK lines raises instead of returning what came back
        device = m.FdcanusbDevice(c.path, command_timeout=1.0, response_timeout=1.0)
        # the library opens pyserial without a write timeout: a device that stops reading would block this process
        # in a write (pyserial waits for the port to take more), beyond any bound; with one, the write fails and the
        # transport's fault is latched.  silence_limit, not reply_timeout: a loaded kernel is late to drain a pty
        # now and then.  (_serial: moteus 1.1.1's AioSerial, pinned; .serial its pyserial port)
        port = getattr(getattr(device, "_serial", None), "serial", None)
        if port is not None:
            port.write_timeout = c.silence_limit
        self.transport = m.Transport(device)
        self.controllers = [m.Controller(id=i, transport=self.transport) for i in c.ids]

    def _loop_error(self, loop, context) -> None:
        """The event loop's exception handler: a callback's error (the serial reader's) becomes the transport's
        fault, named in the next observation."""
        exc = context.get("exception")
        self._transport_error = str(exc) if exc is not None else context.get("message", "unknown error")

    # -- the interface ----------------------------------------------------------------------------------------

    def observe(self) -> Observation:
        """Query both controllers (no command: the watchdog is not fed)."""
        self._open_or_refuse()
        if self._transport_failed():
            return self._last_obs
        return self._exchange([c.make_query() for c in self.controllers])

    def reset(self) -> Observation:
        """Stop both controllers (mode 0, which clears a moteus fault and its timeout mode), clear the latched fault
        and the counters, and read."""
        self._open_or_refuse()
        self.fault = None
        self._transport_error = None
        self.missed = [0, 0]
        self._heard = [time.monotonic()] * 2
        return self._exchange([c.make_stop(query=True) for c in self.controllers])

    def step(self, command: Optional[Command]) -> Observation:
        """Send each wheel its torque (None, or a latched fault: a stop) and read both controllers, in one cycle.

        Parameters
        ----------
        command : Command or None
            Each wheel's torque [N m], forward positive.  A torque that is not finite is refused: both stop,
            and the fault names it.

        Returns
        -------
        Observation
            The controllers' states at the exchange (module docstring).
        """
        self._open_or_refuse()
        if self._transport_failed():
            return self._last_obs
        if command is not None and self.fault is None:
            bad = [w for w, v in zip(WHEELS, (command.left, command.right)) if not math.isfinite(v)]
            if bad:
                self.fault = (f"moteus: the command for the {' and '.join(bad)} wheel is not finite ({command!r}): "
                              "stopped")
        if command is None or self.fault is not None:
            return self._exchange([c.make_stop(query=True) for c in self.controllers])
        c = self.cfg
        cmds = [ctl.make_position(position=math.nan, velocity=0.0, kp_scale=0.0, kd_scale=0.0,
                                  feedforward_torque=sign * tau, maximum_torque=c.maximum_torque,
                                  watchdog_timeout=c.watchdog_timeout, query=True)
                for ctl, sign, tau in zip(self.controllers, c.signs, (command.left, command.right))]
        return self._exchange(cmds)

    def _open_or_refuse(self) -> None:
        if self.closed:
            raise BackendError("moteus: the backend is closed")

    def _transport_failed(self) -> bool:
        """The transport failed and its fault is latched: no more traffic until :meth:`reset` (a write to a device
        that stopped reading would wait ``silence_limit`` each time; its controllers stop by their watchdogs)."""
        return self._transport_error is not None and self.fault is not None and self._last_obs is not None

    def close(self) -> None:
        """Stop both controllers (without waiting for an answer beyond ``reply_timeout``), close the serial device
        and the event loop.  Idempotent."""
        if self.closed:
            return
        self.closed = True
        try:
            self._loop.run_until_complete(self._cycle([c.make_stop() for c in self.controllers]))
        except Exception:   # noqa: BLE001 - closing: the stop was tried, the device may be gone
            pass
        try:
            self.transport.close()
        finally:
            self._loop.close()

    # -- one exchange -----------------------------------------------------------------------------------------

    async def _cycle(self, commands) -> Dict[int, dict]:
        """One ``transport.cycle`` bounded by ``reply_timeout``: each answering controller's register values by CAN
        id.  The replies are taken as they arrive, through each command's ``reply_filter`` (the library asks it of
        every frame from that controller), so a cycle cut by the bound still returns the replies that came."""
        if self._flush:   # late replies of the previous cycle: take them off the line first
            self._flush = False
            await self.transport.flush_read_queue(timeout=self.cfg.reply_timeout / 4)
        frames: Dict[int, object] = {}
        for cid, cmd in zip(self.cfg.ids, commands):
            if cmd.reply_required:
                cmd.reply_filter = self._recorder(cmd.reply_filter, frames, cid)
        try:
            await asyncio.wait_for(self.transport.cycle(commands), self.cfg.reply_timeout)
        except TimeoutError:
            pass
        return {cid: cmd.parse(frames[cid]).values for cid, cmd in zip(self.cfg.ids, commands) if cid in frames}

    @staticmethod
    def _recorder(accept, frames: Dict[int, object], cid: int):
        """A ``reply_filter`` that keeps the first frame ``accept`` takes (a controller's reply) in ``frames``."""
        def recording(frame) -> bool:
            ok = accept is None or accept(frame)
            if ok:
                frames.setdefault(cid, frame)
            return ok
        return recording

    def _exchange(self, commands) -> Observation:
        t0 = time.monotonic()
        try:
            by_id = self._loop.run_until_complete(self._cycle(commands))
        except Exception as exc:   # noqa: BLE001 - the transport failed: an ERR line, a dead reader, a closed port
            by_id = {}
            if type(exc).__name__ == "SerialTimeoutException":   # pyserial's, from the write timeout set in _open
                why = (f"it did not take a write within silence_limit {self.cfg.silence_limit * 1e3:g} ms (it stopped "
                       "reading, or this system is that late)")
            else:
                why = f"{type(exc).__name__}: {exc}"
            self._transport_error = self._transport_error or why
        t1 = time.monotonic()
        self.round_trips.append(t1 - t0)
        reads, faults, stale = [], [], False
        for i, (wheel, cid, sign) in enumerate(zip(WHEELS, self.cfg.ids, self.cfg.signs)):
            values = by_id.get(cid)
            if values is None:
                stale = True   # its last answer is not a read of this exchange's time
                self.missed[i] += 1
                self._flush = True
                silent = t1 - self._heard[i]
                if silent > self.cfg.silence_limit:
                    faults.append(f"moteus {wheel} wheel (CAN id {cid}): no answer for {silent * 1e3:.0f} ms "
                                  f"(silence_limit {self.cfg.silence_limit * 1e3:g} ms)")
                reads.append(self._last[i])
                continue
            self._heard[i] = t1
            faults += self._device_faults(wheel, cid, values)
            self._last[i] = self._wheel(values, sign)
            reads.append(self._last[i])
        if self._transport_error is not None:
            faults.insert(0, f"moteus: the fdcanusb at {self.cfg.path!r} failed: {self._transport_error}")
        if faults and self.fault is None:
            self.fault = "; ".join(faults)
        self._last_obs = Observation(time=0.5 * (t0 + t1), left=reads[0], right=reads[1], fault=self.fault,
                                     stale=stale)
        return self._last_obs

    def _wheel(self, values: dict, sign: int) -> Wheel:
        """A controller's reply as the wheel's read in the robot's forward sense [rad, rad/s, N m]."""
        R = self._moteus.Register
        get = lambda reg: float(values.get(reg, math.nan))   # noqa: E731 - a register not in the reply: NaN
        return Wheel(sign * TWO_PI * get(R.POSITION), sign * TWO_PI * get(R.VELOCITY), sign * get(R.TORQUE))

    def _device_faults(self, wheel: str, cid: int, values: dict) -> List[str]:
        """The faults a controller's reply shows: its mode 1 with the code, or its mode 11 (watchdog)."""
        R = self._moteus.Register
        mode = values.get(R.MODE)
        where = f"moteus {wheel} wheel (CAN id {cid})"
        if mode == MODE_FAULT:
            return [f"{where}: fault {fault_text(values.get(R.FAULT, 0))}"]
        if mode == MODE_TIMEOUT:
            return [f"{where}: watchdog timeout (mode 11): it had no command for watchdog_timeout "
                    f"{self.cfg.watchdog_timeout * 1e3:g} ms and stopped by itself"]
        return []
