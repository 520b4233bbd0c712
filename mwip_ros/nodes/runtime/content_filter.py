"""A DDS content filter on a subscription: the middleware drops what fails it before the reader's queue.

rclpy 7 (Jazzy) does not expose rcl's content-filtered topics, so this calls rcl's C functions
(``rcl_subscription_content_filter_options_init``, ``rcl_subscription_set_content_filter``,
``rcl_subscription_is_cft_enabled``) on the subscription's own ``rcl_subscription_t`` through ctypes.  The
expression is DDS-SQL (the raw topics': :data:`mwip_ros.msgs.layouts.RAW_FILTERS`).  With rmw_fastrtps the
reader evaluates it on each sample as it arrives (and a writer that learnt it in discovery before sending), in
C++: a sample that fails, or cannot be deserialized, never takes a place in the history, and no callback runs
for it, so it is not counted either.  An rmw without content filtering (or a failing call) leaves the
subscription unfiltered: :func:`set_content_filter` then says why, and the node's own checks still judge
every message.

:class:`StampBound` keeps an expression's parameter ``%0`` (a stamp's bound, in whole seconds) moving with a stream:
the realtime observer's and controller's ``joint_states`` and ``disturbance_estimate`` readers
(:data:`mwip_ros.msgs.layouts.STATE_FILTER`), so that a flood of far-future stamps is dropped by the writer's
middleware (Fast DDS learns a reader's new parameters in discovery) instead of costing the control loop a look each.
"""
from __future__ import annotations

import ctypes
import math
from typing import Dict, Optional, Sequence, Tuple

__all__ = ["set_content_filter", "StampBound", "NO_BOUND"]

NO_BOUND = 2 ** 31 - 1   # header.stamp.sec is an int32: no stamp reaches it

_OPTIONS_BYTES = 256   # rcl_subscription_content_filter_options_t: 64 bytes on 64-bit Jazzy; zeroed, room to spare
_rcl = None


def _library():
    global _rcl
    if _rcl is None:
        lib = ctypes.CDLL("librcl.so")   # the one rclpy loaded (dlopen finds it by its soname)
        lib.rcl_subscription_content_filter_options_init.argtypes = [
            ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t, ctypes.POINTER(ctypes.c_char_p), ctypes.c_void_p]
        lib.rcl_subscription_set_content_filter.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        lib.rcl_subscription_content_filter_options_fini.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        lib.rcl_subscription_is_cft_enabled.argtypes = [ctypes.c_void_p]
        lib.rcl_subscription_is_cft_enabled.restype = ctypes.c_bool
        _rcl = lib, ctypes.CDLL("librcutils.so")   # rcl_reset_error is rcutils_reset_error
    return _rcl


def set_content_filter(subscription, expression: str, parameters: Sequence[str] = ()) -> Optional[str]:
    """Filter ``subscription`` (an rclpy Subscription) by the DDS-SQL ``expression``.

    Parameters
    ----------
    subscription : rclpy.subscription.Subscription
        The reader to filter (again: a later call replaces its filter, or only its parameters).
    expression : str
        DDS-SQL; ``%0``, ``%1``, ... stand for ``parameters``.
    parameters : sequence of str
        The expression's parameters, as DDS-SQL literals.

    Returns
    -------
    str or None
        None when the middleware filters, else why not (the subscription is then unfiltered).
    """
    try:
        rcl, rcutils = _library()
        handle = subscription.handle
        with handle:
            ptr = handle.pointer
            options = ctypes.create_string_buffer(_OPTIONS_BYTES)
            argv = (ctypes.c_char_p * max(1, len(parameters)))(*[p.encode() for p in parameters])
            ret = rcl.rcl_subscription_content_filter_options_init(ptr, expression.encode(), len(parameters), argv,
                                                                   options)
            if ret != 0:
                rcutils.rcutils_reset_error()
                return f"rcl could not take the filter expression (rcl_ret {ret})"
            ret = rcl.rcl_subscription_set_content_filter(ptr, options)
            rcl.rcl_subscription_content_filter_options_fini(ptr, options)
            if ret != 0:
                rcutils.rcutils_reset_error()
                return f"the middleware does not filter (rcl_ret {ret})"
            if not rcl.rcl_subscription_is_cft_enabled(ptr):
                return "the middleware took the filter but does not apply it"
    except (OSError, AttributeError) as exc:
        return f"rcl's content filter is not reachable ({exc})"
    return None


class StampBound:
    """A moving bound ``%0`` on the stamps a stream's readers take (``header.stamp.sec < %0``), set on each reader.

    Before the stream's first stamp there is no bound (:data:`NO_BOUND`). After it, the bound is the stream's newest
    stamp plus the StampGuard's window, plus the seconds the stream has been silent (a realtime publisher that was
    paused comes back with stamps that far ahead, which its StampGuard takes as a restart), plus :attr:`SLACK_S`,
    rounded up to a whole second: it moves once a second of the stream's time or of silence, and each move is one
    discovery announcement per reader.

    Parameters
    ----------
    readers : dict
        ``{topic: (subscription, expression)}``, each expression with the parameter ``%0`` (``layouts.STAMP_BOUND``).
    window_ns : int
        How far a stamp may lead the stream's newest one (the StampGuard's window) [ns].
    """

    SLACK_S = 2   # [s] beyond the window: the readers' new bound takes a discovery round to reach the writers

    def __init__(self, readers: Dict[str, Tuple[object, str]], window_ns: int):
        self.readers, self.window_ns = readers, int(window_ns)
        self.bound = NO_BOUND
        self.moves = 0
        why = {t: set_content_filter(s, e, [str(NO_BOUND)]) for t, (s, e) in readers.items()}
        self.unfiltered = {t: w for t, w in why.items() if w}   # topic -> why the middleware does not filter it

    def bound_for(self, newest_ns: Optional[int], silent_s: float) -> int:
        """The bound [s] for a stream whose newest stamp is ``newest_ns`` (None: none yet) and that has been silent
        for ``silent_s`` seconds."""
        if newest_ns is None:
            return NO_BOUND
        return min(NO_BOUND, math.floor((newest_ns + self.window_ns) * 1e-9 + max(0.0, silent_s)) + 1 + self.SLACK_S)

    def follow(self, newest_ns: Optional[int], silent_s: float) -> bool:
        """Move the bound to :meth:`bound_for` on every reader if it changed (True then)."""
        bound = self.bound_for(newest_ns, silent_s)
        if bound == self.bound or self.unfiltered:
            return False
        for topic, (sub, expression) in self.readers.items():
            why = set_content_filter(sub, expression, [str(bound)])
            if why:
                self.unfiltered[topic] = why
        self.bound = bound
        self.moves += 1
        return True
