"""Run-time parameter changes are checked as strictly as start-up values, and every refusal names the key."""
import pytest

from graphproc import Graph

pytestmark = pytest.mark.graph


def _client(domain_id):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    node = rclpy.create_node("test_param_client", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    return rclpy, ctx, node, ex


def _set(node, ex, target, name, value):
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter
    cli = node.create_client(SetParameters, f"/{target}/set_parameters")
    assert cli.wait_for_service(timeout_sec=20)
    msg = Parameter(name, value=value).to_parameter_msg()
    fut = cli.call_async(SetParameters.Request(parameters=[msg]))
    ex.spin_until_future_complete(fut, timeout_sec=20)
    return fut.result().results[0]


def test_absurd_wrong_type_and_unknown_updates_are_refused_naming_the_key(tmp_path):
    with Graph(tmp_path) as g:
        ctl = g.start("dscndo_controller")
        obs = g.start("disturbance_observer")
        assert ctl.wait_for_output("ready") and obs.wait_for_output("ready")
        rclpy, ctx, node, ex = _client(g.domain_id)
        try:
            huge = _set(node, ex, "dscndo_controller", "k1", 1e308)
            tiny = _set(node, ex, "dscndo_controller", "tau4", 1e-300)
            wrong = _set(node, ex, "dscndo_controller", "k2", "fast")
            unknown = _set(node, ex, "dscndo_controller", "tau5", 1.0)
            x_huge = _set(node, ex, "disturbance_observer", "X", [1e308, 0.0, 0.0, 1e308])
            x_ok = _set(node, ex, "disturbance_observer", "X", [90.0, 0.0, 0.0, 90.0])
            ok = _set(node, ex, "dscndo_controller", "k1", 7.0)
            mpc_bad = [_set(node, ex, "dscndo_controller", "mpc.Q", q)    # MPC's design, as lqr.Q's
                       for q in ([-1.0, 10.0, 1.0], [0.0, 0.0, 0.0], [1e300, 10.0, 1.0])]
        finally:
            node.destroy_node()
            rclpy.shutdown(context=ctx)
    for result, key in ((huge, "k1"), (tiny, "tau4"), (wrong, "k2"), (unknown, "tau5"), (x_huge, "X")):
        assert not result.successful and key in result.reason, (key, result.reason)
    for result in mpc_bad:
        assert not result.successful and "mpc.Q" in result.reason, result.reason
    assert "did you mean" in unknown.reason
    assert x_ok.successful and ok.successful
    assert ctl.wait_for_output("k1: 6.0 -> 7.0") and "1e+308" not in ctl.output().split("parameters changed")[-1]
