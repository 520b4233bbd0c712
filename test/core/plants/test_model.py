"""Eq. (1)-(7), (16)-(18): inertia terms, true dynamics, lumped disturbance, semi-strict-feedback form."""
import math

import numpy as np
import pytest

from mathfixtures import NOM, RNG, TRUE, random_state
from mwip_ros.core.plants.model import (Friction, State, lumped_disturbance, nominal_accel, plant_accel,
                                        semi_strict_feedback, x1_of)

pytestmark = pytest.mark.unit


def test_inertia_terms_eq2():
    # Hand-computed from Table II's nominal column.
    assert NOM.m11 == pytest.approx((210.6 + 29.0) * 0.254 ** 2 + 0.6)
    assert NOM.m12 == pytest.approx(210.6 * 0.267 * 0.254)
    assert NOM.m22 == pytest.approx(210.6 * 0.267 ** 2 + 55.0)
    assert NOM.G_b == pytest.approx(210.6 * 9.81 * 0.267)
    assert NOM.A_bar > 0  # eq. (38)

@pytest.mark.parametrize("trial", range(25))
def test_semi_strict_feedback_matches_direct_dynamics(trial):
    """Eq. (18a)/(18b) give the accelerations of eq. (7) (the nominal model driven by tau_d)."""
    x = random_state(RNG)
    q, dq = x.q, x.dq
    u = RNG.uniform(-200, 200)
    tau_d = RNG.uniform(-50, 50, size=2)
    ddq = nominal_accel(NOM, x, u, tau_d)
    # Direct check of eq. (17): M_hat q'' + N_hat = [u, 0] + tau_d, row by row.
    s, c = math.sin(q[1]), math.cos(q[1])
    row1 = NOM.m11 * ddq[0] + NOM.m12 * c * ddq[1] - (u + NOM.m12 * dq[1] ** 2 * s + tau_d[0])
    row2 = ((NOM.m11 + NOM.m12 * c) * ddq[0] + (NOM.m22 + NOM.m12 * c) * ddq[1]
            - (NOM.m12 * dq[1] ** 2 * s + NOM.G_b * s + tau_d[1]))
    assert abs(row1) < 1e-9 and abs(row2) < 1e-9
    x1 = x1_of(NOM, x)
    dx1, dx2, dx4 = semi_strict_feedback(NOM, (x1, q[1], dq[1], dq[0]), u, tau_d)
    # x1' by the chain rule of eq. (16)
    mc = NOM.m12 * c
    dx1_direct = (NOM.m11 + mc) * ddq[0] + (NOM.m22 + mc) * ddq[1] - NOM.m12 * s * dq[1] * (dq[0] + dq[1])
    assert dx1 == pytest.approx(dx1_direct, rel=1e-9, abs=1e-9)
    assert dx2 == pytest.approx(dq[1], rel=1e-9, abs=1e-12)
    assert dx4 == pytest.approx(ddq[0], rel=1e-9, abs=1e-9)

@pytest.mark.parametrize("trial", range(10))
def test_lumped_disturbance_reproduces_true_accelerations(trial):
    """Eq. (6)-(7): the nominal model driven by the true tau_d moves exactly like the true plant."""
    x = random_state(RNG)
    u, e1, e2 = RNG.uniform(-100, 100), RNG.uniform(-30, 30), RNG.uniform(-1, 1)
    ddq = plant_accel(TRUE, Friction(0.1, 0.7), x, u, e1, e2)
    tau_d = lumped_disturbance(NOM, x, ddq, u)
    np.testing.assert_allclose(nominal_accel(NOM, x, u, tau_d), ddq, rtol=1e-9, atol=1e-9)

def test_plant_matches_eq1_rows():
    x = State(0.3, -0.4, 1.2, -0.7)
    q, dq = x.q, x.dq
    fr, u, e1, e2 = Friction(0.1, 0.5), 12.0, 3.0, -0.5
    ddq = plant_accel(TRUE, fr, x, u, e1, e2)
    s, c = math.sin(q[1]), math.cos(q[1])
    r1 = TRUE.m11 * ddq[0] + TRUE.m12 * c * ddq[1] - (
        u - (fr.D_w + fr.D_b) * dq[0] + fr.D_b * dq[1] + TRUE.m12 * dq[1] ** 2 * s + e1)
    r2 = TRUE.m12 * c * ddq[0] + TRUE.m22 * ddq[1] - (
        -u - fr.D_b * (dq[1] - dq[0]) + TRUE.G_b * s + e2 - e1)
    assert abs(r1) < 1e-9 and abs(r2) < 1e-9
