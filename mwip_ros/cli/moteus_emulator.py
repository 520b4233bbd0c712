"""``mwip_moteus_emulator``: an emulated moteus robot in its own process, an fdcanusb on a pseudo-terminal with two
moteus controllers behind it, the robot's plant under them, and its IMU on ROS.

    mwip_moteus_emulator [--params FILE ...] [--link PATH] [--latency S] [--jitter S] [--loss F]
                         [--silent WHEEL [--silent-at S]] [--overheat WHEEL [--overheat-at S]] [--ros-args ...]

It prints ``fdcanusb: PATH`` (the pty's slave side, or ``--link``'s symlink to it) on its first line: the serial path
for ``MoteusBackend`` (or ``moteus_tool --fdcanusb PATH``).  The controllers decode what mjbots' ``moteus`` package
writes and answer as moteus does (:mod:`mwip_ros.robot.moteus_emu`: the modes, ``maximum_torque``, the watchdog and
its timeout mode, fault codes).  The plant is the parameter file's (``backend: rk4`` or ``mujoco``,
:class:`mwip_ros.robot.sim.SimBackend`), stepped in real time at ``--physics-rate`` on the emulator's own clock, each
period with the torques the controllers apply at its start.  The IMU goes out as a ROS IMU driver's would:
``sensor_msgs/Imu`` on ``imu/data_raw`` (frame ``imu_link``, REP-145: the pitch and yaw rates, the proper
acceleration, no orientation), from the plant's raw-sensor model (``sensors.imu.*``), at ``--imu-rate`` on its own
timer, not synchronized with the driver.

Faults on demand: ``--latency`` and ``--jitter`` delay every answer of the fdcanusb, ``--loss`` loses that fraction of
the frames on the bus, ``--silent WHEEL`` unplugs that wheel's controller from ``--silent-at`` on (SIGUSR1 unplugs
it, or plugs it back, at any time), ``--overheat WHEEL`` raises its board's temperature past
``servo.fault_temperature`` from ``--overheat-at`` on (moteus fault 38).  SIGINT or SIGTERM ends it (its counters on
stderr).  Exit codes: 0 stopped (a signal, or ``--duration`` reached), 1 the plant's simulation diverged, 2 a bad
option or parameter file, or the package ``moteus`` missing (one line; nothing started).
"""
from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import time
import tty
from dataclasses import replace
from pathlib import Path
from typing import List, Optional

from mwip_ros import params as P
from mwip_ros.cli.exits import EXIT_ERROR, EXIT_OK, EXIT_USAGE
from mwip_ros.optional import MissingPackage
from mwip_ros.params.paths import default_params_file

PROG = "mwip_moteus_emulator"
WHEELS = ("left", "right")
DESCRIPTION = (
    "An emulated moteus robot in its own process: an fdcanusb on a pseudo-terminal (its path on the first line: "
    "'fdcanusb: PATH') with two moteus controllers behind it, which answer what mjbots' moteus package writes as "
    "moteus does (position mode with the kp/kd scales and a feedforward torque, maximum_torque, the watchdog and its "
    "timeout mode, fault codes), over the parameter file's plant (rk4 or mujoco) in real time, and the plant's IMU on "
    "imu/data_raw (sensor_msgs/Imu, frame imu_link) at its own rate.  Faults on demand: latency and jitter, frame "
    "loss, a controller that stops answering (at a time, or on SIGUSR1), an over-temperature.")


class _Parser(argparse.ArgumentParser):
    def error(self, message):   # one line, exit 2
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _parser() -> argparse.ArgumentParser:
    ap = _Parser(prog=PROG, description=DESCRIPTION,
                 epilog="exit codes: 0 stopped (a signal, or --duration reached), 1 the plant's simulation diverged, "
                        "2 a bad option or parameter file, or the package moteus missing")
    ap.add_argument("--params", type=Path, nargs="+", default=None, metavar="FILE",
                    help="ROS 2 parameter file(s) of the plant (plant_sim's section: the robot, its raw sensors, "
                         "backend rk4 or mujoco), merged in order; default: the package's config/paper.yaml")
    ap.add_argument("--link", type=Path, default=None, metavar="PATH",
                    help="create PATH, a symlink to the pty (removed at exit); default: print the pty's own path")
    ap.add_argument("--force", action="store_true", help="replace an existing symlink at --link")
    ap.add_argument("--physics-rate", type=float, default=1000.0, metavar="HZ",
                    help="the plant's steps per second, in real time (default 1000)")
    ap.add_argument("--imu-rate", type=float, default=400.0, metavar="HZ",
                    help="imu/data_raw's rate (default 400); 0: no IMU and no ROS")
    ap.add_argument("--ids", type=int, nargs=2, default=(1, 2), metavar=("LEFT", "RIGHT"),
                    help="the controllers' CAN ids (default 1 2)")
    ap.add_argument("--signs", type=int, nargs=2, default=(1, -1), metavar=("LEFT", "RIGHT"),
                    help="+1/-1 per wheel: the shaft's positive sense rolls the wheel forward (default 1 -1: mirrored "
                         "motors)")
    ap.add_argument("--kp", type=float, default=4.0, help="servo.pid_position.kp [N m/rev] (default 4)")
    ap.add_argument("--kd", type=float, default=0.1, help="servo.pid_position.kd [N m s/rev] (default 0.1)")
    ap.add_argument("--max-torque", type=float, default=None, metavar="NM",
                    help="the most torque a controller gives [N m] (default: half the plant's torque_limit, none "
                         "when it has none)")
    ap.add_argument("--default-timeout", type=float, default=0.1, metavar="S",
                    help="servo.default_timeout_s: the watchdog of a command that sets none [s] (default 0.1; nan: "
                         "none)")
    ap.add_argument("--timeout-mode", type=int, choices=(0, 12), default=12,
                    help="servo.timeout_mode: 0 disengaged, 12 a damper (zero velocity; moteus's default)")
    ap.add_argument("--timeout-max-torque", type=float, default=5.0, metavar="NM",
                    help="servo.timeout_max_torque_Nm: the damper's torque limit (default 5)")
    ap.add_argument("--latency", type=float, default=0.0, metavar="S",
                    help="added to every answer of the fdcanusb [s] (default 0)")
    ap.add_argument("--jitter", type=float, default=0.0, metavar="S",
                    help="a uniform random delay in [0, S] on top of --latency (default 0)")
    ap.add_argument("--loss", type=float, default=0.0, metavar="F",
                    help="the fraction of frames lost on the bus, 0..1 (default 0)")
    ap.add_argument("--silent", choices=WHEELS, default=None,
                    help="that wheel's controller stops answering (unplugged) at --silent-at; SIGUSR1 toggles it "
                         "(default for SIGUSR1: the right wheel's)")
    ap.add_argument("--silent-at", type=float, default=None, metavar="S",
                    help="seconds after the start (default: only on SIGUSR1)")
    ap.add_argument("--overheat", choices=WHEELS, default=None,
                    help="that wheel's controller overheats (moteus fault 38 while it drives) at --overheat-at")
    ap.add_argument("--overheat-at", type=float, default=0.0, metavar="S", help="seconds after the start (default 0)")
    ap.add_argument("--seed", type=int, default=0, help="of the loss and jitter draws (default 0)")
    ap.add_argument("--hold", action="store_true",
                    help="hold the robot at its initial state (a hand on it) until a controller first drives "
                         "(position mode): a graph that takes a while to come up meets it where the file starts it")
    ap.add_argument("--duration", type=float, default=0.0, metavar="S",
                    help="stop after S seconds (default 0: until SIGINT or SIGTERM)")
    return ap


def _fail(text: str, code: int = EXIT_USAGE) -> int:
    print(f"{PROG}: error: {text}", file=sys.stderr, flush=True)
    return code


def _check(args) -> Optional[str]:
    """The first option that is out of range, as one line."""
    finite = lambda v: v is not None and math.isfinite(v)   # noqa: E731
    if not (finite(args.physics_rate) and args.physics_rate > 0):
        return f"--physics-rate must be > 0 Hz, got {args.physics_rate}"
    if not (finite(args.imu_rate) and args.imu_rate >= 0):
        return f"--imu-rate must be >= 0 Hz, got {args.imu_rate}"
    for key in ("latency", "jitter", "duration", "overheat_at"):
        if not (finite(getattr(args, key)) and getattr(args, key) >= 0):
            return f"--{key.replace('_', '-')} must be a number of seconds >= 0, got {getattr(args, key)}"
    if args.silent_at is not None and not (finite(args.silent_at) and args.silent_at >= 0):
        return f"--silent-at must be a number of seconds >= 0, got {args.silent_at}"
    if not 0.0 <= args.loss <= 1.0:
        return f"--loss must be a fraction in [0, 1], got {args.loss}"
    if args.silent_at is not None and args.silent is None:
        return "--silent-at needs --silent WHEEL"
    return None


def _robot(args, cfg):
    """The emulated robot of the options and the plant ``cfg``."""
    from mwip_ros.core.plants.plant import per_wheel
    from mwip_ros.robot.moteus_emu import EmulatedRobot, Injection, Servo, ServoConfig
    from mwip_ros.robot.sim import SimBackend
    dt = 1.0 / args.physics_rate
    # the file's RK4 sub-step length kept; the loop's delays are the transport's here (--latency), not the file's
    plant = replace(cfg, h=dt, substeps=max(1, round(cfg.substeps * dt / cfg.h)),
                    sensing=replace(cfg.sensing, delay_periods=0, actuator_delay_periods=0))
    max_torque = args.max_torque if args.max_torque is not None else (
        per_wheel(cfg.torque_limit) if cfg.torque_limit > 0 else math.inf)
    servos = [Servo(ServoConfig(can_id=i, sign=s, kp=args.kp, kd=args.kd, max_torque=max_torque,
                                default_timeout=args.default_timeout, timeout_mode=args.timeout_mode,
                                timeout_max_torque=args.timeout_max_torque))
              for i, s in zip(args.ids, args.signs)]
    wheel_id = dict(zip(WHEELS, args.ids))
    injection = Injection(latency=args.latency, jitter=args.jitter, loss=args.loss, seed=args.seed,
                          silent={wheel_id[args.silent]: args.silent_at} if args.silent_at is not None else {},
                          overheat={wheel_id[args.overheat]: args.overheat_at} if args.overheat else {})
    return EmulatedRobot(SimBackend(plant), servos, injection, hold=args.hold)


class _ImuPublisher:
    """``imu/data_raw`` as a ROS IMU driver publishes it, from the emulator's loop (no executor: it only publishes)."""

    def __init__(self, ros_args: List[str], raw):
        import rclpy
        from rclpy.signals import SignalHandlerOptions
        from sensor_msgs.msg import Imu

        from mwip_ros.msgs.qos import qos_for
        from mwip_ros.nodes.runtime import discovery
        discovery.apply()   # the package's discovery profile, unless the user has a set-up of their own
        self.rclpy, self.ctx = rclpy, rclpy.Context()
        rclpy.init(args=[PROG, *ros_args], context=self.ctx, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("moteus_emulator", context=self.ctx)
        self.pub = self.node.create_publisher(Imu, "imu/data_raw", qos_for("realtime")[0])
        self.variances = (raw.gyro_noise_std ** 2, raw.accel_noise_std ** 2)
        self.count = 0

    def __call__(self, stamp_ns: int, obs) -> None:
        from mwip_ros.msgs import layouts as L
        w, a = obs.imu.angular_velocity, obs.imu.linear_acceleration
        self.pub.publish(L.encode_imu(stamp_ns, w[1], a[0], a[2], *self.variances, w[2]))
        self.count += 1

    def close(self) -> None:
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.ctx)


def _link_refused(link: Optional[Path], force: bool) -> Optional[str]:
    """Why ``--link`` may not be made: it exists and is not a symlink (never replaced), or is one without
    ``--force``; None when it may."""
    if link is None or not os.path.lexists(link):
        return None
    if not link.is_symlink():
        return f"--link {link}: exists, not a symlink (never replaced)"
    return None if force else f"--link {link}: exists, a symlink (--force replaces it)"


def _open_pty(link: Optional[Path]):
    """(master fd, slave fd, the path printed): a pty in raw mode (no echo), its master non-blocking; ``link`` a
    symlink made to its slave side (one that is there is replaced: :func:`_link_refused` said it may be)."""
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    path = os.ttyname(slave)
    if link is not None:
        if os.path.lexists(link):
            link.unlink()
        os.symlink(path, link)
        path = str(link)
    return master, slave, path


def main(argv: Optional[List[str]] = None) -> int:
    """The emulator's command line (module docstring); returns the exit code."""
    from mwip_ros.nodes.runtime.arenas import bound_malloc_arenas
    bound_malloc_arenas()   # before rclpy is imported (mwip_ros.nodes.runtime.arenas)
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args: List[str] = []
    if "--ros-args" in argv:
        cut = argv.index("--ros-args")
        argv, ros_args = argv[:cut], argv[cut:]
    args = _parser().parse_args(argv)
    bad = _check(args) or _link_refused(args.link, args.force)
    if bad:
        return _fail(bad)
    try:
        values = P.merged_values(P.load_param_files(args.params or [default_params_file()], option="--params"))
        cfg = P.plant_config(values)
        robot = _robot(args, cfg)
    except (P.ParamError, ValueError, MissingPackage) as exc:
        return _fail(str(exc))
    try:
        master, slave, path = _open_pty(args.link)
    except OSError as exc:
        return _fail(str(exc))
    imu = None
    stop = {"now": False}
    wheel_id = dict(zip(WHEELS, args.ids))
    toggled = wheel_id[args.silent or "right"]

    def on_stop(signum, _frame):
        stop["now"] = True

    def on_usr1(signum, _frame):
        robot.silence(toggled, not robot.silenced[toggled])
        print(f"{PROG}: the controller with CAN id {toggled} is {'unplugged' if robot.silenced[toggled] else 'back'}",
              file=sys.stderr, flush=True)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_stop)
    signal.signal(signal.SIGUSR1, on_usr1)
    code = EXIT_OK
    try:
        if args.imu_rate > 0:
            imu = _ImuPublisher(ros_args, robot.backend.cfg.raw)
        print(f"fdcanusb: {path}", flush=True)
        print(f"{PROG}: controllers {args.ids[0]} (left, sign {args.signs[0]:+d}) and {args.ids[1]} (right, sign "
              f"{args.signs[1]:+d}); plant {cfg.backend} at {args.physics_rate:g} Hz; IMU "
              f"{'imu/data_raw at %g Hz' % args.imu_rate if imu else 'off'}; latency {args.latency:g} s, jitter "
              f"{args.jitter:g} s, loss {args.loss:g}{'; held until driven' if args.hold else ''}", file=sys.stderr,
              flush=True)
        from mwip_ros.robot.backend import BackendError
        from mwip_ros.robot.moteus_emu import serve
        end = time.monotonic() + args.duration if args.duration > 0 else math.inf
        try:
            serve(robot, master, lambda: not stop["now"] and time.monotonic() < end,
                  on_imu=imu, imu_period=1.0 / args.imu_rate if imu else 0.0,
                  on_event=lambda text: print(f"{PROG}: {text}", file=sys.stderr, flush=True))
        except BackendError as exc:
            code = _fail(str(exc), EXIT_ERROR)
    finally:
        c = robot.counters
        trips = [s.watchdog_trips for s in robot.servos]
        print(f"{PROG}: {c.frames} frames ({c.lost} lost, {c.unheard} unheard), {c.replies} replies, {c.errors} "
              f"errors, {c.steps} physics steps ({c.held} held), {c.stalls} stalls (worst {c.worst_stall * 1e3:.1f} "
              f"ms), watchdog trips {trips[0]} left {trips[1]} right, {imu.count if imu else 0} IMU messages",
              file=sys.stderr, flush=True)
        if imu is not None:
            imu.close()
        if args.link is not None and args.link.is_symlink() and os.readlink(args.link) == os.ttyname(slave):
            args.link.unlink()
        os.close(master)
        os.close(slave)
    return code


if __name__ == "__main__":
    sys.exit(main())
