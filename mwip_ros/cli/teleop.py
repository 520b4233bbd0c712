"""``mwip_ctl cmd`` and ``mwip_ctl drive``: velocity commands on ``cmd_vel`` (geometry_msgs/Twist), without a ROS CLI.

``cmd --vx V --wz W --duration S [--rate HZ]`` publishes the Twist (linear.x = V m/s, angular.z = W rad/s) at HZ
for S seconds, then a zero Twist (also on Ctrl-C).  ``drive`` is a keyboard teleop: the arrows change vx (up,
down) and wz (left turns left: +wz, REP-103) by a step, space stops, q quits; it shows the command and the limits
``motion.max_speed`` and ``motion.max_yaw_rate`` (from ``--params`` files, checked as the controller checks them,
else the defaults) and keeps the command within them, publishes at a fixed rate whatever the keys do (a burst of
keys neither delays nor adds a publication), and a zero Twist on exit; the terminal is restored even on Ctrl-C, and
its flow control is off meanwhile (Ctrl-S would stop the output, and with it the loop).  Without a terminal on stdin
it refuses in one line (exit 2).
"""
from __future__ import annotations

import math
import os
import select
import sys
import time
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

from mwip_ros.core.plants.plant import saturate

__all__ = ["Limits", "limits", "apply_key", "read_keys", "cmd", "drive"]

UP, DOWN, RIGHT, LEFT = "\x1b[A", "\x1b[B", "\x1b[C", "\x1b[D"


@dataclass(frozen=True)
class Limits:
    max_speed: float
    max_yaw_rate: float


def _spec(name: str):
    """The controller's ParamSpec of ``name`` (the schema: what the controller checks), or None."""
    from mwip_ros.params.schema import NODE_SPECS
    return next((s for specs in NODE_SPECS.values() for s in specs if s.name == name), None)


def _lookup(tree, dotted: str):
    for part in dotted.split("."):
        if not isinstance(tree, dict) or part not in tree:
            return None
        tree = tree[part]
    return tree


def limits(files: Sequence[str] = ()) -> Limits:
    """``motion.max_speed`` and ``motion.max_yaw_rate``: the last of the ``files`` (any section) that gives them,
    else the schema's defaults (the controller's, :mod:`mwip_ros.params.motion`).  Raises
    ValueError naming the key for a value the controller refuses (the schema's check: its type, finite, its range)."""
    from pathlib import Path

    from mwip_ros.params import defaults_for
    from mwip_ros.yamlio import load_yaml
    own = defaults_for("dscndo_controller")
    out = {"motion.max_speed": float(own["motion.max_speed"]), "motion.max_yaw_rate": float(own["motion.max_yaw_rate"])}
    for f in files:
        doc = load_yaml(Path(f)) or {}
        for section in doc.values() if isinstance(doc, dict) else ():
            params = section.get("ros__parameters", {}) if isinstance(section, dict) else {}
            for key in out:
                v = params.get(key, _lookup(params, key))
                if v is None:
                    continue
                spec = _spec(key)
                if spec is not None:   # the controller's own check: a file it refuses is refused here too
                    from mwip_ros.params import ParamError
                    try:
                        spec.validate(v, key)
                    except ParamError as exc:
                        raise ValueError(f"{exc} (in {f})") from None
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                    raise ValueError(f"{key}: {v!r} in {f} is not a positive number")
                out[key] = float(v)
    return Limits(out["motion.max_speed"], out["motion.max_yaw_rate"])


def apply_key(key: str, vx: float, wz: float, lim: Limits, step_v: float,
              step_w: float) -> Optional[Tuple[float, float]]:
    """The command after ``key`` (an arrow's escape sequence, space or q): None to quit; other keys change nothing."""
    if key in ("q", "Q"):
        return None
    if key == " ":
        return 0.0, 0.0
    dv, dw = {UP: (step_v, 0.0), DOWN: (-step_v, 0.0), LEFT: (0.0, step_w), RIGHT: (0.0, -step_w)}.get(key, (0, 0))
    return saturate(round(vx + dv, 9), lim.max_speed), saturate(round(wz + dw, 9), lim.max_yaw_rate)


def read_keys(text: str):
    """The keys in ``text``: each arrow (ESC [ A..D) one key, any other character one key."""
    i = 0
    while i < len(text):
        if text.startswith("\x1b[", i) and i + 2 < len(text):
            yield text[i:i + 3]
            i += 3
        else:
            yield text[i]
            i += 1


def _twist(vx: float, wz: float):
    from geometry_msgs.msg import Twist
    t = Twist()
    t.linear.x, t.angular.z = float(vx), float(wz)
    return t


def _publisher(ros):
    from geometry_msgs.msg import Twist

    from mwip_ros.msgs.qos import REALTIME_INPUT_QOS
    return ros.node.create_publisher(Twist, "cmd_vel", REALTIME_INPUT_QOS)


def cmd(ros, args, failure) -> int:
    """``mwip_ctl cmd``: the Twist at ``--rate`` for ``--duration``, then a zero Twist."""
    from rclpy.duration import Duration
    pub = _publisher(ros)
    if not ros.until(lambda: pub.get_subscription_count() > 0, args.timeout):
        raise failure(f"nobody subscribes {pub.topic_name} after {args.timeout:g} s: is the controller running?")
    try:   # a zero Twist at the end, also on Ctrl-C: the robot stops
        sent, lasted = ros.publish_for(pub, _twist(args.vx, args.wz), args.duration, args.rate, _twist(0.0, 0.0))
    finally:
        pub.wait_for_all_acked(Duration(seconds=args.timeout))
    print(f"cmd_vel: vx {args.vx:g} m/s, wz {args.wz:g} rad/s for {lasted:.2f} s ({sent} message(s)), then zero")
    return 0


def drive(ros, args, failure, stdin=None, stdout=None) -> int:
    """``mwip_ctl drive``: the keyboard teleop (module docstring)."""
    import termios
    import tty
    stdin, stdout = stdin or sys.stdin, stdout or sys.stdout
    try:
        lim = limits(args.params or ())
    except (ValueError, OSError) as exc:
        raise failure(str(exc), 2) from None
    step_v = args.step_v if args.step_v > 0 else lim.max_speed / 10.0
    step_w = args.step_w if args.step_w > 0 else lim.max_yaw_rate / 10.0
    pub, fd = _publisher(ros), stdin.fileno()
    saved = termios.tcgetattr(fd)
    vx = wz = 0.0
    try:
        tty.setcbreak(fd)   # keys one at a time, no echo; Ctrl-C still interrupts
        raw = termios.tcgetattr(fd)
        raw[0] &= ~(termios.IXON | termios.IXOFF)   # no flow control: Ctrl-S is a key, not a stop of the output
        termios.tcsetattr(fd, termios.TCSANOW, raw)
        stdout.write(f"drive: arrows up/down vx (max {lim.max_speed:g} m/s), left/right wz (max "
                     f"{lim.max_yaw_rate:g} rad/s), space stop, q quit\r\n")
        period, nxt, shown = 1.0 / args.rate, time.monotonic(), None
        while True:
            if (vx, wz) != shown:   # the status line is redrawn when it changes, not at every tick
                stdout.write(f"\rvx {vx:+.3f} m/s  wz {wz:+.3f} rad/s   ")
                stdout.flush()
                shown = (vx, wz)
            now = time.monotonic()
            if now >= nxt:   # the publication's own schedule: keys neither delay it nor add to it
                pub.publish(_twist(vx, wz))
                nxt += period
                if nxt <= now:   # late (a stalled terminal, a loaded machine): the next a period on, not a burst
                    nxt = now + period
            ready, _, _ = select.select([fd], [], [], max(0.0, nxt - time.monotonic()))
            if ready:
                data = os.read(fd, 64).decode("utf-8", "replace")
                if not data:   # the terminal closed
                    break
                quit_ = False
                for key in read_keys(data):
                    out = apply_key(key, vx, wz, lim, step_v, step_w)
                    if out is None:
                        quit_ = True
                        break
                    vx, wz = out
                if quit_:
                    break
            ros.until(lambda: False, 0.0)
    finally:   # also on Ctrl-C: the terminal as it was, the robot stopped
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
        pub.publish(_twist(0.0, 0.0))
        ros.until(lambda: False, 0.05)
        stdout.write("\r\ndrive: stopped (zero cmd_vel sent)\n")
        stdout.flush()
    return 0
