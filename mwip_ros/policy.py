"""A learned linear policy and its file: what ``mwip_ros.envs.examples.cem`` learns and writes, and what the law
``policy`` (:mod:`mwip_ros.policy_law`) reads.  numpy only; importing it registers nothing."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["FEATURES", "LinearPolicy", "linear_action", "MAX_FILE_BYTES", "MAX_WEIGHT", "SCALE_WARN"]

FEATURES = ("theta_b", "dtheta_b", "dtheta_w")   # the state's entries 1, 3, 2
MAX_FILE_BYTES = 64 * 1024   # a policy file is about 150 bytes
MAX_WEIGHT = 1e6             # |w_i| beyond this: w theta overflows toward inf - inf = NaN before the clip
SCALE_WARN = 1000.0          # N m: a scale beyond this is said (a warning); beyond PLAUSIBLE_TORQUE it is refused


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
        """The policy of the file ``path``; a file that is missing, not a regular file, larger than
        :data:`MAX_FILE_BYTES` or not such a policy (:func:`parse`) raises ValueError naming ``policy.file``.  A file
        read before and unchanged since (its inode, size and modification time) is not read again: the controller
        designs every law at each parameter change."""
        import os
        import stat as st_

        from mwip_ros.yamlio import read_bytes
        try:
            info = os.stat(path)   # nothing opened: a FIFO or a device is refused below, unread
            key = (str(path), info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns)
            if st_.S_ISREG(info.st_mode) and key in _LOADED:
                return _LOADED[key]
            data = read_bytes(path, MAX_FILE_BYTES, "policy file")
            doc = json.loads(data.decode("utf-8"))
        except RecursionError:
            raise ValueError(f"policy.file: {str(path)!r} is not a linear policy (nested too deeply)") from None
        except (OSError, ValueError) as exc:   # UnicodeDecodeError and JSONDecodeError are ValueErrors
            raise ValueError(f"policy.file: cannot read a linear policy from {str(path)!r} ({exc})") from None
        policy = cls.parse(doc, str(path))
        if len(_LOADED) >= 8:
            _LOADED.pop(next(iter(_LOADED)))
        _LOADED[key] = policy
        return policy

    @classmethod
    def parse(cls, doc, where: str = "the policy") -> "LinearPolicy":
        """The policy of a policy file's document: ``policy: linear``, ``features`` (if given) exactly
        :data:`FEATURES`, ``w`` a list of three numbers (JSON numbers, not strings), each within
        +/-:data:`MAX_WEIGHT`, and ``scale`` a number > 0 and at most
        :data:`~mwip_ros.core.control.safety.PLAUSIBLE_TORQUE` [N m]; ValueError naming ``policy.file`` and what is
        wrong, else."""
        from mwip_ros.core.control.safety import PLAUSIBLE_TORQUE

        def bad(why: str) -> ValueError:
            return ValueError(f"policy.file: {where!r} is not a linear policy: {why}")

        def number(v) -> bool:
            return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        if not isinstance(doc, dict):
            raise bad(f"a JSON object is needed, got a {type(doc).__name__}")
        if doc.get("policy") != "linear":
            raise bad(f"policy must be 'linear', got {str(doc.get('policy'))[:40]!r}")
        if "features" in doc and doc["features"] != list(FEATURES):
            raise bad(f"features must be {list(FEATURES)} (the weights' order), got {str(doc['features'])[:80]}")
        w = doc.get("w")
        if not isinstance(w, list) or len(w) != 3 or not all(number(v) for v in w):
            raise bad(f"w must be a list of three finite numbers, got {str(w)[:80]}")
        if any(abs(v) > MAX_WEIGHT for v in w):
            raise bad(f"a weight of w is beyond +/-{MAX_WEIGHT:g}: {w}")
        scale = doc.get("scale")
        if not number(scale) or not 0 < scale <= PLAUSIBLE_TORQUE:
            raise bad(f"scale must be a number > 0 and at most {PLAUSIBLE_TORQUE:g} N m, got {str(scale)[:40]}")
        return cls(tuple(float(v) for v in w), float(scale))

    def warnings(self) -> list:
        """What a user should hear about the policy (a scale no drive of this robot gives)."""
        if self.scale > SCALE_WARN:
            return [f"policy.file: scale = {self.scale:g} N m: the policy commands up to that torque, more than "
                    f"{SCALE_WARN:g} N m (this robot's drives give a few hundred; the paper's run stays below 212)"]
        return []


_LOADED: dict = {}   # (path, device, inode, size, mtime) -> LinearPolicy: read once while unchanged
