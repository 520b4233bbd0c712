"""An excitation at or above the Nyquist frequency of the control rate is refused naming the key and the rate (the
command is sampled at the control rate: such a chirp comes out aliased)."""
import pytest

from mwip_ros import params as P
from mwip_ros.params.paths import default_params_file

pytestmark = pytest.mark.unit

BASE = P.merged_values(P.load_param_file(default_params_file()))


@pytest.mark.parametrize("kind", ["chirp", "prbs"])
@pytest.mark.parametrize("rate, f1", [(200.0, 100.0), (200.0, 150.0), (20.0, 10.0), (20.0, 12.0)])
def test_an_excitation_above_nyquist_is_refused_naming_the_key_and_the_rate(kind, rate, f1):
    v = dict(BASE, **{"control_rate_hz": rate, "excitation.type": kind, "excitation.amplitude": 10.0,
                      "excitation.f1": f1})
    with pytest.raises(P.ParamError) as ei:
        P.check_derived(v, "p.yaml")
    assert ei.value.key == "excitation.f1" and f"control_rate_hz / 2 = {rate / 2:g} Hz" in ei.value.reason
    assert "aliased" in ei.value.reason


@pytest.mark.parametrize("kind, rate, f1", [("chirp", 200.0, 99.0), ("prbs", 20.0, 9.9), ("none", 20.0, 500.0)])
def test_below_nyquist_or_no_excitation_is_accepted(kind, rate, f1):
    P.check_derived(dict(BASE, **{"control_rate_hz": rate, "excitation.type": kind, "excitation.f1": f1}))
