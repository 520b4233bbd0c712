"""The driver's state machine (docs/theory.md 6.8): every transition, the latch, reset, refusals, the watchdog."""
import math

import pytest

from mwip_ros.core.safety import DISABLED, ENABLED, FAULT, FAULT_REASONS, DriverStateMachine, Transition, Watchdog

pytestmark = pytest.mark.unit


def test_start_states():
    assert DriverStateMachine().state == "enabled"
    assert DriverStateMachine(require_enable=True).state == "disabled"
    assert DriverStateMachine(require_enable=True).history == type(DriverStateMachine().history)([])


def test_enable_disable_transitions_and_answers():
    d = DriverStateMachine(require_enable=True)
    assert d.torque_gate(5.0) == 0.0
    a = d.enable(1.0)
    assert a.success and a.transition == Transition(1.0, "disabled", "enabled", "enable", "")
    assert d.state == "enabled" and d.torque_gate(5.0) == 5.0
    again = d.enable(1.5)
    assert again.success and again.transition is None and "already" in again.message
    b = d.disable(2.0)
    assert b.success and b.transition == Transition(2.0, "enabled", "disabled", "disable", "")
    assert d.torque_gate(-3.0) == 0.0
    c = d.disable(2.5)
    assert c.success and c.transition is None and "already" in c.message
    assert [tr.reason for tr in d.history] == ["enable", "disable"]


@pytest.mark.parametrize("start", [DISABLED, ENABLED])
@pytest.mark.parametrize("reason", FAULT_REASONS)
def test_every_fault_from_every_state_latches(start, reason):
    d = DriverStateMachine(require_enable=start == DISABLED)
    tr = d.fault(3.0, reason, "why")
    assert tr == Transition(3.0, start, "fault", reason, "why")
    assert d.state == FAULT and d.fault_reason == reason and d.torque_gate(10.0) == 0.0
    level, text = d.diagnostic()
    assert level == 2 and reason in text and "why" in text


def test_the_first_fault_stays():
    d = DriverStateMachine()
    d.fault(1.0, "watchdog", "no command for 0.1 s")
    assert d.fault(1.2, "fall", "tilted") is None
    assert d.fault_reason == "watchdog" and d.fault_t == 1.0 and d.suppressed == 1
    assert d.last_suppressed == (1.2, "fall", "tilted")
    assert len(d.history) == 1


def test_enable_in_fault_is_refused_disable_keeps_the_latch():
    d = DriverStateMachine(require_enable=True)
    d.enable(0.0)
    d.fault(1.0, "emergency_stop")
    a = d.enable(2.0)
    assert not a.success and a.transition is None
    assert "emergency_stop" in a.message and "reset" in a.message
    b = d.disable(2.5)
    assert b.success and b.transition is None and d.state == FAULT and "reset" in b.message


@pytest.mark.parametrize("require_enable, start", [(False, ENABLED), (True, DISABLED)])
def test_reset_clears_the_fault_back_to_the_start_state(require_enable, start):
    d = DriverStateMachine(require_enable=require_enable)
    d.fault(1.0, "fall", "|theta_b| = 1.1 rad")
    d.fault(1.1, "watchdog")
    a = d.reset(2.0)
    assert a.success and a.transition == Transition(2.0, FAULT, start, "reset", "")
    assert "fall" in a.message
    assert d.state == start and d.fault_reason is None and d.suppressed == 0
    b = d.reset(3.0)   # nothing to change
    assert b.success and b.transition is None


def test_reset_from_enabled_restores_disabled_when_enable_is_required():
    d = DriverStateMachine(require_enable=True)
    d.enable(0.0)
    a = d.reset(1.0)
    assert a.transition == Transition(1.0, ENABLED, DISABLED, "reset", "") and d.state == DISABLED


def test_bad_commands():
    d = DriverStateMachine(max_command=500.0)
    assert d.check_command(0.0, 499.0) is None and d.state == ENABLED
    tr = d.check_command(0.1, 501.0)
    assert tr.reason == "bad_command" and "501" in tr.detail
    for bad in (math.nan, math.inf, "x", None):
        e = DriverStateMachine()
        assert e.check_command(0.0, bad).reason == "bad_command"
    assert DriverStateMachine().check_command(0.0, 1e9) is None   # max_command 0: finite is enough


def test_fall_check_and_unknown_reason():
    d = DriverStateMachine()
    assert d.check_fall(0.0, 1.0, 1.0472) is None
    assert d.check_fall(0.1, -1.1, 1.0472).reason == "fall"
    assert DriverStateMachine().check_fall(0.0, math.nan, 1.0).reason == "fall"
    with pytest.raises(ValueError, match="overheat"):
        DriverStateMachine().fault(0.0, "overheat")
    with pytest.raises(ValueError, match="max_command"):
        DriverStateMachine(max_command=-1.0)


def test_transition_text_and_diagnostics():
    d = DriverStateMachine(require_enable=True)
    assert d.diagnostic() == (1, "disabled")
    d.enable(0.25)
    assert d.diagnostic() == (0, "enabled")
    tr = d.fault(1.5, "fall", "|theta_b| = 1.1 rad")
    assert tr.text() == "t = 1.500 s: enabled -> fault (fall: |theta_b| = 1.1 rad)"


def test_watchdog():
    w = Watchdog(0.1)
    assert not w.expired(100.0)            # not armed before the first command
    w.feed(1.0)
    assert not w.expired(1.09) and w.expired(1.1001)
    assert w.silence(1.05) == pytest.approx(0.05)
    w.feed(1.2)
    assert not w.expired(1.25)
    w.reset()
    assert not w.expired(5.0)
    off = Watchdog(0.0)
    off.feed(0.0)
    assert not off.expired(1e6)
    with pytest.raises(ValueError, match="watchdog_s"):
        Watchdog(-1.0)
