"""The batch's compiled RK4 period is the scalar plant's own function: same code, same numbers, bit for bit."""
import math
from pathlib import Path

import numpy as np
import pytest

from mathfixtures import P_FILE
from mwip_ros import params as P
from mwip_ros.core.kernels import compiled, compiled_stages, jitcache
from mwip_ros.core.plants import drive, model, plant
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.kernels.batch import simulate_batch
from mwip_ros.core.plants.model import PhysicalParams, Sinusoid
from mwip_ros.core.closed_loop.sim import simulate

pytestmark = pytest.mark.unit

BASE = P.merged_values(P.load_param_file(P_FILE))
ACTUAL = P.physical(BASE, "actual")


def test_the_compiled_functions_are_the_scalar_ones():
    # not a second copy of eq. (1) or of RK4: numba compiled these very code objects
    assert compiled_stages._accel.py_func.__code__ is model.accel.__code__
    assert compiled_stages._rk4_period.py_func.__code__ is plant.rk4_period.__code__
    assert compiled_stages._rk4_driven.py_func.__code__ is plant.rk4_driven.__code__
    # and inside the compiled RK4, accel and the motor are the compiled ones
    assert compiled_stages._rk4_period.py_func.__globals__["rk4_driven"] is compiled_stages._rk4_driven
    assert compiled_stages._rk4_driven.py_func.__globals__["accel"] is compiled_stages._accel
    assert compiled_stages._rk4_driven.py_func.__globals__["motor_torque"] is compiled_stages._motor_torque
    assert compiled_stages._motor_torque.py_func.__code__ is drive.motor_torque.__code__


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
from mwip_ros.core.kernels import compiled
from mwip_ros.core.plants import plant
from mwip_ros.core.plants.model import PhysicalParams
p = PhysicalParams(m_b=200.0, m_w=10.0, I_b=20.0, I_w=0.5, l=0.5, r=0.3, g=9.81)
x = (0.0, 0.2, 0.1, -0.3)
tau1, tau2 = [5.0] * 11, [1.0] * 11
want = plant.rk4_period(p, 0.3, 0.5, tau1, tau2, x, 10.0, 0.005, 5)
got = compiled.RK4Periods(p, 0.5, 1)(0.3, tau1, tau2, tuple(np.array([v]) for v in x), np.array([10.0]), 0.005, 5,
                                     np.ones(1, dtype=bool))
print(repr(want[3]), repr(float(got[3][0])))
"""


def test_each_lane_width_caches_its_kernels_in_files_of_its_own(tmp_path, monkeypatch):
    """numba renews a function's cache file whenever its stamp differs: one file for both lane widths made each
    process of the other width compile the whole loop again (the tests run both, about 30 s a run)."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))

    def z_next_like(z, step):   # a function of a file numba can cache (this one)
        return z + step
    names = {}
    for width in (0, 8):
        monkeypatch.setattr(compiled.simd, "WIDTH", width)
        monkeypatch.setattr(jitcache, "_CACHES", {})
        tag = compiled._lanes_tag()
        impl = jitcache.cache_for(z_next_like, tag)(z_next_like)._impl
        names[width] = impl.filename_base
        assert jitcache.cache_for(z_next_like, tag) is jitcache.cache_for(z_next_like, tag)   # one per stamp, width
    assert names[0] != names[8] and "lanes0" in names[0] and "lanes8" in names[8], names
    assert jitcache.stamped_cache("s")(z_next_like)._impl.filename_base.startswith(
        "test_compiled.test_each_lane_width_caches_its_kernels_in_files_of_its_own.<locals>.z_next_like-".replace(
            "<", "").replace(">", ""))   # no tag: numba's own name


def test_an_index_that_names_a_module_since_moved_is_stale_not_an_error(tmp_path, monkeypatch):
    """numba's index of a cached function pickles its signatures' classes by module (``compiled.Inertia``): an index
    written before a module moved (issue 48: core/ into rooms) raised ModuleNotFoundError at the next compile; it is
    stale, as one of another stamp, and the function compiles and caches afresh."""
    import pickle

    import numba
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path))

    def twice(x):   # a function of a file numba can cache (this one)
        return 2.0 * x
    index = Path(jitcache.jit(twice, "moved")._cache._cache_file._index_path)
    index.parent.mkdir(parents=True, exist_ok=True)
    # numba's header, then (stamp, overloads) naming a class of a module that is no more
    index.write_bytes(pickle.dumps(numba.__version__) + b"cmwip_ros.core.compiled\nInertia\n.")
    with pytest.raises(ModuleNotFoundError):
        pickle.loads(index.read_bytes()[len(pickle.dumps(numba.__version__)):])
    again = jitcache.jit(twice, "moved")
    assert jitcache.cached(again) is False   # not an error: nothing cached under this stamp
    assert again(1.5) == 3.0                 # compiled afresh
    assert jitcache.cached(jitcache.jit(twice, "moved")) is True   # and cached again, the index written anew


@pytest.mark.cli
@pytest.mark.parametrize("cache_dir", [None, "numba_cache"])
def test_an_edit_to_the_equations_is_compiled_afresh(tmp_path, cache_dir):
    """numba renews a cached function only when its own file changes; the compiled RK4 period must follow an
    edit to model.accel (another file) too, in the next process; in __pycache__ or in NUMBA_CACHE_DIR."""
    import os
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    pkg = Path(compiled.__file__).resolve().parents[2]
    shutil.copytree(pkg, tmp_path / "mwip_ros", ignore=shutil.ignore_patterns("__pycache__"))
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(tmp_path)
    where = tmp_path / "mwip_ros" / "core" / "kernels" / "__pycache__"
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
    model_py = tmp_path / "mwip_ros" / "core" / "plants" / "model.py"
    text = model_py.read_text()
    edit = "+ (tau_ext2 - tau_ext1)                     # eq. (1), row 2"
    assert edit in text
    model_py.write_text(text.replace(edit, "+ 2.0 * (tau_ext2 - tau_ext1)  # eq. (1), row 2"))
    second = run()
    assert second[0] != first[0]           # the edit changes the plant
    assert second[1] == second[0]          # and the compiled batch follows it


# --- the whole batch loop compiled (core.kernels.compiled._loop) equals the scalar loop
# ---------------------------------

REALISTIC = P.merged_values(P.load_param_files([P_FILE, Path(__file__).resolve().parents[3] / "config" /
                                                "sensing_realistic.yaml"]))
WINDOW = (1.0, 2.0)
SENSING = {
    "off": {},
    "realistic": {k: v for k, v in REALISTIC.items() if k.startswith(("sensors.", "actuator."))},
    "delays": {"sensors.delay_periods": 2, "actuator.delay_periods": 3},
}


def _loop_values(sensing, shared_tau: bool, seed=7):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(8):
        v = dict(BASE, **SENSING[sensing])
        v.update({"seed": int(rng.integers(0, 1000)), "actual.m_b": BASE["actual.m_b"] * rng.uniform(0.7, 1.3),
                  "actual.I_b": BASE["actual.I_b"] * rng.uniform(0.7, 1.3),
                  "initial.theta_b": float(rng.uniform(-0.3, 0.3)),
                  "actual.D_w_variance": 0.0 if i == 3 else 0.2, "torque_limit": 400.0 if i == 5 else 0.0})
        if not shared_tau:
            v["tau_ext1.amplitude"] = float(rng.uniform(0, 45))
        if i == 6 and sensing == "realistic":   # one scenario without noise in a noisy batch
            v.update({f"sensors.noise_std.{c}": 0.0 for c in ("theta_w", "theta_b", "dtheta_w", "dtheta_b")})
        out.append(v)
    fall = dict(out[0], **{"initial.theta_b": 1.0, "tau_ext1.amplitude": 3000.0, "seed": 3})   # falls at once
    late = dict(out[1], **{"tau_ext2.amplitude": 2500.0, "tau_ext2.omega": 1.0, "seed": 4})     # falls later
    diverge = dict(out[2], **{"initial.theta_b": 1.0, "tau_ext1.amplitude": 1e5, "seed": 5})
    if shared_tau:
        fall["tau_ext1.amplitude"] = diverge["tau_ext1.amplitude"] = BASE["tau_ext1.amplitude"]
        fall["initial.theta_b"] = diverge["initial.theta_b"] = 1.2   # beyond the fall angle: falls at t = 0
        late["tau_ext2.amplitude"] = BASE["tau_ext2.amplitude"]
        late.update({"k1": 0.05, "k2": 0.05, "lqr.R": 1e4, "initial.theta_b": 0.9})
    return out + [fall, late, diverge]


def _check_equal(loops, r):
    """Every metric, the fall and its time of each scenario of ``r`` equal the scalar loop's to 1e-9."""
    stepped = 0
    for i, lp in enumerate(loops):
        s = simulate(lp)
        m = metrics.compute(s.columns, WINDOW, lp.plant.fall_angle)
        assert bool(r.fallen[i]) == s.fallen, i
        if s.fallen:
            assert abs(r.t_fall[i] - s.t[-1]) <= 1e-9, i
        else:
            assert np.isnan(r.t_fall[i]) and r.upright[i], i
        for key, values in r.metrics.items():
            want, got = getattr(m, key), values[i]
            assert (np.isnan(want) and np.isnan(got)) or abs(got - want) <= 1e-9 * max(1.0, abs(want)), (i, key,
                                                                                                        got, want)
        stepped += len(s) - 1
    assert r.steps == stepped
    return [bool(v) for v in r.fallen]


@pytest.mark.parametrize("sensing", sorted(SENSING))
@pytest.mark.parametrize("controller", ["dsc", "dscndo", "lqr", "lqr_ndo"])
def test_the_compiled_batch_loop_equals_the_scalar_loop(controller, sensing):
    for shared in (True, False):
        loops = [P.closed_loop(v, duration=2.0, controller=controller) for v in _loop_values(sensing, shared)]
        r = simulate_batch(loops, WINDOW, compiled=True)
        fallen = _check_equal(loops, r)
        assert any(fallen) and not all(fallen)   # some fall, the others run on


def test_a_batch_mixing_a_law_with_and_without_the_observer_term_runs_compiled():
    values = _loop_values("realistic", False, seed=3)
    loops = [P.closed_loop(v, duration=2.0, controller="dscndo" if i % 2 else "dsc") for i, v in enumerate(values)]
    _check_equal(loops, simulate_batch(loops, WINDOW, compiled=True))


def test_the_compiled_loop_and_the_numpy_loop_give_the_same_numbers():
    loops = [P.closed_loop(v, duration=2.0, controller="dscndo") for v in _loop_values("realistic", False)]
    a, b = simulate_batch(loops, WINDOW, compiled=True), simulate_batch(loops, WINDOW, compiled=False)
    assert a.steps == b.steps and np.array_equal(a.fallen, b.fallen)
    np.testing.assert_array_equal(a.t_fall, b.t_fall)
    for key in a.metrics:
        np.testing.assert_allclose(a.metrics[key], b.metrics[key], rtol=1e-12, atol=0, err_msg=key)


def test_the_compiled_loop_calls_the_scalar_loops_own_functions():
    from mwip_ros.core.control import controller, observer
    from mwip_ros.core.plants import sensing
    from mwip_ros.core.laws import dsc, lqr
    from mwip_ros.core.laws import get as law
    kernel = compiled.kernel_for(law("dscndo"))
    assert kernel is compiled.kernel_for(law("dsc")) is not compiled.kernel_for(law("lqr"))
    g = kernel.py_func.__globals__
    assert kernel.py_func.__code__ is compiled._loop.__code__
    for name, fn in (("z_start", observer.z_start), ("z_next", observer.z_next), ("tau_hat_of", observer.tau_hat_of),
                     ("u_taud_of", controller.u_taud_of), ("lumped_disturbance", model.lumped_disturbance),
                     ("at", model.Sinusoid.at), ("law_step", dsc.dsc_step),
                     ("drive_stage", compiled.drive_stage), ("sense_state", compiled.sense_state)):
        assert g[name].py_func.__code__ is fn.__code__, name
    # the stages drive and sensors (which the vector env runs too, envs.kernels) call the scalar loop's functions
    assert g["drive_stage"].py_func.__globals__["saturate"].py_func.__code__ is plant.saturate.__code__
    assert g["sense_state"].py_func.__globals__["quantize"].py_func.__code__ is sensing.quantize.__code__
    assert g["accel"] is compiled._accel and g["rk4_period"] is compiled._rk4_period
    assert g["z_next"].py_func.__globals__["z_dot_of"].py_func.__code__ is observer.z_dot_of.__code__
    assert compiled.kernel_for(law("lqr_ndo")).py_func.__globals__["law_step"].py_func.__code__ is \
        lqr.lqr_step.__code__
    # the laws' scalar step is the same pure function
    assert law("dsc").pure_step is dsc.dsc_step and law("lqr").pure_step is lqr.lqr_step


def test_a_law_without_a_pure_form_runs_the_numpy_loop():
    import trivial_law  # noqa: F401  (test/: registers 'trivial' and 'trivial_ndo')
    from mwip_ros.core.laws import get as law
    from mwip_ros.core.laws.dsc import DscLaw
    assert compiled.kernel_for(law("trivial_ndo")) is None
    # a subclass stepping otherwise than the pure form it inherits runs its own step, over numpy arrays
    assert compiled.kernel_for(type("Other", (DscLaw,), {"step": lambda self, x, tau_hat=None: (0.0, {})})) is None
    values = [dict(BASE, **{"trivial.k": 2000.0 + 100 * i, "seed": i, "initial.theta_b": 0.05 * i})
              for i in range(4)]
    loops = [P.closed_loop(v, duration=2.0, controller="trivial_ndo" if i % 2 else "trivial")
             for i, v in enumerate(values)]
    _check_equal(loops, simulate_batch(loops, WINDOW, compiled=True))


_LOOP_CHECK = """
from mwip_ros import params as P
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.kernels.batch import simulate_batch
from mwip_ros.core.closed_loop.sim import simulate
loop = P.closed_loop(dict(P.merged_values(P.load_param_file({p_file!r})), **{{"initial.theta_b": 0.1}}),
                     duration=0.2, controller="dscndo")
r = simulate_batch([loop], (0.1, 0.2), compiled=True)
m = metrics.compute(simulate(loop).columns, (0.1, 0.2), loop.plant.fall_angle)
print(repr(m.tau_err1_rms), repr(float(r.metrics["tau_err1_rms"][0])))
"""


@pytest.mark.slow
def test_an_edit_to_the_observer_is_compiled_afresh_in_the_batch_loop(tmp_path):
    """The compiled loop is cached under the stamp of every file it is made of: an edit to observer.py (not the
    loop's own file) reaches the next process's compiled loop."""
    import os
    import shutil
    import subprocess
    import sys

    pkg = Path(compiled.__file__).resolve().parents[2]
    shutil.copytree(pkg, tmp_path / "mwip_ros", ignore=shutil.ignore_patterns("__pycache__"))
    env = dict(os.environ, PYTHONPATH=str(tmp_path), NUMBA_CACHE_DIR=str(tmp_path / "numba_cache"))
    script = _LOOP_CHECK.format(p_file=str(P_FILE))

    def run():
        out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300,
                             cwd=tmp_path)
        assert out.returncode == 0, out.stderr
        return tuple(float(v) for v in out.stdout.split())

    first = run()
    assert first[1] == pytest.approx(first[0], rel=1e-9)
    assert list((tmp_path / "numba_cache").rglob("compiled._loop__*.nbi"))   # cached there
    obs = tmp_path / "mwip_ros" / "core" / "control" / "observer.py"
    text = obs.read_text()
    edit = "return (z[0] + step * d1, z[1] + step * d2)"
    assert edit in text
    obs.write_text(text.replace(edit, "return (z[0] + 0.5 * step * d1, z[1] + step * d2)"))
    second = run()
    assert second[0] != pytest.approx(first[0], rel=1e-6)   # the edit changes the observer
    assert second[1] == pytest.approx(second[0], rel=1e-9)  # and the compiled loop follows it


_LQR_CHECK = """
from mwip_ros import params as P
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.kernels.batch import simulate_batch
from mwip_ros.core.closed_loop.sim import simulate
loop = P.closed_loop(dict(P.merged_values(P.load_param_file({p_file!r})), **{{"initial.theta_b": 0.1}}),
                     duration=0.2, controller="lqr")
r = simulate_batch([loop], (0.1, 0.2), compiled=True)
m = metrics.compute(simulate(loop).columns, (0.1, 0.2), loop.plant.fall_angle)
print(repr(m.u_rms), repr(float(r.metrics["u_rms"][0])))
"""


@pytest.mark.slow
def test_an_edit_to_a_callee_or_a_frozen_constant_of_another_module_is_compiled_afresh(tmp_path):
    """The loop links in the law's callees (core/control/lqr.py's lqr_u, not the law's own file) and freezes the values
    of the globals it reads, wherever they were assigned: an edit to either reaches the next process's compiled loop,
    and a run without an edit only loads the cache (no file of it is written again)."""
    import os
    import shutil
    import subprocess
    import sys

    pkg = Path(compiled.__file__).resolve().parents[2]
    shutil.copytree(pkg, tmp_path / "mwip_ros", ignore=shutil.ignore_patterns("__pycache__"))
    core = tmp_path / "mwip_ros" / "core" / "control"
    lqr_py = core / "lqr.py"
    body = "return -(K[0] * theta_b + K[1] * dtheta_b + K[2] * dtheta_w)"
    assert body in lqr_py.read_text()
    # a constant lqr_u reads, assigned in a module no compiled function comes from
    (core / "lqr_scale.py").write_text("SCALE = 1.0\n")
    lqr_py.write_text(lqr_py.read_text().replace(body, "return -SCALE * (K[0] * theta_b + K[1] * dtheta_b + "
                                                       "K[2] * dtheta_w)")
                      .replace("\nimport ", "\nfrom .lqr_scale import SCALE\nimport ", 1))
    cache = tmp_path / "numba_cache"
    env = dict(os.environ, PYTHONPATH=str(tmp_path), NUMBA_CACHE_DIR=str(cache))
    script = _LQR_CHECK.format(p_file=str(P_FILE))

    def run():
        out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300,
                             cwd=tmp_path)
        assert out.returncode == 0, out.stderr
        scalar, batch = (float(v) for v in out.stdout.split())
        assert batch == pytest.approx(scalar, rel=1e-9)   # the compiled loop runs the code as it is now
        return batch

    def cache_files():
        return {p: p.stat().st_mtime_ns for p in cache.rglob("*") if p.is_file()}

    first = run()
    assert any(p.name.startswith("compiled._loop__") for p in cache_files())
    before = cache_files()
    assert run() == first
    assert cache_files() == before   # warm: loaded, nothing compiled and written again
    (core / "lqr_scale.py").write_text("SCALE = 1.25\n")   # only the constant's module
    scaled = run()
    assert scaled != pytest.approx(first, rel=1e-3)   # a stiffer law (in closed loop: not simply 1.25 x)
    lqr_py.write_text(lqr_py.read_text().replace("return -SCALE * (", "return -1.25 * SCALE * ("))   # the callee
    again = run()
    assert again != pytest.approx(scaled, rel=1e-3)


def test_the_stamp_follows_the_callees_and_the_frozen_values():
    """What the loop is made of: the law's callee's file (core/control/lqr.py), the estimator's frozen NIS_WINDOW_S by
    its value; a stamp that changes with the value."""
    import mwip_ros.core.estimators.kalman as kalman
    from mwip_ros.core.kernels import jitcache
    from mwip_ros.core.estimators import get as estimator
    from mwip_ros.core.laws import get as law

    kernel = compiled.kernel_for(law("lqr"), estimator("kalman"))
    files, consts = jitcache.made_of(kernel.py_func)
    assert str(Path(compiled.__file__).parents[1] / "control" / "lqr.py") in files
    assert any(c.endswith(f"NIS_WINDOW_S={kalman.NIS_WINDOW_S!r}") for c in consts), consts
    stamp = jitcache.stamp_of(kernel.py_func)
    assert jitcache.stamp_of(kernel.py_func) == stamp   # the same in every process (no address in it)
    # the compiled step's globals (a copy), through the stage that calls it (core.kernels.compiled.sense_raw)
    est = kernel.py_func.__globals__["sense_raw"].py_func.__globals__["est_step"].py_func.__globals__
    old = est["NIS_WINDOW_S"]
    try:
        est["NIS_WINDOW_S"] = old * 2
        assert jitcache.stamp_of(kernel.py_func) != stamp
    finally:
        est["NIS_WINDOW_S"] = old


def test_the_loops_arguments_by_name_are_its_parameters_in_order():
    """core.kernels.batch builds the kernel's arguments by keyword (core.kernels.kernel_args.LoopArgs) and passes them
    positionally: the bundle's fields must be the compiled loop's parameters, in its order."""
    from mwip_ros.core.kernels.kernel_args import LoopArgs
    code = compiled._loop.__code__
    assert LoopArgs._fields == code.co_varnames[:code.co_argcount]
