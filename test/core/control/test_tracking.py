"""Every law tracks the motion references (docs/theory.md 6.11); with x_d = 0 (no reference) DSC is eq.
(22)-(28) to the bit, and a reference at rest with zero gains changes no law's command."""
import math

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core import laws
from mwip_ros.core.control.controller import dsc_terms, dsc_terms_tracking
from mwip_ros.core.control.motion import Reference
from mwip_ros.params.paths import default_params_file

pytestmark = pytest.mark.unit

V = P.merged_values(P.load_param_file(default_params_file()))
NOMINAL = P.physical(V, "nominal")


def _paper_eq_22_28(p, k1, k2, tau4, x, x4d, first):
    """Eq. (16)-(28) transcribed from docs/theory.md section 3 (S1 = x2), independently of the code under test."""
    _, x2, x4, x3 = x
    mc = p.m12 * math.cos(x2)
    A = p.m11 * p.m22 - mc ** 2
    x1 = (p.m11 + mc) * x4 + (p.m22 + mc) * x3
    S1 = x2
    x4_bar = (p.m22 + mc) / (p.m11 + mc) * (x1 / (p.m22 + mc) + k1 * S1)
    if first:
        x4d = x4_bar
    S2 = x4 - x4d
    u = (A / (p.m22 + mc) * ((x4_bar - x4d) / tau4 - k2 * S2)
         - p.m12 * p.m22 * math.sin(x2) * (x1 - (p.m11 + mc) * x4) ** 2 / (p.m22 + mc) ** 3
         + mc * (p.G_b * math.sin(x2)) / (p.m22 + mc))
    return u, S1, S2, x1, x4_bar, x4d


def _states(n=2000, seed=7):
    rng = np.random.default_rng(seed)
    return [(float(a), float(b), float(c), float(d), float(e)) for a, b, c, d, e in
            zip(rng.uniform(-50, 50, n), rng.uniform(-1.0, 1.0, n), rng.uniform(-20, 20, n), rng.uniform(-5, 5, n),
                rng.uniform(-20, 20, n))]


def test_xd_zero_is_eq_22_bit_for_bit():
    for tw, tb, dtw, dtb, x4d in _states():
        x = (tw, tb, dtw, dtb)
        for first in (True, False):
            want = _paper_eq_22_28(NOMINAL, 6.0, 6.0, 0.1, x, x4d, first)
            assert dsc_terms_tracking(NOMINAL, 6.0, 6.0, 0.1, x, x4d, first, 0.0, 0.0) == want
            assert dsc_terms(NOMINAL, 6.0, 6.0, 0.1, x, x4d, first) == want


def test_surface_tracks_xd():
    """S1 = x2 - x_d, and x4 = x4_bar makes S1' = x3 - x_d' = -k1 S1 (the step-1 design of docs/theory.md 6.11)."""
    p = NOMINAL
    for tw, tb, dtw, dtb, xd in _states(200, seed=3):
        dxd = 0.3 * xd
        x4_bar = dsc_terms_tracking(p, 6.0, 6.0, 0.1, (tw, tb, dtw, dtb), 0.0, True, 0.1 * xd, dxd)[4]
        mc = p.m12 * math.cos(tb)
        x1 = (p.m11 + mc) * dtw + (p.m22 + mc) * dtb
        x3_at_bar = (x1 - (p.m11 + mc) * x4_bar) / (p.m22 + mc)   # eq. (16) solved for x3 with x4 = x4_bar
        assert x3_at_bar - dxd == pytest.approx(-6.0 * (tb - 0.1 * xd), rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("name", ["dsc", "dscndo", "lqr", "lqr_ndo", "smc", "smc_ndo", "mpc", "mpc_ndo"])
def test_a_reference_at_rest_with_zero_gains_changes_nothing(name):
    cls = laws.get(name)
    if laws.unavailable(cls):
        pytest.skip(laws.unavailable(cls))
    a, b = (cls.from_params(V, NOMINAL, 0.005) for _ in range(2))
    rest = Reference(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for tw, tb, dtw, dtb, _ in _states(300, seed=11):
        x, tau_hat = (0.0, tb, dtw, dtb), (3.0 * tb, -tb)
        b.track(rest)
        ua, _ = a.step(x, tau_hat)
        ub, _ = b.step(x, tau_hat)
        assert ua == ub


@pytest.mark.parametrize("name", ["lqr", "smc", "mpc"])
def test_state_laws_see_the_error_coordinates(name):
    """LQR, SMC, MPC with a reference: their command is the one of the state in error coordinates."""
    cls = laws.get(name)
    if laws.unavailable(cls):
        pytest.skip(laws.unavailable(cls))
    a, b = (cls.from_params(V, NOMINAL, 0.005) for _ in range(2))
    ref = Reference(theta_w=2.0, dtheta_w=4.0, v=1.016, dpsi=0.0, position_gain=0.5, lean_gain=0.03)
    x = (3.0, 0.05, 5.0, -0.1)
    b.track(ref)
    # the rate the law drives theta_w' to: 4 - 0.5 (3 - 2) = 3.5, so theta_w' - 3.5 = 1.5 (hand-computed)
    assert b.step(x, None)[0] == a.step((1.0, 0.05, 1.5, -0.1), None)[0]


def test_every_plant_tracks_the_profile():
    """Both physics (rk4 and mujoco, docs/theory.md 6.10) drive config/motion.yaml's profile with the same law: the
    references are the law stage's, not the plant's."""
    pytest.importorskip("mujoco")
    from mwip_ros.core.closed_loop import metrics
    from mwip_ros.core.closed_loop.sim import simulate
    from mwip_ros.params.paths import default_params_file
    files = [default_params_file(), default_params_file().parent / "motion.yaml"]
    v = P.merged_values(P.load_param_files(files))
    out = {}
    for backend in ("rk4", "mujoco"):
        run = simulate(P.closed_loop(dict(v, backend=backend), controller="smc_ndo", duration=12.0))
        out[backend] = metrics.motion_metrics(run.columns, v["nominal.r"], v["fall_angle"], run.record.get("t_fall"))
        t, v_ref = run["t"], run["v_ref"]
        assert v_ref[np.searchsorted(t, 8.0)] == 1.0   # the profile's 1 m/s, reached at 4 s
        assert out[backend]["upright"]
    assert abs(out["rk4"]["speed_rms"] - out["mujoco"]["speed_rms"]) < 0.01, out
