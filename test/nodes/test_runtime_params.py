"""Run-time parameter changes are checked as strictly as start-up values, and every refusal names the key: the
controller and the observer in this process, each request through the node's own ``set_parameters`` service
callback (test/nodeharness.py; the service through the middleware: test/cli/test_ctl.py)."""
import pytest

from nodeharness import NodeHarness, node_class

pytestmark = pytest.mark.node


def _set(h, name, value):
    """``rcl_interfaces/SetParameters`` with one parameter, to the node's service: its result."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter
    request = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
    return h.call(f"/{h.name}/set_parameters", request).results[0]


def test_absurd_wrong_type_and_unknown_updates_are_refused_naming_the_key():
    with NodeHarness(node_class("dscndo_controller")) as ctl, NodeHarness(node_class("disturbance_observer")) as obs:
        before = dict(ctl.node.v)
        huge = _set(ctl, "k1", 1e308)
        tiny = _set(ctl, "tau4", 1e-300)
        wrong = _set(ctl, "k2", "fast")
        unknown = _set(ctl, "tau5", 1.0)
        x_huge = _set(obs, "X", [1e308, 0.0, 0.0, 1e308])
        x_ok = _set(obs, "X", [90.0, 0.0, 0.0, 90.0])
        ok = _set(ctl, "k1", 7.0)
        mpc_bad = [_set(ctl, "mpc.Q", q)    # MPC's design, as lqr.Q's
                   for q in ([-1.0, 10.0, 1.0], [0.0, 0.0, 0.0], [1e300, 10.0, 1.0])]
        after, x_now = dict(ctl.node.v), list(obs.node.v["X"])
    for result, key in ((huge, "k1"), (tiny, "tau4"), (wrong, "k2"), (unknown, "tau5"), (x_huge, "X")):
        assert not result.successful and key in result.reason, (key, result.reason)
    for result in mpc_bad:
        assert not result.successful and "mpc.Q" in result.reason, result.reason
    assert "did you mean" in unknown.reason
    assert x_ok.successful and ok.successful
    # the refused values changed nothing: only k1 (7.0) and X (the good one) are new
    assert {k for k in after if after[k] != before[k]} == {"k1"} and after["k1"] == 7.0 and x_now == [90.0, 0.0, 0.0,
                                                                                                        90.0]
    assert "k1: 6.0 -> 7.0" in ctl.logs() and "1e+308" not in ctl.logs().split("parameters changed")[-1]
