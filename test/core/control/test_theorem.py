"""Theorem 2 (eq. 34-35)."""
import pytest

from mathfixtures import NOM, PAPER_GAINS
from mwip_ros.core.control.controller import DscGains
from mwip_ros.core.control.observer import gain_matrix
from mwip_ros.core.control.theorem import controller_conditions, observer_conditions, theorem2

pytestmark = pytest.mark.unit


def test_theorem2_paper_gains_hold_and_slow_filter_violates():
    th = theorem2(NOM, DscGains(6.0, 6.0, 0.1), gain_matrix([100.0, 0, 0, 100.0]))
    assert th.satisfied and th.gamma == pytest.approx(min(th.as_dict()[k] for k in ("a1", "a2", "a3", "a4", "a5")))
    r = (NOM.m11 + NOM.m12) / NOM.m22
    assert th.a5 == pytest.approx(100.0 / NOM.m22 - 1)
    slow = theorem2(NOM, DscGains(6.0, 6.0, 0.5), gain_matrix([100.0, 0, 0, 100.0]))
    assert slow.a3 == pytest.approx(2.0 - 9.0 - r / 2) and not slow.satisfied
    weak_obs = theorem2(NOM, PAPER_GAINS, gain_matrix([10.0, 0, 0, 100.0]))
    assert weak_obs.a4 < 0 and not weak_obs.satisfied


def test_each_node_checks_its_own_half_of_theorem2():
    """a1..a3 depend only on the controller's gains, a4..a5 only on X; together they are Theorem 2."""
    X = gain_matrix([100.0, 0, 0, 100.0])
    c, o = controller_conditions(NOM, PAPER_GAINS), observer_conditions(NOM, X)
    th = theorem2(NOM, PAPER_GAINS, X)
    assert (c.a1, c.a2, c.a3, o.a4, o.a5) == (th.a1, th.a2, th.a3, th.a4, th.a5)
    assert c.satisfied and o.satisfied
    assert not controller_conditions(NOM, DscGains(6.0, 6.0, 0.5)).satisfied        # slow filter: a3 < 0
    assert not observer_conditions(NOM, gain_matrix([10.0, 0, 0, 100.0])).satisfied  # weak c1: a4 < 0
    # changing X never changes the controller's half, and the gains never the observer's
    assert observer_conditions(NOM, X) == observer_conditions(NOM, X.copy())
    assert controller_conditions(NOM, PAPER_GAINS).a1 == PAPER_GAINS.k1 - (NOM.m11 + NOM.m12) / NOM.m22
