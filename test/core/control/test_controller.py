"""DSC / DSCNDO (eq. 19-28) and the exact filter step."""
import math

import numpy as np
import pytest

from mathfixtures import NOM, PAPER_GAINS, exact_model_plant as _exact_model_plant
from mwip_ros.core.control.controller import DscController, DscGains, dsc_law, filter_step
from mwip_ros.core.plants.model import State, nominal_accel
from mwip_ros.core.plants.plant import PlantSim

pytestmark = pytest.mark.unit


def test_dsc_drives_theta_b_to_zero_with_perfect_model():
    plant = PlantSim(_exact_model_plant())
    ctrl = DscController(NOM, PAPER_GAINS, plant.cfg.h, use_observer=False)
    thetas = []
    for _ in range(2000):
        u = ctrl.step(plant.x).u
        plant.step(u)
        thetas.append(plant.x[1])
    assert abs(thetas[0]) > 0.1
    assert max(abs(x) for x in thetas[-400:]) < 1e-4

def test_filter_step_is_exact():
    """x4d after one period equals the solution of tau4 x4d' + x4d = x4_bar (eq. 25)."""
    x4d, x4_bar, h, tau4 = 0.3, -1.2, 0.005, 0.1
    # integrate the ODE finely with RK4
    n, y = 1000, x4d
    dt = h / n

    def f(y):
        return (x4_bar - y) / tau4

    for _ in range(n):
        k1 = f(y)
        k2 = f(y + dt / 2 * k1)
        k3 = f(y + dt / 2 * k2)
        k4 = f(y + dt * k3)
        y += dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert filter_step(x4d, x4_bar, h, tau4) == pytest.approx(y, rel=1e-12)

def test_dsc_law_makes_S2_converge_at_k2():
    """Eq. (27)-(28): with the law applied, the nominal model gives S2' = -k2 S2 when tau_hat = tau_d."""
    g = DscGains(k1=6.0, k2=4.0, tau4=0.1)
    x = State(0.0, 0.2, -0.5, 0.3)
    tau_d = np.array([7.0, -2.0])
    out = dsc_law(NOM, g, x, x4d=0.1, tau_hat=tau_d)
    ddq = nominal_accel(NOM, x, out.u, tau_d)
    dS2 = ddq[0] - (out.x4_bar - out.x4d) / g.tau4
    assert dS2 == pytest.approx(-g.k2 * out.S2, rel=1e-9)
    # plain DSC ignores tau_hat
    assert dsc_law(NOM, g, x, 0.1, None).u == pytest.approx(out.u_dsc)
    c = math.cos(0.2)
    assert out.u == pytest.approx(out.u_dsc - (tau_d[0] - NOM.m12 * c / (NOM.m22 + NOM.m12 * c) * tau_d[1]))
