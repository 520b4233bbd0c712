"""The observer: eq. (15) equals eq. (12), the discrete form is Euler, and it converges at the predicted rate."""
import math

import numpy as np
import pytest
from scipy.linalg import expm

from mathfixtures import NOM, PAPER_GAINS, RNG, UPRIGHT, exact_model_plant as _exact_model_plant, random_state
from mwip_ros.core.control.controller import DscController
from mwip_ros.core.plants.model import mass_matrix
from mwip_ros.core.control.observer import DiscreteObserver, error_rates, gain_matrix, z_dot, z_dot_explicit
from mwip_ros.core.plants.plant import PlantSim

pytestmark = pytest.mark.unit


@pytest.mark.parametrize("trial", range(25))
def test_observer_eq15_equals_eq12(trial):
    X = RNG.uniform(0, 150, size=(2, 2))
    x = random_state(RNG)
    u, z = RNG.uniform(-200, 200), RNG.uniform(-100, 100, size=2)
    np.testing.assert_allclose(z_dot_explicit(NOM, X, x, u, z), z_dot(NOM, X, x, u, z),
                               rtol=1e-10, atol=1e-9)

def test_discrete_observer_is_euler_of_eq12():
    X = gain_matrix([100.0, 5.0, -3.0, 80.0])
    h = 0.005
    obs = DiscreteObserver(NOM, X, h)
    z = None
    prev = None
    for k in range(30):
        x = random_state(RNG)
        dq = x.dq
        u_prev = RNG.uniform(-100, 100)
        tau_hat = obs.update(x, u_prev)
        z = -X @ np.array(dq) if z is None else z + h * z_dot(NOM, X, prev, u_prev, z)
        prev = x
        np.testing.assert_allclose(tau_hat, z + X @ np.array(dq), rtol=1e-10, atol=1e-9)


def test_observer_converges_at_the_predicted_rate():
    """Exact model, constant injected disturbance: tau_hat -> tau_d with e' = -X M_hat^-1 e."""
    h = 0.005
    tau_const = np.array([20.0, 5.0])
    cfg = _exact_model_plant(tuple(tau_const), theta_b0=0.0, h=h)
    plant = PlantSim(cfg)
    X = gain_matrix([100.0, 0.0, 0.0, 100.0])
    obs = DiscreteObserver(NOM, X, h)
    ctrl = DscController(NOM, PAPER_GAINS, h, use_observer=False)  # keeps it upright, independent of tau_hat
    errs, ts, thetas = [], [], []
    for k in range(1600):  # 8 s: the slow mode decays at ~1.4 /s
        tau_hat = obs.update(plant.x, plant.u_prev)
        u = ctrl.step(plant.x).u
        # the plant's true lumped disturbance is the injected one (exact model, no friction)
        np.testing.assert_allclose(plant.lumped_disturbance(u), tau_const, atol=1e-8)
        errs.append(tau_const - tau_hat)
        ts.append(plant.t)
        thetas.append(plant.x[1])
        plant.step(u)
    errs = np.array(errs)
    assert np.abs(errs[-1]).max() < 1e-3 * np.abs(tau_const).max()  # converged
    # Rate: the body stays near upright, so M_hat(q) ~ M_hat(0); compare with expm(-X M0^-1 t) e0.
    assert max(abs(x) for x in thetas) < 0.05
    F = X @ np.linalg.inv(mass_matrix(NOM, UPRIGHT))
    lam = np.sort(error_rates(NOM, X, UPRIGHT).real)
    assert lam[0] > 0
    for i in (20, 60, 120, 200):
        predicted = expm(-F * ts[i]) @ errs[0]
        assert np.linalg.norm(errs[i] - predicted) < 0.03 * np.linalg.norm(errs[0]), i
    # The slowest eigenvalue sets the tail: |e| decays like exp(-lam_min t).
    ratio = np.linalg.norm(errs[300]) / np.linalg.norm(errs[200])
    assert ratio == pytest.approx(math.exp(-lam[0] * (ts[300] - ts[200])), rel=0.05)


def _stiff_gain():
    """A gain whose X M_hat^-1 has an eigenvalue of 180 1/s (Upkie's, config/upkie.yaml): one Euler step of
    h = 5 ms is stable (180 h = 0.9 < 2), one of 10 h is not (|1 - 9| = 8)."""
    X = np.diag([180.0, 2.4]) @ mass_matrix(NOM, UPRIGHT)
    rates = np.sort(error_rates(NOM, X, UPRIGHT).real)
    assert rates[-1] == pytest.approx(180.0, rel=1e-9)
    return X


@pytest.mark.parametrize("gap", [2, 3, 10, 14])
def test_a_gap_of_n_periods_is_n_steps_of_one_period_with_the_state_held(gap):
    """A realtime observer whose states come n periods apart (update(x, u, n h)) integrates eq. (12) in n explicit
    Euler steps of one period, x_{k-1} and u held (the torque the driver held; nothing else is known of the gap): the
    same as an observer called every period with the state repeated.  One step of n h (before issue 49's mend)
    multiplied the error by 1 - 180 n h: -8 at n = 10, and diverged."""
    h = 0.005
    X = _stiff_gain()
    gapped, every = DiscreteObserver(NOM, X, h), DiscreteObserver(NOM, X, h)
    rng = np.random.default_rng(gap)
    states = [tuple(rng.uniform(-0.05, 0.05, 4)) for _ in range(20)]
    torques = list(rng.uniform(-5.0, 5.0, 20))
    gapped.update(states[0], 0.0)
    every.update(states[0], 0.0)
    for j in range(1, len(states)):
        for _ in range(gap - 1):                 # the periods in between: the state of the gap's start again
            every.update(states[j - 1], torques[j])
        want = every.update(states[j], torques[j])
        got = gapped.update(states[j], torques[j], gap * h)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
        assert max(abs(v) for v in got) < 1e3   # (one step of n h: 8^j)


def test_one_period_given_explicitly_is_the_lockstep_step():
    """update(x, u, h) with h the period is bit for bit update(x, u): lockstep (no h given) is unchanged."""
    h = 0.005
    X = _stiff_gain()
    a, b = DiscreteObserver(NOM, X, h), DiscreteObserver(NOM, X, h)
    for k in range(10):
        x, u = random_state(RNG), RNG.uniform(-10, 10)
        assert a.update(x, u) == b.update(x, u, None if k % 2 else h)
