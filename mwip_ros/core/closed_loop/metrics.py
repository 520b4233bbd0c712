"""The metrics of a run (docs/theory.md, what a correct implementation shows), from its columns.

``WINDOW`` is the reporting window the paper's comparison uses, t in [5, 10] s.  ``upright`` means the
run never fell (|theta_b| <= fall_angle over the whole run, :func:`fall_time`, a theta_b that is not a finite
number being a fall, and no failure in the run's own record, ``t_fall``); whether the run lasted
to the window's end is ``covers_window``, a separate question (:func:`fit_window` picks a window that fits
runs shorter than the requested one).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Mapping, Optional, Sequence, Tuple

import numpy as np

__all__ = ["WINDOW", "Metrics", "compute", "window_metrics", "fall_time", "fit_window", "WindowError",
           "layout", "markdown_table", "text_table", "json_safe", "motion_metrics", "motion_rows", "motion_table",
           "HOLD_SETTLE_S", "MOTION_METRICS"]

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
    upright: bool            # never fell: |theta_b| <= fall_angle over the whole run
    t_fall: Optional[float] = None    # the first t with |theta_b| > fall_angle (or the run's own record) [s]
    t_end: float = math.nan           # the run's last sample [s]
    covers_window: bool = True        # the run lasted to the window's end (a fallen run does not)
    theta_b_est_err_rms: float = math.nan    # raw sensors: RMS of theta_b_hat - theta_b [rad] (NaN: no estimate)
    dtheta_b_est_err_rms: float = math.nan   # RMS of dtheta_b_hat - dtheta_b [rad/s]
    u_applied_rms: float = math.nan          # motor model: RMS of the torque that acted in the window [N m]
    saturated_s: float = math.nan            # motor model: time the drive spent saturated (current or voltage
                                             # limit) over the whole run [s]

    def as_dict(self) -> dict:
        """The fields, NaN / infinite values as None (JSON null)."""
        return json_safe(asdict(self))


def json_safe(obj):
    """``obj`` with every non-finite float (NaN, +-inf) replaced by None, so ``json.dumps(..., allow_nan=False)``
    writes valid JSON (null); dicts, lists and tuples are walked."""
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def fall_time(t, theta_b, fall_angle: float) -> Optional[float]:
    """The first t with |theta_b| > ``fall_angle`` or theta_b not a finite number (a diverged state is never
    upright); None when there is none."""
    with np.errstate(invalid="ignore"):
        over = np.flatnonzero(~(np.abs(np.asarray(theta_b, dtype=float)) <= fall_angle))
    return float(np.asarray(t, dtype=float)[over[0]]) if len(over) else None


class WindowError(ValueError):
    """A requested metrics window that no run covers."""


def fit_window(window: Sequence[float], t_end: float, requested: bool = False) -> Tuple[Tuple[float, float], str]:
    """(the window to use, a sentence saying why it differs from ``window``, '' when it does not).

    ``t_end`` is when the longest run ends.  A window ending after it: with ``requested`` (the user asked
    for it) a :class:`WindowError`; else the run's second half, [t_end / 2, t_end]."""
    w0, w1 = float(window[0]), float(window[1])
    if not w0 < w1:
        raise WindowError(f"the window [{w0:g}, {w1:g}] s is empty (T0 must be < T1)")
    if t_end >= w1 - 1e-9:
        return (w0, w1), ""
    if requested:
        raise WindowError(f"the window [{w0:g}, {w1:g}] s lies outside the runs: the longest ends at "
                          f"t = {t_end:.3f} s")
    fit = (t_end / 2, t_end)
    return fit, (f"the runs end at t = {t_end:.3f} s, before the default window [{w0:g}, {w1:g}] s ends: "
                 f"metrics over the run's second half, t in [{fit[0]:g}, {fit[1]:g}] s")


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


def compute(cols: Mapping[str, np.ndarray], window: Sequence[float], fall_angle: float,
            t_fall: Optional[float] = None) -> Metrics:
    """Metrics of the columns ``t``, ``theta_b``, ``u`` (and ``tau_hat*``/``tau_d*`` when present).

    ``t_fall``: the run's own record of a fall (e.g. the plant's "FALLEN at t = ..." in a bag), used when
    the table shows none (|theta_b| never beyond ``fall_angle``)."""
    t = np.asarray(cols["t"])
    th = np.asarray(cols["theta_b"], dtype=float)
    sel = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    nan = np.full(int(sel.sum()), np.nan)
    err = [(np.asarray(cols[f"tau_hat{i}"]) - np.asarray(cols[f"tau_d{i}"]))[sel]
           if f"tau_hat{i}" in cols and f"tau_d{i}" in cols else nan for i in (1, 2)]
    m = window_metrics(th[sel][None, :], np.asarray(cols["u"], dtype=float)[sel][None, :], err[0][None, :],
                       err[1][None, :])
    est = {f"{c}_est_err_rms": float(_rms((np.asarray(cols[f"{c}_hat"], dtype=float) - np.asarray(cols[c]))[sel]))
           for c in ("theta_b", "dtheta_b") if f"{c}_hat" in cols and c in cols}
    if "u_applied" in cols and "drive_saturation" in cols:
        sat = np.asarray(cols["drive_saturation"], dtype=float)
        h = float(t[1] - t[0]) if len(t) > 1 else math.nan
        est["u_applied_rms"] = float(_rms(np.asarray(cols["u_applied"], dtype=float)[sel]))
        known = np.isfinite(sat)   # a bag's rows know the torque that acted, not the drive's saturation
        est["saturated_s"] = float(np.sum(sat[known] > 0) * h) if known.any() else math.nan
    fell = fall_time(t, th, fall_angle)
    fell = t_fall if fell is None else fell
    t_end = float(t[-1]) if len(t) else math.nan
    return Metrics(window_start=float(window[0]), window_end=float(window[1]), samples=int(sel.sum()),
                   upright=fell is None, t_fall=fell, t_end=t_end,
                   covers_window=fell is None and t_end >= window[1] - 1e-9,
                   **{k: float(v[0]) for k, v in m.items()}, **est)


HEADERS = [("run", "{}"), ("upright", "{}"), ("theta_b p2p [rad]", "{:.5f}"), ("theta_b RMS [rad]", "{:.5f}"),
           ("max abs theta_b [rad]", "{:.5f}"), ("u RMS [N m]", "{:.2f}"), ("tau_hat1 err RMS [N m]", "{:.3f}"),
           ("tau_hat2 err RMS [N m]", "{:.3f}"), ("fell at t [s]", "{}")]


def _cell(fmt: str, v) -> str:
    """A table cell; a metric without a value (NaN: no sample in the window) is '-'."""
    if isinstance(v, float) and not math.isfinite(v):
        return "-"
    return fmt.format(v)


# columns a table shows when a run has them: (header, format, the Metrics field)
OPTIONAL_HEADERS = [("theta_b est err RMS [rad]", "{:.5f}", "theta_b_est_err_rms"),
                    ("theta_b' est err RMS [rad/s]", "{:.5f}", "dtheta_b_est_err_rms"),
                    ("u applied RMS [N m]", "{:.2f}", "u_applied_rms"), ("saturated [s]", "{:.3f}", "saturated_s")]


def _optional(named: Sequence[tuple]) -> list:
    """The :data:`OPTIONAL_HEADERS` some run of ``named`` has a value of (raw sensors' estimate, the motor)."""
    return [o for o in OPTIONAL_HEADERS if any(math.isfinite(getattr(m, o[2])) for _, m in named)]


def _headers(named: Sequence[tuple]) -> list:
    return HEADERS + [(h, f) for h, f, _ in _optional(named)]


def table_rows(named: Sequence[tuple]) -> list:
    headers, extra = _headers(named), _optional(named)
    rows = []
    for name, m in named:
        vals = [name, "yes" if m.upright else "NO", m.theta_b_p2p, m.theta_b_rms, m.theta_b_max_abs, m.u_rms,
                m.tau_err1_rms, m.tau_err2_rms, "-" if m.t_fall is None else f"{m.t_fall:.3f}",
                *(getattr(m, f) for _, _, f in extra)]
        rows.append([_cell(fmt, v) for (_, fmt), v in zip(headers, vals)])
    return rows


def layout(head: Sequence[str], rows: Sequence[Sequence[str]], markdown: bool = False) -> str:
    """Cells under ``head`` as a Markdown table, or a fixed-width one for terminals (every table a tool prints)."""
    if markdown:
        return "\n".join(["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|",
                          *("| " + " | ".join(r) + " |" for r in rows)])
    widths = [max(len(head[i]), *(len(r[i]) for r in rows)) for i in range(len(head))]
    fmt = "  ".join("{:<%d}" % w for w in widths)
    return "\n".join([fmt.format(*head)] + [fmt.format(*r) for r in rows])


def markdown_table(named: Sequence[tuple]) -> str:
    """A Markdown table, one row per (name, Metrics)."""
    return layout([h for h, _ in _headers(named)], table_rows(named), markdown=True)


def text_table(named: Sequence[tuple]) -> str:
    """A fixed-width table for terminals."""
    return layout([h for h, _ in _headers(named)], table_rows(named))


HOLD_SETTLE_S = 2.0   # the hold's first seconds after v* reached 0 are the stop, not the hold
MOTION_METRICS = ("speed_rms", "hold_drift", "hold_rate", "max_lean")   # motion_metrics' numbers, in order


def motion_metrics(cols: Mapping[str, np.ndarray], r: float, fall_angle: float, t_fall: Optional[float] = None,
                   settle: float = HOLD_SETTLE_S) -> dict:
    """The tracking metrics of a run with motion references (docs/theory.md 6.11; columns ``v_ref``, ``theta_w_ref``):

    * ``speed_rms``: RMS of v - v* over the run, v = r theta_w' [m/s];
    * ``hold_drift``: r (theta_w(end) - theta_w(hold start)) [m] over the hold: the final stretch with v* = 0, from
      ``settle`` s after v* reached 0 (NaN without such a stretch); ``hold_rate`` that over its length [m/s];
    * ``max_lean``: the largest |theta_b| [rad]; ``upright``: it stayed up (no fall recorded or seen).
    Non-finite samples are left out (a verdict is never taken from NaN)."""
    t = np.asarray(cols["t"], dtype=float)
    v = r * np.asarray(cols["dtheta_w"], dtype=float)
    v_ref = np.asarray(cols["v_ref"], dtype=float)
    th = np.asarray(cols["theta_b"], dtype=float)
    moving = np.flatnonzero(~(v_ref == 0.0))
    start = t[moving[-1] + 1] if len(moving) and moving[-1] + 1 < len(t) else (t[0] if not len(moving) else math.nan)
    hold = t >= start + settle - 1e-9 if math.isfinite(start) else np.zeros(len(t), bool)
    tw = np.asarray(cols["theta_w"], dtype=float)[hold]
    drift = float(r * (tw[-1] - tw[0])) if len(tw) > 1 else math.nan
    span = float(t[hold][-1] - t[hold][0]) if len(tw) > 1 else math.nan
    fell = fall_time(t, th, fall_angle)
    fell = t_fall if fell is None else fell
    finite_th = th[np.isfinite(th)]
    return {"speed_rms": float(_rms(v - v_ref)), "hold_drift": drift,
            "hold_rate": drift / span if len(tw) > 1 and span > 0 else math.nan,
            "max_lean": float(np.max(np.abs(finite_th))) if len(finite_th) else math.nan,
            "upright": fell is None}


MOTION_HEADERS = [("run", "{}"), ("upright", "{}"), ("speed err RMS [m/s]", "{:.4f}"),
                  ("hold drift [m]", "{:.4f}"), ("hold drift rate [m/s]", "{:.4f}"),
                  ("max abs theta_b [rad]", "{:.4f}")]


def motion_rows(named: Sequence[tuple]) -> list:
    """The cells of a motion table, one row per (name, :func:`motion_metrics` dict)."""
    return [[_cell(fmt, v) for (_, fmt), v in zip(MOTION_HEADERS, (name, "yes" if m["upright"] else "NO",
                                                                    m["speed_rms"], m["hold_drift"], m["hold_rate"],
                                                                    m["max_lean"]))] for name, m in named]


def motion_table(named: Sequence[tuple], markdown: bool = False) -> str:
    """The motion metrics as a fixed-width (or Markdown) table."""
    return layout([h for h, _ in MOTION_HEADERS], motion_rows(named), markdown)
