"""A test's own rclpy node on a Graph's domain: raw publishers and recording subscribers.

    with Injector(graph.domain_id) as inj:
        js = inj.publisher("joint_states", JointState)
        got = inj.record("disturbance_estimate", WrenchStamped)   # list of raw payloads, appended as they come
        inj.wait(lambda: js.get_subscription_count() >= 2, 20)
        js.publish(data)
"""
import time
from typing import Callable, List

from mwip_ros.msgs.qos import GRAPH_QOS


class Injector:
    def __init__(self, domain_id: int, name: str = "test_injector"):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.ctx)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)

    def publisher(self, topic: str, msg_type, qos=GRAPH_QOS):
        return self.node.create_publisher(msg_type, topic, qos)

    def record(self, topic: str, msg_type) -> List[bytes]:
        got: List[bytes] = []
        self.node.create_subscription(msg_type, topic, lambda data: got.append(bytes(data)), GRAPH_QOS, raw=True)
        return got

    def wait(self, cond: Callable[[], bool], timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if cond():
                return True
            self.ex.spin_once(timeout_sec=0.01)
        return cond()

    def spin(self, seconds: float) -> None:
        self.wait(lambda: False, seconds)

    def close(self) -> None:
        import rclpy
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def rejected_counts(summary: str) -> dict:
    """{topic: rejected messages} from a node's ``Rejects.summary()`` text ('/clock: 2, joint_states: 5')."""
    from mwip_ros.nodes.runtime.diagnostics import topic_counts
    return topic_counts(summary)


def plant_rejected(output: str) -> dict:
    """{topic: rejected messages} from plant_sim's closing 'rejected messages: ...' line."""
    return rejected_counts(output.split("rejected messages: ")[1].splitlines()[0])


def health(inj) -> dict:
    """{node name: (its clock's seconds, {topic: rejected messages}, {resolved topic: publishers matched})} from the
    latest /diagnostics of each node (a report every wall second), updated as the injector spins."""
    from diagnostic_msgs.msg import DiagnosticArray

    from mwip_ros.nodes.runtime.diagnostics import topic_counts
    latest = {}

    def take(arr):
        for st in arr.status:
            values = {kv.key: kv.value for kv in st.values}
            latest[st.name] = (arr.header.stamp.sec, rejected_counts(values.get("rejected_by_topic", "")),
                               topic_counts(values.get("publishers_by_topic", "")))
    inj.node.create_subscription(DiagnosticArray, "/diagnostics", take, 100)
    return latest


def wait_matched(inj, latest: dict, node: str, publishers: dict, timeout: float = 30.0) -> bool:
    """Wait until ``node``'s /diagnostics (``latest``, :func:`health`) say that its subscription on each topic has
    matched at least as many publishers as ``publishers`` ({resolved topic: n}) gives: a reader loses what a
    publisher sends before the reader has matched it, even when the publisher already counts the reader (its
    ``get_subscription_count()``), so a test that sends a message once waits for this first."""
    def matched():
        counts = latest.get(node, (0, {}, {}))[2]
        return all(counts.get(t, 0) >= n for t, n in publishers.items())
    return inj.wait(matched, timeout)


def controller_publishers(diags, topic: str) -> int:
    """The newest count of publishers the dscndo_controller's subscription on ``topic`` (resolved) has matched, from
    its /diagnostics' ``publishers_by_topic`` among ``diags`` (-1: no report yet)."""
    from mwip_ros.nodes.runtime.diagnostics import topic_counts
    vals = [topic_counts(kv.value).get(topic, 0) for d in diags for s in d.status if "dscndo_controller" in s.name
            for kv in s.values if kv.key == "publishers_by_topic"]
    return vals[-1] if vals else -1


def controller_value(diags, key) -> int:
    """The newest value of ``key`` on the dscndo_controller's /diagnostics status among ``diags`` (the
    DiagnosticArray messages received; -1: none yet)."""
    vals = [kv.value for d in diags for s in d.status if "dscndo_controller" in s.name for kv in s.values
            if kv.key == key]
    return int(vals[-1]) if vals else -1


def publish_until(inj, pub, data, done: Callable[[], bool], timeout: float = 30.0, every: float = 2.5) -> bool:
    """Publish ``data``, again each ``every`` s (a best-effort reader or a history of one may drop it), until
    ``done()`` (what the receiving node reports, e.g. on /diagnostics, a report each second)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        pub.publish(data)
        if inj.wait(done, every):
            return True
    return False


def call_until_answered(inj, client, make_request: Callable, timeout: float = 60.0,
                        gone: Callable[[], bool] = lambda: False):
    """(The first answer, the calls sent): ``make_request()`` sent to ``client`` again each second until one is
    answered (:func:`mwip_ros.nodes.runtime.services.call_until_answered`), or ``gone()`` (the server's process
    ended: the answer is then None). For a first call whose repetition does what one does (a no-op: an empty
    SetParameters, a reset at the initial state), so that a client's later, real calls are sent once: a new
    client's first answer can be lost (that module's docstring)."""
    from mwip_ros.nodes.runtime import services
    call = services.call_until_answered(inj.wait, client, make_request, timeout, gone=gone)
    assert call.answer is not None or gone(), \
        f"none of {call.sent} calls to {client.srv_name} answered in {timeout:g} s"
    return call.answer, call.sent


class ParamSetter:
    """Parameter changes through ``/<node>/set_parameters`` from ``inj``'s node, one client a node: its path shown to
    work first by an empty request (:func:`call_until_answered`: a no-op), so every real change is sent once.

        params = ParamSetter(inj)
        result = params.set("dscndo_controller", "k1", 7.0)   # rcl_interfaces/SetParametersResult
    """

    def __init__(self, inj, timeout: float = 30.0):
        self.inj, self.timeout, self.clients = inj, timeout, {}

    def client(self, target: str):
        from rcl_interfaces.srv import SetParameters
        if target not in self.clients:
            client = self.inj.node.create_client(SetParameters, f"/{target}/set_parameters")
            assert client.wait_for_service(timeout_sec=self.timeout), f"no /{target}/set_parameters"
            call_until_answered(self.inj, client, SetParameters.Request)   # no parameters: nothing changes
            self.clients[target] = client
        return self.clients[target]

    def set(self, target: str, name: str, value):
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter
        future = self.client(target).call_async(
            SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()]))
        assert self.inj.wait(future.done, self.timeout), f"no answer from /{target}/set_parameters ({name})"
        return future.result().results[0]


def publish_until_rejected(inj, latest: dict, node: str, topic: str, pub, data, timeout: float = 30.0) -> bool:
    """Publish ``data`` (:func:`publish_until`) until ``node``'s /diagnostics count one more rejection on
    ``topic``."""
    def count():
        return latest.get(node, (0, {}))[1].get(topic, 0)
    assert inj.wait(lambda: node in latest, timeout), f"no /diagnostics from {node}"
    before = count()
    return publish_until(inj, pub, data, lambda: count() > before, timeout)


def rss_mib(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


def flood(inj, js, n: int, big: int = 60) -> int:
    """Publish ``n`` hostile joint_states of ever new layouts (and ``big`` with 1 MiB names); returns how many.

    Paced by acknowledgements every 500 messages (the reliable history keeps 1000)."""
    import math

    from rclpy.duration import Duration

    from mwip_ros.msgs import cdr
    sent = 0
    for i in range(big):
        enc = cdr.JointStateEncoder(("w" * (1 << 20) + str(i), "body_pitch"))
        js.publish(enc(i, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0)))
        sent += 1
        assert js.wait_for_all_acked(Duration(seconds=30))
    for i in range(n):
        names = ("wheel", "body_pitch" + "x" * (i % 900))  # a new layout for the template cache, every time
        data = cdr.JointStateEncoder(names)(10 ** 9 + i, (0.0, 0.0), (0.0, math.nan), (0.0, 0.0))
        js.publish(data if i % 3 else data[: 20 + i % 50])
        sent += 1
        if i % 500 == 499:  # reliable, keep last 1000: let the reader take them before the history wraps
            assert js.wait_for_all_acked(Duration(seconds=30))
    return sent
