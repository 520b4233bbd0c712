"""Stamps: integer nanoseconds <-> ``builtin_interfaces/Time`` (sec, nanosec), in one place.

The graph keeps time as integer nanoseconds (state k is stamped ``k * period_ns``); a
``Time`` is ``int32 sec`` and ``uint32 nanosec`` with ``0 <= nanosec < 1e9``.
"""
from __future__ import annotations

from typing import Tuple

from .errors import CdrError

__all__ = ["NS_PER_S", "split_ns", "join_ns", "to_time", "stamp_ns"]

NS_PER_S = 1_000_000_000
_INT32_MIN, _INT32_MAX = -(2 ** 31), 2 ** 31 - 1


def split_ns(ns: int) -> Tuple[int, int]:
    """(sec, nanosec) of a ``Time``; raises CdrError when the seconds do not fit an int32."""
    sec, nsec = divmod(int(ns), NS_PER_S)
    if not _INT32_MIN <= sec <= _INT32_MAX:
        raise CdrError(f"time {ns} ns does not fit builtin_interfaces/Time (int32 seconds)")
    return sec, nsec


def join_ns(sec: int, nanosec: int) -> int:
    """Nanoseconds of a (sec, nanosec) pair."""
    return int(sec) * NS_PER_S + int(nanosec)


def to_time(ns: int):
    """A ``builtin_interfaces.msg.Time`` message for ``ns``."""
    from builtin_interfaces.msg import Time
    sec, nsec = split_ns(ns)
    return Time(sec=sec, nanosec=nsec)


def stamp_ns(t) -> int:
    """Nanoseconds of a ``Time`` message (or anything with ``sec`` and ``nanosec``)."""
    return join_ns(t.sec, t.nanosec)
