"""``mwip_ctl``: the live actions of docs/graph.md without a ``ros2`` CLI: set a parameter, reset the plant, push it,
drive its driver's state machine (docs/theory.md 6.8), drive the robot on cmd_vel (:mod:`.teleop`).

    mwip_ctl param set NODE NAME VALUE     # /NODE/set_parameters; VALUE is YAML, as in -p NAME:=VALUE
    mwip_ctl param get NODE NAME           # /NODE/get_parameters
    mwip_ctl param list NODE               # /NODE/list_parameters
    mwip_ctl reset [--node plant_sim]      # std_srvs/Trigger /plant_sim/reset
    mwip_ctl enable [--node plant_sim]     # std_srvs/Trigger /plant_sim/enable
    mwip_ctl disable [--node plant_sim]    # std_srvs/Trigger /plant_sim/disable
    mwip_ctl estop [--release]             # std_msgs/Bool true (false: --release) on emergency_stop
    mwip_ctl push [--wheel NM] [--body NM] [--lateral N] [--yaw NM] [--duration S] [--rate HZ]   # external_wrench
    mwip_ctl cmd --vx V --wz W --duration S [--rate HZ]   # cmd_vel (geometry_msgs/Twist), then a zero one
    mwip_ctl drive [--params FILE ...] [--rate HZ]        # keyboard teleop on cmd_vel (cli.teleop)

The e-stop is a level that the plant holds (core.control.safety): ``estop`` publishes true once, waits until the plant
has acknowledged it and exits; the plant keeps it asserted (its driver in fault, ``~/reset`` and ``~/enable``
refused) until a false comes, ``estop --release``, which does not clear the fault: ``reset`` (and, with
``require_enable: true``, ``enable``) follow.  So the command needs no process that stays up to hold the level,
and a Ctrl-C or a lost terminal cannot release an e-stop.  Restarting the plant forgets it (a new process).

Unlike ``ros2 param set``, a whole number for a ``double`` parameter is sent as a double (the type of
its current value, from ``/NODE/get_parameters``): ``mwip_ctl param set dscndo_controller k1 8``.
Relative names (NODE, ``external_wrench``) resolve in ``--namespace``; names starting with '/' are
absolute.  The domain is the environment's ``ROS_DOMAIN_ID``.  Exit codes: 0 done, 1 nothing answered
within ``--timeout`` or the node refused, 2 a usage error, 130 Ctrl-C.

A new client's first answer can be lost (:mod:`mwip_ros.nodes.runtime.services`): ``param get`` and ``param list``
ask again each second until answered; ``param set`` first sends an empty request (nothing changes) so, then the
change once; ``reset``, ``enable`` and ``disable`` (no no-op, never sent twice) go once, after the node has answered
a ``get_parameters`` client made after theirs (``prove_reply_paths``: that answer shows theirs will arrive).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from typing import List

from mwip_ros import params as P
from mwip_ros.cli import interrupts
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L

PROG = "mwip_ctl"


class Failure(Exception):
    """A one-line reason; ``code`` is the exit code (1: nothing answered, or refused; 2: usage)."""

    def __init__(self, text: str, code: int = 1):
        super().__init__(text)
        self.code = code


class _Parser(argparse.ArgumentParser):
    def error(self, message):   # one line, exit 2 (argparse would print the whole usage first)
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _first_line(exc: Exception) -> str:
    return (str(exc).splitlines() or [type(exc).__name__])[0].split(", at /")[0]   # without rcl's source line


def _domain() -> str:
    return f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID') or '0 (unset)'}"


class Ros:
    """One rclpy node in its own context; every wait is a short spin, so Ctrl-C (KeyboardInterrupt) ends it."""

    def __init__(self, namespace: str, timeout: float):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions
        from rclpy.validate_namespace import validate_namespace
        from mwip_ros.nodes.runtime import discovery
        discovery.apply()   # the package's discovery profile, unless the user has a set-up of their own
        self.rclpy, self.timeout, self.ctx = rclpy, timeout, rclpy.Context()
        try:
            rclpy.init(args=[PROG], context=self.ctx, signal_handler_options=SignalHandlerOptions.NO)
        except Exception as exc:   # e.g. a ROS_DOMAIN_ID that is no number
            raise Failure(f"cannot start ROS ({_domain()}): {_first_line(exc)}") from None
        try:
            if namespace:   # before rclpy's node, which warns on its way out
                validate_namespace("/" + namespace.lstrip("/"))
            self.node = rclpy.create_node(f"{PROG}_{os.getpid()}", namespace=namespace or None, context=self.ctx,
                                          start_parameter_services=False)
        except Exception as exc:   # an invalid namespace
            rclpy.try_shutdown(context=self.ctx)
            raise Failure(f"--namespace {namespace!r}: {_first_line(exc)}", 2) from None
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)

    def until(self, done, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while not done() and time.monotonic() < end:
            self.ex.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))
        return done()

    def publish_for(self, pub, msg, duration: float, rate: float, final) -> tuple:
        """Publish ``msg`` on ``pub`` at ``rate`` Hz (0: once) for ``duration`` s, then ``final``, also on Ctrl-C
        (a push ends, the robot stops); (messages sent, seconds it lasted)."""
        sent, start = 0, time.monotonic()
        try:
            while True:
                pub.publish(msg)
                sent += 1
                left = duration - (time.monotonic() - start)
                if left <= 0:
                    break
                self.until(lambda: False, min(left, 1.0 / rate) if rate > 0 else left)
        finally:
            pub.publish(final)
        return sent, time.monotonic() - start

    def call(self, srv_type, node: str, service: str, request, read: bool = False, no_op=None):
        """The response of NODE's ``service``, or Failure naming the node and the domain.

        A new client's first answer can be lost (:mod:`mwip_ros.nodes.runtime.services`): a ``read`` request is
        sent again each second until answered; otherwise a ``no_op`` request (one that changes nothing), if given,
        is first sent so until answered, and without one NODE's ``get_parameters`` is, through a client made after
        this one (``prove_reply_paths``: its answer shows that NODE can answer this client too); ``request`` is
        then sent once (a change is never sent twice)."""
        from mwip_ros.nodes.runtime.services import call_until_answered, prove_reply_paths
        try:
            name = self.node.resolve_service_name(f"{node}/{service}")
            client = self.node.create_client(srv_type, name)
        except Exception as exc:   # an invalid node name
            raise Failure(f"NODE {node!r}: {_first_line(exc)}", 2) from None
        if not self.until(client.service_is_ready, self.timeout):
            raise Failure(f"no service {name} after {self.timeout:g} s: is the node {node!r} running "
                          f"({_domain()})?")
        silent = f"{name} did not answer within {self.timeout:g} s"
        if read or no_op is not None:
            answer = call_until_answered(self.until, client, lambda: request if read else no_op, self.timeout).answer
            if answer is None:
                raise Failure(silent)
            if read:
                return answer
        else:
            proof = prove_reply_paths(self.until, self.node, node, self.timeout)
            if proof is None or proof.answer is None:
                what = "has no get_parameters service" if proof is None else "did not answer get_parameters"
                raise Failure(f"{node} {what} within {self.timeout:g} s, so {name} was not called (its answer "
                              f"could not be shown to arrive)")
        future = client.call_async(request)
        if not self.until(future.done, self.timeout):
            raise Failure(silent)
        return future.result()

    def close(self) -> None:
        self.ex.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.ctx)


def _text(value) -> str:
    """A parameter value as YAML, so that it can be given back to ``param set``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(map(_text, value)) + "]"
    return str(value)


def _as_declared(value, ptype: int, text: str):
    """``value`` in the declared type where nothing is lost: 8 -> 8.0 for a double, [1, 0] -> [1.0, 0.0] for
    a double array, the text itself for a string; anything else as it is (the node judges it)."""
    from rcl_interfaces.msg import ParameterType as T

    def number(x):
        return isinstance(x, (int, float)) and not isinstance(x, bool)
    if ptype == T.PARAMETER_DOUBLE and number(value):
        return float(value)
    if ptype == T.PARAMETER_DOUBLE_ARRAY and isinstance(value, list) and value and all(map(number, value)):
        return [float(x) for x in value]
    return text if ptype == T.PARAMETER_STRING and not isinstance(value, str) else value


def _param(ros: Ros, args) -> int:
    from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
    from rclpy.parameter import Parameter, parameter_value_to_python

    node, name = args.node, getattr(args, "name", None)
    if args.action == "list":
        print("\n".join(sorted(ros.call(ListParameters, node, "list_parameters", ListParameters.Request(),
                                        read=True).result.names)))
        return 0
    if args.action == "get":
        values = ros.call(GetParameters, node, "get_parameters", GetParameters.Request(names=[name]), read=True).values
        if not values or values[0].type == 0:   # PARAMETER_NOT_SET: not declared
            raise Failure(f"{node} has no parameter {name!r} (see: {PROG} param list {node})")
        value = parameter_value_to_python(values[0])
        print(_text(value if isinstance(value, (str, bool, int, float)) else list(value)))
        return 0
    # the type of the current value: the declared one (the node validates every value; a descriptor's type can
    # follow a refused value of another type, rclpy's dynamic typing); none for an undeclared name: sent as it
    # is, the node's refusal names it
    current = ros.call(GetParameters, node, "get_parameters", GetParameters.Request(names=[name]), read=True).values
    value = _as_declared(args.value, current[0].type, args.text) if current else args.value
    try:
        msg = Parameter(name, value=value).to_parameter_msg()
    except Exception as exc:   # e.g. a list of mixed types
        raise Failure(f"VALUE {args.text!r}: {_first_line(exc)}", 2) from None
    result = ros.call(SetParameters, node, "set_parameters", SetParameters.Request(parameters=[msg]),
                      no_op=SetParameters.Request()).results[0]   # no_op: no parameters, nothing changes
    if not result.successful:
        raise Failure(f"{node} refused {name} = {_text(value)}: {result.reason}")
    print(f"{node}: {name} = {_text(value)}")
    for text in _warnings(ros, node, name):   # what the node logs about the new values, where the user looks
        print(f"{node}: warning: {text}", file=sys.stderr)
    return 0


def _warnings(ros: Ros, node: str, changed: str) -> List[str]:
    """The node's own warnings about its values after ``changed`` changed (:func:`mwip_ros.params.typed.
    design_warnings`: the controller's laws against Theorem 2, the observer's gain), from every value it reports;
    none for another node, or when its values cannot be read back or designed from."""
    from rcl_interfaces.srv import GetParameters, ListParameters
    from rclpy.parameter import parameter_value_to_python

    from mwip_ros.params.typed import design_warnings
    base = node.rstrip("/").rsplit("/", 1)[-1]
    if base not in ("dscndo_controller", "disturbance_observer"):
        return []
    try:
        specs = P.specs_for(base)
        listed = ros.call(ListParameters, node, "list_parameters", ListParameters.Request(), read=True).result.names
        # the schema's, but an array left empty (motion.profile): rclpy answers no value at all for a request with one
        names = [n for n in listed if n in specs and not (isinstance(specs[n].default, list) and not specs[n].default)]
        got = ros.call(GetParameters, node, "get_parameters", GetParameters.Request(names=names), read=True).values
        values = dict(P.defaults_for(base))
        for n, v in zip(names, got):
            x = parameter_value_to_python(v)
            values[n] = x if isinstance(x, (str, bool, int, float)) or x is None else list(x)
        return design_warnings(node, values, [changed])
    except Exception:  # noqa: BLE001 - the change is made; its advice is a courtesy (the node logs it anyway)
        return []


def _trigger(ros: Ros, args) -> int:
    """``reset``, ``enable``, ``disable``: the plant's std_srvs/Trigger service of that name; its answer printed
    (stdout when it succeeded, else stderr and exit 1: e.g. a reset refused while the e-stop is asserted)."""
    from std_srvs.srv import Trigger
    response = ros.call(Trigger, args.node, args.command, Trigger.Request())
    if not response.success:
        raise Failure(f"{args.node} refused {args.command}: {response.message}")
    print(f"{args.node}: {response.message}")
    return 0


def _plant_listens(ros: Ros, pub, node: str) -> bool:
    plant = node.rstrip("/").rsplit("/", 1)[-1]
    return pub.get_subscription_count() > 0 and any(
        s.node_name == plant for s in ros.node.get_subscriptions_info_by_topic(pub.topic_name))


def _estop(ros: Ros, args) -> int:
    """``estop``: std_msgs/Bool true on ``emergency_stop`` (``--release``: false), published until the plant's
    reliable subscription acknowledges it, then exit; the plant holds the level (module doc)."""
    from rclpy.duration import Duration
    from std_msgs.msg import Bool

    from mwip_ros.msgs.qos import REALTIME_INPUT_QOS
    value = not args.release
    pub = ros.node.create_publisher(Bool, "emergency_stop", REALTIME_INPUT_QOS)   # reliable, volatile, keep last 1
    topic, plant = pub.topic_name, args.node.rstrip("/").rsplit("/", 1)[-1]
    if not ros.until(lambda: _plant_listens(ros, pub, args.node), args.timeout):
        raise Failure(f"no {plant} subscribes {topic} after {args.timeout:g} s: is it running ({_domain()})?")
    # the plant hears it on a reliable and a best-effort subscription: a few copies 50 ms apart, so the best-effort
    # one (which may drop a message) holds the same value; the reliable one acknowledges
    for i in range(3):
        pub.publish(Bool(data=value))
        if i < 2:
            ros.until(lambda: False, 0.05)
    if not pub.wait_for_all_acked(Duration(seconds=args.timeout)):
        raise Failure(f"{plant} did not acknowledge the emergency stop on {topic} within {args.timeout:g} s")
    if value:
        print(f"{plant}: emergency stop asserted on {topic}; the driver holds zero torque in fault until "
              f"'{PROG} estop --release' and '{PROG} reset'")
    else:
        print(f"{plant}: emergency stop released on {topic}; the fault stays latched until '{PROG} reset'")
    return 0


def _push(ros: Ros, args) -> int:
    from geometry_msgs.msg import Wrench
    from rclpy.duration import Duration

    # reliable and volatile, as plant_sim subscribes; keep last 1: the newest wrench is the one that holds, and
    # Fast DDS acknowledges it at once (at depth 1000, only at its heartbeat, 3 s later)
    from mwip_ros.msgs.qos import REALTIME_INPUT_QOS
    t1, t2 = args.wheel, args.wheel + args.body   # the body row of eq. 1 carries tau_ext2 - tau_ext1
    push = L.encode_external_wrench(t1, t2, args.lateral, args.yaw)
    pub = ros.node.create_publisher(Wrench, "external_wrench", REALTIME_INPUT_QOS)
    topic, plant = pub.topic_name, args.node.rstrip("/").rsplit("/", 1)[-1]
    if not ros.until(lambda: _plant_listens(ros, pub, args.node), args.timeout):
        raise Failure(f"no {plant} subscribes {topic} after {args.timeout:g} s: is it running ({_domain()})?")
    try:
        sent, lasted = ros.publish_for(pub, push, args.duration, args.rate, L.encode_external_wrench(0.0, 0.0))
    finally:   # also on Ctrl-C: the zero wrench sent is delivered
        acked = pub.wait_for_all_acked(Duration(seconds=args.timeout))
    if not acked:
        raise Failure(f"{plant} did not acknowledge the end of the push on {topic} within {args.timeout:g} s")
    side = f", force.y {args.lateral:g} N, torque.z {args.yaw:g} N m" if args.lateral or args.yaw else ""
    print(f"pushed {plant}: tau_ext1 += {t1:g}, tau_ext2 += {t2:g} N m (wheel row {args.wheel:g}, body row "
          f"{args.body:g}){side} for {lasted:.2f} s ({sent} message(s)), then a zero wrench")
    return 0


def _cmd(ros: Ros, args) -> int:
    from mwip_ros.cli import teleop
    return teleop.cmd(ros, args, Failure)


def _drive(ros: Ros, args) -> int:
    from mwip_ros.cli import teleop
    return teleop.drive(ros, args, Failure)


def _number(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} is not finite")
    return v


MAX_RATE_HZ = 1000.0   # --rate of push, cmd and drive: the control rate of the fastest loop here, not a flood


def _checked(ap: argparse.ArgumentParser, args) -> argparse.Namespace:
    """What the nodes would refuse anyway, refused here as a usage error, before any ROS."""
    for key in ("timeout", "duration", "rate"):
        if getattr(args, key, 0.0) < 0:
            ap.error(f"--{key} must be >= 0, got {getattr(args, key):g}")
    if getattr(args, "rate", 0.0) > MAX_RATE_HZ:   # a tool that drives the robot is no flood of its inputs
        ap.error(f"--rate must be at most {MAX_RATE_HZ:g} Hz (a command a control period or slower), got {args.rate:g}")
    if args.command == "param" and args.action == "set":
        args.text = args.value
        try:   # as ROS 2 reads a -p name:=value rule (its numbers: 1e-1 is a double)
            args.value = P.load_yaml(args.text)
        except Exception as exc:
            ap.error(f"VALUE {args.text!r} is not YAML ({_first_line(exc)})")
        if args.value is None or isinstance(args.value, dict):
            ap.error(f"VALUE {args.text!r}: give a number, true/false, a string or a [list]")
    if args.command == "cmd" and not args.duration > 0:
        ap.error("--duration must be > 0")
    if args.command == "drive" and not args.rate > 0:
        ap.error("--rate must be > 0")
    if args.command == "push":
        if not args.duration > 0:   # the plant holds a wrench until the next one: 0 s would be no push at all
            ap.error("--duration must be > 0")
        try:   # the plant's own check of an external_wrench
            L.parse_external_wrench(L.encode_external_wrench(args.wheel, args.wheel + args.body, args.lateral,
                                                             args.yaw))
        except BadMessage as exc:
            ap.error(f"--wheel {args.wheel:g} --body {args.body:g} --lateral {args.lateral:g} --yaw {args.yaw:g}: "
                     f"{exc}")
    return args


def parser() -> argparse.ArgumentParser:
    common = _Parser(add_help=False)
    common.add_argument("--timeout", type=_number, default=5.0, metavar="S",
                        help="how long to wait for the service or the subscriber, and for an answer (default 5)")
    common.add_argument("--namespace", default="", metavar="NS",
                        help="where relative names resolve (the graph's -r __ns:=NS); default /")
    ap = _Parser(prog=PROG, description="Set parameters, reset, enable, disable, emergency-stop, push and drive a "
                 "running mwip_ros graph, without a ros2 CLI, on the environment's ROS_DOMAIN_ID. Exit codes: 0 "
                 "done, 1 nothing answered within --timeout or the node refused (one line on stderr), 2 a usage error, "
                 "130 Ctrl-C.")
    sub = ap.add_subparsers(dest="command", required=True,
                            metavar="{param,reset,enable,disable,estop,push,cmd,drive}")
    psub = sub.add_parser("param", help="set, get or list a node's parameters").add_subparsers(
        dest="action", required=True, metavar="{set,get,list}")
    s = psub.add_parser("set", parents=[common], help="set a parameter (the node checks it; a refusal exits 1)",
                        description="Set NAME on NODE. VALUE is YAML, as in -p NAME:=VALUE (8.0, 8, true, dsc, "
                        "[100.0, 0.0, 0.0, 100.0]); a whole number for a double parameter is sent as a double.")
    g = psub.add_parser("get", parents=[common], help="print a parameter's value (as YAML)")
    lst = psub.add_parser("list", parents=[common], help="print a node's parameter names")
    for p in (s, g, lst):
        p.add_argument("node", metavar="NODE")
    for p in (s, g):
        p.add_argument("name", metavar="NAME")
    s.add_argument("value", metavar="VALUE")
    r = sub.add_parser("reset", parents=[common], help="put the robot back in its initial state and clear the "
                       "driver's fault (plant's ~/reset; refused, exit 1, while the e-stop is asserted)",
                       description="Call the plant's ~/reset: the robot back at its initial state, the driver's fault "
                       "cleared and the driver at its start state (disabled with require_enable: true). Refused "
                       "(exit 1, the plant's reason on stderr) while the emergency stop is asserted or the state "
                       "estimator reports ERROR.")
    en = sub.add_parser("enable", parents=[common], help="let the command act (plant's ~/enable; refused in fault)",
                        description="Call the plant's ~/enable: disabled -> enabled. Refused (exit 1) in fault: "
                        "reset first.")
    dis = sub.add_parser("disable", parents=[common], help="zero torque, the bridge open (plant's ~/disable)",
                         description="Call the plant's ~/disable: enabled -> disabled (no torque until enable); in "
                         "fault the fault stays latched.")
    es = sub.add_parser("estop", parents=[common], help="assert the emergency stop (--release: release it)",
                        description="Publish std_msgs/Bool true on emergency_stop (--release: false) until the plant "
                        "acknowledges it, then exit. The e-stop is a level the plant holds: asserted, the driver "
                        "is in fault with zero torque and ~/reset and ~/enable are refused, until a release; a "
                        "release does not clear the fault, 'mwip_ctl reset' (and with require_enable: true, "
                        "'mwip_ctl enable') brings the torque back.")
    es.add_argument("--release", action="store_true", help="release the e-stop (publish false)")
    p = sub.add_parser("push", parents=[common], help="push the robot: external_wrench for a while, then zero",
                       description="Publish external_wrench (geometry_msgs/Wrench) for --duration, then a zero "
                       "wrench. The plant adds torque.x to tau_ext1 (the wheel row of eq. 1) and torque.y to "
                       "tau_ext2 (the sum of the rows, eq. 3; the body row gets tau_ext2 - tau_ext1): --wheel W "
                       "--body B sends torque.x = W, torque.y = W + B, i.e. W on the wheel row and B on the body row.")
    p.add_argument("--wheel", type=_number, default=0.0, metavar="NM", help="torque on the wheel row [N m] "
                   "(tau_ext1 += NM)")
    p.add_argument("--body", type=_number, default=0.0, metavar="NM", help="torque on the body-pitch row [N m] "
                   "(tau_ext2 += WHEEL + NM)")
    p.add_argument("--lateral", type=_number, default=0.0, metavar="N", help="a sideways force at the body's centre "
                   "of gravity [N], +y left (force.y; backend mujoco, the rk4 plant ignores it)")
    p.add_argument("--yaw", type=_number, default=0.0, metavar="NM", help="a torque about the vertical [N m], "
                   "counterclockwise (torque.z; backend mujoco, the rk4 plant ignores it)")
    p.add_argument("--duration", type=_number, default=0.5, metavar="S", help="how long the push lasts [s] "
                   "(default 0.5)")
    p.add_argument("--rate", type=_number, default=10.0, metavar="HZ", help="resend the push at this rate while "
                   "it lasts; 0 = once (default 10)")
    for q in (r, en, dis, es, p):
        q.add_argument("--node", default="plant_sim", help="the plant node (default plant_sim)")
    c = sub.add_parser("cmd", parents=[common], help="drive: cmd_vel (geometry_msgs/Twist) for a while, then zero",
                       description="Publish cmd_vel (linear.x = VX m/s, angular.z = WZ rad/s, REP-103) at --rate for "
                       "--duration, then a zero Twist (also on Ctrl-C).")
    c.add_argument("--vx", type=_number, default=0.0, metavar="V", help="forward speed [m/s]")
    c.add_argument("--wz", type=_number, default=0.0, metavar="W", help="yaw rate [rad/s], + turns left")
    c.add_argument("--duration", type=_number, default=1.0, metavar="S", help="how long [s] (default 1)")
    c.add_argument("--rate", type=_number, default=10.0, metavar="HZ", help="resend at this rate; 0 = once "
                   "(default 10)")
    d = sub.add_parser("drive", parents=[common], help="keyboard teleop on cmd_vel (arrows, space stops, q quits)",
                       description="Arrows up/down change vx, left/right wz by a step; space stops; q quits. The "
                       "command stays within motion.max_speed and motion.max_yaw_rate (from --params, else the "
                       "defaults), is published at --rate, and a zero Twist is sent on exit (also Ctrl-C). Needs a "
                       "terminal on stdin.")
    d.add_argument("--params", nargs="+", default=[], metavar="FILE", help="parameter files with motion.* limits")
    d.add_argument("--rate", type=_number, default=20.0, metavar="HZ", help="publish rate (default 20)")
    d.add_argument("--step-v", type=_number, default=0.0, metavar="V", help="vx step [m/s] (default max_speed/10)")
    d.add_argument("--step-w", type=_number, default=0.0, metavar="W", help="wz step [rad/s] (default "
                   "max_yaw_rate/10)")
    return ap


def main(argv=None) -> int:
    try:
        ap = parser()
        args = _checked(ap, ap.parse_args(argv))
        if args.command == "drive" and not sys.stdin.isatty():
            raise Failure("drive needs a terminal on stdin (use 'mwip_ctl cmd' in scripts)", 2)
        # SIGINT and SIGTERM raise KeyboardInterrupt whatever this process inherited (a script's background job
        # starts with SIGINT ignored): a push ends with its zero wrench, a drive with its zero Twist, exit 130 / 143
        with interrupts.handled():
            ros = Ros(args.namespace, args.timeout)
            try:
                return {"param": _param, "reset": _trigger, "enable": _trigger, "disable": _trigger, "estop": _estop,
                        "push": _push, "cmd": _cmd, "drive": _drive}[args.command](ros, args)
            finally:
                ros.close()
    except Failure as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return exc.code
    except KeyboardInterrupt:
        return interrupts.exit_code()
    except SystemExit as exc:   # --help (0) and usage errors (2), also when main() is called as a function
        return exc.code if isinstance(exc.code, int) else 2


if __name__ == "__main__":
    sys.exit(main())
