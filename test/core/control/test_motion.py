"""core.control.motion: the shaping of docs/theory.md 6.11 against hand-computed references; bad commands never enter
them."""
import math

import pytest

from mwip_ros.core.control.motion import MotionConfig, Reference, Shaper, error_state, rate_reference

pytestmark = pytest.mark.unit

H = 0.1   # a round period so the hand arithmetic is short


def _cfg(**kw):
    base = dict(max_speed=1.5, max_accel=0.5, max_yaw_rate=1.0, timeout_s=0.5, position_gain=0.2, lean_gain=0.03,
                r=0.25)
    base.update(kw)
    return MotionConfig(**base)


def test_acceleration_limit_and_integral():
    s = Shaper(_cfg(), H)
    assert s.command(1.0, 0.0) is None
    refs = [s.reference(k, theta_w0=2.0) for k in range(4)]
    # v* rises 0.05 m/s per 0.1 s period from rest: 0.05, 0.10, 0.15, 0.20; theta_w'* = v*/0.25
    assert [r.v for r in refs] == pytest.approx([0.05, 0.10, 0.15, 0.20], abs=1e-15)
    assert [r.dtheta_w for r in refs] == pytest.approx([0.2, 0.4, 0.6, 0.8], abs=1e-14)
    # theta_w* starts at the first state's angle and integrates the rate held over each period
    assert [r.theta_w for r in refs] == pytest.approx([2.0, 2.02, 2.06, 2.12], abs=1e-14)


def test_speed_is_clipped_and_counted():
    s = Shaper(_cfg(max_accel=100.0), H)
    assert s.command(9.0, -7.0) is None
    r = s.reference(0)
    assert (r.v, r.dpsi) == (1.5, -0.1)   # max_speed; the yaw rate moves max_yaw_rate * h per period
    assert s.clipped == 1 and s.rejected == 0 and s.accepted == 1   # a clipped command is taken


@pytest.mark.parametrize("v, wz", [(math.nan, 0.0), (0.0, math.inf), (-math.inf, 0.0), (1e4, 0.0), (0.0, -2e3),
                                   ("x", 0.0)])
def test_bad_commands_rejected_counted_never_integrated(v, wz):
    s = Shaper(_cfg(), H)
    assert s.command(0.5, 0.0) is None
    s.reference(0)
    assert s.command(v, wz) is not None
    assert s.rejected == 1 and s.accepted == 1
    refs = [s.reference(k) for k in range(1, 4)]
    assert all(math.isfinite(x) for r in refs for x in r)
    assert refs[-1].v == pytest.approx(0.2, abs=1e-15)   # still ramping to the good command's 0.5


def test_timeout_ramps_to_zero_and_holds_position():
    s = Shaper(_cfg(), H)
    s.command(0.2, 0.5)
    refs = [s.reference(k) for k in range(30)]
    # the command came before period 0 (k = -1): at k = 4, 5 periods = 0.5 s of silence, the target is zero
    assert s.timeouts == 1
    assert refs[3].v == pytest.approx(0.2) and refs[4].v == pytest.approx(0.15)
    assert abs(refs[7].v) < 1e-15 and [r.v for r in refs[8:]] == [0.0] * 22   # (rounding: 0.2 - 3 x 0.05)
    assert refs[-1].dpsi == 0.0
    # position hold: theta_w* stops moving once v* = 0
    assert refs[-1].theta_w == refs[10].theta_w
    # the integral of the trapezoid: 0.05 + 0.1 + 0.15 + 4 * 0.2 + 0.15 + 0.1 + 0.05 (m/s) * 0.1 s / r
    assert refs[-1].theta_w == pytest.approx((0.05 + 0.1 + 0.15 + 0.2 + 0.15 + 0.1 + 0.05) * H / 0.25, abs=1e-12)


def test_timeout_logged_once():
    s = Shaper(_cfg(), H)
    s.command(0.1, 0.0)
    now = [s.reference(k).v is not None and s.stopped_now for k in range(20)]
    assert now.count(True) == 1 and now.index(True) == 4


def test_profile():
    s = Shaper(_cfg(profile=((0.0, 0.0), (0.3, 1.0), (1.0, -0.5))), H)
    vs = [s.reference(k).v for k in range(16)]
    assert vs[:3] == [0.0] * 3     # 0 before 0.3 s; from t_3 = 0.3 s toward 1 m/s
    assert vs[3:6] == pytest.approx([0.05, 0.10, 0.15])
    assert vs[9] == pytest.approx(0.35) and vs[10] == pytest.approx(0.30)   # from t_10 = 1.0 s toward -0.5
    assert s.timeouts == 0


def test_error_state():
    ref = Reference(theta_w=1.0, dtheta_w=2.0, v=0.5, dpsi=0.0, position_gain=0.2, lean_gain=0.03)
    x = (1.5, 0.1, 3.0, -0.2)
    assert rate_reference(ref, 1.5) == pytest.approx(2.0 - 0.2 * 0.5)
    assert error_state(x, ref) == pytest.approx((0.5, 0.1, 3.0 - 1.9, -0.2))
    assert error_state(x, None) is x
