"""A learned linear policy and its file: what ``mwip_ros.envs.examples.cem`` learns and writes, and what the law
``policy`` (:mod:`mwip_ros.policy_law`) reads.  numpy only; importing it registers nothing."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["FEATURES", "LinearPolicy", "linear_action"]

FEATURES = ("theta_b", "dtheta_b", "dtheta_w")   # the state's entries 1, 3, 2


def linear_action(w, theta_b, dtheta_b, dtheta_w):
    """clip(w1 theta_b + w2 theta_b' + w3 theta_w', -1, 1): floats or arrays (one robot each)."""
    return np.clip(w[0] * theta_b + w[1] * dtheta_b + w[2] * dtheta_w, -1.0, 1.0)


@dataclass(frozen=True)
class LinearPolicy:
    """The policy ``a = linear_action(w, ...)`` of the measured state, its action's scale S [N m] (the env's)."""

    w: tuple
    scale: float

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """The actions (N, 1) of observations (N, 4) = (theta_w, theta_b, theta_w', theta_b')."""
        return linear_action(self.w, obs[:, 1], obs[:, 3], obs[:, 2])[:, None]

    def save(self, path) -> None:
        Path(path).write_text(json.dumps({"policy": "linear", "features": list(FEATURES), "w": list(self.w),
                                          "scale": self.scale}, indent=1) + "\n")

    @classmethod
    def load(cls, path) -> "LinearPolicy":
        """The policy of the file ``path``; a file that is missing or not such a policy raises ValueError naming
        ``policy.file``."""
        try:
            doc = json.loads(Path(path).read_text())
            w = tuple(float(v) for v in doc["w"])
            scale = float(doc["scale"])
            ok = doc.get("policy") == "linear" and len(w) == 3 and all(map(math.isfinite, (*w, scale))) and scale > 0
        except (OSError, ValueError, TypeError, KeyError) as exc:
            raise ValueError(f"policy.file: cannot read a linear policy from {str(path)!r} ({exc})") from None
        if not ok:
            raise ValueError(f"policy.file: {str(path)!r} is not a linear policy (policy: linear, three finite "
                             "weights w, a scale > 0)")
        return cls(w, scale)


