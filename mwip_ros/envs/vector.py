"""``MwipVectorEnv``: N robots stepped together (placeholder)."""
from gymnasium.vector import VectorEnv

__all__ = ["MwipVectorEnv"]


class MwipVectorEnv(VectorEnv):
    pass
