"""The motor and driver (theory.md 6.7): hand-computed torques per branch, the RK4-weighted mean, the holding torque."""
import math

import numpy as np
import pytest

from mathfixtures import FALL_ANGLE, TRUE
from mwip_ros.core.plants.drive import (SAT_CURRENT, SAT_NONE, SAT_VOLTAGE, MotorConfig, acted_torque, holding_torque,
                                        motor_torque, recoverable_angle, torque_warning)
from mwip_ros.core.plants.model import accel

pytestmark = pytest.mark.unit

K, R, V, I = 2.0, 0.15, 48.0, 60.0   # docs/theory.md 6.7's example drive


@pytest.mark.parametrize("u_cmd, w, u, code", [
    (20.0, 0.0, 20.0, SAT_NONE),                 # i* = 10 A, V = 1.5 V
    (20.0, 10.0, 20.0, SAT_NONE),                # V = 1.5 + 20 = 21.5 V < 48
    (-100.0, 20.0, -100.0, SAT_NONE),            # braking at speed: V = -7.5 + 40 = 32.5 V
    (100.0, 20.0, 100.0, SAT_NONE),              # V = 7.5 + 40 = 47.5 V, just below 48
    (200.0, 0.0, 120.0, SAT_CURRENT),            # i* clipped to 60 A, V = 9 V
    (-200.0, 5.0, -120.0, SAT_CURRENT),          # i* = -60 A, V = -9 + 10 = 1 V
    (100.0, 22.0, 2.0 * (48.0 - 44.0) / 0.15, SAT_VOLTAGE),   # V = 7.5 + 44 = 51.5 -> 48: i = 4 / 0.15 A
    (200.0, 22.0, 2.0 * (48.0 - 44.0) / 0.15, SAT_VOLTAGE),   # current and voltage: the voltage binds
    (0.0, 40.0, -120.0, SAT_VOLTAGE),            # over-speed: V = 80 -> 48, i = -213 A -> -60 A
])
def test_hand_computed_branches(u_cmd, w, u, code):
    got, c = motor_torque(u_cmd, w, K, R, V, I)
    assert got == pytest.approx(u, rel=1e-12, abs=1e-12)
    assert c == code


def test_torque_falls_with_speed_and_is_symmetric():
    ws = np.linspace(0.0, 30.0, 61)
    us = [motor_torque(150.0, w, K, R, V, I)[0] for w in ws]
    assert all(b <= a + 1e-12 for a, b in zip(us, us[1:]))
    assert us[0] == pytest.approx(120.0)
    # at full voltage the torque is the line (V_max - K_t w) K_t / R: at w = 23, (48 - 46) / 0.15 A x 2 N m/A
    assert motor_torque(150.0, 23.0, K, R, V, I)[0] == pytest.approx(2.0 * 2.0 / 0.15)
    # at w = 30 the back-EMF (60 V) passes V_max: i = (48 - 60) / 0.15 = -80 A, clipped at -60 A
    assert us[-1] == pytest.approx(-120.0)
    rng = np.random.default_rng(1)
    for u_cmd, w in rng.uniform(-300, 300, (200, 2)) * [1.0, 0.15]:
        a, ca = motor_torque(u_cmd, w, K, R, V, I)
        b, cb = motor_torque(-u_cmd, -w, K, R, V, I)
        assert b == pytest.approx(-a, abs=1e-9) and ca == cb
        assert abs(a) <= K * I + 1e-9


def test_numba_compiles_it_unchanged():
    numba = pytest.importorskip("numba")
    f = numba.njit(motor_torque)
    for u_cmd, w in [(20.0, 0.0), (200.0, 0.0), (100.0, 22.0), (0.0, 40.0)]:
        assert f(u_cmd, w, K, R, V, I) == motor_torque(u_cmd, w, K, R, V, I)


def test_acted_torque_is_the_rk4_weighted_mean():
    assert acted_torque([1.0, 2.0, 3.0, 4.0], 1) == pytest.approx((1 + 4 + 6 + 4) / 6)
    assert acted_torque([1.0] * 4 + [4.0] * 4, 2) == pytest.approx((6 + 24) / 12)
    assert acted_torque([7.5] * 20, 5) == pytest.approx(7.5)
    with pytest.raises(ValueError, match="4 x 2"):
        acted_torque([1.0] * 7, 2)


def test_motor_config_defaults_and_checks():
    m = MotorConfig()
    assert (m.enabled, m.torque_constant, m.resistance, m.voltage_limit, m.current_limit) == (False, 2.0, 0.15,
                                                                                                48.0, 60.0)
    assert m.peak_torque == 120.0
    assert m.torque(200.0, 0.0) == (120.0, SAT_CURRENT)
    for key in ("torque_constant", "resistance", "voltage_limit", "current_limit"):
        with pytest.raises(ValueError, match=f"motor.{key}"):
            MotorConfig(**{key: 0.0})
    with pytest.raises(ValueError, match="motor.resistance"):
        MotorConfig(resistance=math.nan)


def test_holding_torque_stops_the_body_at_rest():
    """At the holding torque eq. (1) gives theta_b'' = 0 for the body at rest at that tilt (no friction)."""
    for a in (0.1745, 0.5, FALL_ANGLE):
        u = holding_torque(TRUE, a)
        _, ddb = accel(TRUE, 0.0, 0.0, (0.0, a, 0.0, 0.0), u, 0.0, 0.0)
        assert ddb == pytest.approx(0.0, abs=1e-9)
        _, ddb_less = accel(TRUE, 0.0, 0.0, (0.0, a, 0.0, 0.0), 0.99 * u, 0.0, 0.0)
        assert ddb_less > 0   # less torque: the body keeps falling
        assert u < TRUE.G_b * math.sin(a)   # below the wheel-locked figure
    assert holding_torque(TRUE, -0.3) == pytest.approx(holding_torque(TRUE, 0.3))


def test_torque_warning():
    on = MotorConfig(enabled=True)
    text = torque_warning(on, TRUE, FALL_ANGLE)
    assert text is not None and "120 N m" in text and f"{holding_torque(TRUE, FALL_ANGLE):.4g} N m" in text
    assert torque_warning(MotorConfig(), TRUE, FALL_ANGLE) is None                 # motor off
    assert torque_warning(MotorConfig(enabled=True, current_limit=1000.0), TRUE, FALL_ANGLE) is None
    a = recoverable_angle(TRUE, on.peak_torque)
    assert 0.1745 < a < FALL_ANGLE   # the paper's initial tilt is recoverable with docs/theory.md 6.7's drive
    assert holding_torque(TRUE, a) == pytest.approx(120.0, rel=1e-9)
    assert f"{a:.4f} rad" in text
