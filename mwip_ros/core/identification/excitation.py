"""A known excitation torque added to the controller's command, for identification (docs/theory.md 6.9); off by default.

``excitation.type``:

* ``none``: zero (the default).
* ``chirp``: ``amplitude sin(2 pi (f0 t + (f1 - f0) t^2 / (2 duration_s)))``, a linear sweep whose
  instantaneous frequency ``f0 + (f1 - f0) t / duration_s`` goes from ``f0`` to ``f1`` over
  ``duration_s``; zero after it.
* ``prbs``: a random binary sequence, ``+-amplitude``, each bit held ``bit_periods`` control periods
  (whole periods: the command is held over a period); zero after ``duration_s``.  The bits are drawn
  from ``numpy.random.default_rng([seed, EXCITATION_STREAM])`` (a generator of its own, so the plant's D_w
  and sensor draws are unchanged), in blocks of :data:`BIT_BLOCK`, always in the same order: the value of
  period k is the same whichever periods were asked for before.  Its spectrum is that of a held random
  sign, ``~ sinc^2(f T)``, ``T`` the bit time: flat from 0 to about ``0.44 / T`` (-3 dB); with
  ``bit_periods`` 0 the bit time is chosen from ``f1``: ``round(0.44 / (f1 h))`` periods (at least 1),
  so the band [0, f1] is flat within 3 dB.  ``f0`` is the chirp's only.

Period k (the command answering state k, held over [t_k, t_k+1)) gets the value at ``t_k = k h``:
:func:`at`.  :func:`chirp` is the pure function of t.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Optional

import numpy as np

__all__ = ["TYPES", "EXCITATION_STREAM", "BIT_BLOCK", "ExcitationConfig", "Excitation", "chirp",
           "chirp_frequency", "prbs_bit_periods", "at"]

TYPES = ("none", "chirp", "prbs")
EXCITATION_STREAM = 3   # default_rng([seed, 3]); the plant's D_w is default_rng(seed), its sensors [seed, 1]
BIT_BLOCK = 4096        # bits drawn per generator call
_PRBS_3DB = 0.443       # sinc^2(f T) = 1/2 at f T = 0.443


def _number(key: str, v, lo: float, lo_open: bool = False) -> float:
    ok = not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) and (v > lo if lo_open
                                                                                             else v >= lo)
    if not ok:
        raise ValueError(f"excitation.{key}: must be a finite number {'>' if lo_open else '>='} {lo:g}, got {v!r}")
    return float(v)


@dataclass(frozen=True)
class ExcitationConfig:
    """``excitation.*`` of the controller (module doc); ValueError naming the key for a value out of range."""

    type: str = "none"
    amplitude: float = 0.0       # [N m]
    f0: float = 0.1              # chirp start frequency [Hz]
    f1: float = 5.0              # chirp end frequency, prbs band edge [Hz]
    duration_s: float = 10.0     # the excitation lasts this long [s], from t = 0
    bit_periods: int = 0         # prbs: control periods a bit is held; 0 = from f1
    seed: int = 0                # prbs

    def __post_init__(self):
        if self.type not in TYPES:
            raise ValueError(f"excitation.type: must be one of {', '.join(TYPES)}, got {self.type!r}")
        _number("amplitude", self.amplitude, 0.0)
        _number("f0", self.f0, 0.0)
        _number("f1", self.f1, 0.0, lo_open=True)
        if self.f0 > self.f1:
            raise ValueError(f"excitation.f0: must be <= excitation.f1 ({self.f1:g} Hz), got {self.f0:g}")
        _number("duration_s", self.duration_s, 0.0, lo_open=True)
        for key in ("bit_periods", "seed"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"excitation.{key}: must be an integer >= 0, got {v!r}")

    @property
    def active(self) -> bool:
        return self.type != "none" and self.amplitude > 0.0


def chirp_frequency(cfg: ExcitationConfig, t: float) -> float:
    """The chirp's instantaneous frequency at t [Hz] (over [0, duration_s]; 0 outside)."""
    if not 0.0 <= t <= cfg.duration_s:
        return 0.0
    return cfg.f0 + (cfg.f1 - cfg.f0) * t / cfg.duration_s


def chirp(cfg: ExcitationConfig, t: float, m=math) -> float:
    """``amplitude sin(2 pi (f0 t + (f1 - f0) t^2 / (2 T)))`` for t in [0, T = duration_s), else 0 [N m]."""
    if not 0.0 <= t < cfg.duration_s:
        return 0.0
    return cfg.amplitude * m.sin(2.0 * math.pi * (cfg.f0 * t + 0.5 * (cfg.f1 - cfg.f0) * t * t / cfg.duration_s))


def prbs_bit_periods(cfg: ExcitationConfig, h: float) -> int:
    """Control periods a PRBS bit is held: ``bit_periods``, or (0) ``round(0.443 / (f1 h))``, at least 1."""
    if cfg.bit_periods > 0:
        return int(cfg.bit_periods)
    return max(1, int(round(_PRBS_3DB / (cfg.f1 * h))))


class Excitation:
    """The excitation of one run at control period ``h``: :meth:`at` (period k) keeps its PRBS bits."""

    def __init__(self, cfg: ExcitationConfig, h: float):
        if not (math.isfinite(h) and h > 0):
            raise ValueError(f"control period h: must be > 0, got {h!r}")
        self.cfg, self.h = cfg, float(h)
        self._end = int(math.ceil(cfg.duration_s / self.h - 1e-9))   # first period at or after duration_s
        self._bits = np.empty(0, dtype=np.int8)
        self._rng: Optional[np.random.Generator] = None
        self.bit_periods = prbs_bit_periods(cfg, self.h) if cfg.type == "prbs" else 0

    def _bit(self, j: int) -> int:
        while j >= len(self._bits):   # sequential blocks: bit j is the same whatever was asked before
            if self._rng is None:
                self._rng = np.random.default_rng([int(self.cfg.seed), EXCITATION_STREAM])
            self._bits = np.concatenate([self._bits, self._rng.integers(0, 2, BIT_BLOCK, dtype=np.int8)])
        return int(self._bits[j])

    def at(self, k: int) -> float:
        """The excitation over period k [N m] (0 for k < 0 and from ``duration_s`` on)."""
        c = self.cfg
        if not c.active or k < 0 or k >= self._end:
            return 0.0
        if c.type == "chirp":
            return chirp(c, k * self.h)
        return c.amplitude if self._bit(k // self.bit_periods) else -c.amplitude

    def series(self, n: int) -> np.ndarray:
        """Periods 0 .. n-1 as an array."""
        return np.array([self.at(k) for k in range(n)])


@lru_cache(maxsize=16)
def _cached(cfg: ExcitationConfig, h: float) -> Excitation:
    return Excitation(cfg, h)


def at(cfg: ExcitationConfig, k: int, h: float) -> float:
    """The excitation over period k at control period ``h`` [N m]: a pure function of (cfg, k, h) (the PRBS bits
    of the last few configurations are kept, so a caller need not hold an :class:`Excitation`)."""
    return _cached(cfg, float(h)).at(k)
