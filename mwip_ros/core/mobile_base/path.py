"""The path of a run on the ground against the ideal one of its references (docs/laws.md, "Driving a path").

The ideal path is the references' own: v*_k and psi'*_k (the trajectory's ``v_ref`` and ``dpsi_ref``) held over each
period, integrated exactly along arcs (:func:`.odometry.arc_step`, the odometry's own step) from the run's first pose.
The cross-track error of a sample is the distance of the axle's centre (x, y) to the nearest point of that path (a
polyline through the ideal pose of every period, 2.5 mm apart at 0.5 m/s): how far off the path the robot is,
whatever its timing along it.  Turning in place (v* = 0, psi'* not 0) the robot pitches with the yaw torque; its
largest |theta_b| there is the pitch bound of the turn.  Non-finite samples are left out (no verdict from NaN).
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence, Tuple, Union

import numpy as np

from ..closed_loop.metrics import layout
from .odometry import arc_step

__all__ = ["ideal_path", "cross_track", "path_metrics", "PATH_HEADERS", "path_rows", "path_table"]


def ideal_path(v_ref: Union[Sequence[float], np.ndarray], dpsi_ref: Union[Sequence[float], np.ndarray],
               h: float, start=(0.0, 0.0, 0.0)
               ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, psi) of the references at every t_k: the pose ``start`` at t_0, then v*_k, psi'*_k held over period k."""
    n = len(v_ref)
    out = np.empty((3, n))
    x, y, psi = (float(s) for s in start)
    for k in range(n):
        out[:, k] = x, y, psi
        x, y, psi = arc_step(x, y, psi, float(v_ref[k]), float(dpsi_ref[k]), h)
    return out[0], out[1], out[2]


def cross_track(px: np.ndarray, py: np.ndarray, ix: np.ndarray, iy: np.ndarray, chunk: int = 256) -> np.ndarray:
    """The distance of each point (px, py) to the polyline through (ix, iy) (a single point: the distance to it)."""
    ax, ay = ix[:-1], iy[:-1]
    dx, dy = np.diff(ix), np.diff(iy)
    ll = dx * dx + dy * dy
    if not len(ll):
        return np.hypot(px - ix[0], py - iy[0])
    safe = np.where(ll > 0.0, ll, 1.0)
    out = np.empty(len(px))
    for s in range(0, len(px), chunk):
        qx, qy = px[s:s + chunk, None], py[s:s + chunk, None]
        u = np.clip(((qx - ax) * dx + (qy - ay) * dy) / safe, 0.0, 1.0)
        u = np.where(ll > 0.0, u, 0.0)
        out[s:s + chunk] = np.min(np.hypot(qx - (ax + u * dx), qy - (ay + u * dy)), axis=1)
    return out


def path_metrics(cols: Mapping[str, np.ndarray], h: float) -> dict:
    """``cross_rms`` and ``cross_max`` [m] of the axle's centre against the ideal path; ``turn_max_lean`` [rad], the
    largest |theta_b| while turning in place (NaN without such a period); ``final_offset`` [m], the distance of the
    last pose to the ideal one at that time; ``heading_err`` [rad] the final yaw minus the ideal."""
    x, y = np.asarray(cols["x"], float), np.asarray(cols["y"], float)
    v_ref, dpsi_ref = np.asarray(cols["v_ref"], float), np.asarray(cols["dpsi_ref"], float)
    yaw = np.unwrap(np.asarray(cols["yaw"], float))
    ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(v_ref) & np.isfinite(dpsi_ref) & np.isfinite(yaw)
    n = int(np.argmin(ok)) if not ok.all() else len(x)   # the finite start of the run
    ix, iy, ipsi = ideal_path(v_ref[:n], dpsi_ref[:n], h, (x[0], y[0], yaw[0]))
    e = cross_track(x[:n], y[:n], ix, iy)
    th = np.asarray(cols["theta_b"], float)[:n]
    turning = (v_ref[:n] == 0.0) & (dpsi_ref[:n] != 0.0) & np.isfinite(th)
    return {"cross_rms": float(np.sqrt(np.mean(e * e))) if n else math.nan,
            "cross_max": float(np.max(e)) if n else math.nan,
            "turn_max_lean": float(np.max(np.abs(th[turning]))) if turning.any() else math.nan,
            "final_offset": float(math.hypot(x[n - 1] - ix[-1], y[n - 1] - iy[-1])) if n else math.nan,
            "heading_err": float(yaw[n - 1] - ipsi[-1]) if n else math.nan}


PATH_HEADERS = [("run", "{}"), ("cross-track RMS [m]", "{:.4f}"), ("cross-track max [m]", "{:.4f}"),
                ("max abs theta_b turning in place [rad]", "{:.4f}"), ("final offset [m]", "{:.4f}"),
                ("heading error [rad]", "{:.4f}")]
_KEYS = ("cross_rms", "cross_max", "turn_max_lean", "final_offset", "heading_err")


def path_rows(named: Sequence[tuple]) -> list:
    """(label, :func:`path_metrics`) pairs as rows of strings ('-' for NaN)."""
    fmts = [f for _, f in PATH_HEADERS[1:]]
    return [[label] + ["-" if not math.isfinite(m[k]) else f.format(m[k]) for k, f in zip(_KEYS, fmts)]
            for label, m in named]


def path_table(named: Sequence[tuple], markdown: bool = False) -> str:
    """The path metrics as a fixed-width (or Markdown) table."""
    return layout([h for h, _ in PATH_HEADERS], path_rows(named), markdown)
