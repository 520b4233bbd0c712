"""Gymnasium environments of the MWIP: :class:`MwipEnv` (one robot, the offline loop's stages) and
:class:`MwipVectorEnv` (N robots stepped together over arrays), configured from the same parameter files as
``mwip_sim`` (docs/learning.md).

Importing this package registers the ids :data:`ENV_ID` (``gymnasium.make``; ``gymnasium.make_vec`` runs the vector
env); without an import first, ``gymnasium.make("mwip_ros.envs:mwip_ros/Mwip-v0")`` imports it.  Gymnasium is an
optional package (:mod:`mwip_ros.optional`): without it this import raises the one line that names it, and the rest
of mwip_ros runs; so is numba, which only the vector env needs (its RK4).
"""
from mwip_ros.optional import required

with required("gymnasium", "mwip_ros.envs (the Gymnasium environments)"):
    import gymnasium

from .common import DEFAULT_TORQUE_SCALE, Reward, load_values   # noqa: E402
from .scalar import MwipEnv   # noqa: E402

__all__ = ["ENV_ID", "MwipEnv", "MwipVectorEnv", "Reward", "DEFAULT_TORQUE_SCALE", "load_values"]

ENV_ID = "mwip_ros/Mwip-v0"



def __getattr__(name: str):
    """``MwipVectorEnv`` on first use: it needs numba (its RK4), which ``MwipEnv`` does not."""
    if name == "MwipVectorEnv":
        from .vector import MwipVectorEnv
        return MwipVectorEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point="mwip_ros.envs.scalar:MwipEnv",
                       vector_entry_point="mwip_ros.envs.vector:MwipVectorEnv")
