"""The identification excitation: none, chirp, prbs (docs/theory.md 6.9)."""
import math

import numpy as np
import pytest

from mwip_ros.core.identification.excitation import (Excitation, ExcitationConfig, at, chirp, chirp_frequency,
                                                     prbs_bit_periods)

pytestmark = pytest.mark.unit

H = 0.005


def test_none_is_zero_and_the_default():
    cfg = ExcitationConfig()
    assert cfg.type == "none" and not cfg.active
    assert all(at(cfg, k, H) == 0.0 for k in range(0, 5000, 37))
    assert all(at(ExcitationConfig("chirp", 0.0), k, H) == 0.0 for k in range(100))


def test_chirp_sweeps_f0_to_f1():
    cfg = ExcitationConfig("chirp", 3.0, 0.5, 4.5, 8.0)
    assert chirp_frequency(cfg, 0.0) == 0.5 and chirp_frequency(cfg, 8.0) == 4.5
    assert chirp_frequency(cfg, 4.0) == pytest.approx(2.5)
    t = np.arange(0.0, 8.0, 1e-4)
    x = np.array([chirp(cfg, s) for s in t])
    assert np.abs(x).max() == pytest.approx(3.0, rel=1e-3)
    # the zero crossings' spacing gives the local frequency: 1 / (2 spacing)
    up = np.flatnonzero(np.diff(np.signbit(x)))
    tz = t[up]
    mid = 0.5 * (tz[1:] + tz[:-1])
    f = 1.0 / (2.0 * np.diff(tz))
    for when, want in ((1.0, 1.0), (4.0, 2.5), (7.0, 4.0)):
        i = np.argmin(np.abs(mid - when))
        assert f[i] == pytest.approx(want, rel=0.03)
    assert chirp(cfg, 8.0) == 0.0 and chirp(cfg, -0.1) == 0.0   # only over [0, duration_s)
    # the period's value is the value at t_k = k h
    assert at(cfg, 123, H) == pytest.approx(3.0 * math.sin(2 * math.pi * (0.5 * 0.615 + 0.5 * 4.0 * 0.615 ** 2 / 8.0)))
    assert at(cfg, 1600, H) == 0.0   # t = 8.0 s: over


def test_prbs_is_plus_minus_amplitude_held_and_deterministic():
    cfg = ExcitationConfig("prbs", 7.0, f1=5.0, duration_s=60.0, seed=4)
    n = prbs_bit_periods(cfg, H)
    assert n == round(0.443 / (5.0 * H)) == 18
    x = Excitation(cfg, H).series(12000)
    assert set(np.unique(x)) == {-7.0, 7.0}
    assert np.all(x.reshape(-1, 1000)[:, :1] == x.reshape(-1, 1000)[:, :1])
    bits = x[: (len(x) // n) * n].reshape(-1, n)
    assert np.all(bits == bits[:, :1])            # held over n periods
    assert 0.4 < (bits[:, 0] > 0).mean() < 0.6    # both signs, about as often
    # deterministic per seed, whichever periods were asked for first
    late = Excitation(cfg, H)
    assert late.at(11999) == x[11999] and late.at(5) == x[5]
    assert np.array_equal(Excitation(cfg, H).series(12000), x)
    other = Excitation(ExcitationConfig("prbs", 7.0, f1=5.0, duration_s=60.0, seed=5), H).series(12000)
    assert not np.array_equal(other, x)
    assert at(cfg, 12000 * 5, H) == 0.0           # t = 300 s: after duration_s
    assert prbs_bit_periods(ExcitationConfig("prbs", 1.0, bit_periods=3), H) == 3


def test_prbs_spectrum_is_flat_in_band():
    cfg = ExcitationConfig("prbs", 1.0, f1=5.0, duration_s=400.0, seed=0)
    x = Excitation(cfg, H).series(80000)
    seg = 4000                                        # Welch by hand: 20 s segments, 0.05 Hz resolution
    p = np.mean([np.abs(np.fft.rfft(x[i:i + seg] * np.hanning(seg))) ** 2 for i in range(0, len(x), seg)], axis=0)
    f = np.fft.rfftfreq(seg, H)
    band = (f >= 0.2) & (f <= 5.0)
    T = 18 * H                                        # the bit time
    lo = np.arange(0.25, 5.0, 0.5)
    bands = np.array([p[(f >= a) & (f < a + 0.5)].mean() for a in lo])
    assert bands.max() / bands.min() < 10 ** 0.45     # within 4.5 dB over 0.25 .. 4.75 Hz (sinc^2: 3 dB, + scatter)
    shape = bands / np.sinc((lo + 0.25) * T) ** 2     # divided by a held random sign's sinc^2(f T)
    assert shape.max() / shape.min() < 10 ** 0.2      # what is left is flat within 2 dB
    assert p[band].mean() > 10 * p[(f > 20.0) & (f < 25.0)].mean()   # and it falls off beyond


def test_config_errors_name_the_key():
    for kwargs, key in ((dict(type="sine"), "excitation.type"), (dict(amplitude=-1.0), "excitation.amplitude"),
                        (dict(f1=0.0), "excitation.f1"), (dict(f0=6.0, f1=5.0), "excitation.f0"),
                        (dict(duration_s=0.0), "excitation.duration_s"), (dict(seed=-1), "excitation.seed"),
                        (dict(bit_periods=1.5), "excitation.bit_periods"), (dict(amplitude=math.inf),
                                                                              "excitation.amplitude")):
        with pytest.raises(ValueError, match=key):
            ExcitationConfig(**kwargs)
