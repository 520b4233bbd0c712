"""Process plumbing shared by every node: init, signals, a spin loop that exits, one way to end.

Every node's ``main()`` is ``return run_node(MyNode, argv)``; its console script enters through
:mod:`.entry` (the malloc arena limit, before rclpy is imported).  The loop is a
``spin_once`` loop (an ``EventsExecutor.spin()`` never returns on SIGINT), and
SIGINT/SIGTERM only set a flag, so a node gets to flush its files and print its
report before ``rclpy.shutdown()``.  A node ends its run with
:meth:`GracefulNodeMixin.finish` (an exit code and, for a failure, the reason logged
as an error); nothing else sets ``done`` or ``exit_code``.
"""
from __future__ import annotations

import ast
import faulthandler
import gc
import inspect
import os
import signal
import sys
import textwrap
from typing import Callable, Dict, List, Optional, Sequence

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from mwip_ros.optional import MissingPackage
from mwip_ros.params import ParamError

from .arenas import bound_malloc_arenas

__all__ = ["EXIT_OK", "EXIT_ERROR", "EXIT_BAD_PARAMS", "EXIT_FALLEN", "GracefulNodeMixin", "StopRequested",
           "StartRefused", "build_node", "init_context", "node_help", "node_name", "run_node"]

# Exit codes of every mwip_ros executable.
EXIT_OK = 0
EXIT_ERROR = 1          # a runtime error (e.g. lockstep timeout)
EXIT_BAD_PARAMS = 2     # a bad parameter file, override or value
EXIT_FALLEN = 3         # plant_sim: the robot fell
# plant_sim stopped by a signal before its duration_s was done: 128 + the signal (130 SIGINT, 143 SIGTERM)

SHUTDOWN_GRACE_S = 10.0  # after the node's own shutdown work, the middleware gets this long to clean up


class StopRequested(Exception):
    """Raised by a node (or set by a signal) to leave the spin loop."""


class GracefulNodeMixin:
    """Hooks ``run_node`` calls: ``spin_step`` and ``on_shutdown``; and ``finish``, the one way to end a run.

    ``done`` tells ``run_node`` to leave the loop; ``exit_code`` is returned by the process.
    """

    done: bool = False
    exit_code: int = EXIT_OK
    stop_signal: Optional[int] = None  # set by run_node before on_shutdown when SIGINT/SIGTERM ended the loop
    failure: Optional[str] = None      # the reason a run ended in error (reported on /diagnostics as ERROR)
    diagnostics = None                 # the node's /diagnostics publisher (nodes.diagnostics), set by run_node

    def report_health_now(self) -> None:
        """The node's health changed (its ``diagnostic_status`` level): its /diagnostics report goes out now, from
        the callback that calls this, besides the report once a second."""
        if self.diagnostics is not None:
            self.diagnostics.tick(now=True)

    def finish(self, code: int = EXIT_OK, reason: Optional[str] = None) -> None:
        """End the run with exit ``code``; ``reason`` (a failure) is logged as an error first."""
        if reason:
            self.get_logger().error(reason)
            self.failure = reason
        self.exit_code = code
        self.done = True

    watch = None  # a guards.PublisherWatch, checked between callbacks when the node has one

    def spin_step(self, executor) -> None:
        """One turn of the loop: take what arrived (up to 0.1 s), then look for a second publisher."""
        executor.spin_once(timeout_sec=0.1)
        if self.watch is not None:
            self.watch.check()

    def on_shutdown(self) -> None:
        """Flush files, print reports. Called once, before the node is destroyed."""


def _make_executor(context):
    """EventsExecutor by default (faster lockstep, see scripts/bench.sh); MWIP_EXECUTOR=single to compare.

    Its ``spin()`` never returns on SIGINT, which is why ``run_node`` drives a ``spin_once`` loop.
    """
    if os.environ.get("MWIP_EXECUTOR", "events") == "single":
        return SingleThreadedExecutor(context=context)
    try:
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    except ImportError:  # pragma: no cover - older rclpy
        return SingleThreadedExecutor(context=context)


def for_every_thread(apply: Callable[[int], None]) -> None:
    """``apply(tid)`` for every thread of this process (Linux: scheduling and nice are per thread; threads
    started later inherit their creator's); a thread that ended meanwhile is skipped, an OSError goes up."""
    for tid in map(int, os.listdir("/proc/self/task")):
        try:
            apply(tid)
        except ProcessLookupError:  # the thread ended meanwhile
            pass


def _realtime_priority(node) -> None:
    """Put every thread of this process (rclpy's, Fast DDS's, the executor's timers) under SCHED_FIFO at the
    node's ``realtime_priority``; threads started later inherit it.  0 leaves normal scheduling."""
    prio = getattr(node, "v", {}).get("realtime_priority", 0)
    if not prio:
        return
    try:
        for_every_thread(lambda tid: os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(prio)))
    except (OSError, AttributeError) as exc:
        node.get_logger().warning(f"realtime_priority {prio}: cannot switch to SCHED_FIFO ({exc}); running with "
                                  "normal scheduling (needs root or CAP_SYS_NICE, e.g. an rtprio limit)")
        return
    node.get_logger().info(f"SCHED_FIFO priority {prio}")


_TOPIC_CALLS = {"create_publisher": "publishes", "create_subscription": "subscribes", "create_service": "services",
                "side_input": "subscribes"}   # side_input: wheel_driver's side inputs (a subscription)
_GENERIC_EXIT_CODES = ("exit codes: 0 done (or stopped by SIGINT/SIGTERM), 1 a runtime error, 2 bad parameters or "
                       "arguments, or an optional package the node needs is missing (one line naming the key or the "
                       "package; nothing started)")


def _topics(source_file: Optional[str]) -> Dict[str, List[str]]:
    """The topics and services the node's module creates by a literal name ({'publishes': [...], ...}), read from
    its source (nothing is imported or started); {} when it names none (its topics are parameters)."""
    try:
        with open(source_file or "", encoding="utf-8") as f:
            tree = ast.parse(f.read())
    except (OSError, SyntaxError, ValueError):
        return {}
    calls = sorted((c.lineno, _TOPIC_CALLS[c.func.attr], c.args[1].value) for c in ast.walk(tree)
                   if isinstance(c, ast.Call) and isinstance(c.func, ast.Attribute) and c.func.attr in _TOPIC_CALLS
                   and len(c.args) >= 2 and isinstance(c.args[1], ast.Constant) and isinstance(c.args[1].value, str))
    found: Dict[str, List[str]] = {}
    for _line, kind, topic in calls:   # in the order of the source
        names = found.setdefault(kind, [])
        if topic not in names:
            names.append(topic)
    return found


def _paragraphs(doc: str) -> List[str]:
    return [p for p in inspect.cleandoc(doc or "").split("\n\n") if p.strip()]


def node_help(name: str, module=None) -> str:
    """``NODE --help``: what the node does (its module docstring's first paragraph), its usage, its topics (read
    from its source), its parameters from the schema and its exit codes.  Creates no ROS context."""
    from mwip_ros.nodes.runtime.params import parameter_help, usage_line
    paragraphs = _paragraphs(getattr(module, "__doc__", None) or "")
    lines = [f"usage: {usage_line(name)}", ""]
    if paragraphs:   # what it does; a usage paragraph of its own (bag_replay's two modes) after it
        lines += [p.replace("``", "") + "\n" for i, p in enumerate(paragraphs) if i == 0 or p.startswith("usage:")]
    topics = _topics(getattr(module, "__file__", None))
    if topics:
        topics.setdefault("publishes", []).append("/diagnostics")   # runtime's Diagnostics, on every node
        lines.append("topics (relative names follow -r __ns:=/NS):")
        lines += [f"  {kind}: {', '.join(names)}" for kind, names in topics.items()]
        lines.append("")
    params = parameter_help(name)
    if params:
        lines += params + [""]
    codes = [p.replace("``", "") for p in paragraphs if p.lower().startswith("exit code")]
    lines += codes or textwrap.wrap(_GENERIC_EXIT_CODES, width=100)
    dotted = getattr(getattr(module, "__spec__", None), "name", None)   # also under python -m (__name__ __main__)
    if dotted and dotted != "__main__":
        lines += ["", f"the full description: python -m pydoc {dotted}"]
    return "\n".join(lines)


class StartRefused(Exception):
    """A node that does not start: ``line`` is its one line (naming the key, the file or the package), ``code``
    the exit code (:data:`EXIT_BAD_PARAMS`)."""

    def __init__(self, line: str, code: int = EXIT_BAD_PARAMS):
        super().__init__(line)
        self.line, self.code = line, code


def node_name(factory: Callable[..., object], argv: Sequence[str]) -> str:
    """The node's name for its messages: its module's ``NAME``, else the command's own name."""
    module = sys.modules.get(getattr(factory, "__module__", None) or "")
    return getattr(module, "NAME", None) or (argv[0].rsplit('/', 1)[-1] if argv else "node")


def init_context(argv: Sequence[str], name: str, discovery_range: Optional[str] = None):
    """Everything a node's process does before its node exists: the command line checked (before rcl parses it: its
    parser would end the process with a traceback), the law plug-ins imported, rclpy's patches
    (:mod:`.rclpy_compat`), the discovery set-up (:mod:`.discovery`), and an initialised context of its own.

    Parameters
    ----------
    argv : sequence of str
        The node's command line, ``--ros-args`` included.
    name : str
        The node's name, for the messages.
    discovery_range : str, optional
        ``ROS_AUTOMATIC_DISCOVERY_RANGE`` for this context only (``"OFF"``: a node that finds no other, as a test
        that feeds it directly wants); None: the environment's.

    Returns
    -------
    rclpy.Context
        The initialised context (no signal handlers: the caller's).

    Raises
    ------
    StartRefused
        A mistake on the command line, a law plug-in that fails to import, ROS arguments rcl cannot parse.
    """
    from mwip_ros.nodes.runtime.params import check_command_line
    try:
        check_command_line(argv, name)
    except ParamError as exc:
        raise StartRefused(str(exc)) from None
    from mwip_ros.core import laws
    try:
        laws.check_plugins()   # a law plug-in ($MWIP_ROS_LAWS) that failed to import: its one line
    except laws.PluginError as exc:
        raise StartRefused(str(exc)) from None
    from mwip_ros.nodes.runtime import rclpy_compat
    # rclpy's classes, patched before any node binds their callbacks: a parameter request rclpy cannot read is
    # refused, naming it, and a /clock it cannot use is rejected, neither raised in the executor
    rclpy_compat.install()
    from mwip_ros.nodes.runtime import discovery
    discovery.apply()   # before the participant exists: the package's discovery profile, or the user's set-up
    context = rclpy.Context()
    key, before = "ROS_AUTOMATIC_DISCOVERY_RANGE", os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")
    if discovery_range is not None:
        os.environ[key] = discovery_range   # rcl reads it once, in rclpy.init
    try:
        rclpy.init(args=list(argv), context=context, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # rcl's own argument errors (RCLError, RCLInvalidROSArgsError): one line, exit 2
        raise StartRefused(f"the ROS arguments cannot be parsed: {str(exc).splitlines()[0].split(', at ')[0]}") \
            from None
    finally:
        if discovery_range is not None:
            if before is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = before
    return context


def build_node(factory: Callable[..., object], context, argv: Sequence[str]):
    """The node, made by ``factory(context=context, argv=argv)``; a bad parameter or a missing optional package is
    :class:`StartRefused` (its one line)."""
    try:
        return factory(context=context, argv=list(argv))
    except (ParamError, MissingPackage) as exc:   # a bad parameter; an optional package the node needs
        raise StartRefused(str(exc)) from None


def run_node(factory: Callable[..., object], argv: Optional[Sequence[str]] = None) -> int:
    """Create the node, spin until done/SIGINT/SIGTERM, shut down cleanly, return an exit code.

    ``-h`` / ``--help`` before ``--ros-args`` prints :func:`node_help` and returns 0 without a ROS context; any
    other argument outside ``--ros-args`` (rcl would ignore it) is refused with one line, exit 2."""
    bound_malloc_arenas()   # first, for a node started as python -m mwip_ros.nodes.NODE (entry.run did it earlier)
    argv = list(sys.argv if argv is None else argv)
    stop = {"signal": None}

    def _on_signal(signum, _frame):
        stop["signal"] = signum

    module = sys.modules.get(getattr(factory, "__module__", None) or "")
    name = node_name(factory, argv)

    def refuse(text: str) -> int:
        print(f"[ERROR] {name}: {text}", file=sys.stderr, flush=True)
        return EXIT_BAD_PARAMS

    from mwip_ros.nodes.runtime.params import wants_help
    if wants_help(argv):
        print(node_help(name, module), flush=True)
        return EXIT_OK
    try:
        context = init_context(argv, name)
    except StartRefused as exc:
        return refuse(exc.line)
    old = {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    node = executor = None
    code = EXIT_OK
    from mwip_ros.nodes.runtime.memtrace import from_environment
    memtrace = from_environment()   # off unless MWIP_MEMTRACE names a file (a debugging aid)
    try:
        try:
            node = build_node(factory, context, argv)
        except StartRefused as exc:
            return refuse(exc.line)
        # Start-up made tens of thousands of long-lived objects (rclpy, numpy, parameters); a full
        # garbage collection over them takes ~9 ms, more than a realtime period.  Freeze them: later
        # collections scan only what the node allocates while it runs.
        gc.freeze()
        executor = _make_executor(context)
        executor.add_node(node)
        _realtime_priority(node)
        from mwip_ros.nodes.runtime.diagnostics import Diagnostics
        diagnostics = node.diagnostics = Diagnostics(node)
        from mwip_ros.nodes.runtime import stallprobe
        probe = stallprobe.from_environment(name)   # off unless MWIP_STALL_PROBE names a directory (a debugging aid)
        try:
            while stop["signal"] is None and not node.done and context.ok():
                node.spin_step(executor)
                diagnostics.tick()
                if memtrace is not None:
                    memtrace.tick()
        except StopRequested:
            pass
        if stop["signal"] is not None:
            node.stop_signal = stop["signal"]
            node.get_logger().info(f"received {signal.Signals(stop['signal']).name}, shutting down")
        node.on_shutdown()
        if memtrace is not None:
            memtrace.close()
        if probe is not None:
            probe.close()
        if context.ok():
            diagnostics.tick(force=True)   # the run's last word: ERROR with the reason if it failed
        code = node.exit_code
    finally:
        # Everything is written; what is left is the middleware's own clean-up.  Fast DDS 2.14 can
        # deadlock there (rmw destroy_participant spins in set_listener, holding the GIL, while a
        # discovery thread waits for its lock; seen when several nodes exit at once).  faulthandler's
        # watchdog needs no GIL: it prints where the process is stuck and ends it with exit code 1
        # (whatever the node's own code was: its files are written, but a script sees a failure).
        # Armed here, so it also covers a loop or an on_shutdown that raised.
        faulthandler.dump_traceback_later(SHUTDOWN_GRACE_S, exit=True)
        if executor is not None:
            executor.remove_node(node)
            try:
                executor.shutdown(timeout_sec=1.0)
            except TypeError:  # pragma: no cover
                executor.shutdown()
        if node is not None:
            from mwip_ros.nodes.runtime.rclpy_compat import destroy_polled_inputs
            destroy_polled_inputs(node)   # its readers outside the executor, before the node
            node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)
        faulthandler.cancel_dump_traceback_later()
        for s, h in old.items():
            signal.signal(s, h)
    return code
