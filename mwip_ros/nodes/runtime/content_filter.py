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
"""
from __future__ import annotations

import ctypes
from typing import Dict, Optional, Tuple

__all__ = ["set_content_filter", "filter_readers"]

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


def set_content_filter(subscription, expression: str) -> Optional[str]:
    """Filter ``subscription`` (an rclpy Subscription) by the DDS-SQL ``expression``; None when the middleware
    filters, else why not (the subscription is then unfiltered)."""
    try:
        rcl, rcutils = _library()
        handle = subscription.handle
        with handle:
            ptr = handle.pointer
            options = ctypes.create_string_buffer(_OPTIONS_BYTES)
            argv = (ctypes.c_char_p * 1)()
            ret = rcl.rcl_subscription_content_filter_options_init(ptr, expression.encode(), 0, argv, options)
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


def filter_readers(log, readers: Dict[str, Tuple[object, str]], dropped: str) -> bool:
    """A content filter on each reader ``{topic: (subscription, expression)}``, and the one line a node logs of it:
    a warning naming why when the middleware does not filter one of them (then every message reaches the node's
    parser), else ``content filter on TOPICS: DROPPED is dropped by DDS and not counted``. Whether all are filtered."""
    why = [f"{t}: {w}" for t, (sub, expression) in readers.items() if (w := set_content_filter(sub, expression))]
    topics = " and ".join(readers)
    if why:
        log.warning(f"no content filter ({'; '.join(why)}): every message on {topics} reaches the parser")
        return False
    log.info(f"content filter on {topics}: {dropped} is dropped by DDS and not counted")
    return True
