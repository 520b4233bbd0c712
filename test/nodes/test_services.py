"""runtime.services.Answered: a request sent again until one answer comes, the unanswered ones then let go."""
import pytest
from rclpy.task import Future

from mwip_ros.nodes.runtime.services import Answered, call_until_answered

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
