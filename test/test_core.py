"""The paper's mathematics: model, observer, controller, filter, Theorem 2, closed loop."""
import math

import numpy as np
import pytest
from scipy.linalg import expm

from mwip_ros import metrics, params as P, sim
from mwip_ros.controller import DscController, DscGains, dsc_law, filter_step
from mwip_ros.model import (Friction, PhysicalParams, Sinusoid, lumped_disturbance, mass_matrix, nominal_accel,
                            plant_accel, semi_strict_feedback, x1_of)
from mwip_ros.observer import DiscreteObserver, error_rates, gain_matrix, z_dot, z_dot_explicit
from mwip_ros.plant import PlantConfig, PlantSim
from mwip_ros.theorem import theorem2

NOM = PhysicalParams(**P.PAPER_NOMINAL)
TRUE = PhysicalParams(**P.PAPER_ACTUAL)
RNG = np.random.default_rng(12345)


def random_state(rng):
    return (rng.uniform(-5, 5), rng.uniform(-0.8, 0.8)), (rng.uniform(-3, 3), rng.uniform(-2, 2))


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
    q, dq = random_state(RNG)
    u = RNG.uniform(-200, 200)
    tau_d = RNG.uniform(-50, 50, size=2)
    ddq = nominal_accel(NOM, q, dq, u, tau_d)
    # Direct check of eq. (17): M_hat q'' + N_hat = [u, 0] + tau_d, row by row.
    s, c = math.sin(q[1]), math.cos(q[1])
    row1 = NOM.m11 * ddq[0] + NOM.m12 * c * ddq[1] - (u + NOM.m12 * dq[1] ** 2 * s + tau_d[0])
    row2 = ((NOM.m11 + NOM.m12 * c) * ddq[0] + (NOM.m22 + NOM.m12 * c) * ddq[1]
            - (NOM.m12 * dq[1] ** 2 * s + NOM.G_b * s + tau_d[1]))
    assert abs(row1) < 1e-9 and abs(row2) < 1e-9
    x1 = x1_of(NOM, q[1], dq[1], dq[0])
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
    q, dq = random_state(RNG)
    u, e1, e2 = RNG.uniform(-100, 100), RNG.uniform(-30, 30), RNG.uniform(-1, 1)
    ddq = plant_accel(TRUE, Friction(0.1, 0.7), q, dq, u, e1, e2)
    tau_d = lumped_disturbance(NOM, q, dq, ddq, u)
    np.testing.assert_allclose(nominal_accel(NOM, q, dq, u, tau_d), ddq, rtol=1e-9, atol=1e-9)


def test_plant_matches_eq1_rows():
    q, dq = (0.3, -0.4), (1.2, -0.7)
    fr, u, e1, e2 = Friction(0.1, 0.5), 12.0, 3.0, -0.5
    ddq = plant_accel(TRUE, fr, q, dq, u, e1, e2)
    s, c = math.sin(q[1]), math.cos(q[1])
    r1 = TRUE.m11 * ddq[0] + TRUE.m12 * c * ddq[1] - (
        u - (fr.D_w + fr.D_b) * dq[0] + fr.D_b * dq[1] + TRUE.m12 * dq[1] ** 2 * s + e1)
    r2 = TRUE.m12 * c * ddq[0] + TRUE.m22 * ddq[1] - (
        -u - fr.D_b * (dq[1] - dq[0]) + TRUE.G_b * s + e2 - e1)
    assert abs(r1) < 1e-9 and abs(r2) < 1e-9


@pytest.mark.parametrize("trial", range(25))
def test_observer_eq15_equals_eq12(trial):
    X = RNG.uniform(0, 150, size=(2, 2))
    q, dq = random_state(RNG)
    u, z = RNG.uniform(-200, 200), RNG.uniform(-100, 100, size=2)
    np.testing.assert_allclose(z_dot_explicit(NOM, X, q, dq, u, z), z_dot(NOM, X, q, dq, u, z),
                               rtol=1e-10, atol=1e-9)


def test_plant_step_is_classic_rk4_of_eq1():
    """The unrolled scalar RK4 of PlantSim.step equals a textbook vector RK4 over plant_accel."""
    cfg = PlantConfig(actual=TRUE, nominal=NOM, D_b=0.1, D_w_mean=0.5, D_w_variance=0.2,
                      tau_ext1=Sinusoid(30.0, 2.0, math.pi / 2), tau_ext2=Sinusoid(0.2, 1.0, 0.0),
                      h=0.005, substeps=5, seed=3, initial=(0.1, -0.3, 0.4, 0.8))
    plant = PlantSim(cfg)
    extra = (1.5, -0.25)
    for k in range(40):
        u = 80.0 * math.sin(0.3 * k)
        x, fr, t0 = np.array(plant.x), Friction(cfg.D_b, plant.D_w), plant.t
        dt = cfg.h / cfg.substeps

        def f(t, x):
            e1, e2 = cfg.tau_ext1(t) + extra[0], cfg.tau_ext2(t) + extra[1]
            return np.concatenate([x[2:], plant_accel(TRUE, fr, x[:2], x[2:], u, e1, e2)])

        for i in range(cfg.substeps):
            t = t0 + i * dt
            k1 = f(t, x); k2 = f(t + dt / 2, x + dt / 2 * k1); k3 = f(t + dt / 2, x + dt / 2 * k2)
            k4 = f(t + dt, x + dt * k3)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        plant.step(u, extra)
        np.testing.assert_allclose(plant.x, x, rtol=1e-12, atol=1e-12)
    # D_w is redrawn every period, from the seeded generator, clipped at 0
    rng = np.random.default_rng(3)
    expected = [max(0.0, 0.5 + math.sqrt(0.2) * rng.standard_normal()) for _ in range(41)]
    assert plant.D_w == pytest.approx(expected[-1], rel=1e-15)


def test_discrete_observer_is_euler_of_eq12():
    X = gain_matrix([100.0, 5.0, -3.0, 80.0])
    h = 0.005
    obs = DiscreteObserver(NOM, X, h)
    z = None
    prev = None
    for k in range(30):
        q, dq = random_state(RNG)
        u_prev = RNG.uniform(-100, 100)
        tau_hat = obs.update(q, dq, u_prev)
        z = -X @ np.array(dq) if z is None else z + h * z_dot(NOM, X, prev[0], prev[1], u_prev, z)
        prev = (q, dq)
        np.testing.assert_allclose(tau_hat, z + X @ np.array(dq), rtol=1e-10, atol=1e-9)


def _exact_model_plant(tau_ext=(0.0, 0.0), theta_b0=-0.1745, h=0.005):
    return PlantConfig(actual=NOM, nominal=NOM, D_b=0.0, D_w_mean=0.0, D_w_variance=0.0,
                       tau_ext1=Sinusoid(tau_ext[0], 0.0, math.pi / 2), tau_ext2=Sinusoid(tau_ext[1], 0.0, math.pi / 2),
                       h=h, initial=(0.0, theta_b0, 0.0, 0.0))


def test_observer_converges_at_the_predicted_rate():
    """Exact model, constant injected disturbance: tau_hat -> tau_d with e' = -X M_hat^-1 e."""
    h = 0.005
    tau_const = np.array([20.0, 5.0])
    cfg = _exact_model_plant(tuple(tau_const), theta_b0=0.0, h=h)
    plant = PlantSim(cfg)
    X = gain_matrix([100.0, 0.0, 0.0, 100.0])
    obs = DiscreteObserver(NOM, X, h)
    ctrl = DscController(NOM, DscGains(), h, use_observer=False)  # keeps it upright, independent of tau_hat
    errs, ts, thetas = [], [], []
    for k in range(1600):  # 8 s: the slow mode decays at ~1.4 /s
        tau_hat = obs.update(plant.q, plant.dq, plant.u_prev)
        u = ctrl.step(plant.x[1], plant.x[3], plant.x[2]).u
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
    F = X @ np.linalg.inv(mass_matrix(NOM, (0.0, 0.0)))
    lam = np.sort(error_rates(NOM, X, (0.0, 0.0)).real)
    assert lam[0] > 0
    for i in (20, 60, 120, 200):
        predicted = expm(-F * ts[i]) @ errs[0]
        assert np.linalg.norm(errs[i] - predicted) < 0.03 * np.linalg.norm(errs[0]), i
    # The slowest eigenvalue sets the tail: |e| decays like exp(-lam_min t).
    ratio = np.linalg.norm(errs[300]) / np.linalg.norm(errs[200])
    assert ratio == pytest.approx(math.exp(-lam[0] * (ts[300] - ts[200])), rel=0.05)


def test_dsc_drives_theta_b_to_zero_with_perfect_model():
    plant = PlantSim(_exact_model_plant())
    ctrl = DscController(NOM, DscGains(), plant.cfg.h, use_observer=False)
    thetas = []
    for _ in range(2000):
        u = ctrl.step(plant.x[1], plant.x[3], plant.x[2]).u
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
    f = lambda y: (x4_bar - y) / tau4
    for _ in range(n):
        k1 = f(y); k2 = f(y + dt / 2 * k1); k3 = f(y + dt / 2 * k2); k4 = f(y + dt * k3)
        y += dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert filter_step(x4d, x4_bar, h, tau4) == pytest.approx(y, rel=1e-12)


def test_dsc_law_makes_S2_converge_at_k2():
    """Eq. (27)-(28): with the law applied, the nominal model gives S2' = -k2 S2 when tau_hat = tau_d."""
    g = DscGains(k1=6.0, k2=4.0, tau4=0.1)
    q, dq = (0.0, 0.2), (-0.5, 0.3)
    tau_d = np.array([7.0, -2.0])
    out = dsc_law(NOM, g, q[1], dq[1], dq[0], x4d=0.1, tau_hat=tau_d)
    ddq = nominal_accel(NOM, q, dq, out.u, tau_d)
    dS2 = ddq[0] - (out.x4_bar - out.x4d) / g.tau4
    assert dS2 == pytest.approx(-g.k2 * out.S2, rel=1e-9)
    # plain DSC ignores tau_hat
    assert dsc_law(NOM, g, q[1], dq[1], dq[0], 0.1, None).u == pytest.approx(out.u_dsc)
    assert out.u == pytest.approx(out.u_dsc - (tau_d[0] - NOM.m12 * math.cos(0.2) / (NOM.m22 + NOM.m12 * math.cos(0.2)) * tau_d[1]))


def test_theorem2_paper_gains_hold_and_slow_filter_violates():
    th = theorem2(NOM, DscGains(6.0, 6.0, 0.1), gain_matrix([100.0, 0, 0, 100.0]))
    assert th.satisfied and th.gamma == pytest.approx(min(th.as_dict()[k] for k in ("a1", "a2", "a3", "a4", "a5")))
    r = (NOM.m11 + NOM.m12) / NOM.m22
    assert th.a5 == pytest.approx(100.0 / NOM.m22 - 1)
    slow = theorem2(NOM, DscGains(6.0, 6.0, 0.5), gain_matrix([100.0, 0, 0, 100.0]))
    assert slow.a3 == pytest.approx(2.0 - 9.0 - r / 2) and not slow.satisfied
    weak_obs = theorem2(NOM, DscGains(), gain_matrix([10.0, 0, 0, 100.0]))
    assert weak_obs.a4 < 0 and not weak_obs.satisfied


@pytest.fixture(scope="module")
def paper_runs():
    values = sim.merged_values(P.load_param_file(P_FILE))
    return {k: sim.simulate(values, use_observer=(k == "dscndo")) for k in ("dsc", "dscndo")}


from mwip_ros.paths import default_params_file  # noqa: E402
P_FILE = default_params_file()


def test_paper_values_both_upright_and_dscndo_reduces_oscillation(paper_runs):
    m = {k: metrics.compute(r.columns) for k, r in paper_runs.items()}
    for k, r in paper_runs.items():
        assert not r.fallen and r.t[-1] == pytest.approx(10.0), k
        assert m[k].upright, k
    assert m["dsc"].theta_b_p2p >= 3 * m["dscndo"].theta_b_p2p
    # the oscillation is real, not a numerical artefact
    assert m["dsc"].theta_b_p2p > 0.01


def test_simulation_rows_follow_the_contract(paper_runs):
    r = paper_runs["dscndo"]
    assert len(r) == 2001
    np.testing.assert_allclose(np.diff(r.t), 0.005, atol=1e-12)
    assert r["tau_hat1"][0] == 0.0 and r["tau_hat2"][0] == 0.0          # tau_hat(0) = 0
    assert r["theta_b"][0] == pytest.approx(-0.1745)
    np.testing.assert_allclose(r["u"], r["u_dsc"] - r["u_taud"], atol=1e-9)  # eq. (19)
    assert r["x4d"][0] == r["x4_bar"][0]                                # eq. (25) initial condition


def test_friction_noise_is_seeded():
    values = sim.merged_values(P.load_param_file(P_FILE))
    a = sim.simulate(values, duration=0.5)
    b = sim.simulate(values, duration=0.5)
    c = sim.simulate({**values, "seed": 1}, duration=0.5)
    np.testing.assert_array_equal(a["theta_b"], b["theta_b"])
    assert not np.array_equal(a["theta_b"], c["theta_b"])


def test_torque_limit_saturates():
    values = sim.merged_values(P.load_param_file(P_FILE))
    r = sim.simulate({**values, "torque_limit": 50.0}, duration=1.0)
    assert np.abs(r["u"]).max() <= 50.0 + 1e-12
    assert np.abs(r["u"]).max() == pytest.approx(50.0)
