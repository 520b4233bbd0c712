"""A node built in the test's own process and driven directly: no discovery, no other process, no waiting.

    with NodeHarness(DisturbanceObserver) as h:            # argv: NAME --ros-args --params-file config/paper.yaml
        h.feed("joint_states", L.encode_state(...))        # raw bytes (or a message) into its subscription callback
        assert h.sent("disturbance_estimate")              # what it published, in order, as bytes
        h.call("~/enable")                                 # a service callback (std_srvs/Trigger by default)
        results = h.set(k1=7.0)                            # a parameter change through the node's own callbacks
        assert "ready" in h.logs()                         # what its logger said

    with NodeHarness(PlantSimNode) as plant, NodeHarness(DscndoController) as ctl:
        wire = Wire(plant, ctl)                            # what one publishes is fed to the other
        plant.node._start("test"); wire.pump()             # a lockstep loop, in this process

:class:`Loop` wires the plant and the answering stages its parameters configure (the lockstep loop in this
process, a state nobody answered resent at once). A :meth:`NodeHarness.peer` is a plain node in the harness's own
context: what it publishes, serves or calls reaches the node under test through the middleware inside that one
participant (no discovery), as :meth:`NodeHarness.spin` spins them together (a late joiner of a latched topic, a
best-effort publisher; :func:`run_ctl`: ``mwip_ctl`` with its node there).

The node goes through the start-up a process makes (:func:`mwip_ros.nodes.runtime.process.init_context` and
:func:`~mwip_ros.nodes.runtime.process.build_node`: the command line, the law plug-ins, rclpy's patches, a private
context), with ``ROS_AUTOMATIC_DISCOVERY_RANGE=OFF`` for that context only: its participant finds no other, so
nothing races discovery. A start-up refusal is :func:`refused`'s one line. What needs separate processes (exit codes
and the one line on stderr, signals, lockstep across processes, the recorder's file, ``ros2 run``) keeps its
process-level test (test/graphproc.py).
"""
from __future__ import annotations

import contextlib
import itertools
from collections import deque
from typing import Any, Callable, Dict, List, Optional

from graphproc import PARAMS, loop_chain, node_rules, param_files

__all__ = ["Loop", "NodeHarness", "Wire", "node_class", "realtime_tick", "refused", "run_ctl"]

_LOGS: Dict[str, List[tuple]] = {}   # logger name -> [(severity name, message)], while a harness records it
_PATCHED = False
_CTL_NAMES = itertools.count()   # run_ctl's nodes, each a name of its own


def _record_logs() -> None:
    """Every rclpy logger's messages kept for the harness (and still written where rclpy writes them): the C call
    at the end of ``RcutilsLogger.log`` is wrapped, so rclpy's own per-call-site checks see their usual frames."""
    global _PATCHED
    if _PATCHED:
        return
    from rclpy.impl import rcutils_logger
    c_module = rcutils_logger._rclpy
    original = c_module.rclpy_logging_rcutils_log

    def log(severity, name, message, *where):
        got = _LOGS.get(name)
        if got is not None:
            got.append((getattr(severity, "name", str(severity)), str(message)))
        return original(severity, name, message, *where)
    c_module.rclpy_logging_rcutils_log = log
    _PATCHED = True


@contextlib.contextmanager
def _schema_laws():
    """The law registry (:mod:`mwip_ros.core.laws`) as a node process has it, while a node is built here: the laws
    whose parameters the parameter schema declares. A process imports its plug-ins ($MWIP_ROS_LAWS) before the
    schema is made, so the schema declares every law it has; a law a test registered in this process afterwards
    (test/trivial_law.py, imported by test/core/laws/test_laws.py) is not declared, and the controller, which designs
    every registered family at start-up, would fail on its missing parameter."""
    from mwip_ros import params as P
    from mwip_ros.core import laws
    declared = P.specs_for("dscndo_controller")
    registry = laws._LAWS
    kept = dict(registry)
    registry.clear()
    registry.update({name: law for name, law in kept.items()
                     if all(p.name in declared for p in getattr(law, "base", law).parameters)})
    try:
        yield
    finally:
        registry.clear()
        registry.update(kept)


def node_class(name: str):
    """The node class of the node ``name`` (a key of ``mwip_ros.nodes.runtime.entry.NODES``): the rclpy ``Node``
    subclass its module defines."""
    import importlib
    import inspect

    from rclpy.node import Node

    from mwip_ros.nodes.runtime.entry import NODES
    module = importlib.import_module(NODES[name])
    found = [c for _n, c in inspect.getmembers(module, inspect.isclass)
             if issubclass(c, Node) and c.__module__ == module.__name__]
    if len(found) != 1:
        raise LookupError(f"{NODES[name]} defines {len(found)} node classes")
    return found[0]


def _argv(name: str, ros_args, params, as_given: bool) -> List[str]:
    """The node's command line as graphproc.Graph.start makes it: a ``--params-file`` per file of ``params``, then
    ``ros_args`` with each ``-p`` rule made the node's own (:func:`graphproc.node_rules`) unless ``as_given``."""
    argv = [name, "--ros-args"]
    for f in param_files(params):
        argv += ["--params-file", str(f)]
    args = [str(a) for a in ros_args]
    return argv + (args if as_given else node_rules(name, args))


def _thread_nices() -> Dict[int, int]:
    """{thread id: nice} of this process's threads now."""
    import os

    from mwip_ros.nodes.runtime.process import for_every_thread
    out: Dict[int, int] = {}
    for_every_thread(lambda tid: out.__setitem__(tid, os.getpriority(os.PRIO_PROCESS, tid)))
    return out


def _restore_nices(before: Dict[int, int]) -> None:
    """Each of this process's threads that ``before`` knew back at its nice then (a node built here, as
    foxglove_server's ``nice`` parameter does, lowers every thread of its process: the test worker's too, for the rest
    of its tests)."""
    import os
    for tid, nice in before.items():
        try:
            if os.getpriority(os.PRIO_PROCESS, tid) != nice:
                os.setpriority(os.PRIO_PROCESS, tid, nice)
        except OSError:   # gone, or not allowed
            pass


class NodeHarness:
    """``factory`` (a node class of mwip_ros.nodes) built in this process with ``ros_args`` after the parameter file
    ``params`` (one, several or None), or with the whole command line ``argv``;
    :class:`~mwip_ros.nodes.runtime.process.StartRefused` if it refuses to start."""

    def __init__(self, factory: Callable[..., Any], *ros_args, params=PARAMS, name: Optional[str] = None,
                 as_given: bool = False, argv: Optional[List[str]] = None):
        import rclpy
        from rclpy.node import Node

        from mwip_ros.nodes.runtime import process
        _record_logs()
        self._nice = _thread_nices()   # a node that lowers its process's priority (foxglove_server) is undone at close
        self.name = name or process.node_name(factory, [getattr(factory, "__name__", "node")])
        self.argv = list(argv) if argv is not None else _argv(self.name, ros_args, params, as_given)
        self._published: Dict[str, List[Any]] = {}
        self._taps: List[Callable[[str, Any], None]] = []   # told of every publication (Wire)
        self.context = process.init_context(self.argv, self.name, discovery_range="OFF")
        original = Node.create_publisher
        harness = self

        def create_publisher(node, msg_type, topic, *args, **kwargs):
            pub = original(node, msg_type, topic, *args, **kwargs)
            harness._capture(pub)
            return pub
        Node.create_publisher = create_publisher
        self._log_names: List[str] = []
        try:
            self.node = None
            self._logs = _LOGS[self._logger_name(ros_args)] = []
            with _schema_laws():
                self.node = process.build_node(factory, self.context, self.argv)
        except BaseException:
            rclpy.shutdown(context=self.context)
            raise
        finally:
            Node.create_publisher = original
        self._executor = None
        self._services: Dict[str, Any] = {}   # service name as asked -> the node's service
        self._names: Dict[str, str] = {}      # topic as asked -> resolved
        self._loop_executor = None   # turn()'s: run_node's kind
        self._feeders: Dict[tuple, Any] = {}
        self._feeder_nodes: Dict[str, Any] = {}   # the peers (publisher's feeders too), by name

    # -------------------------------------------------------------------------------------------- plumbing
    def _logger_name(self, ros_args) -> str:
        ns, node = "", self.name
        for a in map(str, ros_args):
            if a.startswith("__ns:="):
                ns = a.split(":=", 1)[1].strip("/").replace("/", ".")
            elif a.startswith("__node:="):
                node = a.split(":=", 1)[1]
        return f"{ns}.{node}" if ns else node

    def _capture(self, pub) -> None:
        sent = self._published.setdefault(pub.topic_name, [])
        publish = pub.publish

        def record(msg):
            sent.append(msg)
            for tap in self._taps:
                tap(pub.topic_name, msg)
            return publish(msg)
        pub.publish = record

    def _resolve(self, topic: str) -> str:
        name = self._names.get(topic)
        if name is None:
            name = self._names[topic] = self.node.resolve_topic_name(topic)
        return name

    # ------------------------------------------------------------------------------------------------- input
    def subscriptions(self, topic: str) -> list:
        """The node's subscriptions on ``topic`` (relative names resolve in the node's namespace), its polled inputs
        (:class:`~mwip_ros.nodes.runtime.rclpy_compat.PolledInput`) among them: :meth:`feed` hands them a message as
        their node's ``poll`` would."""
        name = self._resolve(topic)
        polled = getattr(self.node, "polled_inputs", ())   # rclpy_compat.PolledInput: fed as the node's poll would
        return [s for s in (*self.node.subscriptions, *polled) if s.topic_name == name]

    def publisher(self, topic: str, msg_type=None, name: str = "feeder"):
        """A publisher on ``topic`` of a node ``name`` in the harness's context (made once per name and topic): the
        node's graph lists it, as it lists a real publisher of the stream (the input guards ask the graph who
        publishes). Nothing it publishes reaches the node: :meth:`feed` hands data over."""
        key = (name, self._resolve(topic))
        if key not in self._feeders:
            if msg_type is None:
                subs = self.subscriptions(topic)
                if not subs:
                    raise KeyError(f"{self.name} does not subscribe to {key[1]}: give the message type")
                msg_type = subs[0].msg_type
            from mwip_ros.msgs.qos import GRAPH_QOS
            self._feeders[key] = self.peer(name).create_publisher(msg_type, key[1], GRAPH_QOS)
        return self._feeders[key]

    def peer(self, name: str):
        """A plain rclpy node ``name`` in the harness's context (made once; no parameter services): what it
        publishes, serves or calls reaches the node under test through the middleware within this one participant,
        as :meth:`spin` (or :attr:`executor`) spins them together."""
        if name not in self._feeder_nodes:
            import rclpy
            self._feeder_nodes[name] = rclpy.create_node(name, context=self.context, start_parameter_services=False)
            if self._executor is not None:
                self._executor.add_node(self._feeder_nodes[name])
        return self._feeder_nodes[name]

    def listen(self, topic: str, msg_type, qos=None, name: str = "listener") -> list:
        """A subscription of :meth:`peer` ``name`` on ``topic`` (``qos`` default GRAPH_QOS): the list of the
        messages it receives (in order, as the harness spins), which the caller reads."""
        from mwip_ros.msgs.qos import GRAPH_QOS
        got: list = []
        self.peer(name).create_subscription(msg_type, self._resolve(topic), got.append,
                                            GRAPH_QOS if qos is None else qos)
        return got

    def feed(self, topic: str, data, feeder: Optional[str] = "feeder") -> int:
        """Hand ``data`` (serialized bytes or a message) to every subscription of the node on ``topic``, as the
        executor would, after making sure the graph lists a publisher ``feeder`` on it (:meth:`publisher`; None:
        no publisher is made); returns how many took it (0: the node does not subscribe to ``topic``)."""
        from rclpy.serialization import deserialize_message, serialize_message
        subs = self.subscriptions(topic)
        if subs and feeder is not None:
            self.publisher(topic, subs[0].msg_type, feeder)
        for sub in subs:
            if sub.raw:
                sub.callback(data if isinstance(data, (bytes, bytearray)) else serialize_message(data))
            else:
                sub.callback(deserialize_message(bytes(data), sub.msg_type)
                             if isinstance(data, (bytes, bytearray)) else data)
        return len(subs)

    def call(self, service: str, request=None):
        """Call the node's service ``service`` (``~/enable``, ``/plant_sim/set_parameters``, ...) with ``request``
        (default: an empty request of its type) and return the response its callback gives."""
        srv = self._services.get(service)
        if srv is None:
            resolve = self.node.resolve_service_name
            name = resolve(service)
            found = [s for s in self.node.services if resolve(s.srv_name) == name]   # as made: '~/reset', 'n/get_..'
            if not found:
                have = sorted(resolve(s.srv_name) for s in self.node.services)
                raise KeyError(f"{self.name} has no service {name} (it has {have})")
            srv = self._services[service] = found[0]
        return srv.callback(request if request is not None else srv.srv_type.Request(), srv.srv_type.Response())

    def set(self, **values) -> list:
        """Set parameters (dotted names as keyword arguments with ``__`` for ``.``) through the node's own callbacks;
        the list of ``SetParametersResult``."""
        from rclpy.parameter import Parameter
        return self.node.set_parameters([Parameter(k.replace("__", "."), value=v) for k, v in values.items()])

    def fire(self, index: int = 0) -> None:
        """Run the callback of the node's timer ``index`` once (in creation order)."""
        list(self.node.timers)[index].callback()

    @property
    def executor(self):
        """The harness's executor (made at first use): the node and its peers, spun by :meth:`spin`."""
        if self._executor is None:
            from rclpy.executors import SingleThreadedExecutor
            self._executor = SingleThreadedExecutor(context=self.context)
            for node in (self.node, *self._feeder_nodes.values()):
                self._executor.add_node(node)
        return self._executor

    def spin(self, until: Callable[[], bool], timeout: float) -> bool:
        """Spin the node's own executor (its timers run on the wall clock) until ``until()`` or ``timeout`` s; the
        node's polled inputs (:class:`~mwip_ros.nodes.runtime.rclpy_compat.PolledInput`) are read between its
        callbacks, as its process's loop reads them."""
        import time
        end = time.monotonic() + timeout
        while not until() and time.monotonic() < end:
            self.spin_once(0.01)
        return until()

    def turn(self, timeout: float, until: Optional[Callable[[], bool]] = None) -> bool:
        """Turn the node's own loop as ``run_node`` turns it (``node.spin_step``: a plant's graph wait and its
        runner's watch too) with the executor ``run_node`` makes (:func:`~mwip_ros.nodes.runtime.process.
        _make_executor`, events by default: a realtime plant's ticks keep time as in its process), until the node
        is done (or ``until()``), at most ``timeout`` s of wall time; whether it is. (Not with :meth:`spin` on the
        same harness: a node is spun by one executor.)"""
        import time

        from mwip_ros.nodes.runtime import process
        if self._loop_executor is None:
            self._loop_executor = process._make_executor(self.context)
            self._loop_executor.add_node(self.node)
        done = until if until is not None else (lambda: self.node.done)
        end = time.monotonic() + timeout
        while not done() and time.monotonic() < end:
            self.node.spin_step(self._loop_executor)
        return done()

    def spin_once(self, timeout_sec: float) -> None:
        """One turn of the node's loop: the executor's next callback (up to ``timeout_sec``), then its polled inputs
        (:class:`~mwip_ros.nodes.runtime.rclpy_compat.PolledInput`) read, as its process's loop reads them between
        callbacks."""
        self.executor.spin_once(timeout_sec=timeout_sec)
        for p in getattr(self.node, "polled_inputs", ()):
            p.poll()

    def diagnostics(self):
        """The node's ``/diagnostics`` reporter as ``run_node`` attaches it (made once: ``node.diagnostics``); its
        reports, once :meth:`~mwip_ros.nodes.runtime.diagnostics.Diagnostics.tick` sends them, are
        ``messages("/diagnostics", DiagnosticArray)``."""
        if self.node.diagnostics is None:
            from mwip_ros.nodes.runtime.diagnostics import Diagnostics
            self.node.diagnostics = Diagnostics(self.node)
            self._capture(self.node.diagnostics.pub)
        return self.node.diagnostics

    # ------------------------------------------------------------------------------------------------ output
    def sent(self, topic: str) -> List[bytes]:
        """What the node published on ``topic``, in order, as serialized bytes."""
        from rclpy.serialization import serialize_message
        return [m if isinstance(m, (bytes, bytearray)) else serialize_message(m)
                for m in self._published.get(self._resolve(topic), [])]

    def messages(self, topic: str, msg_type) -> list:
        """What the node published on ``topic``, in order, as messages of ``msg_type``."""
        from rclpy.serialization import deserialize_message
        return [m if not isinstance(m, (bytes, bytearray)) else deserialize_message(bytes(m), msg_type)
                for m in self._published.get(self._resolve(topic), [])]

    def logs(self, severity: Optional[str] = None) -> str:
        """What the node's logger said (one message per line), only ``severity`` (INFO, WARN, ERROR) if given."""
        return "\n".join(m for s, m in self._logs if severity is None or s == severity)

    # ---------------------------------------------------------------------------------------------- the end
    def close(self) -> None:
        """The node's shutdown work (``on_shutdown``), then the node and its context destroyed."""
        import rclpy
        if self.node is None:
            return
        try:
            getattr(self.node, "on_shutdown", lambda: None)()   # a plain rclpy node has none
        finally:
            self._taps.clear()
            for executor in (self._executor, self._loop_executor):
                if executor is not None:
                    executor.shutdown(timeout_sec=1.0)
            for feeder in self._feeder_nodes.values():
                feeder.destroy_node()
            from mwip_ros.nodes.runtime.rclpy_compat import destroy_polled_inputs
            destroy_polled_inputs(self.node)
            self.node.destroy_node()
            self.node = None
            rclpy.try_shutdown(context=self.context)
            _restore_nices(self._nice)

    def __enter__(self) -> "NodeHarness":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Wire:
    """Harnesses joined by their topics: what one node publishes is handed (:meth:`NodeHarness.feed`) to each other
    harness whose node subscribes to the topic, in the order published, through one queue (no callback runs inside
    another's): a graph's flow of data in this process, without the middleware and without a clock of its own.

        wire = Wire(plant, observer, controller)
        plant.node._start("test")          # state 0 out: queued for the observer and the controller
        wire.pump()                        # delivered, their answers too, until nothing is left (or until())
    """

    def __init__(self, *harnesses: NodeHarness):
        self.harnesses = list(harnesses)
        self.queue: deque = deque()
        self.delivered = 0
        for h in self.harnesses:
            h._taps.append(lambda topic, msg, src=h: self._route(src, topic, msg))

    def _route(self, source: NodeHarness, topic: str, msg) -> None:
        for h in self.harnesses:
            if h is not source and h.node is not None and h.subscriptions(topic):
                self.queue.append((h, topic, msg))

    def cut(self, h: NodeHarness) -> None:
        """``h`` hears nothing more, and what was queued for it is dropped: a node killed (its publishers may stay in
        the others' graphs, as a killed process's do for a while)."""
        self.harnesses.remove(h)
        self.queue = deque(item for item in self.queue if item[0] is not h)

    def pump(self, until: Optional[Callable[[], bool]] = None, limit: int = 10_000_000) -> bool:
        """Deliver what is queued, and what those deliveries publish, until the queue is empty, ``until()`` holds
        (looked at after each delivery) or ``limit`` messages were delivered; whether ``until()`` holds (without
        ``until``: whether the queue is empty)."""
        n = 0
        while self.queue and n < limit:
            if until is not None and until():
                return True
            h, topic, msg = self.queue.popleft()
            h.feed(topic, msg)
            n += 1
            self.delivered += 1
        return until() if until is not None else not self.queue


class Loop:
    """The lockstep loop in this process: ``plant_sim`` and the answering stages its parameters configure (the
    observer and the controller; a raw plant's state estimator first: :func:`graphproc.loop_chain`), each a
    :class:`NodeHarness` with ``params``, joined by a :class:`Wire`. ``plant_args`` are the plant's ROS arguments,
    ``args`` a node's own (``args={"dscndo_controller": ("-p", "law:=lqr")}``). Leaving the ``with`` block closes
    them, the plant last (its csv and summary are then written).

        with Loop("-p", "duration_s:=2.0") as loop:
            loop.start()                                   # the plant's first state
            loop.run(lambda: loop.plant.node.plant.k >= 100)   # stepped until then (None: to the run's end)
    """

    def __init__(self, *plant_args, params=PARAMS, args: Optional[Dict[str, tuple]] = None):
        args = args or {}
        self.nodes: Dict[str, NodeHarness] = {}
        try:
            for a in loop_chain(params, *plant_args):
                self.nodes[a.node] = NodeHarness(node_class(a.node), *args.get(a.node, ()), params=params)
            self.plant = self.nodes["plant_sim"] = NodeHarness(node_class("plant_sim"), *plant_args, params=params)
        except BaseException:
            self.close()
            raise
        self.wire = Wire(*self.nodes.values())

    def __getitem__(self, node: str) -> NodeHarness:
        return self.nodes[node]

    def start(self) -> None:
        """The plant's run starts (what its graph wait does once the graph is there): state 0 is queued."""
        self.plant.node._start("the loop's harnesses are wired")

    def run(self, until: Optional[Callable[[], bool]] = None, limit: int = 10_000_000, resends: int = 10) -> bool:
        """Step the loop (:meth:`Wire.pump`) until ``until()`` holds (True), or the run ends (without ``until``:
        True) or stalls (False). A state that nothing answered is sent again at once, as the plant's spin loop does
        after ``RESEND_S`` of wall time (``runner.watch``: the lockstep driver's check), at most ``resends`` times
        in a row: the observer and the controller follow a stream that went back to its start (a reset) once
        ``RESYNC`` copies of its first state came."""
        node, stalled, last = self.plant.node, 0, None
        while True:
            if self.wire.pump(until, limit) and until is not None:
                return True
            d = node.lockstep
            if node.done or d.awaiting is None or (d.awaiting == last and stalled >= resends):
                return until() if until is not None else node.done
            stalled, last = (stalled + 1 if d.awaiting == last else 1), d.awaiting
            d.resent_at = float("-inf")   # due now
            node.runner.watch({})

    def close(self) -> None:
        """Every node's shutdown work, the plant's last."""
        for h in sorted(self.nodes.values(), key=lambda h: h is getattr(self, "plant", None)):
            h.close()

    def __enter__(self) -> "Loop":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def realtime_tick(node, periods: int = 1) -> None:
    """One wake of a realtime plant's timer ``periods`` periods after the last: its runner's clock is the test's
    (set here, from the node's clock, the first time), so each call finishes exactly ``periods`` periods however
    fast the test calls it (plant_runners.RealtimeRunner runs the periods its clock has passed)."""
    runner = node.runner
    if not hasattr(runner, "_test_now"):   # from the last deadline the runner finished (start(): state 0's)
        runner._test_now = runner.schedule.due(runner.schedule.k) + 1000
        runner._now = lambda: runner._test_now
    runner._test_now += periods * node.period_ns
    runner._tick()

class _Turns:
    """What mwip_ctl's Ros spins (``spin_once``): a turn of the harness node's loop (:meth:`NodeHarness.spin_once`)."""

    def __init__(self, h: NodeHarness):
        self.h = h

    def spin_once(self, timeout_sec: float = 0.0) -> None:
        self.h.spin_once(timeout_sec)


def run_ctl(h: NodeHarness, *argv: str) -> tuple:
    """``mwip_ctl argv`` in this process (its ``main``) with its ROS node a :meth:`NodeHarness.peer`-like node in
    ``h``'s context, spun with the node under test by ``h``'s executor: its service calls and messages reach that
    node through the middleware within the one participant. Returns (exit code, stdout, stderr)."""
    import contextlib
    import io

    import rclpy

    from mwip_ros.cli import ctl

    class PeerRos(ctl.Ros):
        def __init__(self, namespace: str, timeout: float):   # no context, no discovery of its own
            self.rclpy, self.timeout, self.ctx = rclpy, timeout, h.context
            self.node = rclpy.create_node(f"mwip_ctl_{next(_CTL_NAMES)}", namespace=namespace or None,
                                          context=h.context, start_parameter_services=False)
            h.executor.add_node(self.node)
            self.ex = _Turns(h)   # its spin_once is a turn of the node's loop (the polled inputs read too)

        def close(self) -> None:   # the harness's executor and context go on
            h.executor.remove_node(self.node)
            self.node.destroy_node()

    out, err, ros = io.StringIO(), io.StringIO(), ctl.Ros
    ctl.Ros = PeerRos
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = ctl.main(list(argv))
    finally:
        ctl.Ros = ros
    return code, out.getvalue(), err.getvalue()


def refused(factory: Callable[..., Any], *ros_args, params=PARAMS, name: Optional[str] = None,
            as_given: bool = False, argv: Optional[List[str]] = None) -> str:
    """The one line with which ``factory`` refuses to start with ``ros_args`` (AssertionError if it starts)."""
    from mwip_ros.nodes.runtime.process import StartRefused
    try:
        h = NodeHarness(factory, *ros_args, params=params, name=name, as_given=as_given, argv=argv)
    except StartRefused as exc:
        return exc.line
    h.close()
    raise AssertionError(f"{factory.__name__} started with {list(ros_args)} (params {params})")
