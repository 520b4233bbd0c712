"""A law registered by a test, to prove that adding a law is one module and one registry line.

``u = k theta_b`` with one parameter, ``trivial.k`` (k above G_b, about 900 N m/rad nominal: the
wheel drives under the body), which the law declares itself (so the controller node declares
it too); ``trivial_ndo`` is it with the observer term, composed by the registry.  Offline, in a
batch and in the graph (``MWIP_ROS_LAWS=trivial_law``, this directory on ``PYTHONPATH``) it gives
the same numbers (test/core/laws/test_laws.py, test/nodes/test_graph.py).
"""
from __future__ import annotations

from dataclasses import dataclass

from mwip_ros.core.laws import Law, LawParam, register


@dataclass(frozen=True)
class TrivialGain:
    k: float   # [N m/rad]


class TrivialLaw(Law):
    """u = k theta_b: no state, no model."""

    name = "trivial"
    param_keys = ("trivial.k",)
    parameters = (LawParam("trivial.k", "double", 2000.0, "gain k of the trivial test law u = k theta_b [N m/rad]",
                           lo=0.0, hi=1e6),)
    internal_names = ("u", "theta_b")
    Params = TrivialGain

    @classmethod
    def design(cls, values, nominal, h):
        return TrivialGain(values["trivial.k"])

    def step(self, x, tau_hat=None):
        u = self.params.k * x[1]
        return u, {"u": u, "theta_b": x[1]}

    def summary(self) -> str:
        return f"k = {self.params.k}"


register(TrivialLaw, with_observer="trivial_ndo")
