"""The law ``policy``: a learned linear policy, read from its file, as a law of the registry (a plug-in).

``MWIP_ROS_LAWS=mwip_ros.policy_law`` registers it (:mod:`mwip_ros.core.laws`' plug-in hook) in every process that
starts with it: ``mwip_sim --controller policy``, a sweep's ``controllers: [policy]``, the controller node
(``law: policy``, with ``policy.file`` the file).  The file is what ``python -m mwip_ros.envs.examples.cem --out
FILE`` writes (JSON): ``w`` = (w1, w2, w3) and the action's ``scale`` S [N m]; the law's command is::

    u = S clip(w1 theta_b + w2 theta_b' + w3 theta_w', -1, 1)

of the measured state, exactly the torque :class:`~mwip_ros.envs.MwipEnv` makes of the policy's action
(:func:`mwip_ros.policy.linear_action` is the one computation both use), so the law in ``mwip_sim`` or the ROS
graph repeats the environment's episode bit for bit.  Importing this module registers the law (so only
``MWIP_ROS_LAWS`` imports it); it needs numpy only (no Gymnasium).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List

from mwip_ros.core.laws import Law, LawParam, register
from mwip_ros.policy import LinearPolicy, linear_action

__all__ = ["PolicyParams", "PolicyLaw"]

@dataclass(frozen=True)
class PolicyParams:
    w1: float
    w2: float
    w3: float
    scale: float   # [N m]; 0: no policy file (the command is 0)


class PolicyLaw(Law):
    """u = S linear_action(w, theta_b, theta_b', theta_w'): the policy file's weights, no state, no model."""

    name = "policy"
    title = "policy"
    param_keys = ("policy.file",)
    parameters = (LawParam("policy.file", "string", "", "the learned policy's file (JSON, written by "
                           "python -m mwip_ros.envs.examples.cem --out FILE); empty: the command is 0"),)
    internal_names = ("u", "a")
    Params = PolicyParams

    @classmethod
    def design(cls, values, nominal, h) -> PolicyParams:
        path = values.get("policy.file", "")
        if not path:
            return PolicyParams(0.0, 0.0, 0.0, 0.0)
        p = LinearPolicy.load(path)   # a regular file, bounded, read once while it is unchanged
        return PolicyParams(*p.w, p.scale)

    def step(self, x, tau_hat=None):
        g = self.params
        a = linear_action((g.w1, g.w2, g.w3), x[1], x[3], x[2])
        u = a * g.scale
        if self.m is math:
            a, u = float(a), float(u)
        return u, {"u": u, "a": a}

    def summary(self) -> str:
        g = self.params
        return f"w = ({g.w1:.4g}, {g.w2:.4g}, {g.w3:.4g}), S = {g.scale:g} N m"

    def warnings(self) -> List[str]:
        g = self.params
        if not g.scale > 0:
            return ["policy.file is empty: the law policy commands 0"]
        return LinearPolicy((g.w1, g.w2, g.w3), g.scale).warnings()


register(PolicyLaw, with_observer="policy_ndo")
