"""The metrics of a run (docs/theory.md, what a correct implementation shows), from its columns.

``WINDOW`` is the reporting window the paper's comparison uses, t in [5, 10] s.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Mapping, Sequence

import numpy as np

__all__ = ["WINDOW", "Metrics", "compute", "window_metrics", "markdown_table", "text_table"]

WINDOW = (5.0, 10.0)


@dataclass(frozen=True)
class Metrics:
    window_start: float
    window_end: float
    samples: int
    theta_b_p2p: float       # peak-to-peak theta_b in the window [rad]
    theta_b_rms: float       # [rad]
    theta_b_max_abs: float   # [rad]
    u_rms: float             # [N m]
    tau_err1_rms: float      # RMS of tau_hat1 - tau_d1 [N m] (NaN without estimates)
    tau_err2_rms: float      # RMS of tau_hat2 - tau_d2 [N m]
    upright: bool            # |theta_b| stayed below fall_angle for the whole run

    def as_dict(self) -> dict:
        return asdict(self)


def _rms(x: np.ndarray) -> np.ndarray:
    """RMS along the last axis over the finite entries (NaN marks a missing sample); NaN without any."""
    ok = np.isfinite(x)
    n = ok.sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.sqrt(np.sum(np.where(ok, x, 0.0) ** 2, axis=-1) / n), np.nan)


def window_metrics(theta_b: np.ndarray, u: np.ndarray, err1: np.ndarray, err2: np.ndarray) -> dict:
    """The window's metrics of many runs at once: each argument has a row per run and a column per sample
    of the window (NaN where a run has no sample, e.g. after it fell).  One implementation serves a single
    run (:func:`compute`) and the batch simulator."""
    ok = np.isfinite(theta_b)
    any_ = ok.any(axis=-1)
    if theta_b.shape[-1] == 0:  # no sample in the window at all (a run that ended before it)
        nan = np.full(theta_b.shape[:-1], np.nan)
        return {k: nan for k in ("theta_b_p2p", "theta_b_rms", "theta_b_max_abs", "u_rms", "tau_err1_rms",
                                 "tau_err2_rms")}
    with np.errstate(invalid="ignore"):
        hi = np.where(any_, np.max(np.where(ok, theta_b, -np.inf), axis=-1), np.nan)
        lo = np.where(any_, np.min(np.where(ok, theta_b, np.inf), axis=-1), np.nan)
        max_abs = np.where(any_, np.max(np.where(ok, np.abs(theta_b), -np.inf), axis=-1), np.nan)
    return {"theta_b_p2p": hi - lo, "theta_b_rms": _rms(theta_b), "theta_b_max_abs": max_abs, "u_rms": _rms(u),
            "tau_err1_rms": _rms(err1), "tau_err2_rms": _rms(err2)}


def compute(cols: Mapping[str, np.ndarray], window: Sequence[float], fall_angle: float) -> Metrics:
    """Metrics of the columns ``t``, ``theta_b``, ``u`` (and ``tau_hat*``/``tau_d*`` when present)."""
    t = np.asarray(cols["t"])
    th = np.asarray(cols["theta_b"], dtype=float)
    sel = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    nan = np.full(int(sel.sum()), np.nan)
    err = [(np.asarray(cols[f"tau_hat{i}"]) - np.asarray(cols[f"tau_d{i}"]))[sel]
           if f"tau_hat{i}" in cols and f"tau_d{i}" in cols else nan for i in (1, 2)]
    m = window_metrics(th[sel][None, :], np.asarray(cols["u"], dtype=float)[sel][None, :], err[0][None, :],
                       err[1][None, :])
    return Metrics(window_start=float(window[0]), window_end=float(window[1]), samples=int(sel.sum()),
                   upright=bool(np.all(np.abs(th) <= fall_angle) and t[-1] >= window[1] - 1e-9),
                   **{k: float(v[0]) for k, v in m.items()})


HEADERS = [("run", "{}"), ("upright", "{}"), ("theta_b p2p [rad]", "{:.5f}"), ("theta_b RMS [rad]", "{:.5f}"),
           ("max abs theta_b [rad]", "{:.5f}"), ("u RMS [N m]", "{:.2f}"), ("tau_hat1 err RMS [N m]", "{:.3f}"),
           ("tau_hat2 err RMS [N m]", "{:.3f}")]


def table_rows(named: Sequence[tuple]) -> list:
    rows = []
    for name, m in named:
        vals = [name, "yes" if m.upright else "NO", m.theta_b_p2p, m.theta_b_rms, m.theta_b_max_abs, m.u_rms,
                m.tau_err1_rms, m.tau_err2_rms]
        rows.append([fmt.format(v) for (_, fmt), v in zip(HEADERS, vals)])
    return rows


def markdown_table(named: Sequence[tuple]) -> str:
    """A Markdown table, one row per (name, Metrics)."""
    head = [h for h, _ in HEADERS]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in table_rows(named)]
    return "\n".join(lines)


def text_table(named: Sequence[tuple]) -> str:
    """A fixed-width table for terminals."""
    head = [h for h, _ in HEADERS]
    rows = table_rows(named)
    widths = [max(len(head[i]), *(len(r[i]) for r in rows)) for i in range(len(head))]
    fmt = "  ".join("{:<%d}" % w for w in widths)
    return "\n".join([fmt.format(*head)] + [fmt.format(*r) for r in rows])
