"""The DC motor and its driver as the parameters give them (``motor.*``, docs/theory.md 6.7): :func:`motor`.

Below :mod:`.typed` (which builds the whole plant and re-exports it) and :mod:`.motion` (whose yaw stage's wheel
limit is derived from the drive's), so neither imports the other for it.
"""
from __future__ import annotations

from typing import Any, Mapping

from mwip_ros.core.plants.drive import MotorConfig

__all__ = ["motor"]


def motor(v: Mapping[str, Any]) -> MotorConfig:
    """The DC motor and its driver (docs/theory.md 6.7), ``motor.enabled`` false by default."""
    return MotorConfig(enabled=v.get("motor.enabled", False), **{
        k: v.get(f"motor.{k}", getattr(MotorConfig, k))
        for k in ("torque_constant", "resistance", "voltage_limit", "current_limit")})
