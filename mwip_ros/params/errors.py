"""The parameter layer's error: a bad parameter file, override or value, naming the key."""
from __future__ import annotations

from typing import Optional

__all__ = ["ParamError"]


class ParamError(ValueError):
    """A bad parameter file, override or value; ``key`` names the offending parameter."""

    def __init__(self, key: str, message: str, source: Optional[str] = None):
        self.key = key
        self.reason = message
        self.source = source
        where = f"{source}: " if source else ""
        super().__init__(f"{where}parameter '{key}': {message}")
