"""A service call whose answer may be lost: the request sent again until one answer comes.

A service found (``Client.wait_for_service``, ``service_is_ready``) does not mean that its answer can reach the
client yet. The server's reply writer matches the client's reply reader on its own, once the server has discovered
that reader; until then rmw_fastrtps waits up to its writers' ``max_blocking_time`` (100 ms) and drops the reply
(the server warns "failed to send response ... client will not receive response"). On a loaded machine, or when a
discovery packet is lost, the first call of a new client can thus go unanswered. Once one answer has come, the path
works for good.

:class:`Answered` is for a call whose repetition does what one call does: a read (``get_parameters``), or a
no-op sent first to show that the path works (an empty ``SetParameters`` request: no parameter changes), after
which the real, non-repeatable call is sent once. It does not block: :meth:`Answered.poll` between callbacks (a
node's loop) or inside a spin loop's condition (:func:`call_until_answered`).
"""
from __future__ import annotations

import time
from typing import Callable, Optional

__all__ = ["Answered", "RESEND_S", "call_until_answered", "prove_reply_paths"]

RESEND_S = 1.0   # [s] between two sends of the same request: ten times rmw_fastrtps' 100 ms


class Answered:
    """``make_request()`` sent to ``client`` now and again each ``every`` s (at :meth:`poll`) until one is answered.

    ``answer`` is the first answer (None before), ``sent`` the requests sent. The requests left unanswered are
    removed from the client once one is answered (a late answer to them is dropped, nothing is kept)."""

    def __init__(self, client, make_request: Callable[[], object], every: float = RESEND_S):
        self.client, self.make_request, self.every = client, make_request, every
        self.started = time.monotonic()
        self.answer = None
        self.sent = 0
        self._futures = []
        self._send()

    def _send(self) -> None:
        self._futures.append(self.client.call_async(self.make_request()))
        self.sent += 1
        self._last = time.monotonic()

    def poll(self) -> Optional[object]:
        """The first answer once one has come (then always it), else None, after sending the request again when
        ``every`` s have passed since the last send."""
        if self.answer is None:
            done = next((f for f in self._futures if f.done()), None)
            if done is not None:
                self.answer = done.result()
                for f in self._futures:
                    if f is not done and not f.done():
                        self.client.remove_pending_request(f)
                self._futures = []
            elif time.monotonic() - self._last >= self.every:
                self._send()
        return self.answer

    def waited(self) -> float:
        """Seconds since the first send."""
        return time.monotonic() - self.started


def call_until_answered(until: Callable[[Callable[[], bool], float], bool], client, make_request,
                        timeout: float, every: float = RESEND_S,
                        gone: Callable[[], bool] = lambda: False) -> Answered:
    """:class:`Answered`, spun until it has its answer (``.answer``, None when none came), ``timeout`` s passed or
    ``gone()`` (the server's process ended); ``until(done, timeout)`` spins the client's node until ``done()`` or
    the timeout (e.g. ``mwip_ctl``'s ``Ros.until``, a test's ``Injector.wait``)."""
    call = Answered(client, make_request, every)
    until(lambda: call.poll() is not None or gone(), timeout)
    return call


def prove_reply_paths(until: Callable[[Callable[[], bool], float], bool], node, server: str, timeout: float,
                      every: float = RESEND_S, gone: Callable[[], bool] = lambda: False) -> Optional[Answered]:
    """Show that node ``server`` (its name, relative to ``node``'s namespace or absolute) can answer every client
    ``node`` made before this call: :func:`call_until_answered` with a new ``rcl_interfaces/GetParameters`` client of
    ``server``'s (a read: an empty request), destroyed after; its :class:`Answered` (``.answer`` None: no answer
    within ``timeout`` s), or None when ``server`` has no parameter service within ``timeout`` s (the module's
    docstring says why an answer proves the earlier clients' paths)."""
    from rcl_interfaces.srv import GetParameters
    client = node.create_client(GetParameters, node.resolve_service_name(f"{server}/get_parameters"))
    try:
        end = time.monotonic() + timeout
        if not until(lambda: client.service_is_ready() or gone(), timeout) or gone():
            return None
        return call_until_answered(until, client, GetParameters.Request, max(0.0, end - time.monotonic()), every,
                                   gone)
    finally:
        node.destroy_client(client)
