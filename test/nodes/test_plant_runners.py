"""The realtime loop's tick log (nodes.runtime.schedule): bounded memory on a run of days, the statistics of the list
it replaces."""
import numpy as np
import pytest

from mwip_ros.nodes.runtime.schedule import TickLog

pytestmark = pytest.mark.unit

H = 0.005


def _ticks(n, seed=1):
    rng = np.random.default_rng(seed)
    per = H + rng.normal(0, 2e-4, n - 1)
    per[rng.integers(0, n - 1, 80)] = 3 * H   # late ticks
    return np.concatenate([[100.0], 100.0 + np.cumsum(per)])


def test_a_short_run_gets_the_exact_statistics_of_every_tick():
    t = _ticks(TickLog.RESERVOIR)   # every period fits in the sample
    log = TickLog(1.5 * H)
    for x in t:
        log.append(float(x))
    per = np.diff(t) * 1e3
    assert len(log) == len(t) and log[-1] == t[-1] and log[-5] == t[-5]
    assert log[-400:] == list(t[-400:])
    assert np.percentile(log.periods_ms(), 99) == np.percentile(per, 99)
    assert log.max_period * 1e3 == per.max() and log.max_index == int(np.argmax(per))
    assert log.late == list(np.flatnonzero(per > 1.5 * H * 1e3)[:TickLog.MISSED])


def test_a_long_run_keeps_the_same_memory_and_a_fair_sample():
    """Not timed: the structures' sizes after 8,192 and after 200,000 ticks are the same; the maximum and the late
    ticks stay exact, the percentiles come from a uniform sample of every period."""
    t = _ticks(200_000, seed=2)
    log = TickLog(1.5 * H)
    sizes = []
    for i, x in enumerate(t):
        log.append(float(x))
        if i in (TickLog.RESERVOIR, len(t) - 1):
            sizes.append((log.recent.nbytes, log.intervals.sample.nbytes))
    assert sizes[0] == sizes[1] and len(log.late) == TickLog.MISSED   # 80 late ticks: the first 50 kept
    per = np.diff(t) * 1e3
    assert log.max_period * 1e3 == per.max() and len(log) == len(t)
    assert abs(np.percentile(log.periods_ms(), 50) - np.percentile(per, 50)) < 0.01   # ms; the spread is 0.2 ms
    assert log[-3000:] == list(t[-3000:])
    with pytest.raises(IndexError):
        log[-TickLog.RECENT - 1]
