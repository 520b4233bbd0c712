"""Every physical parameter has a range over which the arithmetic holds: at each end of each range (the others at
their defaults) the model's inertia terms and accelerations are finite, and the drive gives the peak torque the
plant's start-up line promises (MotorConfig.peak_torque), at rest and at a speed with voltage headroom."""
import math

import pytest

from mwip_ros import params as P
from mwip_ros.core.plants.drive import MotorConfig, motor_torque
from mwip_ros.core.plants.model import State, accel
from mwip_ros.params.paths import default_params_file

pytestmark = pytest.mark.unit

BASE = dict(P.merged_values(P.load_param_file(default_params_file())), **{"motor.enabled": True})
SPECS = P.specs_for("plant_sim")
PHYSICAL = [name for name, s in SPECS.items() if name.split(".")[0] in ("nominal", "actual", "motor")
            and s.type == "double"]


def _ends(spec):
    """The smallest and the largest value ``spec`` accepts (an open lower end without a floor: 1e-300, a value
    the range accepts)."""
    lo = spec.floor if spec.floor is not None else (1e-300 if spec.lo_open else spec.lo)
    assert spec.check(lo) is None and spec.check(spec.hi) is None, spec.name
    return lo, spec.hi


def test_every_physical_parameter_is_bounded_on_both_sides():
    assert len(PHYSICAL) == 7 + 7 + 3 + 4 + 3             # nominal, actual, actual.D_*, motor, the 3D body (mujoco)
    for name in PHYSICAL:
        s = SPECS[name]
        assert s.hi is not None and s.lo is not None and (s.floor is not None or not s.lo_open), name


@pytest.mark.parametrize("name", PHYSICAL)
@pytest.mark.parametrize("end", [0, 1])
def test_the_model_and_the_drive_hold_at_each_end_of_each_range(name, end):
    value = _ends(SPECS[name])[end]
    v = dict(BASE, **{name: value})
    try:
        P.check_derived(v)
    except P.ParamError:                  # a model the schema refuses, naming a key (nominal.r = 1e6: no LQR
        return                            # design, lqr.Q named): fine, nothing runs
    for prefix in ("nominal", "actual"):
        p = P.physical(v, prefix)
        assert all(math.isfinite(t) and t > 0 for t in (p.m11, p.m22, p.A_bar)), (prefix, p)
        for x in (State(0.0, 0.0, 0.0, 0.0), State(1.0, 0.5, 10.0, -2.0), State(0.0, -1.0, -100.0, 5.0)):
            for u in (0.0, 120.0, -1e5):
                assert all(math.isfinite(a) for a in accel(p, 0.5, 0.1, x, u, 30.0, 0.2)), (prefix, x, u)
    m = P.motor(v)
    K, R, V, I = m.torque_constant, m.resistance, m.voltage_limit, m.current_limit
    peak = m.peak_torque
    assert math.isfinite(peak) and peak > 0
    for sign in (1.0, -1.0):                                 # at rest: the promised peak, exactly
        assert motor_torque(sign * 10 * peak, 0.0, K, R, V, I)[0] == pytest.approx(sign * peak, rel=1e-9)
    i_peak = peak / K
    headroom = V - R * i_peak                                # the voltage left for the back-EMF at the peak current
    if headroom > 1e-9 * V:
        w = 0.5 * headroom / K                               # half of it: the peak must still flow
        u, _ = motor_torque(10 * peak, w, K, R, V, I)
        assert u == pytest.approx(peak, rel=1e-6), (name, value, u, peak)
        u, _ = motor_torque(0.5 * peak, w, K, R, V, I)       # and half the peak, asked, is given
        assert u == pytest.approx(0.5 * peak, rel=1e-6), (name, value, u, peak)


def test_the_peak_is_what_the_battery_can_drive_through_the_winding():
    """K_t min(I_max, V_max / R): 120 N m with the defaults; a winding of 10 ohm on 48 V drives 4.8 A, 9.6 N m."""
    assert MotorConfig(enabled=True).peak_torque == 120.0
    weak = MotorConfig(enabled=True, resistance=10.0)
    assert weak.peak_torque == pytest.approx(9.6)
    assert motor_torque(1e6, 0.0, 2.0, 10.0, 48.0, 60.0)[0] == pytest.approx(weak.peak_torque)


@pytest.mark.parametrize("key", ["motor.resistance", "motor.torque_constant", "motor.current_limit",
                                 "actual.m_b", "nominal.I_w", "actual.r"])
def test_a_vanishing_physical_value_is_refused_naming_the_key(key):
    """1e-300 (motor.resistance: 1e-300 gave a drive with no torque at speed, R i* rounding away against the
    back-EMF, while the start-up line promised 120 N m)."""
    with pytest.raises(P.ParamError) as ei:
        SPECS[key].validate(1e-300, key)
    assert ei.value.key == key and "must be >=" in ei.value.reason
