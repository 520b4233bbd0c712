"""runtime.services.Answered: a request sent again until one answer comes, the unanswered ones then let go."""
import pytest
from rclpy.task import Future

from mwip_ros.nodes.runtime.services import Answered, call_until_answered, prove_reply_paths

pytestmark = pytest.mark.unit


class _Client:
    """A client whose answers the test gives: each call's future, kept in order; what was let go."""

    srv_name = "/plant_sim/reset"

    def __init__(self):
        self.futures, self.requests, self.removed = [], [], []

    def call_async(self, request):
        self.requests.append(request)
        self.futures.append(Future())
        return self.futures[-1]

    def remove_pending_request(self, future):
        self.removed.append(future)


def test_sent_again_when_due_until_an_answer_then_the_first_answer_and_nothing_more():
    client = _Client()
    made = iter(range(100))
    call = Answered(client, lambda: next(made), every=0.0)   # due again at every poll
    assert call.sent == 1 and client.requests == [0] and call.poll() is None
    assert call.sent == 2 and call.poll() is None and call.sent == 3
    assert client.requests == [0, 1, 2]   # a fresh request each time
    client.futures[1].set_result("second")
    assert call.poll() == "second" and call.answer == "second"
    assert client.removed == [client.futures[0], client.futures[2]]   # the others let go
    client.futures[0].set_result("late")
    assert call.poll() == "second" and call.sent == 3 and len(client.futures) == 3


def test_not_sent_again_before_it_is_due():
    client = _Client()
    call = Answered(client, object, every=3600.0)
    assert [call.poll() for _ in range(5)] == [None] * 5 and call.sent == 1
    client.futures[0].set_result("ok")
    assert call.poll() == "ok" and client.removed == [] and 0.0 <= call.waited() < 3600.0


def test_call_until_answered_spins_until_the_answer_or_gives_none():
    client = _Client()

    def until(done, timeout):   # the third send is answered
        for _ in range(10):
            if done():
                return True
            if len(client.futures) == 3:
                client.futures[2].set_result("third")
        return done()
    call = call_until_answered(until, client, object, timeout=1.0, every=0.0)
    assert call.answer == "third" and call.sent == 3
    silent = _Client()
    assert call_until_answered(lambda done, timeout: done(), silent, object, timeout=1.0, every=3600.0).answer is None
    assert len(silent.requests) == 1
    ended = _Client()   # the server gone: no answer awaited, none sent again
    assert call_until_answered(lambda done, timeout: done(), ended, object, timeout=1.0, every=0.0,
                               gone=lambda: True).answer is None


class _Node:
    """A node whose clients are :class:`_Client` (ready or not); the order they were made and destroyed in."""

    def __init__(self, ready=True):
        self.ready, self.made, self.destroyed = ready, [], []

    def resolve_service_name(self, name):
        return "/" + name.lstrip("/")

    def create_client(self, srv_type, name):
        client = _Client()
        client.srv_type, client.srv_name = srv_type, name
        client.service_is_ready = lambda: self.ready
        self.made.append(client)
        return client

    def destroy_client(self, client):
        self.destroyed.append(client)


def _spin(answer_at: int, clients):
    """An ``until`` that answers the ``answer_at``-th request of the last client made (0: never)."""
    def until(done, timeout):
        for _ in range(20):
            if done():
                return True
            client = clients[-1]
            if answer_at and len(client.futures) >= answer_at and not client.futures[answer_at - 1].done():
                client.futures[answer_at - 1].set_result("values")
        return done()
    return until


def test_prove_reply_paths_asks_the_servers_get_parameters_with_a_new_client_until_answered_then_destroys_it():
    from rcl_interfaces.srv import GetParameters
    node = _Node()
    proof = prove_reply_paths(_spin(2, node.made), node, "plant_sim", timeout=1.0, every=0.0)
    (client,) = node.made
    assert client.srv_type is GetParameters and client.srv_name == "/plant_sim/get_parameters"
    assert proof.answer == "values" and proof.sent == 2 and node.destroyed == [client]
    assert all(isinstance(r, GetParameters.Request) and not r.names for r in client.requests)   # reads nothing
    silent = _Node()
    assert prove_reply_paths(_spin(0, silent.made), silent, "plant_sim", timeout=1.0, every=3600.0).answer is None
    absent = _Node(ready=False)   # no parameter service: nothing sent, None
    assert prove_reply_paths(_spin(1, absent.made), absent, "plant_sim", timeout=1.0) is None
    assert absent.made[0].requests == [] and absent.destroyed == absent.made


def test_mwip_ctl_sends_a_trigger_once_and_only_after_a_get_parameters_client_made_after_it_was_answered():
    """The order that makes the Trigger's answer arrive: its client first, then the proof's client answered, then
    the Trigger once; no proof, no Trigger (a one-line failure naming the node)."""
    from std_srvs.srv import Trigger

    from mwip_ros.cli.ctl import Failure, Ros
    events = []

    class Node(_Node):
        def create_client(self, srv_type, name):
            client = super().create_client(srv_type, name)
            events.append(("made", name))
            sent = client.call_async

            def call_async(request, _name=name, _sent=sent):
                events.append(("sent", _name))
                future = _sent(request)
                future.set_result(f"answer of {_name}")   # answered at once
                return future
            client.call_async = call_async
            return client

    ros = Ros.__new__(Ros)
    ros.node, ros.timeout = Node(), 1.0
    ros.until = lambda done, timeout: done()
    assert ros.call(Trigger, "plant_sim", "reset", Trigger.Request()) == "answer of /plant_sim/reset"
    assert events == [("made", "/plant_sim/reset"), ("made", "/plant_sim/get_parameters"),
                      ("sent", "/plant_sim/get_parameters"), ("sent", "/plant_sim/reset")]
    events.clear()

    class Silent(Node):   # the get_parameters service found, but never answering
        def create_client(self, srv_type, name):
            client = _Node.create_client(self, srv_type, name)
            events.append(("made", name))
            return client
    ros.node = Silent()
    with pytest.raises(Failure, match="plant_sim did not answer get_parameters within 1 s, so /plant_sim/enable "
                                      "was not called"):
        ros.call(Trigger, "plant_sim", "enable", Trigger.Request())
    assert [name for what, name in events if what == "made"] == ["/plant_sim/enable", "/plant_sim/get_parameters"]
    assert ros.node.made[0].requests == []   # the Trigger never sent
