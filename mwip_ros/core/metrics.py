"""The metrics of a run (docs/theory.md, what a correct implementation shows), from its columns.

``WINDOW`` is the reporting window the paper's comparison uses, t in [5, 10] s.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Mapping, Sequence

import numpy as np

__all__ = ["WINDOW", "Metrics", "compute", "markdown_table", "text_table"]

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


def _rms(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2))) if len(x) else float("nan")


def compute(cols: Mapping[str, np.ndarray], window: Sequence[float], fall_angle: float) -> Metrics:
    """Metrics of the columns ``t``, ``theta_b``, ``u`` (and ``tau_hat*``/``tau_d*`` when present)."""
    t = np.asarray(cols["t"])
    th = np.asarray(cols["theta_b"])
    sel = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    w = th[sel]
    nan = float("nan")
    err = {}
    for i in (1, 2):
        if f"tau_hat{i}" in cols and f"tau_d{i}" in cols:
            err[i] = _rms((np.asarray(cols[f"tau_hat{i}"]) - np.asarray(cols[f"tau_d{i}"]))[sel])
        else:
            err[i] = nan
    return Metrics(
        window_start=float(window[0]), window_end=float(window[1]), samples=int(sel.sum()),
        theta_b_p2p=float(w.max() - w.min()) if len(w) else nan,
        theta_b_rms=_rms(w), theta_b_max_abs=float(np.abs(w).max()) if len(w) else nan,
        u_rms=_rms(np.asarray(cols["u"])[sel]), tau_err1_rms=err[1], tau_err2_rms=err[2],
        upright=bool(np.all(np.abs(th) <= fall_angle) and t[-1] >= window[1] - 1e-9),
    )


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
