"""Shared values of the core tests: the paper's nominal and true models, random states, simple plants."""
import math

import numpy as np

from mwip_ros import params as P
from mwip_ros.core.plants.model import PhysicalParams, Sinusoid, State
from mwip_ros.core.plants.plant import PlantConfig
from mwip_ros.params.paths import default_params_file

NOM = PhysicalParams(**P.PAPER_NOMINAL)
TRUE = PhysicalParams(**P.PAPER_ACTUAL)
PAPER_GAINS = P.gains(P.defaults_for("dscndo_controller"))
FALL_ANGLE = P.defaults_for("plant_sim")["fall_angle"]
UPRIGHT = State(0.0, 0.0, 0.0, 0.0)
RNG = np.random.default_rng(12345)
P_FILE = default_params_file()


def random_state(rng) -> State:
    return State(rng.uniform(-5, 5), rng.uniform(-0.8, 0.8), rng.uniform(-3, 3), rng.uniform(-2, 2))


def exact_model_plant(tau_ext=(0.0, 0.0), theta_b0=-0.1745, h=0.005) -> PlantConfig:
    """The nominal model as the plant: no friction, no noise, constant external torques."""
    return PlantConfig(actual=NOM, nominal=NOM, D_b=0.0, D_w_mean=0.0, D_w_variance=0.0,
                       tau_ext1=Sinusoid(tau_ext[0], 0.0, math.pi / 2), tau_ext2=Sinusoid(tau_ext[1], 0.0, math.pi / 2),
                       h=h, substeps=5, seed=0, initial=State(0.0, theta_b0, 0.0, 0.0), torque_limit=0.0,
                       fall_angle=FALL_ANGLE)


def assert_batch_equals_scalar(loops, window, batch=None, scalar=None):
    """The oracle of the batch simulator: its trajectories (``record=True``) equal the scalar loop's, scenario by
    scenario, every column of the trajectory table to 1e-9, the same length, fall and label. Returns
    (batch result, scalar trajectories)."""
    from mwip_ros.core.kernels.batch import simulate_batch
    from mwip_ros.core.closed_loop.sim import simulate
    from mwip_ros.core.closed_loop.trajectory import COLUMNS
    batch = batch if batch is not None else simulate_batch(loops, window, record=True)
    scalar = scalar if scalar is not None else [simulate(lp) for lp in loops]
    for i, (b, s) in enumerate(zip(batch.trajectories, scalar)):
        assert len(b) == len(s) and b.fallen == s.fallen and b.label == s.label, i
        for c in COLUMNS:
            np.testing.assert_allclose(b[c], s[c], rtol=0, atol=1e-9, err_msg=f"scenario {i}, {c}")
    return batch, scalar


def assert_ndo_is_law_minus_u_taud(plain, ndo, rng, n: int = 50, each=None):
    """``ndo`` (a law with the observer term) commands ``plain``'s u minus u_taud of eq. (20)-(21), on ``n`` random
    states and estimates, and reports that u_taud; ``each(internals)``, when given, checks every step's internals
    (a law's own rule)."""
    for _ in range(n):
        x, tau_hat = random_state(rng), tuple(rng.uniform(-30, 30, 2))
        mc = NOM.m12 * math.cos(x[1])
        u_taud = tau_hat[0] - mc / (NOM.m22 + mc) * tau_hat[1]              # eq. (20)-(21)
        u, internals = ndo.step(x, tau_hat)
        assert u == plain.step(x)[0] - u_taud and internals["u_taud"] == u_taud   # eq. (19)
        if each is not None:
            each(internals)
