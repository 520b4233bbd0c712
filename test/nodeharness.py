"""A node built in the test's own process and driven directly: no discovery, no other process, no waiting.

    with NodeHarness(DisturbanceObserver) as h:            # argv: NAME --ros-args --params-file config/paper.yaml
        h.feed("joint_states", L.encode_state(...))        # raw bytes (or a message) into its subscription callback
        assert h.sent("disturbance_estimate")              # what it published, in order, as bytes
        h.call("~/enable")                                 # a service callback (std_srvs/Trigger by default)
        results = h.set(k1=7.0)                            # a parameter change through the node's own callbacks
        assert "ready" in h.logs()                         # what its logger said

The node goes through the start-up a process makes (:func:`mwip_ros.nodes.runtime.process.init_context` and
:func:`~mwip_ros.nodes.runtime.process.build_node`: the command line, the law plug-ins, rclpy's patches, a private
context), with ``ROS_AUTOMATIC_DISCOVERY_RANGE=OFF`` for that context only: its participant finds no other, so
nothing races discovery. A start-up refusal is :func:`refused`'s one line. What needs separate processes (exit codes
and the one line on stderr, signals, lockstep across processes, the recorder's file, ``ros2 run``) keeps its
process-level test (test/graphproc.py).
"""
from __future__ import annotations

from typing import Any, Callable, Dict, List, Optional

from graphproc import PARAMS, node_rules, param_files

__all__ = ["NodeHarness", "node_class", "refused"]

_LOGS: Dict[str, List[tuple]] = {}   # logger name -> [(severity name, message)], while a harness records it
_PATCHED = False


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
        self.name = name or process.node_name(factory, [getattr(factory, "__name__", "node")])
        self.argv = list(argv) if argv is not None else _argv(self.name, ros_args, params, as_given)
        self._published: Dict[str, List[Any]] = {}
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
            self.node = process.build_node(factory, self.context, self.argv)
        except BaseException:
            rclpy.shutdown(context=self.context)
            raise
        finally:
            Node.create_publisher = original
        self._executor = None
        self._feeders: Dict[tuple, Any] = {}
        self._feeder_nodes: Dict[str, Any] = {}

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
            return publish(msg)
        pub.publish = record

    def _resolve(self, topic: str) -> str:
        return self.node.resolve_topic_name(topic)

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
            import rclpy
            if name not in self._feeder_nodes:
                self._feeder_nodes[name] = rclpy.create_node(name, context=self.context,
                                                             start_parameter_services=False)
            if msg_type is None:
                subs = self.subscriptions(topic)
                if not subs:
                    raise KeyError(f"{self.name} does not subscribe to {key[1]}: give the message type")
                msg_type = subs[0].msg_type
            from mwip_ros.msgs.qos import GRAPH_QOS
            self._feeders[key] = self._feeder_nodes[name].create_publisher(msg_type, key[1], GRAPH_QOS)
        return self._feeders[key]

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
        name = self.node.resolve_service_name(service)
        found = [s for s in self.node.services if s.srv_name == name]
        if not found:
            have = sorted(s.srv_name for s in self.node.services)
            raise KeyError(f"{self.name} has no service {name} (it has {have})")
        srv = found[0]
        return srv.callback(request if request is not None else srv.srv_type.Request(), srv.srv_type.Response())

    def set(self, **values) -> list:
        """Set parameters (dotted names as keyword arguments with ``__`` for ``.``) through the node's own callbacks;
        the list of ``SetParametersResult``."""
        from rclpy.parameter import Parameter
        return self.node.set_parameters([Parameter(k.replace("__", "."), value=v) for k, v in values.items()])

    def fire(self, index: int = 0) -> None:
        """Run the callback of the node's timer ``index`` once (in creation order)."""
        list(self.node.timers)[index].callback()

    def spin(self, until: Callable[[], bool], timeout: float) -> bool:
        """Spin the node's own executor (its timers run on the wall clock) until ``until()`` or ``timeout`` s."""
        import time

        from rclpy.executors import SingleThreadedExecutor
        if self._executor is None:
            self._executor = SingleThreadedExecutor(context=self.context)
            self._executor.add_node(self.node)
        end = time.monotonic() + timeout
        while not until() and time.monotonic() < end:
            self._executor.spin_once(timeout_sec=0.01)
        return until()

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
            self.node.on_shutdown()
        finally:
            if self._executor is not None:
                self._executor.shutdown(timeout_sec=1.0)
            for feeder in self._feeder_nodes.values():
                feeder.destroy_node()
            from mwip_ros.nodes.runtime.rclpy_compat import destroy_polled_inputs
            destroy_polled_inputs(self.node)
            self.node.destroy_node()
            self.node = None
            rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> "NodeHarness":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


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
