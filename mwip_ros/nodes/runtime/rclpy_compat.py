"""What mwip_ros changes in rclpy's internals, in one place, for the rclpy it was written for.

Written for rclpy 7.1.6 (ROS 2 Jazzy, the PyPI wheels ``ros-rclpy``).  :func:`check_version`
compares the installed rclpy with :data:`WRITTEN_FOR` and, on another version, warns once (to
stderr) that the replaced internals may have changed; nothing stops.  Nothing happens at import
time: :func:`install` (called by ``run_node`` for every node, before rclpy.init) patches rclpy's
classes once per process, and a node's ``__init__`` calls the per-node functions.  Every use of an
rclpy internal is here, each behind one function with its own test (test/nodes/test_rclpy_compat.py,
test/nodes/test_param_hostile.py); a missing internal raises :class:`RclpyChanged` naming it:

====================================  ==================================================================
:func:`install`                       the parameter services' callbacks (below) and :func:`guard_clock`
:func:`guard_clock`                   ``TimeSource.clock_callback``: a /clock it cannot use is rejected
:func:`parameter_overrides`           ``Node._parameter_overrides``: the start-up values rclpy read
:func:`name_undeclared_parameters`    ``Node._check_undeclared_parameters``: a refusal names the keys
:func:`use_ros_time_override`         ``ROSClock._set_ros_time_is_active``: a clock the node sets
:class:`PolledInput`                  ``_rclpy.Subscription``: a subscription the executor never serves
:class:`IsolatedInput`                the same, on a context (participant) of its own, threads at nice 19
====================================  ==================================================================

rclpy's parameter services (``rclpy.parameter_service.ParameterService``) read each request
parameter with ``Parameter.from_parameter_msg`` outside any ``try``: one ``SetParameters`` request
with a ``ParameterValue`` of type code 99, from any node on the domain, raises ``ValueError`` in the
executor and ends the process.  :func:`install` replaces the two set callbacks:

* every request parameter is read by :func:`parameter_from_msg` first; one it cannot read is refused
  with a reason that names it (``parameter 'k1': type code 99 is not a ROS parameter type``), and the
  rest of the request is still answered, one result per parameter, as rclpy answers;
* refused without reading further: an unknown type code, ``PARAMETER_NOT_SET`` (rclpy would undeclare
  the parameter), an empty name, a name longer than :data:`MAX_NAME_CHARS` that the node has not
  declared, an array longer than :data:`MAX_ARRAY_LEN`, and the parameters past the first
  :data:`MAX_PARAMETERS` of one request (``set_parameters_atomically``: the whole request);
* the rest goes to the node as before (rclpy's descriptor checks, then :mod:`.params`' validation); a
  refusal's reason is prefixed ``parameter 'NAME': `` when it does not start so, an exception from
  the node's callbacks becomes a refusal, and the descriptor type rclpy changes while checking a
  dynamically typed parameter is put back when the value is refused.

The four read-only services (get, get_types, describe, list) already answer odd names and depths
(an undeclared name gives rclpy's empty answer); an exception from one of them is answered with an
empty response instead of ending the process.  Requests refused unread are counted in the node's
``rejects`` (:class:`~mwip_ros.nodes.runtime.guards.Rejects`, on ``/diagnostics``) and logged rate-limited.
"""
from __future__ import annotations

import sys
from typing import Callable, Dict, List, Optional, Tuple

from mwip_ros.msgs.stamps import NS_PER_S, join_ns
from mwip_ros.nodes.runtime.guards import NEW, REPEAT, RESTART, Rejects, StampGuard

__all__ = ["WRITTEN_FOR", "MAX_NAME_CHARS", "MAX_ARRAY_LEN", "MAX_PARAMETERS", "CLOCK_WINDOW_NS", "RclpyChanged",
           "rclpy_version", "check_version", "install", "installed", "parameter_from_msg", "shown_name", "guard_clock",
           "clock_guarded", "parameter_overrides", "name_undeclared_parameters", "use_ros_time_override",
           "PolledInput", "IsolatedInput", "polled_inputs", "destroy_polled_inputs", "SIDE_DEPTH"]

WRITTEN_FOR = ("7.1.6",)   # the rclpy versions whose internals this module was written against (and tested with)
MAX_NAME_CHARS = 256       # a longer name that the node has not declared is refused unread
MAX_ARRAY_LEN = 4096       # an array value longer than this is refused unread (the schema's arrays hold a few values)
MAX_PARAMETERS = 1000      # per request: the parameters after these are refused unread (each still answered)
SHOWN_NAME_CHARS = 80      # in a reason, a name is cut to this many characters
CLOCK_WINDOW_NS = NS_PER_S   # /clock may jump ahead by at most 1 s (simulated time) at once
SIDE_DEPTH = 10   # a robot side's side inputs: the newest messages of each a PolledInput keeps between two looks

_CALLBACKS = ("_set_parameters_callback", "_set_parameters_atomically_callback", "_get_parameters_callback",
              "_get_parameter_types_callback", "_describe_parameters_callback", "_list_parameters_callback")
_ARRAY_FIELDS = {5: "byte_array_value", 6: "bool_array_value", 7: "integer_array_value", 8: "double_array_value",
                 9: "string_array_value"}   # ParameterType codes of the arrays

_state = {"installed": False, "warned": False}


# --- the version ----------------------------------------------------------------------------------

def rclpy_version() -> Optional[str]:
    """The version of the distribution that installed the ``rclpy`` package imported (the wheel
    ``ros-rclpy``; a build may leave a second ``rclpy`` record beside it), None if none says."""
    from importlib import metadata

    def owners():
        yield from ("ros-rclpy", "ros-jazzy-rclpy", "rclpy")     # the wheels' names: no scan of every distribution
        try:
            yield from metadata.packages_distributions().get("rclpy", [])
        except Exception:  # noqa: BLE001 - a broken environment: no version known
            return

    versions = []
    for name in dict.fromkeys(owners()):
        try:
            dist = metadata.distribution(name)
        except metadata.PackageNotFoundError:
            continue
        if any(str(f).replace("\\", "/") == "rclpy/parameter_service.py" for f in (dist.files or ())):
            return dist.version
        versions.append(dist.version)
    return versions[0] if versions else None


def check_version(version: Optional[str] = None, warn: Optional[Callable[[str], None]] = None) -> Optional[str]:
    """None when ``version`` (default: the installed rclpy's) is one of :data:`WRITTEN_FOR`; else the
    warning text, which is also given to ``warn`` (default: one line on stderr) the first time only."""
    version = rclpy_version() if version is None else version
    if version in WRITTEN_FOR:
        return None
    text = (f"nodes.runtime.rclpy_compat was written for rclpy {', '.join(WRITTEN_FOR)} (ROS 2 Jazzy); this is "
            f"rclpy {version or 'of an unknown version'}: its patches are installed as written, check them "
            f"(test/nodes/test_rclpy_compat.py, test/nodes/test_param_hostile.py)")
    if not _state["warned"]:
        _state["warned"] = True
        (warn or (lambda t: print(f"[WARN] [rclpy_compat]: {t}", file=sys.stderr, flush=True)))(text)
    return text


class RclpyChanged(RuntimeError):
    """An rclpy internal this module uses is missing or has another shape (an rclpy other than WRITTEN_FOR)."""

    def __init__(self, what: str):
        super().__init__(f"rclpy {rclpy_version() or '(unknown version)'}: {what}; nodes.runtime.rclpy_compat was "
                         f"written for rclpy {', '.join(WRITTEN_FOR)}")


# --- a node's parameters: the start-up values rclpy read, the refusal of undeclared names ----------

def parameter_overrides(node) -> Dict[str, object]:
    """The node's start-up values as rclpy read them in ``Node.__init__`` from its ``--params-file``
    sections and ``-p`` rules: rclpy's own ``{name: rclpy.parameter.Parameter}`` dict
    (``Node._parameter_overrides``), which ``declare_parameter`` takes a value from; a value put in it is
    the one declared.  Raises :class:`RclpyChanged` when the node has no such dict."""
    overrides = getattr(node, "_parameter_overrides", None)
    if not isinstance(overrides, dict):
        raise RclpyChanged(f"Node._parameter_overrides is {type(overrides).__name__}, not the dict of the "
                           f"node's start-up values")
    return overrides


def name_undeclared_parameters(node, hint: Callable[[str], str] = lambda _name: "") -> None:
    """Make ``node.set_parameters*`` refuse undeclared names by name: rclpy's check
    (``Node._check_undeclared_parameters``, called with the list of Parameters before any is set) raises
    ``ParameterNotDeclaredException([])`` (it consumes a generator twice).  The replacement raises it with
    each undeclared name followed by ``hint(name)`` (a spelling hint).  Raises :class:`RclpyChanged` when
    rclpy has no such check or no ``Node._parameters`` dict."""
    from rclpy.exceptions import ParameterNotDeclaredException

    if not callable(getattr(node, "_check_undeclared_parameters", None)) \
            or not isinstance(getattr(node, "_parameters", None), dict):
        raise RclpyChanged("Node._check_undeclared_parameters or the Node._parameters dict is missing")

    def check_undeclared(parameter_list) -> None:
        unknown = [f"{p.name}{hint(p.name)}" for p in parameter_list if p.name not in node._parameters]
        if unknown:
            raise ParameterNotDeclaredException(unknown)

    check_undeclared._mwip_guarded = True
    node._check_undeclared_parameters = check_undeclared


# --- clocks ---------------------------------------------------------------------------------------

def use_ros_time_override(clock) -> None:
    """Make ``clock`` (a node's ROS-time clock, without ``use_sim_time``) read what the node gives
    ``clock.set_ros_time_override``: rclpy lets only its TimeSource switch that on
    (``ROSClock._set_ros_time_is_active``).  Raises :class:`RclpyChanged` when the clock cannot."""
    switch = getattr(clock, "_set_ros_time_is_active", None)
    if not callable(switch):
        raise RclpyChanged("ROSClock._set_ros_time_is_active is missing")
    switch(True)


def clock_guarded() -> bool:
    """Whether :func:`guard_clock` replaced rclpy's ``TimeSource.clock_callback`` in this process."""
    from rclpy.time_source import TimeSource
    return getattr(TimeSource.clock_callback, "_mwip_guarded", False)


def guard_clock() -> None:
    """Make rclpy's time source reject a ``/clock`` it cannot use instead of raising in the executor.

    rclpy's ``TimeSource.clock_callback`` (bound when a node with ``use_sim_time`` subscribes to /clock,
    so this runs before any node is made) raises on a negative time, which ends the node.  The replacement
    judges each stamp with a :class:`~mwip_ros.nodes.runtime.guards.StampGuard` of :data:`CLOCK_WINDOW_NS`: a
    negative time, one that goes backwards or one that jumps ahead by more than a second is rejected,
    counted in the node's ``rejects`` (if it has one) and logged; the node's clock keeps its last good
    time; a resend is dropped; the rest goes to rclpy's callback.  Idempotent."""
    from rclpy.time_source import TimeSource

    original = getattr(TimeSource, "clock_callback", None)
    if not callable(original) or not callable(getattr(TimeSource, "_get_node", None)):
        raise RclpyChanged("TimeSource.clock_callback or TimeSource._get_node is missing")
    if getattr(original, "_mwip_guarded", False):
        return

    def clock_callback(self, msg) -> None:
        stamp = join_ns(msg.clock.sec, msg.clock.nanosec)
        guard = self.__dict__.setdefault("_mwip_guard", StampGuard(CLOCK_WINDOW_NS, "/clock"))
        verdict = guard.check(stamp) if stamp >= 0 else f"/clock {stamp} ns is negative"
        if verdict == REPEAT:
            return
        if verdict not in (NEW, RESTART):
            node = self._get_node()
            rejects = getattr(node, "rejects", None)
            if rejects is not None:
                rejects("/clock", verdict)
            elif node is not None:
                node.get_logger().warning(f"rejected /clock: {verdict}", throttle_duration_sec=5.0)
            return
        original(self, msg)

    clock_callback._mwip_guarded = True
    clock_callback.__wrapped__ = original
    TimeSource.clock_callback = clock_callback


# --- reading a request parameter ------------------------------------------------------------------

def shown_name(name: str) -> str:
    """``name`` as a reason shows it: control characters escaped, cut to :data:`SHOWN_NAME_CHARS`."""
    text = name if name.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in name)
    if len(text) > SHOWN_NAME_CHARS:
        text = f"{text[:SHOWN_NAME_CHARS]}... ({len(name)} characters)"
    return text


def _named(name: str, reason: str) -> str:
    prefix = f"parameter '{shown_name(name)}'"
    return reason if reason.startswith("parameter '") else f"{prefix}: {reason}"


def parameter_from_msg(msg, declared=None) -> Tuple[object, Optional[str]]:
    """``(rclpy Parameter, None)`` for an ``rcl_interfaces/Parameter`` message, or ``(None, reason)``
    naming it when it cannot be set: an unknown type code, no value (``PARAMETER_NOT_SET``), an empty
    name, a name longer than :data:`MAX_NAME_CHARS` not in ``declared`` (a container of names), an
    array longer than :data:`MAX_ARRAY_LEN`, or a value rclpy cannot read."""
    from rcl_interfaces.msg import ParameterType
    from rclpy.parameter import Parameter

    name = msg.name
    if not isinstance(name, str) or not name:
        return None, "parameter '': an empty name is not a parameter name"
    if len(name) > MAX_NAME_CHARS and (declared is None or name not in declared):
        return None, f"parameter '{shown_name(name)}': no parameter has a name this long (at most {MAX_NAME_CHARS})"
    code = msg.value.type
    if code not in {t.value for t in Parameter.Type}:
        return None, f"parameter '{shown_name(name)}': type code {code} is not a ROS parameter type"
    if code == ParameterType.PARAMETER_NOT_SET:
        return None, (f"parameter '{shown_name(name)}': no value (type code {code}, PARAMETER_NOT_SET); a "
                      f"parameter cannot be unset")
    field = _ARRAY_FIELDS.get(code)
    if field is not None:
        n = len(getattr(msg.value, field))
        if n > MAX_ARRAY_LEN:
            return None, (f"parameter '{shown_name(name)}': an array of {n} values is longer than any parameter "
                          f"takes (at most {MAX_ARRAY_LEN})")
    try:
        return Parameter.from_parameter_msg(msg), None
    except Exception as exc:  # noqa: BLE001 - whatever rclpy cannot read is refused, naming the parameter
        return None, f"parameter '{shown_name(name)}': its value cannot be read ({type(exc).__name__}: {exc})"


# --- the wrapped callbacks ------------------------------------------------------------------------

def _refused(reason: str):
    from rcl_interfaces.msg import SetParametersResult
    return SetParametersResult(successful=False, reason=reason)


def _report(service, node, what: str, reason: str) -> None:
    """Count and log (rate-limited) a request refused unread, in the node's ``rejects`` when it has one."""
    rejects = getattr(node, "rejects", None)
    if rejects is None:
        rejects = service.__dict__.get("_mwip_rejects")
        if rejects is None:
            rejects = service.__dict__["_mwip_rejects"] = Rejects(node.get_logger())
    try:
        where = f"{node.get_fully_qualified_name().rstrip('/')}/{what}"
    except Exception:  # noqa: BLE001
        where = what
    try:
        rejects(where, reason)
    except Exception:  # noqa: BLE001 - a report never ends a request
        pass


def _descriptor_types(node, names) -> Dict[str, int]:
    descriptors = getattr(node, "_descriptors", {})
    return {n: descriptors[n].type for n in names if n in descriptors}


def _restore(node, saved: Dict[str, int]) -> None:
    """rclpy's ``_apply_descriptor`` sets a dynamically typed parameter's descriptor type to the type asked
    for before the value is judged; put the old one back when the value was refused."""
    descriptors = getattr(node, "_descriptors", {})
    for name, type_code in saved.items():
        if name in descriptors:
            descriptors[name].type = type_code


def _set(node, params: List[object]):
    """``node.set_parameters_atomically(params)`` that never raises: a refusal names the parameter."""
    from rcl_interfaces.msg import SetParametersResult
    from rclpy.exceptions import ParameterNotDeclaredException

    saved = _descriptor_types(node, [p.name for p in params])
    try:
        result = node.set_parameters_atomically(params)
        if not isinstance(result, SetParametersResult):
            result = _refused(f"the node answered {type(result).__name__}, not a SetParametersResult")
    except ParameterNotDeclaredException as exc:
        result = _refused(str(exc))
    except Exception as exc:  # noqa: BLE001 - a callback that raised: refused, the node goes on
        result = _refused(f"{type(exc).__name__}: {exc}")
    if not result.successful:
        _restore(node, saved)
        if len(params) == 1:
            result.reason = _named(params[0].name, result.reason)
    return result


def _declared(node):
    return getattr(node, "_parameters", None)


def _set_parameters_callback(self, request, response):
    node = self._get_node()
    declared = _declared(node)
    for i, msg in enumerate(request.parameters):
        if i >= MAX_PARAMETERS:
            reason = (f"parameter '{shown_name(msg.name)}': not read (a request may set at most {MAX_PARAMETERS} "
                      f"parameters; it has {len(request.parameters)})")
            if i == MAX_PARAMETERS:
                _report(self, node, "set_parameters", reason)
            response.results.append(_refused(reason))
            continue
        param, reason = parameter_from_msg(msg, declared)
        if reason is not None:
            _report(self, node, "set_parameters", reason)
            response.results.append(_refused(reason))
            continue
        response.results.append(_set(node, [param]))
    return response


def _set_parameters_atomically_callback(self, request, response):
    node = self._get_node()
    declared = _declared(node)
    n = len(request.parameters)
    if n > MAX_PARAMETERS:
        first = shown_name(request.parameters[0].name)
        reason = (f"parameter '{first}' and {n - 1} more: not read (a request may set at most {MAX_PARAMETERS} "
                  f"parameters); nothing was set")
        _report(self, node, "set_parameters_atomically", reason)
        response.result = _refused(reason)
        return response
    params = []
    for msg in request.parameters:
        param, reason = parameter_from_msg(msg, declared)
        if reason is not None:
            reason += "; nothing was set"
            _report(self, node, "set_parameters_atomically", reason)
            response.result = _refused(reason)
            return response
        params.append(param)
    response.result = _set(node, params)
    return response


def _guarded(original, what: str):
    """A read-only service callback that answers an empty response instead of raising."""
    def callback(self, request, response):
        try:
            return original(self, request, response)
        except Exception as exc:  # noqa: BLE001
            try:
                _report(self, self._get_node(), what, f"{type(exc).__name__}: {exc}; answered empty")
            except Exception:  # noqa: BLE001 - no node left to report to
                pass
            return type(response)()
    callback.__name__ = getattr(original, "__name__", what)
    return callback


def installed() -> bool:
    """Whether :func:`install` replaced rclpy's parameter-service callbacks and its /clock callback in this
    process."""
    from rclpy.parameter_service import ParameterService
    return all(getattr(getattr(ParameterService, a, None), "_mwip_guarded", False) for a in _CALLBACKS) \
        and clock_guarded()


def install() -> None:
    """Replace rclpy's parameter-service callbacks (see the module text) and its /clock callback
    (:func:`guard_clock`); idempotent.  Nodes created after this answer with the guarded callbacks
    (rclpy binds them when a node creates its services and its /clock subscription)."""
    from rclpy.parameter_service import ParameterService

    if _state["installed"] and installed():
        return
    check_version()
    guard_clock()
    replacements = {"_set_parameters_callback": lambda _orig: _set_parameters_callback,
                    "_set_parameters_atomically_callback": lambda _orig: _set_parameters_atomically_callback,
                    "_get_parameters_callback": lambda orig: _guarded(orig, "get_parameters"),
                    "_get_parameter_types_callback": lambda orig: _guarded(orig, "get_parameter_types"),
                    "_describe_parameters_callback": lambda orig: _guarded(orig, "describe_parameters"),
                    "_list_parameters_callback": lambda orig: _guarded(orig, "list_parameters")}
    for attr, make in replacements.items():
        original = getattr(ParameterService, attr, None)
        if original is None or getattr(original, "_mwip_guarded", False):
            continue
        replacement = make(original)
        replacement._mwip_guarded = True
        replacement.__wrapped__ = original
        setattr(ParameterService, attr, replacement)
    _state["installed"] = True



# --- inputs the executor never serves ---------------------------------------------------------------

class PolledInput:
    """A subscription that the node reads when it is ready, not when a message arrives: what keeps a flood on a side
    input (``cmd_vel``, ``driver_state``, ``emergency_stop``, ``external_wrench``) from starving the control period.

    rclpy's ``EventsExecutor`` queues one event per message that arrives (asio's first-in first-out queue, the
    timers' events in the same queue), and serves each with the GIL held: 50,000 Twists a second on ``cmd_vel`` put
    the controller's ``joint_states`` behind thousands of events, its commands came late and the realtime robot fell
    (BENCHMARKS.md, "Input floods").  This subscription is made with rclpy's own ``_rclpy.Subscription`` (the DDS
    reader: the graph, the QoS matching and ``get_publisher_count`` are a subscription's) but is not in the node's
    ``subscriptions``, so no executor ever sees it: a flood costs DDS's receive thread only, and the node takes
    at most ``depth`` messages at each :meth:`poll` (the newest ones: keep-last history), so its work per period is
    bounded whatever comes in.

    ``callback(data)`` gets each message's CDR bytes, as a ``raw=True`` subscription's callback does (``depth``: keep
    that many, whatever ``qos`` says); the node calls
    :meth:`poll` where its period is (the controller with each state, the plant between its callbacks) and
    :meth:`destroy` before it is destroyed (``run_node`` does: :func:`destroy_polled_inputs`).  It is listed in
    ``node.polled_inputs`` (:func:`polled_inputs`), where the diagnostics and the tests' node harness find it."""

    raw = True

    def __init__(self, node, msg_type, topic: str, qos, callback: Callable[[bytes], None],
                 depth: Optional[int] = None):
        from copy import copy

        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
        from rclpy.type_support import check_is_valid_msg_type
        check_is_valid_msg_type(msg_type)
        if depth is not None:   # ``qos``'s reliability and durability (the publishers it matches), the newest ``depth``
            qos = copy(qos)
            qos.depth = depth
        c_qos = qos.get_c_qos_profile()
        make = getattr(_rclpy, "Subscription", None)
        if make is None:   # pragma: no cover - another rclpy
            raise RclpyChanged("no _rclpy.Subscription")
        with node.handle:
            self.handle = make(node.handle, msg_type, topic, c_qos)
        self.msg_type, self.qos_profile, self.callback = msg_type, qos, callback
        self.topic_name = self.handle.get_topic_name()
        self.depth = max(1, int(qos.depth or 1))
        self.taken = 0
        _listed(node, self)

    @property
    def topic(self) -> str:
        return self.topic_name

    def get_publisher_count(self) -> int:
        """The publishers this subscription has matched (as ``rclpy.subscription.Subscription``'s)."""
        return self.handle.get_publisher_count()

    def poll(self, limit: Optional[int] = None) -> int:
        """Hand the messages waiting (at most ``limit``, default the QoS depth) to the callback, oldest first;
        returns how many."""
        n, most = 0, self.depth if limit is None else limit
        while n < most:
            got = self.handle.take_message(self.msg_type, True)
            if got is None:
                break
            n += 1
            self.callback(got[0])
        self.taken += n
        return n

    def destroy(self) -> None:
        """The DDS reader destroyed (idempotent)."""
        if self.handle is not None:
            self.handle.destroy_when_not_in_use()
            self.handle = None


def _listed(node, polled: "PolledInput") -> None:
    """``polled`` in ``node.polled_inputs`` (:func:`polled_inputs` reads it)."""
    if not hasattr(node, "polled_inputs"):
        node.polled_inputs = []
    node.polled_inputs.append(polled)


def polled_inputs(node) -> List[PolledInput]:
    """The node's :class:`PolledInput` subscriptions (none: [])."""
    return list(getattr(node, "polled_inputs", ()))


def destroy_polled_inputs(node) -> None:
    """Destroy the node's :class:`PolledInput` subscriptions, before the node itself."""
    for p in polled_inputs(node):
        p.destroy()


def _own_threads() -> set:
    """The ids of this process's threads (Linux: /proc/self/task; elsewhere none)."""
    import os
    try:
        return set(os.listdir("/proc/self/task"))
    except OSError:   # pragma: no cover - not Linux
        return set()


class IsolatedInput(PolledInput):
    """A :class:`PolledInput` on a DDS participant of its own, whose threads (Fast DDS's receive, event and
    discovery threads) run at the lowest priority (nice ``nice``): a flood of *valid* messages on its topic, which
    no content filter can tell from genuine ones, costs the process only CPU that its own loop does not want.

    A :class:`PolledInput` shares its node's participant, and so the receive thread that also carries the node's
    control inputs (the controller's ``joint_states``): 60,000-76,000 valid Twists a second on ``cmd_vel`` cost
    that thread a third of a core and the realtime robot fell (BENCHMARKS.md, "Input floods").  Here the topic has
    a context (rclpy ``Context``: one participant), a node ``<node>_<topic>_reader`` in the node's namespace and
    shared-memory and UDP ports of its own; what the low-priority thread cannot take in time the transport drops
    (best effort).  It is listed in the node's ``polled_inputs`` as a :class:`PolledInput` is."""

    def __init__(self, node, msg_type, topic: str, qos, callback: Callable[[bytes], None],
                 depth: Optional[int] = None, nice: int = 19):
        import os

        import rclpy
        from rclpy.signals import SignalHandlerOptions
        from mwip_ros.nodes.runtime import discovery
        before = _own_threads()
        self.side_context = rclpy.Context()
        discovery.apply()   # as the process's own context has it (its start-up applied it already: no change)
        rclpy.init(args=[], context=self.side_context, domain_id=node.context.get_domain_id(),
                   signal_handler_options=SignalHandlerOptions.NO)
        name = f"{node.get_name()}_{topic.strip('/').replace('/', '_')}_reader"
        self.side_node = rclpy.create_node(name, namespace=node.get_namespace(), context=self.side_context,
                                           start_parameter_services=False, enable_rosout=False,
                                           use_global_arguments=False)
        super().__init__(self.side_node, msg_type, node.resolve_topic_name(topic), qos, callback, depth)
        self.niced, self.nice = 0, nice
        for tid in _own_threads() - before:   # the new participant's threads
            try:
                os.setpriority(os.PRIO_PROCESS, int(tid), max(nice, os.getpriority(os.PRIO_PROCESS, int(tid))))
                self.niced += 1
            except OSError:   # gone, or not allowed: it keeps its priority
                pass
        _listed(node, self)

    def destroy(self) -> None:
        """The DDS reader, its node and its context destroyed (idempotent)."""
        super().destroy()
        if self.side_node is not None:
            self.side_node.destroy_node()
            self.side_node = None
            self.side_context.try_shutdown()
