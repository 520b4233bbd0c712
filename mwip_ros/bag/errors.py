"""The one exception of the bag layer.

Every function in :mod:`mwip_ros.bag` that cannot write, read or repair a bag raises
:class:`BagError`; its message names the file, topic or type at fault.  It derives from
``ValueError`` so that callers which only know "bad input" still catch it.
"""
from __future__ import annotations

__all__ = ["BagError"]


class BagError(ValueError):
    """A bag cannot be written, read or repaired; the message says what and where."""
