"""Re-simulated outputs against recorded ones: the largest absolute difference, compared and missing samples."""
from __future__ import annotations

import math
from typing import Dict

__all__ = ["Stat", "diff", "compare_stamped"]


def diff(a: float, b: float) -> float:
    if math.isnan(a) and math.isnan(b):
        return 0.0
    if a == b:  # also equal infinities
        return 0.0
    d = abs(a - b)
    return math.inf if math.isnan(d) else d


class Stat:
    """Largest absolute difference and the number of compared / not reproduced samples."""

    def __init__(self):
        self.compared = 0
        self.missing = 0
        self.extra = 0
        self.max_diff = 0.0

    def add(self, d: float) -> None:
        self.max_diff = max(self.max_diff, d)

    def ok(self, tol: float) -> bool:
        return self.missing == 0 and self.max_diff <= tol


def compare_stamped(rec: Dict[int, Dict[str, float]], new: Dict[int, Dict[str, float]], fed, names):
    """Compare recorded and new stamped outputs field by field, for the stamps that were fed.

    Returns the topic's Stat and {field: Stat}; a recorded stamp with no new output counts as missing,
    a recorded field the new output lacks as an infinite difference.
    """
    st = Stat()
    names = list(names)
    for fields in rec.values():
        names += [n for n in fields if n not in names]
    fs = {n: Stat() for n in names}
    for stamp, r in rec.items():
        if stamp not in fed:
            continue
        n_new = new.get(stamp)
        if n_new is None:
            st.missing += 1
            continue
        st.compared += 1
        for n, a in r.items():
            d = diff(a, n_new[n]) if n in n_new else math.inf
            fs[n].add(d)
            fs[n].compared += 1
            st.add(d)
    st.extra = sum(1 for s in new if s not in rec)
    return st, fs
