"""A parameter's specification (:class:`ParamSpec`): the one piece every module of this package that lists
parameters shares.

:mod:`.schema` lists every node's parameters with it, and so do the small modules it gathers them from
(:mod:`.ground`, :mod:`.motion`, :mod:`.upkie`, :mod:`.driver`): they import it from here, below the schema, so
the schema imports them and none of them the schema.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional

from .errors import ParamError

__all__ = ["ParamSpec", "INT32_MAX", "HI_WHY"]

INT32_MAX = 2 ** 31 - 1   # the top of an integer parameter's descriptor range when it has no ``hi``
HI_WHY = "far beyond any robot of this kind"


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: dotted name, ROS type, default, description, its range or choices, run-time changeable.

    The accepted values are data: ``lo``/``hi`` (``lo_open``: lo < v; else lo <= v; v <= hi), ``floor`` (a
    smallest value above an open ``lo``, with ``floor_why``), ``choices``; ``rule`` checks what is not a range
    (an array's shape), ``words`` says it (and replaces an integer range's words).  :attr:`check` (start-up
    and run-time values), the ROS descriptor and the ``--help`` text are derived from them."""

    name: str
    type: str  # 'double' | 'integer' | 'bool' | 'string' | 'double_array' | 'string_array'
    default: Any
    description: str
    lo: Optional[float] = None
    hi: Optional[float] = None
    lo_open: bool = False
    floor: Optional[float] = None
    floor_why: str = ""
    hi_why: str = HI_WHY     # a double's refusal above ``hi`` says why ('' says nothing)
    choices: Optional[tuple] = None
    rule: Optional[Callable[[Any], Optional[str]]] = None
    words: str = ""
    dynamic: bool = False
    unit: str = ""

    def range_reason(self, v: Any) -> Optional[str]:
        """None when ``v`` (of the right type) is within the range and choices, else the reason."""
        if self.choices is not None:
            return None if v in self.choices else f"must be one of {', '.join(map(repr, self.choices))}, got {v!r}"
        lo, hi = self.lo, self.hi
        if self.type == "integer":
            if (lo is None or v >= lo) and (hi is None or v <= hi):
                return None
            if self.words:
                return f"must be {self.words}, got {v!r}"
            if hi is None:
                return f"must be >= {lo}, got {v!r}"
            if lo is None:
                return f"must be <= {hi}, got {v!r}"
            return f"must be a whole number from {lo} to {hi}, got {v!r}"
        if self.type == "double":
            if lo is not None and self.lo_open and not v > lo:
                return f"must be > {lo:g}, got {v!r}"
            if lo is not None and not self.lo_open and not v >= lo:
                return f"must be >= {lo:g}, got {v!r}"
            if self.floor is not None and v < self.floor:
                return f"must be >= {self.floor:g} ({self.floor_why}), got {v!r}"
            if hi is not None and not v <= hi:
                return f"must be <= {hi:g}{f' ({self.hi_why})' if self.hi_why else ''}, got {v!r}"
        return None

    def check(self, v: Any) -> Optional[str]:
        """None when ``v`` (of the right type) is accepted, else the reason (the range, then the rule)."""
        return self.range_reason(v) or (self.rule(v) if self.rule is not None else None)

    def validate(self, value: Any, key: Optional[str] = None, source: Optional[str] = None) -> Any:
        """Return the value (arrays as lists) or raise ParamError naming ``key``."""
        key = key or self.name
        reason = _type_error(self.type, value)
        if reason:
            raise ParamError(key, reason, source)
        if self.type in ("double", "double_array"):
            vals = value if self.type == "double_array" else [value]
            if not all(math.isfinite(x) for x in vals):
                raise ParamError(key, f"must be finite, got {value!r}", source)
        if self.type.endswith("_array"):
            value = list(value)
        reason = self.check(value)
        if reason:
            raise ParamError(key, reason, source)
        return value


def _type_error(kind: str, v: Any) -> Optional[str]:
    def is_int(x):
        return isinstance(x, int) and not isinstance(x, bool)

    if kind == "double":
        if is_int(v):
            return f"expected a floating-point number (write {v}.0 - ROS 2 reads {v} as an integer)"
        return None if isinstance(v, float) else f"expected a floating-point number, got {type(v).__name__} {v!r}"
    if kind == "integer":
        return None if is_int(v) else f"expected an integer, got {type(v).__name__} {v!r}"
    if kind == "bool":
        return None if isinstance(v, bool) else f"expected true or false, got {type(v).__name__} {v!r}"
    if kind == "string":
        return None if isinstance(v, str) else f"expected a string, got {type(v).__name__} {v!r}"
    if kind == "double_array":
        if not isinstance(v, (list, tuple)) or not all(isinstance(x, float) for x in v):
            return f"expected a list of floating-point numbers (e.g. [100.0, 0.0]), got {v!r}"
        return None
    if kind == "string_array":
        if not isinstance(v, (list, tuple)) or not all(isinstance(x, str) for x in v):
            return f"expected a list of strings, got {v!r}"
        return None
    raise AssertionError(kind)
