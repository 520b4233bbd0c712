"""The driver's state machine (docs/theory.md 6.8): every transition, the latch, reset, refusals, the watchdog."""
import math

import pytest

from mwip_ros.core.control.safety import (DISABLED, ENABLED, FAULT, FAULT_REASONS, DriverStateMachine, Transition,
                                          Watchdog)

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


# --- levels: the e-stop and the estimator's health (issue 31: no reset or enable while one is asserted) -------
@pytest.mark.parametrize("require_enable", [False, True])
def test_the_emergency_stop_is_a_level_pressed_reset_refused_released_reset_succeeds(require_enable):
    d = DriverStateMachine(require_enable=require_enable)
    d.enable(0.0)
    tr = d.set_level(1.0, "emergency_stop", True, "a std_msgs/Bool true")
    assert tr == Transition(1.0, ENABLED, FAULT, "emergency_stop", "a std_msgs/Bool true")
    assert d.set_level(1.1, "emergency_stop", True) is None and d.suppressed == 0   # the same level, heard again
    a = d.reset(2.0)                                           # still pressed: refused, naming the e-stop
    assert not a.success and a.transition is None and d.state == FAULT and d.torque_gate(7.0) == 0.0
    assert "emergency stop is still asserted" in a.message and "release" in a.message, a.message
    b = d.enable(2.1)
    assert not b.success and d.state == FAULT
    assert "held: emergency_stop" in d.diagnostic()[1]
    assert d.set_level(3.0, "emergency_stop", False) is None and d.state == FAULT   # released: still latched
    c = d.reset(4.0)
    start = DISABLED if require_enable else ENABLED            # the reset policy: the start state, never more
    assert c.success and c.transition == Transition(4.0, FAULT, start, "reset", "") and "emergency_stop" in c.message
    assert [tr.reason for tr in d.history] == ["enable"] * require_enable + ["emergency_stop", "reset"]


def test_the_estimators_error_level_held_refuses_reset_until_it_reports_ok_or_warn():
    d = DriverStateMachine()
    d.set_level(1.0, "estimator_unhealthy", True, "/state_estimator: diverged")
    assert d.state == FAULT and d.fault_reason == "estimator_unhealthy"
    for t in (2.0, 3.0):   # refused as long as the latest known level is ERROR
        a = d.reset(t)
        assert not a.success and "state estimator still reports ERROR" in a.message and d.state == FAULT, a.message
    d.set_level(4.0, "estimator_unhealthy", False)   # OK or WARN
    assert d.reset(5.0).success and d.state == ENABLED


def test_an_emergency_stop_during_a_watchdog_fault_is_kept_and_refuses_the_reset_until_released():
    d = DriverStateMachine()
    d.fault(1.0, "watchdog", "no command for 0.5 s")
    assert d.set_level(1.5, "emergency_stop", True) is None   # during another fault: no transition ...
    assert d.fault_reason == "watchdog" and d.suppressed == 1 and "emergency_stop" in d.held   # ... but held
    a = d.reset(2.0)
    assert not a.success and "emergency stop" in a.message and "watchdog" in a.message and d.state == FAULT
    assert d.fault_reason == "watchdog"                       # nothing was forgotten by the refused reset
    d.set_level(3.0, "emergency_stop", False)
    assert d.reset(4.0).success and d.state == ENABLED


def test_a_released_level_asserted_again_faults_again_and_unknown_levels_are_refused():
    d = DriverStateMachine()
    d.set_level(1.0, "emergency_stop", True)
    d.set_level(2.0, "emergency_stop", False)
    assert d.reset(3.0).success
    assert d.set_level(4.0, "emergency_stop", True).reason == "emergency_stop"
    with pytest.raises(ValueError, match="watchdog"):
        d.set_level(5.0, "watchdog", True)


def test_the_watchdog_counts_from_the_first_state_when_no_command_ever_comes():
    w = Watchdog(0.5)
    w.arm(10.0)                          # the first state is out
    assert not w.expired(10.5) and w.expired(10.5001) and not w.answered
    assert w.silence(10.6) == pytest.approx(0.6)
    w.arm(10.4)                          # armed already: the count does not restart
    assert w.expired(10.6)
    w.feed(11.0)
    assert w.answered and not w.expired(11.4)
    w.reset()
    assert not w.expired(100.0) and not w.answered
