"""The trajectory table: rows in column order, internals optional, estimates joined by stamp."""
import math

import numpy as np
import pytest

from mwip_ros.core.control.controller import ControlOutput
from mwip_ros.core.plants.model import State
from mwip_ros.core.closed_loop.trajectory import COLUMNS, TRAJECTORY_COLUMNS, TrajectoryTable, join_estimates

pytestmark = pytest.mark.unit


def test_rows_hold_the_state_command_estimate_truth_and_internals_in_column_order():
    table = TrajectoryTable(internals=True)
    out = ControlOutput(u=1.0, u_dsc=2.0, u_taud=3.0, S1=4.0, S2=5.0, x1=6.0, x4_bar=7.0, x4d=8.0)
    table.append(0.005, State(0.1, 0.2, 0.3, 0.4), 1.5, (9.0, 10.0), (11.0, 12.0), out)
    run = table.trajectory("r", False, 0.005)
    assert list(run.columns) == COLUMNS
    row = [run[c][0] for c in COLUMNS]
    assert row == [0.005, 0.1, 0.2, 0.3, 0.4, 1.5, 9.0, 10.0, 11.0, 12.0, 2.0, 3.0, 4.0, 5.0, 7.0, 8.0]
    assert len(run) == len(table) == 1 and table.last("u") == 1.5


def test_a_source_without_estimates_writes_nan_and_the_join_fills_them_by_stamp():
    table = TrajectoryTable()
    h = 0.005
    for k in range(5):
        table.append(k * h, State(0.0, 0.01 * k, 0.0, 0.0), float(k), tau_d=(1.0, 2.0))
    run = table.trajectory("plant", False, h)
    assert list(run.columns) == TRAJECTORY_COLUMNS
    assert np.isnan(run["tau_hat1"]).all() and np.isnan(run["tau_hat2"]).all()
    # the observer's stamps, in seconds computed another way (k * 5e6 ns * 1e-9); one missing, one foreign
    est = [(k * 5_000_000 * 1e-9, 10.0 + k, -float(k)) for k in (0, 1, 3, 4)] + [(0.0123, 99.0, 99.0)]
    joined = join_estimates(run, est)
    np.testing.assert_array_equal(joined["tau_hat1"][[0, 1, 3, 4]], [10.0, 11.0, 13.0, 14.0])
    np.testing.assert_array_equal(joined["tau_hat2"][[0, 1, 3, 4]], [0.0, -1.0, -3.0, -4.0])
    assert math.isnan(joined["tau_hat1"][2]) and 99.0 not in joined["tau_hat1"]
    assert np.isnan(run["tau_hat1"]).all()  # the original is unchanged
    np.testing.assert_array_equal(joined["u"], run["u"])


def test_a_bounded_table_keeps_the_window_and_the_newest_row_and_streams_every_row_final():
    """A node's table on a run of days: rows up to keep_until and the newest in memory, whatever the number of
    periods; each row handed to the sink once, final (set_drive's values in it), in order; the saturated periods
    counted over the whole run."""
    got = []
    table = TrajectoryTable(drive=True, keep_until=0.5, sink=lambda k, row: got.append((k, tuple(row))))
    h, n = 0.005, 20_000
    sizes = []
    for k in range(n):
        table.append(k * h, State(0.0, 1e-3 * k, 0.0, 0.0), float(k))
        table.set_drive(float(k) / 2, 1 if k % 3 == 0 else 0)
        if k in (1_000, n - 1):
            sizes.append(len(table.rows))
    kept = int(0.5 / h) + 1
    assert sizes == [(kept + 1) * table.width] * 2   # bounded: the same size after 1,000 and 20,000 periods
    assert len(table) == n and table.dropped == n - kept - 1 and table.last("t") == (n - 1) * h
    assert len(got) == n - 1   # the newest is not final yet
    table.flush()
    table.flush()
    assert [k for k, _ in got] == list(range(n))
    ui, si = table.names.index("u_applied"), table.names.index("drive_saturation")
    assert all(row[0] == k * h and row[ui] == k / 2 and row[si] == (1.0 if k % 3 == 0 else 0.0) for k, row in got)
    assert table.saturated == len(range(0, n, 3))
    run = table.trajectory("x", False, h)
    assert len(run) == kept + 1 and run.t[kept - 1] == (kept - 1) * h and run.t[-1] == (n - 1) * h


def test_an_unbounded_table_is_unchanged():
    table = TrajectoryTable()
    for k in range(100):
        table.append(k * 0.01, State(0.0, 0.0, 0.0, 0.0), 1.0)
    assert len(table) == 100 and table.dropped == 0 and len(table.trajectory("x", False, 0.01)) == 100
