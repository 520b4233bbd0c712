"""A computed number against its printed digits, on every CPU.

A number the code computes differs in its last bits between machines (another BLAS or SIMD path, another order of a
sum); printed to a few digits it reads the same, except where it lies on a rounding boundary, where either neighbour
is right. :func:`as_printed` gives every way the number may be printed, so a test compares the printed cell with them:
an edited digit still fails, a CPU's rounding does not. A number that is rounding noise itself (1e-16) is no digit to
compare: give its bound instead.
"""
from __future__ import annotations

from typing import Set

__all__ = ["REL", "as_printed", "prints_as"]

REL = 1e-9   # the relative difference a computed number may carry between CPUs (far above double rounding)


def as_printed(value: float, fmt: str, rel: float = REL) -> Set[str]:
    """``format(value, fmt)`` for ``value`` and for its neighbours ``value * (1 -+ rel)``."""
    return {format(value * (1.0 + s * rel), fmt) for s in (-1.0, 0.0, 1.0)}


def prints_as(cell: str, value: float, fmt: str, rel: float = REL) -> bool:
    """Whether the printed ``cell`` is ``value`` printed with ``fmt`` on some CPU (:func:`as_printed`)."""
    return cell in as_printed(value, fmt, rel)
