"""core.mobile_base.path: the ideal path of the references and the cross-track error, against paths computed by hand."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mwip_ros.core.mobile_base.path import cross_track, ideal_path, path_metrics

pytestmark = pytest.mark.unit


def test_a_straight_run_then_a_quarter_turn_in_place_then_a_side():
    h = 0.01
    v = [1.0] * 100 + [0.0] * 100 + [1.0] * 100
    w = [0.0] * 100 + [math.pi / 2] * 100 + [0.0] * 100
    x, y, psi = ideal_path(v, w, h)
    # after 1 s at 1 m/s: (1, 0); after the turn: psi = pi/2 at (1, 0); the last sample is one period before the end
    assert (x[100], y[100], psi[100]) == pytest.approx((1.0, 0.0, 0.0), abs=1e-12)
    assert (x[200], y[200], psi[200]) == pytest.approx((1.0, 0.0, math.pi / 2), abs=1e-12)
    assert (x[-1], y[-1]) == pytest.approx((1.0, 0.99), abs=1e-12)


def test_a_circle():
    h, w = 0.005, 0.5
    n = int(round(2 * math.pi / w / h))
    x, y, _ = ideal_path([0.5] * n, [w] * n, h)
    assert np.hypot(x, y - 1.0) == pytest.approx(np.ones(n), abs=1e-12)   # radius v / w = 1 m about (0, 1)


def test_cross_track_is_the_distance_to_the_nearest_segment():
    ix, iy = np.array([0.0, 2.0, 2.0]), np.array([0.0, 0.0, 2.0])
    px, py = np.array([1.0, 2.5, 3.0, -1.0, 1.0]), np.array([0.3, 1.0, 3.0, 0.0, 1.0])
    assert cross_track(px, py, ix, iy) == pytest.approx([0.3, 0.5, math.sqrt(2.0), 1.0, 1.0], abs=1e-15)


def test_path_metrics_of_a_run_on_its_path_and_one_beside_it():
    h, n = 0.01, 300
    v = np.r_[np.ones(100), np.zeros(100), np.ones(100)]
    w = np.r_[np.zeros(100), np.full(100, math.pi / 2), np.zeros(100)]
    x, y, psi = ideal_path(v, w, h)
    th = np.r_[np.zeros(100), np.full(100, 0.02), np.zeros(100)]
    th[150] = -0.05
    cols = {"x": x, "y": y + 0.1 * (x > 0.5) * (x < 0.9), "yaw": psi, "v_ref": v, "dpsi_ref": w, "theta_b": th}
    m = path_metrics(cols, h)
    assert m["cross_max"] == pytest.approx(0.1, abs=1e-12)
    assert m["turn_max_lean"] == 0.05 and m["heading_err"] == pytest.approx(0.0, abs=1e-15)
    on = path_metrics(dict(cols, y=y), h)
    assert on["cross_rms"] == 0.0 and on["final_offset"] == 0.0
    assert n == len(x)
