"""The glibc malloc arena limit a node process sets first (:func:`bound_malloc_arenas`).

Below :mod:`.entry` (which sets it before it imports a node's module: :data:`.entry.NODES`) and :mod:`.process`
(whose ``run_node`` sets it again for a node started as ``python -m mwip_ros.nodes.loop.NODE``), so the node's
module, imported by name from :mod:`.entry`, does not import :mod:`.entry` back.  Imports neither rclpy nor numpy;
importing it changes nothing.
"""
from __future__ import annotations

import ctypes
import os

__all__ = ["M_ARENA_MAX", "bound_malloc_arenas"]

M_ARENA_MAX = -8   # glibc's mallopt() parameter number for the arena limit


def bound_malloc_arenas(arenas: int = 1) -> bool:
    """Let every thread of this process allocate from ``arenas`` glibc malloc arena(s), unless the user set
    ``MALLOC_ARENA_MAX``; True when the limit was set.

    Under a flood of messages Fast DDS's receive threads and the executor allocate and free small
    buffers in turns; with an arena per thread (glibc's default, up to 8 per core) the arenas keep
    their fragments, and an observer's resident memory grew by about 5 MiB per 100,000 messages, for
    as long as the flood lasted.  With one arena it stays flat (``scripts/soak.py``, BENCHMARKS.md).
    glibc keeps the arenas a thread made before the limit: call this before any thread allocates
    (before rclpy is imported).  No effect on a C library without ``mallopt``.
    """
    if os.environ.get("MALLOC_ARENA_MAX"):
        return False
    try:
        return bool(ctypes.CDLL(None).mallopt(M_ARENA_MAX, arenas))
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        return False
