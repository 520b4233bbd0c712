"""The plant's progress line's steps/s (nodes.runtime.diagnostics.StepRate): right after a reset (issue 29, item 9)."""
import pytest

from mwip_ros.nodes.runtime.diagnostics import StepRate

pytestmark = pytest.mark.unit


def test_the_steps_per_second_line_is_right_after_a_reset():
    """The plant's progress line's rate (nodes.runtime.diagnostics.StepRate) from a count that grows across resets:
    200 Hz for 10 s with resets at 3 s and 7 s reads 200 steps/s (k / time since the start read 4 to 15 after them)."""
    rate = StepRate(window_s=5.0)
    assert rate.add(100.0, 0) is None
    for t in (2.0, 4.0, 6.0, 8.0, 10.0):
        r = rate.add(100.0 + t, int(200 * t))
        assert r == pytest.approx(200.0), (t, r)
    assert len(rate.samples) <= 4   # one window kept
    assert rate.add(112.0, 2000 + 100) == pytest.approx((2100 - 1200) / 6.0)   # the last 5+ s: a slowdown shows
