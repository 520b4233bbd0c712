"""The plant stepper: written-out RK4 of eq. (1), D_w per period."""
import math

import numpy as np
import pytest

from mathfixtures import NOM, TRUE
from mwip_ros.core.plants.model import Friction, Sinusoid, State, plant_accel
from mwip_ros.core.plants.plant import PlantConfig, PlantSim

pytestmark = pytest.mark.unit


def test_plant_step_is_classic_rk4_of_eq1():
    """The unrolled scalar RK4 of PlantSim.step equals a textbook vector RK4 over plant_accel."""
    cfg = PlantConfig(actual=TRUE, nominal=NOM, D_b=0.1, D_w_mean=0.5, D_w_variance=0.2,
                      tau_ext1=Sinusoid(30.0, 2.0, math.pi / 2), tau_ext2=Sinusoid(0.2, 1.0, 0.0),
                      h=0.005, substeps=5, seed=3, initial=State(0.1, -0.3, 0.4, 0.8),
                      torque_limit=0.0, fall_angle=1.0472)
    plant = PlantSim(cfg)
    extra = (1.5, -0.25)
    for k in range(40):
        u = 80.0 * math.sin(0.3 * k)
        x, fr, t0 = np.array(plant.x), Friction(cfg.D_b, plant.D_w), plant.t
        dt = cfg.h / cfg.substeps

        def f(t, x):
            e1, e2 = cfg.tau_ext1(t) + extra[0], cfg.tau_ext2(t) + extra[1]
            return np.concatenate([x[2:], plant_accel(TRUE, fr, x, u, e1, e2)])

        for i in range(cfg.substeps):
            t = t0 + i * dt
            k1 = f(t, x)
            k2 = f(t + dt / 2, x + dt / 2 * k1)
            k3 = f(t + dt / 2, x + dt / 2 * k2)
            k4 = f(t + dt, x + dt * k3)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        plant.step(u, extra)
        np.testing.assert_allclose(plant.x, x, rtol=1e-12, atol=1e-12)
    # D_w is redrawn every period, from the seeded generator, clipped at 0
    rng = np.random.default_rng(3)
    expected = [max(0.0, 0.5 + math.sqrt(0.2) * rng.standard_normal()) for _ in range(41)]
    assert plant.D_w == pytest.approx(expected[-1], rel=1e-15)
