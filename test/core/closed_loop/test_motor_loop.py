"""The motor in the closed loop (theory.md 6.7): a run recomputed period by period from its own rows, and the observer
fed the torque that acted."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.closed_loop import loop as core_loop
from mwip_ros.core.plants.model import Friction, plant_accel
from mwip_ros.core.control.observer import DiscreteObserver
from mwip_ros.core.closed_loop.sim import simulate

pytestmark = pytest.mark.unit

CONFIG = Path(__file__).resolve().parents[3] / "config"
MOTOR = {"motor.enabled": True}   # docs/theory.md 6.7's drive: K_t 2, R 0.15, V_max 48, I_max 60 (120 N m)


def _values(**over):
    v = P.merged_values(P.load_param_file(CONFIG / "paper.yaml"))
    v.update(MOTOR, **over)
    return v


def _drive(u_cmd, w, K_t=2.0, R=0.15, V_max=48.0, I_max=60.0):
    """docs/theory.md 6.7 written out here (not the code under test)."""
    i_set = min(max(u_cmd / K_t, -I_max), I_max)
    V = min(max(R * i_set + K_t * w, -V_max), V_max)
    return K_t * min(max((V - K_t * w) / R, -I_max), I_max)


def test_each_period_of_a_run_recomputed_from_its_rows():
    """From row k's true state and command: a textbook RK4 with the drive's torque at every stage gives row
    k + 1's state and row k's u_applied (the RK4-weighted mean of the stage torques) to 1e-9."""
    loop = P.closed_loop(_values(), controller="dscndo", duration=2.0)
    run = simulate(loop)
    c, pc = run.columns, loop.plant
    n, h, ns = len(run), pc.h, pc.substeps
    dw = [max(0.0, pc.D_w_mean + math.sqrt(pc.D_w_variance) * z)
          for z in np.random.default_rng(pc.seed).standard_normal(n + 1)]
    saturated = 0
    for k in range(n - 1):
        x = np.array([c["theta_w"][k], c["theta_b"][k], c["dtheta_w"][k], c["dtheta_b"][k]])
        u_cmd, fr, dt = c["u"][k], Friction(pc.D_b, dw[k]), h / ns
        acted = 0.0

        def f(t, x):
            u = _drive(u_cmd, x[2] - x[3])
            return np.concatenate([x[2:], plant_accel(pc.actual, fr, x, u, pc.tau_ext1(t), pc.tau_ext2(t))]), u

        for i in range(ns):
            t = k * h + i * dt
            k1, u1 = f(t, x)
            k2, u2 = f(t + dt / 2, x + dt / 2 * k1)
            k3, u3 = f(t + dt / 2, x + dt / 2 * k2)
            k4, u4 = f(t + dt, x + dt * k3)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            acted += (u1 + 2 * u2 + 2 * u3 + u4) / (6 * ns)
        nxt = [c[name][k + 1] for name in ("theta_w", "theta_b", "dtheta_w", "dtheta_b")]
        np.testing.assert_allclose(nxt, x, rtol=0, atol=1e-9, err_msg=f"k = {k}")
        assert abs(c["u_applied"][k] - acted) <= 1e-9, (k, c["u_applied"][k], acted)
        saturated += abs(acted - u_cmd) > 1.0
    assert saturated > 10   # the drive does bind in this run: the check above is not of u = u_cmd
    assert math.isnan(c["u_applied"][-1])


def test_the_observer_integrates_the_torque_that_acted_not_the_command(monkeypatch):
    """The observer's torque at state k is row k - 1's u_applied; fed the command instead (the mistake theory.md 6.7
    warns of), DSCNDO winds up and falls from the paper's initial tilt."""
    seen = []
    update = DiscreteObserver.update
    monkeypatch.setattr(DiscreteObserver, "update", lambda self, x, u: (seen.append(u), update(self, x, u))[1])
    loop = P.closed_loop(_values(), controller="dscndo")
    run = simulate(loop)
    assert not run.fallen
    acted, cmd = run["u_applied"], run["u"]
    np.testing.assert_array_equal(seen[1:], acted[:-1])
    assert np.max(np.abs(acted[:-1] - cmd[:-1])) > 10.0
    monkeypatch.setattr(DiscreteObserver, "update", update)

    sense = core_loop.PlantSide.sense

    def fed_the_command(self):
        x, _ = sense(self)
        return x, self.plant.u_cmd_prev
    monkeypatch.setattr(core_loop.PlantSide, "sense", fed_the_command)
    assert simulate(loop).fallen


def test_motor_off_is_the_paper_bit_for_bit():
    base = P.merged_values(P.load_param_file(CONFIG / "paper.yaml"))
    off = simulate(P.closed_loop(dict(base, **{"motor.enabled": False, "motor.current_limit": 1.0}),
                                 controller="dscndo", duration=1.0))
    ref = simulate(P.closed_loop(base, controller="dscndo", duration=1.0))
    assert "u_applied" not in off.columns
    for name in ("theta_b", "u", "tau_hat1"):
        np.testing.assert_array_equal(off[name], ref[name])


def test_motor_parameters_out_of_range_are_refused_naming_the_key():
    with pytest.raises(P.ParamError, match="motor.resistance"):
        P.specs_for("plant_sim")["motor.resistance"].validate(0.0)


def test_a_disabled_driver_applies_no_torque_with_the_wheel_spinning_faster_than_v_max_over_k_t():
    """require_enable: true and nobody to enable (the offline loop): the bridge is open, no current flows, so
    u_applied is exactly 0 in every row although the wheel turns at 40 rad/s > V_max / K_t = 24 rad/s (fed the
    gated zero command, the drive model drove the back-EMF's braking current: -120 N m in 100 of 101 rows)."""
    loop = P.closed_loop(_values(**{"require_enable": True, "initial.theta_b": 0.0, "initial.dtheta_w": 40.0}),
                         controller="dscndo", duration=0.5)
    run = simulate(loop)
    w_rel = run["dtheta_w"] - run["dtheta_b"]
    assert len(run) == 101 and np.all(w_rel > 48.0 / 2.0)     # spinning faster than V_max / K_t in every row
    assert np.all(run["u"] == 0.0)                              # the gated command
    assert np.all(run["u_applied"][:-1] == 0.0), run["u_applied"][:5]   # and no torque: the bridge is open
