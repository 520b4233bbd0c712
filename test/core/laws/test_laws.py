"""The laws' registry: the four laws, the observer term composed, and a law added by a test (test/trivial_law.py)
runs offline, in a batch (equal to the scalar loop) and, through the plug-in hook, in mwip_sim and the schema."""
import copy
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from mathfixtures import NOM, P_FILE, PAPER_GAINS, RNG, assert_batch_equals_scalar, random_state
from mwip_ros import params as P
from mwip_ros.core import laws
from mwip_ros.core.control.controller import DscController
from mwip_ros.core.control.lqr import LqrController, lqr_gain
from mwip_ros.core.closed_loop.sim import LAWS, law_name, simulate
from mwip_ros.msgs import layouts as L

import trivial_law  # noqa: E402  registers 'trivial' and 'trivial_ndo', as a plug-in module would

pytestmark = pytest.mark.unit

TEST_DIR = Path(__file__).resolve().parents[2]
BASE = P.merged_values(P.load_param_file(P_FILE))
H = 1.0 / BASE["control_rate_hz"]


def test_the_registry_holds_the_four_laws_and_maps_the_node_parameters_onto_them():
    assert laws.names()[:4] == ("dsc", "dscndo", "lqr", "lqr_ndo")
    assert laws.families()[:2] == ("dsc", "lqr")
    old = {"dsc": ("dsc", False), "dscndo": ("dsc", True), "lqr": ("lqr", False), "lqr_ndo": ("lqr", True)}
    assert {n: LAWS[n] for n in old} == old                     # the old table, now a view of the registry
    for name, (family, obs) in old.items():
        assert law_name(family, obs) == name == laws.variant(family, obs).name
    assert [laws.get(n).title for n in old] == ["DSC", "DSCNDO", "LQR", "LQR+NDO"]
    assert P.specs_for("dscndo_controller")["law"].choices[:2] == ("dsc", "lqr")
    with pytest.raises(KeyError, match="unknown law 'pid'"):
        laws.get("pid")


def test_the_observer_variants_compose_the_one_observer_term():
    """DSCNDO = DSC + u_taud (eq. 19-21) and LQR+NDO = LQR + u_taud: the same class, bit for bit as before."""
    from mwip_ros.core.laws.ndo import WithObserver
    assert issubclass(laws.get("dscndo"), WithObserver) and laws.get("dscndo").base is laws.get("dsc")
    assert issubclass(laws.get("lqr_ndo"), WithObserver) and laws.get("lqr_ndo").base is laws.get("lqr")
    K = lqr_gain(NOM, H, BASE["lqr.Q"], BASE["lqr.R"])
    for obs in (False, True):
        old = [DscController(NOM, PAPER_GAINS, H, use_observer=obs), LqrController(NOM, K, use_observer=obs)]
        new = [laws.variant(f, obs).from_params(BASE, NOM, H) for f in ("dsc", "lqr")]
        for _ in range(50):
            x, tau_hat = random_state(RNG), tuple(RNG.uniform(-30, 30, 2))
            for a, b in zip(old, new):
                out = a.step(x, tau_hat)
                u, internals = b.step(x, tau_hat)
                assert u == out.u
                assert all(internals[n] == getattr(out, n) for n in internals)
                assert set(internals) <= set(b.internal_names)


def test_each_law_publishes_its_own_internals_and_lqr_keeps_the_documented_layout():
    for name in ("dsc", "dscndo", "lqr", "lqr_ndo"):
        assert laws.get(name).internal_names == L.INTERNAL_NAMES
    u, internals = laws.get("lqr").from_params(BASE, NOM, H).step(random_state(RNG))
    stamp, values = L.parse_internals(L.encode_internals(7, internals, laws.get("lqr").internal_names))
    assert list(values) == list(L.INTERNAL_NAMES) and values["u"] == u and values["u_taud"] == 0.0
    assert all(math.isnan(values[n]) for n in ("S2", "x1", "x4_bar", "x4d"))   # as before: DSC's own, NaN
    law = laws.get("trivial_ndo").from_params(dict(BASE, **{"trivial.k": 2000.0}), NOM, H)
    assert law.internal_names == ("u", "theta_b", "u_taud")
    u, internals = law.step(random_state(RNG), (1.0, 2.0))
    assert L.parse_internals(L.encode_internals(1, internals, law.internal_names))[1] == internals


def test_a_name_is_registered_once():
    class Other(trivial_law.TrivialLaw):
        pass
    with pytest.raises(ValueError, match="registered already"):
        laws.register(Other)
    assert laws.register(trivial_law.TrivialLaw, with_observer="trivial_ndo") is trivial_law.TrivialLaw


def _trivial(i, **extra):
    return dict(BASE, seed=i, **{"trivial.k": 1800.0 + 100.0 * i, "initial.theta_b": -0.05 * (i + 1)}, **extra)


def test_a_law_added_by_a_test_runs_offline():
    run = simulate(P.closed_loop(_trivial(0), controller="trivial", duration=2.0))
    assert run.label == "trivial" and len(run) == 401 and not run.fallen
    np.testing.assert_array_equal(run["u"], 1800.0 * run["theta_b"])                 # u = k theta_b
    assert np.isnan(run["S2"]).all() and np.isnan(run["u_taud"]).all()              # not this law's signals
    ndo = simulate(P.closed_loop(_trivial(0), law="trivial", use_observer=True, duration=2.0))
    assert ndo.label == "trivial_ndo" and np.isfinite(ndo["u_taud"]).all()
    m12, m22 = NOM.m12, NOM.m22
    mc = m12 * np.cos(ndo["theta_b"])
    u_taud = ndo["tau_hat1"] - mc / (m22 + mc) * ndo["tau_hat2"]                      # eq. (20)-(21)
    np.testing.assert_allclose(ndo["u"], 1800.0 * ndo["theta_b"] - u_taud, rtol=0, atol=1e-9)   # eq. (19)


def test_a_law_added_by_a_test_runs_in_a_batch_equal_to_the_scalar_loop():
    loops = [P.closed_loop(_trivial(i), law="trivial", use_observer=bool(i % 2), duration=2.0) for i in range(5)]
    batch, _ = assert_batch_equals_scalar(loops, (1.0, 2.0))
    assert [b.label for b in batch.trajectories] == ["trivial_ndo" if i % 2 else "trivial" for i in range(5)]


def _with_plugin():
    env = dict(os.environ, MWIP_ROS_LAWS="trivial_law")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(TEST_DIR), env.get("PYTHONPATH", "")) if p)
    return env


@pytest.mark.cli
def test_the_plugin_hook_gives_the_law_to_the_schema_and_to_mwip_sim(tmp_path):
    code = ("from mwip_ros import params as P; s = P.specs_for('dscndo_controller'); "
            "print(s['law'].choices, s['trivial.k'].default, s['trivial.k'].dynamic)")
    r = subprocess.run([sys.executable, "-c", code], env=_with_plugin(), capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["('dsc',", "'lqr',", "'smc',", "'mpc',", "'trivial')", "2000.0", "True"]
    out = tmp_path / "trivial.csv"
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", "--controller", "trivial", "--duration", "1",
                        "--csv", str(out), "-q"], env=_with_plugin(), capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    from mwip_ros.runs import read_csv
    offline = simulate(P.closed_loop(dict(BASE, **{"trivial.k": 2000.0}), controller="trivial", duration=1.0))
    graph = read_csv(out)
    np.testing.assert_allclose(graph["u"], offline["u"], rtol=0, atol=1e-9)


# --- the parameters a law declares itself (smc, mpc): the node has them, ranges refused naming the key -----------
def _declaring():
    from mwip_ros.core.laws import mpc, smc
    return {"smc": smc, "mpc": mpc}


@pytest.mark.parametrize("name", ["smc", "mpc"])
def test_a_law_declares_its_parameters_and_the_node_has_them(name):
    module = _declaring()[name]
    base = P.merged_values(P.load_param_file(P_FILE))
    specs = P.specs_for("dscndo_controller")
    assert name in specs["law"].choices
    for p in module.PARAMETERS:
        spec = specs[p.name]
        assert spec.dynamic and (spec.lo, spec.hi, spec.default) == (p.lo, p.hi, p.default)
        assert base[p.name] == p.default                   # config/paper.yaml holds the defaults
    assert set(laws.get(name).param_keys) == {p.name for p in module.PARAMETERS}


@pytest.mark.parametrize("key, value, words", [
    ("smc.boundary_layer", -0.1, ">= 0"), ("smc.k", -1.0, ">= 0"), ("smc.q", 151.0, "<= 150"),
    ("smc.pole1", 0.0, ">= 0.01"), ("smc.pole2", 2000.0, "<= 1000"), ("smc.k", 40, "floating-point"),
    ("mpc.horizon", 0, "from 1 to 200"), ("mpc.horizon", 201, "from 1 to 200"), ("mpc.horizon", 20.0, "integer"),
    ("mpc.R", 0.0, ">= 1e-06"), ("mpc.R", 2e6, "<= 1e+06"), ("mpc.u_max", 0.0, ">= 0.1"),
    ("mpc.u_max", 120, "floating-point")])
def test_a_declared_parameter_out_of_range_is_refused_naming_the_key(key, value, words):
    pf = P.load_param_file(P_FILE)
    with pytest.raises(P.ParamError) as ei:                  # an override (-p smc.k:=-1.0), as the node checks it
        pf.for_node("dscndo_controller", {key: value})
    assert ei.value.key == key and words in str(ei.value)
    doc = copy.deepcopy(yaml.safe_load(P_FILE.read_text()))  # and in a file
    doc["dscndo_controller"]["ros__parameters"][key.split(".")[0]][key.split(".")[1]] = value
    with pytest.raises(P.ParamError) as ei:
        P.parse_param_dict(doc, "p.yaml")
    assert ei.value.key == f"dscndo_controller.{key}" and words in str(ei.value)


@pytest.mark.parametrize("name", ["dsc", "dscndo"])
@pytest.mark.parametrize("tracking", [False, True])
def test_dsc_told_of_a_gap_advances_its_filters_over_it(name, tracking):
    """A realtime controller whose states come n periods apart says so (Law.elapsed(n h)) and DSC's filters (eq. 25:
    x4d, and x_d when it tracks a reference) advance over the whole gap with the last step's targets held: the same
    as the law stepped every period with the state of the gap's start repeated.  Told nothing, it is unchanged."""
    from mwip_ros.core.control.motion import Reference
    h, gap = 0.005, 10
    cls = laws.get(name)
    gapped, every = (cls(PAPER_GAINS, NOM, h) for _ in range(2))
    ref = Reference(0.3, 0.5, 0.5 * NOM.r, 0.0, 2.0, 0.8) if tracking else None
    rng = np.random.default_rng(49)
    states = [tuple(rng.uniform(-0.1, 0.1, 4)) for _ in range(8)]
    tau = (0.0, 0.0) if name == "dscndo" else None
    for law in (gapped, every):
        law.track(ref)
        law.step(states[0], tau)
    for j in range(1, len(states)):
        for _ in range(gap - 1):
            every.step(states[j - 1], tau)
        want_u, want = every.step(states[j], tau)
        gapped.elapsed(gap * h)
        got_u, got = gapped.step(states[j], tau)
        assert got_u == pytest.approx(want_u, rel=1e-9, abs=1e-9)
        assert got["x4d"] == pytest.approx(want["x4d"], rel=1e-9, abs=1e-12)
    plain, told = (cls(PAPER_GAINS, NOM, h) for _ in range(2))
    for k, x in enumerate(states):   # elapsed(h): one period, the lockstep step to the bit
        if k:
            told.elapsed(h)
        assert told.step(x, tau) == plain.step(x, tau)
