"""The controller's excitation in the offline loop (identification): added to the law's command and recorded."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mwip_ros import params as P
from mwip_ros.core.closed_loop.sim import simulate

pytestmark = pytest.mark.unit

CONFIG = Path(__file__).resolve().parents[3] / "config"


def test_the_command_is_the_law_plus_the_chirp_and_the_chirp_is_recorded():
    v = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "identify.yaml"]))
    run = simulate(P.closed_loop(v, controller="dscndo", duration=3.0))
    t = run["t"]
    A, f0, f1, T = (v[f"excitation.{k}"] for k in ("amplitude", "f0", "f1", "duration_s"))
    chirp = A * np.sin(2 * math.pi * (f0 * t + 0.5 * (f1 - f0) * t ** 2 / T))   # written out, not the code's
    np.testing.assert_allclose(run["excitation"], chirp, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run["u"] - run["excitation"], run["u_dsc"] - run["u_taud"], rtol=0, atol=1e-9)
    assert v["tau_ext1.amplitude"] == 0.0 and v["tau_ext2.amplitude"] == 0.0   # nothing unknown pushes the robot


def test_no_excitation_is_the_paper_bit_for_bit():
    base = P.merged_values(P.load_param_file(CONFIG / "paper.yaml"))
    off = simulate(P.closed_loop(dict(base, **{"excitation.type": "chirp", "excitation.amplitude": 0.0}),
                                 controller="dscndo", duration=1.0))
    ref = simulate(P.closed_loop(base, controller="dscndo", duration=1.0))
    assert "excitation" not in off.columns
    np.testing.assert_array_equal(off["u"], ref["u"])


def test_f0_above_f1_is_refused_naming_the_key():
    v = P.merged_values(P.load_param_files([CONFIG / "paper.yaml", CONFIG / "identify.yaml"]))
    with pytest.raises(P.ParamError, match="excitation.f0"):
        P.check_derived(dict(v, **{"excitation.f0": 6.0}))
