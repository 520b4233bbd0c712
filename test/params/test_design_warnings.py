"""What a node warns about its parameter values (params.typed.design_warnings), the text mwip_ctl prints after a
change: the controller's laws against Theorem 2, for the laws the change touched; the observer's gain."""
import pytest

from mwip_ros import params as P
from mwip_ros.params.paths import default_params_file
from mwip_ros.params.typed import design_warnings

pytestmark = pytest.mark.unit


@pytest.fixture
def paper():
    return P.merged_values(P.load_param_files([default_params_file()], option="params"))


def _theorem(lines):
    """The Theorem 2 lines (another test's plug-in law, registered in this process, may add its own)."""
    return [w for w in lines if "Theorem 2" in w]


def test_k1_7_breaks_theorem_2_and_says_a3(paper):
    v = dict(paper, k1=7.0)
    (w,) = _theorem(design_warnings("dscndo_controller", v, ["k1"]))
    assert "a3 = -0.7167" in w
    assert _theorem(design_warnings("/robot/dscndo_controller", v, ["k1"])) == [w]   # a namespaced node
    assert _theorem(design_warnings("dscndo_controller", v, ["lqr.Q"])) == []   # LQR's parameters: DSC not touched
    assert _theorem(design_warnings("dscndo_controller", v, ["law"])) == [w]    # switched to the law in use (dsc)
    assert _theorem(design_warnings("dscndo_controller", dict(v, law="lqr"), ["law"])) == []
    assert _theorem(design_warnings("dscndo_controller", paper)) == []           # the paper's gains keep it


def test_an_observer_gain_that_breaks_theorem_2_is_said(paper):
    bad = dict(paper, X=[1.0, 0.0, 0.0, 1.0])
    (w,) = design_warnings("disturbance_observer", bad, ["X"])
    assert "observer gains break Theorem 2" in w and "a4 = " in w
    assert design_warnings("disturbance_observer", bad, ["csv"]) == []
    assert design_warnings("disturbance_observer", paper, ["X"]) == []
    assert design_warnings("plant_sim", bad) == []
