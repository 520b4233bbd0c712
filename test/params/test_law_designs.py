"""Every registered law's design is checked with the parameters (check_derived), at start-up and for a run-time
change, whatever the law in use: a weight that gives no design is a ParamError naming its key."""
import pytest

from mwip_ros import params as P
from mwip_ros.params.paths import default_params_file
from mwip_ros.core.control.lqr import NO_DESIGN

pytestmark = pytest.mark.unit

BASE = P.merged_values(P.load_param_file(default_params_file()))


@pytest.mark.parametrize("key, value, words", [
    ("mpc.Q", [-1.0, 10.0, 1.0], ">= 0"), ("mpc.Q", [0.0, 0.0, 0.0], NO_DESIGN),
    ("mpc.Q", [1e300, 10.0, 1.0], "<= 1e+12"), ("mpc.Q", [1.0, 1.0], "3 entries"),
    ("lqr.Q", [100.0, 10.0, 0.0], NO_DESIGN)])
def test_a_weight_with_no_design_is_refused_naming_its_key(key, value, words):
    for law in ("dsc", "mpc", "lqr"):
        with pytest.raises(P.ParamError) as ei:
            P.check_derived(dict(BASE, **{key: value, "law": law}), "start-up value")
        assert ei.value.key == key and words in ei.value.reason, ei.value


def test_the_files_values_pass():
    P.check_derived(BASE)
