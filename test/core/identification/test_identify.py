"""Identification from a log (theory.md 6.9): the real plant, a stabilizing LQR, an excitation: the truth back."""
import math
from dataclasses import replace

import numpy as np
import pytest

from mathfixtures import P_FILE
from mwip_ros import params as P
from mwip_ros.core.identification.excitation import Excitation, ExcitationConfig
from mwip_ros.core.identification.identify import IdentificationError, identify, regression
from mwip_ros.core.control.lqr import lqr_gain, lqr_u
from mwip_ros.core.plants.model import Sinusoid, State
from mwip_ros.core.plants.plant import PlantSim

pytestmark = pytest.mark.unit

VALUES = P.merged_values(P.load_param_files([P_FILE]))
BASE = P.plant_config(VALUES)          # the paper's plant as config/paper.yaml builds it
ROBOT = replace(BASE.actual, m_b=250.0, I_b=12.0, l=0.15)   # not the paper's body
CHIRP = ExcitationConfig("chirp", 20.0, 0.1, 5.0, 20.0)
PRBS = ExcitationConfig("prbs", 20.0, f1=5.0, duration_s=20.0, seed=1)


def record(exc, duration=20.0, theta_b0=0.0, D_w_variance=None, seed=None):
    """The table of an LQR-balanced run of ROBOT with ``exc`` added to the command, no tau_ext: columns
    t, theta_w, theta_b, dtheta_w, dtheta_b, u (the torque applied over the period).  ``seed``: of D_w's noise
    (default: the paper file's)."""
    cfg = replace(BASE, actual=ROBOT, tau_ext1=Sinusoid(0.0, 2.0, math.pi / 2), tau_ext2=Sinusoid(0.0, 1.0, 0.0),
                  initial=State(0.0, theta_b0, 0.0, 0.0),
                  D_w_variance=BASE.D_w_variance if D_w_variance is None else D_w_variance,
                  seed=BASE.seed if seed is None else seed)
    K = lqr_gain(BASE.nominal, cfg.h, VALUES["lqr.Q"], VALUES["lqr.R"])   # designed on the paper's nominal
    ex = Excitation(exc, cfg.h)
    plant = PlantSim(cfg)
    rows = []
    for k in range(int(round(duration / cfg.h)) + 1):
        u = lqr_u(K, plant.x) + ex.at(k)
        rows.append((plant.t, *plant.x, u))
        assert not plant.fallen
        plant.step(u)
    return np.array(rows).T


@pytest.fixture(scope="module")
def chirp_log():
    return record(CHIRP)


@pytest.mark.parametrize("exc", [CHIRP, PRBS], ids=["chirp", "prbs"])
def test_identifies_the_body_within_3_percent(exc, chirp_log):
    log = chirp_log if exc is CHIRP else record(exc)
    res = identify(*log, known=BASE.actual)   # m_w, I_w, r, g: the paper's (ROBOT's) values
    for name, truth in (("m_b", 250.0), ("I_b", 12.0), ("l", 0.15)):
        e = getattr(res, name)
        assert e.value == pytest.approx(truth, rel=0.03), name
        assert e.low <= truth <= e.high, (name, e)          # the 95 % interval holds the truth
    assert res.m11.value == pytest.approx(ROBOT.m11, rel=0.01)
    assert res.G_b.value == pytest.approx(ROBOT.G_b, rel=0.01)
    assert res.D_b.value == pytest.approx(0.1, rel=0.1)
    assert 0.4 < res.D_w.value < 0.65      # the mean of the clipped Gaussian (mean 0.5, variance 0.2): 0.53
    assert res.G_b_check.low <= 0.0 <= res.G_b_check.high
    assert res.samples == 4000 and res.condition_number < 1e4
    assert all(r < 0.5 for r in res.residual_rms)


def test_the_regression_is_eq1(chirp_log):
    """With the true parameters (and a constant D_w) every period's equation holds to the integration error."""
    log = record(CHIRP, duration=5.0, D_w_variance=0.0)
    A1, A2, U = regression(*log)
    theta = np.array([ROBOT.m11, ROBOT.m12, ROBOT.m22, ROBOT.G_b, 0.5, 0.1])
    assert np.sqrt(np.mean((A1 @ theta - U) ** 2)) < 2e-3 * np.sqrt(np.mean(U ** 2))
    assert np.sqrt(np.mean((A2 @ theta + U) ** 2)) < 2e-3 * np.sqrt(np.mean(U ** 2))
    wrong = theta * [1.0, 1.1, 1.0, 1.0, 1.0, 1.0]
    assert np.sqrt(np.mean((A2 @ wrong + U) ** 2)) > 0.01 * np.sqrt(np.mean(U ** 2))


def test_no_discretization_bias_without_noise():
    """With a constant D_w (no noise at all) the fit is the truth to the integration error: the trapezoid of sin th_b
    is end-corrected (Euler-Maclaurin), else m22 and I_b are off by G_b h^2 / 12 = 7.7e-4 kg m^2, 2.5 times the
    spread of I_b over seeds (the plain trapezoid of the first version)."""
    res = identify(*record(CHIRP, D_w_variance=0.0), known=BASE.actual)
    h = BASE.h
    assert abs(res.m22.value - ROBOT.m22) < 0.01 * ROBOT.G_b * h * h / 12
    assert abs(res.I_b.value - 12.0) < 1e-6 * 12.0
    assert abs(res.m_b.value - 250.0) < 1e-6 * 250.0 and abs(res.l.value - 0.15) < 1e-6 * 0.15


def test_delta_method_agrees_with_monte_carlo(chirp_log):
    res = identify(*chirp_log, known=BASE.actual)
    rng = np.random.default_rng(0)
    th = rng.multivariate_normal([getattr(res, n).value for n in ("m11", "m12", "m22", "G_b", "D_w", "D_b")],
                                 res.covariance, 20000)
    k = BASE.actual
    m_b = (th[:, 0] - k.I_w) / k.r ** 2 - k.m_w
    l = th[:, 1] / (m_b * k.r)
    I_b = th[:, 2] - m_b * l ** 2
    for name, s in (("m_b", m_b), ("l", l), ("I_b", I_b)):
        assert getattr(res, name).std == pytest.approx(s.std(), rel=0.05), name


def test_a_log_at_rest_is_not_excited():
    with pytest.raises(IdentificationError, match="not excited") as err:
        identify(*record(ExcitationConfig(), duration=5.0), known=BASE.actual)
    assert err.value.cause == "not_excited"


def test_a_short_log_is_refused(chirp_log):
    short = chirp_log[:, :200]   # 1 s
    with pytest.raises(IdentificationError, match="too short: 199 usable") as err:
        identify(*short, known=BASE.actual)
    assert err.value.cause == "too_short"


def test_an_unresolved_parameter_is_refused(chirp_log):
    with pytest.raises(IdentificationError, match="unresolved") as err:
        identify(*chirp_log, known=BASE.actual, max_relative_ci=1e-6)
    assert err.value.cause == "unresolved" and "m_b" in str(err.value)


def test_a_degenerate_regressor_is_refused(chirp_log):
    with pytest.raises(IdentificationError, match="condition number") as err:
        identify(*chirp_log, known=BASE.actual, max_condition=10.0)
    assert err.value.cause == "not_excited"


def test_non_finite_rows_are_dropped(chirp_log):
    log = chirp_log.copy()
    log[5, -1] = np.nan        # a bag's last torque may be unknown
    log[3, 1500] = np.nan      # a hole inside
    res = identify(*log, known=BASE.actual)
    assert res.samples == 4000 - 2
    assert res.m_b.value == pytest.approx(250.0, rel=0.03)


def test_wrong_known_values_are_unphysical(chirp_log):
    with pytest.raises(IdentificationError) as err:
        identify(*chirp_log, known=replace(BASE.actual, m_w=400.0))
    assert err.value.cause == "unphysical" and "m_b" in str(err.value)


@pytest.mark.parametrize("how", ["each row twice", "the log twice"])
def test_repeated_periods_count_once(chirp_log, how):
    """A log whose rows all appear twice gives the fit of the log itself (old code: every row twice left only
    one-period stretches between zero-length periods, no filter and no autocorrelation inflation: the 95 % interval
    of m_b shrank from +-0.21 % to +-0.015 %; the log appended to itself doubled the samples)."""
    once = identify(*chirp_log, known=BASE.actual)
    log = np.repeat(chirp_log, 2, axis=1) if how == "each row twice" else np.concatenate([chirp_log] * 2, axis=1)
    res = identify(*log, known=BASE.actual)
    assert res.samples == once.samples == 4000 and res.duplicates == 4001 and once.duplicates == 0
    for name in ("m_b", "l", "I_b"):
        assert getattr(res, name) == getattr(once, name), name
    assert res.m_b.low <= 250.0 <= res.m_b.high


def test_a_repeated_time_with_other_values_is_refused(chirp_log):
    log = np.repeat(chirp_log, 2, axis=1)
    log[2, 11] += 1e-3                         # row 11 repeats row 10's time, with another pitch
    with pytest.raises(IdentificationError) as err:
        identify(*log, known=BASE.actual)
    assert err.value.cause == "bad_data" and "rows 10 and 11" in str(err.value) and "t = 0.025 s" in str(err.value)


def test_prediction_with_the_true_model_is_the_log():
    """core.identification.identify_validate: with the plant's own model and a constant D_w the open-loop prediction is
    the log to rounding (the torque of row k acts over [t_k, t_k+1)); shifted by one period it is not."""
    from mwip_ros.core.identification.identify_validate import prediction_errors
    log = record(CHIRP, duration=5.0, D_w_variance=0.0)
    e = prediction_errors(*log, ROBOT, 0.5, 0.1, substeps=BASE.substeps)
    assert e.windows == 5 and e.worst < 1e-9
    shifted = log.copy()
    shifted[5] = np.roll(log[5], 1)
    assert prediction_errors(*shifted, ROBOT, 0.5, 0.1, substeps=BASE.substeps).worst > 1e-4
