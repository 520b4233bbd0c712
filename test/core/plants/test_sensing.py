"""Sensing and actuation: noise on its own stream, the encoder, the delays; off = the paper's numbers."""
import math

import numpy as np
import pytest

from mathfixtures import P_FILE
from mwip_ros import params as P
from mwip_ros.core.plants.model import State
from mwip_ros.core.plants.sensing import Actuator, SensingConfig, Sensors, measure
from mwip_ros.core.closed_loop.sim import simulate

pytestmark = pytest.mark.unit

BASE = P.merged_values(P.load_param_file(P_FILE))


def test_every_option_defaults_to_off():
    cfg = P.closed_loop(BASE).plant.sensing
    assert cfg == SensingConfig() and not cfg.active


def test_noise_has_its_own_stream_and_leaves_the_friction_draws_alone():
    """A noise far below rounding changes nothing measurable: had it taken D_w's draws, theta_b would move by
    tenths of a degree."""
    base = simulate(P.closed_loop(BASE, duration=3.0))
    tiny = simulate(P.closed_loop(dict(BASE, **{"sensors.noise_std.dtheta_b": 1e-30}), duration=3.0))
    for c in ("theta_b", "u", "tau_d1"):
        np.testing.assert_allclose(tiny[c], base[c], rtol=0, atol=1e-12)
    noisy = simulate(P.closed_loop(dict(BASE, **{"sensors.noise_std.dtheta_b": 0.05}), duration=3.0))
    assert np.abs(noisy["u"] - base["u"]).max() > 1.0


def test_the_noise_has_the_stated_deviation_per_channel():
    std = (0.01, 0.002, 0.3, 0.05)
    s = Sensors.for_plant(SensingConfig(noise_std=std), seed=5)
    x = State(1.0, -0.2, 3.0, 0.5)
    err = np.array([np.subtract(s.sample(x, 0.0)[0], x) for _ in range(20000)])
    np.testing.assert_allclose(err.std(axis=0), std, rtol=0.03)
    np.testing.assert_allclose(err.mean(axis=0), 0.0, atol=4 * max(std) / math.sqrt(20000))


def test_the_encoder_rounds_theta_w_to_the_nearest_count_only():
    q = 2 * math.pi / 1024
    for w in (0.0, 0.4 * q, 0.6 * q, -0.6 * q, 1000.3 * q, -7.49 * q):
        got = measure(State(w, 0.1, 0.2, 0.3), None, (0.0,) * 4, 1024)
        assert got[0] == pytest.approx(q * round(w / q), abs=1e-15) and got[1:] == (0.1, 0.2, 0.3)
    arr = measure(State(np.array([0.4 * q, 0.6 * q]), 0.0, 0.0, 0.0), None, (0.0,) * 4, 1024, np)
    np.testing.assert_allclose(arr[0], [0.0, q])


def test_delays_give_the_measurement_and_the_command_of_d_periods_ago():
    s = Sensors(2, 0, (0.0,) * 4)
    out = [s.sample(State(k, 0.0, 0.0, 0.0), float(k)) for k in range(6)]
    assert [o[0][0] for o in out] == [0, 0, 0, 1, 2, 3] and [o[1] for o in out] == [0.0, 0.0, 0.0, 1.0, 2.0, 3.0]
    a = Actuator(3)
    assert [a.apply(float(k + 1)) for k in range(6)] == [0.0, 0.0, 0.0, 1.0, 2.0, 3.0]
    assert [Actuator(0).apply(5.0)] == [5.0]


def test_a_delay_costs_the_loop_and_the_table_keeps_the_true_state():
    run = simulate(P.closed_loop(dict(BASE, **{"actuator.delay_periods": 2}), duration=1.0))
    assert run["u"][0] == run["u"][1] == 0.0 and run["u"][2] != 0.0   # zero torque until the first command acts
    assert run["theta_b"][0] == BASE["initial.theta_b"]
