"""The ``ground.*`` parameters of ``plant_sim`` with ``backend: mujoco`` (docs/theory.md 6.10): the ground the
3D model rolls on.

:func:`specs` gives their :class:`~.spec.ParamSpec` (``params.schema`` lists them with the plant's own);
:func:`check` refuses what passes each key's range but no robot can start on (``params.schema.check_derived``).
``ground.slope`` tilts the plane about y, uphill ahead for a positive slope; ``ground.bumps`` are steps across the
path, [x0, h0, x1, h1, ...]: from x_i [m, along the slope] on, the ground is h_i [m] above the plane (up to the
next step; the last goes on).  Both default to flat ground: the model is then the one without them, to the bit.
"""
from __future__ import annotations

import math
from typing import Any, List, Mapping, Optional

from .spec import ParamSpec

__all__ = ["specs", "check", "bumps_rule", "MAX_SLOPE", "MAX_BUMP", "MAX_BUMPS"]

MAX_SLOPE = 0.5    # rad (28.6 deg): steeper is a wall for this robot and a wheel that slides at any friction below 0.55
MAX_BUMP = 1.0     # m: a step higher than a metre is a wall
MAX_BUMPS = 100


def bumps_rule(v) -> Optional[str]:
    """None when ``v`` is a list of steps [x0, h0, x1, h1, ...]: pairs, x increasing, 0 <= h <= MAX_BUMP."""
    if len(v) % 2:
        return f"give pairs [x0, h0, x1, h1, ...] (position [m], height [m]), got {len(v)} entries"
    if len(v) > 2 * MAX_BUMPS:
        return f"at most {MAX_BUMPS} steps, got {len(v) // 2}"
    xs, hs = v[0::2], v[1::2]
    if not all(math.isfinite(x) and abs(x) <= 1e4 for x in xs) or any(b <= a for a, b in zip(xs, xs[1:])):
        return f"the positions must be finite, within +/-1e4 m, and increase, got {list(xs)!r}"
    if not all(math.isfinite(h) and 0.0 <= h <= MAX_BUMP for h in hs):
        return f"the heights must be within [0, {MAX_BUMP:g}] m, got {list(hs)!r}"
    return None


def specs() -> List[ParamSpec]:
    """The ``ground.*`` ParamSpecs."""
    return [
        ParamSpec("ground.friction", "double", 2.0, "mujoco: the ground's sliding friction coefficient (wheel on "
                  "ground)", lo=0.0, hi=100.0, lo_open=True, floor=1e-3, floor_why="ground with no grip", hi_why=""),
        ParamSpec("ground.slope", "double", 0.0, "mujoco: the ground's slope [rad], the plane tilted about y, uphill "
                  "ahead (+x) for a positive slope; the robot starts on it, standing", lo=-MAX_SLOPE, hi=MAX_SLOPE,
                  unit="rad"),
        ParamSpec("ground.bumps", "double_array", [], "mujoco: steps across the path, [x0, h0, x1, h1, ...]: from "
                  "x_i [m, along the slope] on the ground is h_i [m] high (to the next step); empty = none",
                  rule=bumps_rule, words="pairs [x0, h0, x1, h1, ...], x increasing, heights in [0, 1] m"),
    ]


def check(values: Mapping[str, Any], source: Optional[str] = None) -> None:
    """Raise :class:`~.errors.ParamError` naming ``ground.bumps`` when the robot would not start on the plane: every
    step higher than 0 must begin at least a wheel radius ``actual.r`` ahead of the wheel (at r theta_w(0))."""
    from .errors import ParamError
    bumps = values.get("ground.bumps") or []
    r = values["actual.r"]
    x0 = r * values.get("initial.theta_w", 0.0)
    near = [x for x, h in zip(bumps[0::2], bumps[1::2]) if h > 0.0 and x < x0 + r]
    if near:
        raise ParamError("ground.bumps", f"a step at x = {near[0]:g} m is not a wheel radius ({r:g} m) ahead of where "
                                         f"the robot starts (x = {x0:g} m): the wheel would start on or in it", source)
