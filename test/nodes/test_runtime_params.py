"""Run-time parameter changes are checked as strictly as start-up values, and every refusal names the key."""
import pytest

from graphproc import Graph
from injector import Injector, ParamSetter

pytestmark = pytest.mark.graph


def test_absurd_wrong_type_and_unknown_updates_are_refused_naming_the_key(tmp_path):
    with Graph(tmp_path) as g:
        ctl = g.start("dscndo_controller")
        obs = g.start("disturbance_observer")
        assert ctl.wait_for_output("ready") and obs.wait_for_output("ready")
        with Injector(g.domain_id, name="test_param_client") as inj:
            params = ParamSetter(inj)
            huge = params.set("dscndo_controller", "k1", 1e308)
            tiny = params.set("dscndo_controller", "tau4", 1e-300)
            wrong = params.set("dscndo_controller", "k2", "fast")
            unknown = params.set("dscndo_controller", "tau5", 1.0)
            x_huge = params.set("disturbance_observer", "X", [1e308, 0.0, 0.0, 1e308])
            x_ok = params.set("disturbance_observer", "X", [90.0, 0.0, 0.0, 90.0])
            ok = params.set("dscndo_controller", "k1", 7.0)
            mpc_bad = [params.set("dscndo_controller", "mpc.Q", q)    # MPC's design, as lqr.Q's
                       for q in ([-1.0, 10.0, 1.0], [0.0, 0.0, 0.0], [1e300, 10.0, 1.0])]
    for result, key in ((huge, "k1"), (tiny, "tau4"), (wrong, "k2"), (unknown, "tau5"), (x_huge, "X")):
        assert not result.successful and key in result.reason, (key, result.reason)
    for result in mpc_bad:
        assert not result.successful and "mpc.Q" in result.reason, result.reason
    assert "did you mean" in unknown.reason
    assert x_ok.successful and ok.successful
    assert ctl.wait_for_output("k1: 6.0 -> 7.0") and "1e+308" not in ctl.output().split("parameters changed")[-1]
