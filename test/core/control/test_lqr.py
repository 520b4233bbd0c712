"""The LQR baseline: the linearization, the gain against an independent Riccati iteration, the law, bad weights."""
import math

import numpy as np
import pytest

from mathfixtures import NOM, random_state
from mwip_ros.core.control.controller import DscController, DscGains
from mwip_ros.core.control.lqr import LqrController, LqrDesignError, linearization, lqr_gain, lqr_law, weights
from mwip_ros.core.plants.model import State, nominal_accel
from mwip_ros.core.control.lqr import NO_DESIGN

pytestmark = pytest.mark.unit

H = 0.005
Q, R = [100.0, 10.0, 1.0], 0.01


def test_the_linearization_is_the_nominal_models_jacobian_at_upright():
    """A and B against finite differences of the nominal model (eq. 7 with tau_d = 0)."""
    A, B = linearization(NOM)

    def f(z, u):   # z = [theta_b, theta_b', theta_w'] -> z'
        ddw, ddb = nominal_accel(NOM, State(0.0, z[0], z[2], z[1]), u, (0.0, 0.0))
        return np.array([z[1], ddb, ddw])

    eps = 1e-6
    J = np.column_stack([(f(eps * e, 0.0) - f(-eps * e, 0.0)) / (2 * eps) for e in np.eye(3)])
    Bn = (f(np.zeros(3), eps) - f(np.zeros(3), -eps)) / (2 * eps)
    np.testing.assert_allclose(A, J, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(B[:, 0], Bn, rtol=1e-6, atol=1e-9)


def test_the_gain_equals_a_riccati_iteration_and_stabilizes_the_discrete_model():
    from scipy.linalg import expm
    A, B = linearization(NOM)
    M = expm(np.block([[A, B], [np.zeros((1, 4))]]) * H)    # zero-order hold, written out
    Ad, Bd = M[:3, :3], M[:3, 3:]
    P = np.diag(Q)
    for _ in range(200000):   # the Riccati difference equation, iterated to its fixed point
        Kp = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
        P_next = np.diag(Q) + Ad.T @ P @ (Ad - Bd @ Kp)
        if np.abs(P_next - P).max() < 1e-9 * np.abs(P).max():
            break
        P = P_next
    K = lqr_gain(NOM, H, Q, R)
    np.testing.assert_allclose(K, Kp[0], rtol=1e-6)
    assert np.abs(np.linalg.eigvals(Ad - Bd @ np.array([K]))).max() < 1.0


def test_the_law_with_floats_and_arrays_and_the_observer_term_of_dscndo():
    K = lqr_gain(NOM, H, Q, R)
    rng = np.random.default_rng(3)
    xs = [random_state(rng) for _ in range(20)]
    taus = [tuple(rng.uniform(-20, 20, 2)) for _ in range(20)]
    outs = [lqr_law(NOM, K, x, t) for x, t in zip(xs, taus)]
    for x, out in zip(xs, outs):
        assert out.u_dsc == pytest.approx(-(K[0] * x[1] + K[1] * x[3] + K[2] * x[2]))
    arr = lqr_law(NOM, K, State(*np.array(xs).T), tuple(np.array(taus).T), np)
    np.testing.assert_array_equal(arr.u, [o.u for o in outs])
    # the observer term is DSCNDO's: u_taud of eq. (20) for the same state and estimate
    dsc = DscController(NOM, DscGains(6.0, 6.0, 0.1), H)
    for x, t, o in zip(xs, taus, outs):
        assert o.u_taud == dsc.step(x, t).u_taud and o.u == o.u_dsc - o.u_taud
    plain = LqrController(NOM, K, use_observer=False)
    assert plain.step(xs[0], taus[0]).u_taud == 0.0 and math.isnan(plain.step(xs[0]).x4d)


@pytest.mark.parametrize("Qv, Rv, key, words", [
    ([-1.0, 1.0, 1.0], R, "lqr.Q", "positive semidefinite"),
    ([1.0, 2.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], R, "lqr.Q", "symmetric"),
    ([1.0, 1.0], R, "lqr.Q", "3 entries"),
    (Q, 0.0, "lqr.R", "> 0"),
    (Q, -1.0, "lqr.R", "> 0"),
    # Degenerate weights: the Riccati solve may fail outright or return a P whose gain leaves a mode on the
    # unit circle, depending on the CPU's LAPACK path. Either way the refusal starts with the same words (NO_DESIGN).
    ([100.0, 10.0, 0.0], R, "lqr.Q", NO_DESIGN),        # the wheel-speed mode left on the unit circle
    ([0.0, 0.0, 0.0], R, "lqr.Q", NO_DESIGN),
])
def test_weights_that_give_no_design_are_refused_naming_the_parameter(Qv, Rv, key, words):
    with pytest.raises(LqrDesignError) as e:
        lqr_gain(NOM, H, Qv, Rv)
    assert e.value.key == key and words in e.value.reason, str(e.value)


def test_a_full_symmetric_q_equals_its_diagonal_form():
    full = list(np.diag(Q).ravel())
    assert weights(full, R)[0].tolist() == np.diag(Q).tolist()
    assert lqr_gain(NOM, H, full, R) == lqr_gain(NOM, H, Q, R)
