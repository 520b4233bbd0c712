"""The batch's compiled RK4 period is the scalar plant's own function: same code, same numbers, bit for bit."""
import math

import numpy as np
import pytest

from mathfixtures import P_FILE
from mwip_ros import params as P
from mwip_ros.core import compiled, model, plant
from mwip_ros.core.model import PhysicalParams, Sinusoid

pytestmark = pytest.mark.unit

BASE = P.merged_values(P.load_param_file(P_FILE))
ACTUAL = P.physical(BASE, "actual")


def test_the_compiled_functions_are_the_scalar_ones():
    # not a second copy of eq. (1) or of RK4: numba compiled these very code objects
    assert compiled._accel.py_func.__code__ is model.accel.__code__
    assert compiled._rk4_period.py_func.__code__ is plant.rk4_period.__code__
    # and inside the compiled rk4_period, accel is the compiled accel
    assert compiled._rk4_period.py_func.__globals__["accel"] is compiled._accel


def _scenarios(n, seed=5):
    rng = np.random.default_rng(seed)
    scale = lambda: rng.uniform(0.7, 1.3, n)  # noqa: E731
    params = PhysicalParams(m_b=ACTUAL.m_b * scale(), m_w=ACTUAL.m_w, I_b=ACTUAL.I_b * scale(), I_w=ACTUAL.I_w,
                            l=ACTUAL.l * scale(), r=ACTUAL.r, g=ACTUAL.g)
    x = (rng.uniform(-3, 3, n), rng.uniform(-0.6, 0.6, n), rng.uniform(-2, 2, n), rng.uniform(-2, 2, n))
    return params, rng.uniform(0, 1, n), rng.uniform(-200, 200, n), x, rng


def test_every_scenario_equals_the_scalar_plant_bit_for_bit():
    n, h, substeps, t0 = 64, 0.005, 5, 1.234
    p, D_w, u, x, rng = _scenarios(n)
    amp1 = rng.uniform(0, 45, n)       # tau_ext1 differs per scenario, tau_ext2 is shared (a float)
    f1, f2 = Sinusoid(amp1, 2.0, math.pi / 2), Sinusoid(5.0, 3.0, 0.1)
    tau1, tau2 = plant.stage_torques(f1, f2, (0.0, 0.0), t0, h, substeps, np)
    D_b = 0.5
    out = compiled.RK4Periods(p, D_b, n)(D_w, tau1, tau2, x, u, h, substeps, np.ones(n, dtype=bool))
    for i in range(n):
        p_i = PhysicalParams(m_b=p.m_b[i], m_w=p.m_w, I_b=p.I_b[i], I_w=p.I_w, l=p.l[i], r=p.r, g=p.g)
        t1, t2 = plant.stage_torques(Sinusoid(float(amp1[i]), 2.0, math.pi / 2), f2, (0.0, 0.0), t0, h, substeps)
        want = plant.rk4_period(p_i, float(D_w[i]), D_b, t1, t2, tuple(float(v[i]) for v in x), float(u[i]), h,
                                substeps)
        assert tuple(float(o[i]) for o in out) == want, i


def test_inactive_scenarios_keep_their_state_and_the_input_is_not_changed():
    n = 10
    p, D_w, u, x, _ = _scenarios(n)
    before = tuple(v.copy() for v in x)
    active = np.arange(n) % 3 != 0
    tau = [0.0] * 11
    out = compiled.RK4Periods(p, 0.5, n)(D_w, tau, tau, x, u, 0.005, 5, active)
    for v, b in zip(x, before):
        assert np.array_equal(v, b)            # the caller's arrays (the observer keeps x_k-1) are untouched
    for o, b in zip(out, before):
        assert np.array_equal(o[~active], b[~active])
        assert not np.any(o[active] == b[active])


def test_a_diverging_scenario_gives_nan_not_an_exception_and_spares_the_others():
    n = 4
    p, D_w, u, x, _ = _scenarios(n)
    # a zero inertia makes eq. (1)'s determinant 0 for scenario 2: numpy's 0/0, not ZeroDivisionError
    p = PhysicalParams(m_b=np.where(np.arange(n) == 2, 0.0, p.m_b), m_w=0.0, I_b=np.where(np.arange(n) == 2, 0.0,
                       p.I_b), I_w=np.where(np.arange(n) == 2, 0.0, 1.0), l=p.l, r=p.r, g=p.g)
    tau = [0.0] * 11
    out = compiled.RK4Periods(p, 0.5, n)(D_w, tau, tau, x, u, 0.005, 5, np.ones(n, dtype=bool))
    assert np.isnan(out[1][2]) and np.isnan(out[3][2])
    assert np.isfinite(np.array(out)[:, [0, 1, 3]]).all()


_CHECK = """
import numpy as np
from mwip_ros.core import compiled, plant
from mwip_ros.core.model import PhysicalParams
p = PhysicalParams(m_b=200.0, m_w=10.0, I_b=20.0, I_w=0.5, l=0.5, r=0.3, g=9.81)
x = (0.0, 0.2, 0.1, -0.3)
tau1, tau2 = [5.0] * 11, [1.0] * 11
want = plant.rk4_period(p, 0.3, 0.5, tau1, tau2, x, 10.0, 0.005, 5)
got = compiled.RK4Periods(p, 0.5, 1)(0.3, tau1, tau2, tuple(np.array([v]) for v in x), np.array([10.0]), 0.005, 5,
                                     np.ones(1, dtype=bool))
print(repr(want[3]), repr(float(got[3][0])))
"""


@pytest.mark.parametrize("cache_dir", [None, "numba_cache"])
def test_an_edit_to_the_equations_is_compiled_afresh(tmp_path, cache_dir):
    """numba renews a cached function only when its own file changes; the compiled RK4 period must follow an
    edit to model.accel (another file) too, in the next process; in __pycache__ or in NUMBA_CACHE_DIR."""
    import os
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    pkg = Path(compiled.__file__).resolve().parents[1]
    shutil.copytree(pkg, tmp_path / "mwip_ros", ignore=shutil.ignore_patterns("__pycache__"))
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(tmp_path)
    where = tmp_path / "mwip_ros" / "core" / "__pycache__"
    if cache_dir:
        env["NUMBA_CACHE_DIR"] = str(tmp_path / cache_dir)
        where = tmp_path / cache_dir

    def run():
        out = subprocess.run([sys.executable, "-c", _CHECK], env=env, capture_output=True, text=True, timeout=120,
                             cwd=tmp_path)
        assert out.returncode == 0, out.stderr
        scalar, batch = out.stdout.split()
        return float(scalar), float(batch)

    first = run()
    assert first[0] == first[1]
    assert list(where.rglob("compiled._advance-*.nbi"))   # cached there
    model_py = tmp_path / "mwip_ros" / "core" / "model.py"
    text = model_py.read_text()
    edit = "+ (tau_ext2 - tau_ext1)                     # eq. (1), row 2"
    assert edit in text
    model_py.write_text(text.replace(edit, "+ 2.0 * (tau_ext2 - tau_ext1)  # eq. (1), row 2"))
    second = run()
    assert second[0] != first[0]           # the edit changes the plant
    assert second[1] == second[0]          # and the compiled batch follows it
