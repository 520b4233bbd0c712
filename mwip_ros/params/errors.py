"""The parameter layer's error: a bad parameter file, override or value, naming the key."""
from __future__ import annotations

from typing import Optional

__all__ = ["ParamError", "MAX_REASON", "bounded"]

MAX_REASON = 600   # characters of an error's reason: a value's repr in it never makes a message of megabytes


def bounded(text: str, limit: int = MAX_REASON) -> str:
    """``text`` on one line, cut to ``limit`` characters (an elided middle says how much was left out)."""
    text = " ".join(str(text).splitlines())
    if len(text) <= limit:
        return text
    keep = limit - 40
    return f"{text[:keep]} ...[{len(text) - keep - 20:,} characters]... {text[-20:]}"


class ParamError(ValueError):
    """A bad parameter file, override or value; ``key`` names the offending parameter."""

    def __init__(self, key: str, message: str, source: Optional[str] = None):
        self.key = key
        self.reason = message = bounded(message)
        self.source = source
        where = f"{source}: " if source else ""
        super().__init__(f"{where}parameter '{key}': {message}")
