"""Figures: the paper's Fig. 3 layout, the observer's estimate against the truth, and a sweep's figures.

Every time-series figure shades the metrics window it is given and draws at most :data:`MAX_POINTS` samples
a line (:func:`decimate`: a run of hours plots in the time and memory of one of minutes); legends sit between
the title and the axes (they cover no curve); sweep axes are labelled with their parameter's unit (:func:`axis_label`).
"""
from __future__ import annotations

import textwrap
from typing import Optional, Sequence

import numpy as np

from mwip_ros.sweep.results import laws


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


MAX_POINTS = 20_000   # per drawn line: a longer series is decimated (min and max per bucket, :func:`decimate`)


def decimate(t, y, max_points: int = MAX_POINTS):
    """(t, y) with at most ``max_points`` samples, drawn as the full series would be at a figure's resolution:
    the smallest and the largest y of each of ``max_points / 2`` consecutive buckets, in time order (peaks
    and falls kept; a bucket without a finite y stays a gap).  Short series are returned as they are."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    n = len(t)
    if n <= max_points:
        return t, y
    buckets = max(1, max_points // 2)
    size = -(-n // buckets)
    yy = np.full(buckets * size, np.nan)
    yy[:n] = y
    yy = yy.reshape(buckets, size)
    nan = np.isnan(yy)
    lo = np.where(nan, np.inf, yy).argmin(axis=1)
    hi = np.where(nan, -np.inf, yy).argmax(axis=1)
    base = np.arange(buckets) * size
    idx = np.unique(np.concatenate([base + lo, base + hi]))
    idx = idx[idx < n]
    return t[idx], y[idx]


MAX_DRAWN = 1e100   # |value| a figure can draw: beyond, an axis range overflows (matplotlib: arange of inf)
DRAWN_COLUMNS = ("t", "theta_b", "dtheta_b", "dtheta_w", "u", "tau_hat1", "tau_hat2", "tau_d1", "tau_d2", "theta_w")


def refusal(runs: Sequence) -> Optional[str]:
    """Why the runs' figures cannot be drawn, in one line, or None: a finite value beyond :data:`MAX_DRAWN`
    (non-finite values are gaps; t is checked when a run is read)."""
    for run in runs:
        for col in DRAWN_COLUMNS:
            try:
                x = np.asarray(run[col], dtype=float)
            except KeyError:
                continue
            big = np.isfinite(x) & (np.abs(x) > MAX_DRAWN)
            if big.any():
                i = int(np.argmax(big))
                return (f"{run.label}: {col} = {float(x[i]):g} at row {i + 1}: beyond what a figure can draw "
                        f"(|value| <= {MAX_DRAWN:g})")
    return None


FIG3_PANELS = [("theta_b", r"$\theta_b$ [rad]"), ("dtheta_b", r"$\dot\theta_b$ [rad/s]"),
               ("dtheta_w", r"$\dot\theta_w$ [rad/s]"), ("u", r"$u$ [N m] (applied)")]
WINDOW_SHADE = dict(color="0.55", alpha=0.13, lw=0)


def title_of(runs: Sequence, what: str = "MWIP") -> str:
    """'MWIP: dsc vs dscndo vs lqr': the labels that ran."""
    labels = [str(r.label) for r in runs]
    return f"{what}: " + " vs ".join(labels) if labels else what


def _suptitle(fig, text: str):
    """``fig.suptitle(text)``, wrapped at spaces into as few lines as fit the figure's width (a title naming
    parameter files by their absolute paths is not cut at both edges)."""
    title = fig.suptitle(text)
    renderer = fig.canvas.get_renderer()
    width = 0.98 * fig.bbox.width
    if title.get_window_extent(renderer).width <= width:
        return title
    for chars in range(len(text) - 1, 9, -1):
        title.set_text(textwrap.fill(text, chars, break_long_words=False, break_on_hyphens=False))
        if title.get_window_extent(renderer).width <= width:
            break
    return title


def _window_label(window) -> str:
    return f"metrics window [{window[0]:g}, {window[1]:g}] s"


def _legend_outside(fig, axes) -> float:
    """One legend for the figure, between the title and the axes (it covers no curve), in as many columns (at most
    4) as fit the figure's width (a narrow figure's long labels are not cut at its edges).  Returns the top of the
    axes' area (figure fraction) for ``tight_layout(rect=...)``."""
    handles, labels = [], []
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    height = fig.get_figheight()
    renderer = fig.canvas.get_renderer()
    width = fig.bbox.width
    for ncol in range(min(len(labels), 4) or 1, 0, -1):
        legend = fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 1 - 0.45 / height), ncol=ncol,
                            fontsize=9, frameon=False)
        if ncol == 1 or legend.get_window_extent(renderer).width <= 0.98 * width:
            break
        legend.remove()
    rows = -(-len(labels) // ncol)
    return 1 - (0.42 + 0.2 * rows) / height


def _failed_label(label: str, t: float) -> str:
    return f"{label} failed at t = {t:.3f} s"


def _scale_to_upright(ax, runs: Sequence, cols: Sequence[str], failed: dict, scale=None) -> None:
    """Set ``ax``'s y range to what the runs that did not fail (``failed``: {label: t}) drew of ``cols`` (times
    ``scale``), with a margin: a run that failed (its command past 10^6 N m, its wheels at thousands of rad/s) would
    flatten the others into lines.  Nothing failed: matplotlib's own range.  Everything failed: the runs up to half a
    second before they failed."""
    if not failed:
        return
    parts = []
    for run in runs:
        t = np.asarray(run["t"], dtype=float)
        keep = np.ones(len(t), bool) if run.label not in failed else t < failed[run.label] - 0.5
        if run.label in failed and len(failed) < len(runs):
            continue
        for col in cols:
            y = np.asarray(run[col], dtype=float)[keep] * (1.0 if scale is None else scale)
            parts.append(y[np.isfinite(y)])
    y = np.concatenate(parts) if parts else np.zeros(0)
    if not len(y):
        return
    lo, hi = float(y.min()), float(y.max())
    pad = 0.08 * (hi - lo) or 0.1 * max(abs(lo), abs(hi)) or 1.0
    ax.set_ylim(lo - pad, hi + pad)


def _mark_failures(ax, runs: Sequence, failed: dict, colours: dict, col: Optional[str] = None, scale=None) -> None:
    """A dotted line at each failed run's failure time (its colour), labelled; with ``col``, an X at the run's value
    there, held at the axis' edge when it is off the scale (:func:`_scale_to_upright`)."""
    lo, hi = ax.get_ylim()
    for run in runs:
        if run.label not in failed:
            continue
        tf = failed[run.label]
        colour = colours.get(run.label)
        ax.axvline(tf, color=colour, ls=":", lw=1.2, label=_failed_label(run.label, tf))
        if col is not None:
            t = np.asarray(run["t"])
            k = min(int(np.searchsorted(t, tf - 1e-9)), len(t) - 1)
            y = float(run[col][k]) * (1.0 if scale is None else scale)
            if np.isfinite(y):   # (the dotted line's label names it)
                ax.plot([t[k]], [min(max(y, lo), hi)], "X", ms=9, color=colour, label="_nolegend_")
    ax.set_ylim(lo, hi)


def fig3(runs: Sequence, path, title: Optional[str] = None, window=None, falls: Optional[dict] = None) -> None:
    """theta_b, theta_b', theta_w' and u against time, one line per run (paper Fig. 3).

    ``runs`` are objects with ``label`` and ``__getitem__(column)`` (SimResult or a bag run); ``u`` is the
    torque the plant applied.  ``title`` defaults to the labels that ran; ``window`` (t0, t1) is shaded
    (the metrics window); ``falls`` {label: t} are the runs that failed (fell, diverged, a command refused): each
    panel's y range is that of the runs that did not (:func:`_scale_to_upright`), and each failure is marked, a
    dotted line at its time and an X on theta_b.
    """
    plt = _plt()
    fig, axes = plt.subplots(len(FIG3_PANELS), 1, sharex=True, figsize=(8.5, 9.5))
    falls = falls or {}
    colours = {}
    notes: dict = {}   # (a run, the run it is drawn over): the panels where a figure cannot tell them apart
    for ax, (col, ylabel) in zip(axes, FIG3_PANELS):
        if window is not None:
            ax.axvspan(window[0], window[1], **WINDOW_SHADE, label=_window_label(window))
        same = _same_curves(runs, [col], falls)   # a figure cannot tell them from an earlier run's: dashed over it
        for run in runs:
            line, = ax.plot(*decimate(run["t"], run[col]), label=run.label, lw=1.0,
                            ls=(0, (4, 3)) if run.label in same else "-")
            colours[run.label] = line.get_color()
        for a, (b, d) in same.items():
            notes.setdefault((a, b), []).append(f"{ylabel.split(' [')[0]} to {d:.1%}")
        _scale_to_upright(ax, runs, [col], falls)
        _mark_failures(ax, runs, falls, colours, col if col == "theta_b" else None)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    footnote = [f"{a} is dashed over {b}: the same curve ({', '.join(where)} of the range)"
                for (a, b), where in notes.items()]
    if falls and len(falls) < len(runs):
        footnote.append("y ranges: the runs that did not fail; a failed run leaves the scale at its dotted line")
    if footnote:
        axes[-1].text(0.0, -0.3, "\n".join(footnote), transform=axes[-1].transAxes, fontsize=8, color="0.3",
                      va="top")
    top = _legend_outside(fig, axes)
    axes[-1].set_xlabel("t [s]")
    _suptitle(fig, title or title_of(runs))
    fig.tight_layout(rect=(0, 0, 1, top))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def speed_plot(runs: Sequence, path, r: float, source: str = "", falls: Optional[dict] = None) -> None:
    """v = r theta_w' and the reference v* (column ``v_ref``, docs/theory.md 6.11) against time, one panel per run,
    titled after ``source`` (the parameter files that set the references); the panels share the y range of the runs
    that did not fail (``falls`` {label: t}: each failure is marked, :func:`_mark_failures`)."""
    plt = _plt()
    falls = falls or {}
    fig, axes = plt.subplots(len(runs), 1, sharex=True, sharey=True, figsize=(8.5, 1.6 + 1.35 * len(runs)),
                             squeeze=False)
    for ax, run in zip(axes[:, 0], runs):
        ax.plot(*decimate(run["t"], r * np.asarray(run["dtheta_w"])), lw=1.0, label="v = r theta_w'")
        ax.plot(*decimate(run["t"], run["v_ref"]), lw=1.2, ls="--", color="k", label="v*")
        ax.set_ylabel(f"{run.label}\n[m/s]")
        ax.grid(True, alpha=0.3)
    _scale_to_upright(axes[0, 0], runs, ["dtheta_w"], falls, scale=r)
    lo, hi = axes[0, 0].get_ylim()
    refs = np.concatenate([np.asarray(run["v_ref"], dtype=float) for run in runs])
    refs = refs[np.isfinite(refs)]
    if len(refs):   # the reference always in view
        axes[0, 0].set_ylim(min(lo, refs.min() - 0.1), max(hi, refs.max() + 0.1))
    for ax, run in zip(axes[:, 0], runs):
        _mark_failures(ax, [run], falls, {run.label: "C3"}, "dtheta_w", scale=r)
        if run.label in falls:
            ax.legend(loc="center right", fontsize=8, handles=ax.get_legend_handles_labels()[0][2:])
    axes[0, 0].legend(loc="upper right", fontsize=8, handles=axes[0, 0].get_legend_handles_labels()[0][:2])
    axes[-1, 0].set_xlabel("t [s]")
    _suptitle(fig, "speed and its reference" + (f" ({source})" if source else ""))
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def path_plot(runs: Sequence, path, h: float, title: str = "", falls: Optional[dict] = None) -> None:
    """The axle's centre (x, y) of each run against the ideal path of its references
    (``core.mobile_base.path.ideal_path``), equal axes; a run that failed ends where it failed, an X there (``falls``
    {label: t}: the legend says when); a run whose path a figure cannot tell from an earlier one's is dashed over it and
    its legend says so (:func:`_same_path`).  The legend sits below the axes (it covers no path)."""
    from mwip_ros.core.mobile_base.path import ideal_path
    plt = _plt()
    falls = falls or {}
    fig, ax = plt.subplots(figsize=(7.5, 7.0 + 0.18 * len(runs)))
    first = runs[0]
    ix, iy, _ = ideal_path(first["v_ref"], first["dpsi_ref"], h, (first["x"][0], first["y"][0],
                                                                 float(first["yaw"][0])))
    ax.plot(ix, iy, lw=2.0, ls="--", color="k", label="ideal (the references)")
    drawn = []
    for run in runs:
        x, y = np.asarray(run["x"], dtype=float), np.asarray(run["y"], dtype=float)
        failed = run.label in falls or run.fallen
        label = run.label + ((f" (failed at t = {falls[run.label]:.3f} s: X)" if run.label in falls else " (failed: X)")
                             if failed else "")
        same = _same_path(x, y, drawn)
        if same is not None:   # drawn over an earlier run: say so, and dash it so both show
            label += f" (the path of {same[0]}, within {same[1]:.3f} m: drawn over it, dashed)"
        line, = ax.plot(x, y, lw=1.0, ls=(0, (4, 3)) if same else "-", label=label)
        if failed and len(x):
            ax.plot([x[-1]], [y[-1]], "X", ms=8, color=line.get_color())
        drawn.append((run.label, x, y))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=2, fontsize=8, frameon=False)
    ax.set_title(title or "path on the ground (axle's centre) against the ideal")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _same_path(x: np.ndarray, y: np.ndarray, drawn: list, share: float = 0.01):
    """(the label of an earlier run whose path this one's stays within ``share`` of the larger side of both paths'
    extent of, at every period, that largest distance [m]) or None: two lines a figure cannot tell apart."""
    for label, x2, y2 in drawn:
        n = min(len(x), len(x2))
        if n == 0 or len(x) != len(x2):
            continue
        d = np.hypot(x[:n] - x2[:n], y[:n] - y2[:n])
        extent = max(np.ptp(np.r_[x, x2]), np.ptp(np.r_[y, y2]), 1e-9)
        if np.all(np.isfinite(d)) and d.max() <= share * extent:
            return label, float(d.max())
    return None


def _same_curves(runs: Sequence, cols: Sequence[str], failed: dict, share: float = 0.01) -> dict:
    """{label: (an earlier run's label, the largest difference as a share of the panel's span)} for each run that did
    not fail whose every column of ``cols`` stays within ``share`` of that column's span (over the runs that did not
    fail) of an earlier run's, at every sample: curves a figure cannot tell apart (e.g. MPC and LQR on a path, its
    constraints never active)."""
    ok = [r for r in runs if r.label not in failed]
    span = {}
    for col in cols:
        y = np.concatenate([np.asarray(r[col], dtype=float) for r in ok]) if ok else np.zeros(0)
        y = y[np.isfinite(y)]
        span[col] = float(np.ptp(y)) if len(y) else 0.0
    out = {}
    for i, run in enumerate(ok):
        for other in ok[:i]:
            if other.label in out or len(other["t"]) != len(run["t"]):
                continue
            worst = 0.0
            for col in cols:
                d = np.abs(np.asarray(run[col], dtype=float) - np.asarray(other[col], dtype=float))
                if not np.all(np.isfinite(d)) or span[col] <= 0:
                    worst = np.inf
                    break
                worst = max(worst, float(d.max()) / span[col])
            if worst <= share:
                out[run.label] = (other.label, worst)
                break
    return out


def _finite(x) -> bool:
    return bool(np.isfinite(np.asarray(x, dtype=float)).any())


def observer_plot(runs: Sequence, path, window=None) -> None:
    """tau_hat against the true lumped disturbance tau_d, both components, a column per run.  A run
    without estimates (a plant CSV without --estimates, plain DSC) shows its tau_d and says so."""
    plt = _plt()
    runs = [r for r in runs if _finite(r["tau_hat1"]) or _finite(r["tau_d1"]) or _finite(r["tau_d2"])] or list(runs)
    n = max(1, len(runs))
    fig, axes = plt.subplots(2, n, sharex=True, figsize=(5.2 * n, 6), squeeze=False)
    for j, run in enumerate(runs):
        has_est = _finite(run["tau_hat1"]) or _finite(run["tau_hat2"])
        for i in (1, 2):
            ax = axes[i - 1][j]
            if window is not None:
                ax.axvspan(window[0], window[1], **WINDOW_SHADE, label=_window_label(window))
            ax.plot(*decimate(run["t"], run[f"tau_d{i}"]), color="C0", label=r"$\tau_{d}$ (true)", lw=1.2)
            if has_est:
                ax.plot(*decimate(run["t"], run[f"tau_hat{i}"]), "--", color="C1", label=r"$\hat\tau_{d}$ (observer)",
                        lw=1.0)
            else:
                ax.text(0.5, 0.5, "no estimate recorded", transform=ax.transAxes, ha="center", va="center",
                        fontsize=11, color="0.35", bbox=dict(fc="white", ec="0.7", alpha=0.8))
            if not _finite(run[f"tau_d{i}"]):
                ax.text(0.5, 0.35, "no true disturbance recorded", transform=ax.transAxes, ha="center",
                        fontsize=9, color="0.35")
            ax.set_ylabel(rf"$\tau_{{d{i}}}$ [N m]")
            ax.set_title(f"{run.label}: component {i}")
            ax.grid(True, alpha=0.3)
        axes[-1][j].set_xlabel("t [s]")
    top = _legend_outside(fig, axes.ravel())
    _suptitle(fig, title_of(runs, "Lumped disturbance and its estimate"))
    fig.tight_layout(rect=(0, 0, 1, top))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def pitch_estimate_plot(runs: Sequence, path, window=None) -> bool:
    """The state estimator's pitch against the true pitch, and the error, a column per run with raw sensors
    (``theta_b_hat``); False (nothing written) when no run has an estimate."""
    runs = [r for r in runs if "theta_b_hat" in r.columns and _finite(r["theta_b_hat"])]
    if not runs:
        return False
    plt = _plt()
    n = len(runs)
    fig, axes = plt.subplots(2, n, sharex=True, figsize=(5.2 * n, 6), squeeze=False)
    for j, run in enumerate(runs):
        top, bottom = axes[0][j], axes[1][j]
        for ax in (top, bottom):
            if window is not None:
                ax.axvspan(window[0], window[1], **WINDOW_SHADE, label=_window_label(window))
            ax.grid(True, alpha=0.3)
        top.plot(*decimate(run["t"], run["theta_b"]), color="C0", lw=1.2, label=r"$\theta_b$ (true)")
        top.plot(*decimate(run["t"], run["theta_b_hat"]), "--", color="C1", lw=1.0, label=r"$\hat\theta_b$ (estimator)")
        bottom.plot(*decimate(run["t"], run["theta_b_hat"] - run["theta_b"]), color="C3", lw=0.9,
                    label=r"$\hat\theta_b - \theta_b$")
        top.set_ylabel(r"$\theta_b$ [rad]")
        bottom.set_ylabel("estimation error [rad]")
        top.set_title(f"{run.label}: body pitch")
        bottom.set_xlabel("t [s]")
    top = _legend_outside(fig, axes.ravel())
    _suptitle(fig, title_of(runs, "Body pitch and its estimate (raw IMU and encoder)"))
    fig.tight_layout(rect=(0, 0, 1, top))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


# --- sweeps ------------------------------------------------------------------------------------

def _axis_values(values, is_grid: bool, bins: int = 8):
    """(the levels of an axis, each run's level index): a grid axis's own values, a random axis in bins."""
    v = np.asarray(values, dtype=float)
    if is_grid:
        levels = np.unique(v)
        return levels, np.searchsorted(levels, v)
    edges = np.linspace(v.min(), v.max(), bins + 1)
    idx = np.clip(np.digitize(v, edges[1:-1]), 0, bins - 1)
    return 0.5 * (edges[:-1] + edges[1:]), idx


def axis_label(key: str) -> str:
    """A sweep axis's label: its key and the unit of its parameter (the schema's description, e.g.
    'plant_sim.initial.theta_b [rad]'); the key alone when the schema gives none."""
    import re
    try:
        from mwip_ros.sweep.spec import _resolve
        ps = _resolve(key, "")[2]
    except Exception:  # noqa: BLE001 - not a parameter key (an old results.csv): the key alone
        return key
    unit = getattr(ps, "unit", "") or ""
    if not unit:
        m = re.search(r"\[([^\]]+)\]", ps.description)
        unit = m.group(1) if m else ""
    return f"{key} [{unit}]" if unit else key


def _thin_ticks(ax, which: str, levels, max_ticks: int = 10) -> None:
    """Ticks on the cells of a categorical axis: every k-th level, at most ``max_ticks`` labels."""
    step = max(1, -(-len(levels) // max_ticks))
    idx = list(range(0, len(levels), step))
    labels = [f"{levels[i]:.3g}" for i in idx]
    (ax.set_xticks if which == "x" else ax.set_yticks)(idx, labels)


def sweep_upright_map(cols: dict, axes: Sequence, path) -> bool:
    """Share upright over the first two varied axes: a heat map per law (cells labelled when few) for two
    axes, one chart with a line per law for one axis (a varied axis with a single value counts as none).
    ``axes`` are (key, is_grid) of the numeric varied parameters; False when none varies.  Grid axes show
    their own values; random axes are binned.  Axis labels carry the parameter's unit."""
    names = laws(cols)
    ctrl = np.asarray(cols["controller"])
    varied = [(k, g) for k, g in axes if len(np.unique(np.asarray(cols[k], dtype=float))) > 1] or list(axes[:1])
    if not varied:
        return False
    plt = _plt()
    up = np.asarray(cols["upright"], dtype=float)
    (kx, gx), *rest = varied[:2]
    xlabel = axis_label(kx) + ("" if gx else " (binned)")
    if not rest:   # one axis: a line per law on one chart, offset so equal curves stay visible
        _share_figure(plt, cols, kx, gx, names, "Share of scenarios upright", path)
        return True
    ky, gy = rest[0]
    ncols = min(4, len(names))   # at most four panels a row: eight groups (law x choice) in two
    nrows = -(-len(names) // ncols)
    fig, panels = plt.subplots(nrows, ncols, figsize=(5.4 * ncols + 1.2, 4.6 * nrows), squeeze=False,
                               constrained_layout=True)
    for ax in panels.ravel()[len(names):]:
        ax.set_visible(False)
    im = None
    for ax, law in zip(panels.ravel(), names):
        sel = ctrl == law
        lx, ix = _axis_values(np.asarray(cols[kx])[sel], gx)
        ly, iy = _axis_values(np.asarray(cols[ky])[sel], gy)
        share = np.full((len(ly), len(lx)), np.nan)
        for a in range(len(lx)):
            for b in range(len(ly)):
                m = (ix == a) & (iy == b)
                if m.any():
                    share[b, a] = up[sel][m].mean()
        im = ax.imshow(share, origin="lower", vmin=0, vmax=1, cmap="RdYlGn", aspect="auto")
        _thin_ticks(ax, "x", lx)
        _thin_ticks(ax, "y", ly)
        if len(lx) <= 12 and len(ly) <= 12:   # cells wide enough for their share
            for (b, a), v in np.ndenumerate(share):
                if np.isfinite(v):
                    ax.text(a, b, f"{v:.2f}", ha="center", va="center", fontsize=7)
        ax.set_ylabel(axis_label(ky) + ("" if gy else " (binned)"))
        ax.set_xlabel(xlabel)
        ax.set_title(f"{law}: share upright")
    if im is not None:
        fig.colorbar(im, ax=list(panels.ravel()), label="share upright [-]")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


_STYLES = [dict(marker="o", ls="-"), dict(marker="s", ls="--"), dict(marker="^", ls="-."), dict(marker="D", ls=":")]


def _share_lines(ax, cols: dict, key: str, is_grid: bool, names, roa: Optional[dict] = None) -> str:
    """Share upright against ``key``, a line per law at its true share (0 to 1), each with its own marker and line
    style, the markers of the ``n`` laws on every ``n``-th level, each law's starting one level after the one before
    (``markevery``): laws with equal shares, drawn one over another, stay distinguishable by their markers.
    Returns a note naming the laws whose curves are identical ('' when none are)."""
    ctrl = np.asarray(cols["controller"])
    up = np.asarray(cols["upright"], dtype=float)
    curves = {}
    for law in names:
        sel = ctrl == law
        lx, ix = _axis_values(np.asarray(cols[key], dtype=float)[sel], is_grid)
        curves[law] = (lx, np.array([up[sel][ix == a].mean() if (ix == a).any() else np.nan
                                     for a in range(len(lx))]))
    groups, seen = [], set()
    for law in names:
        if law in seen:
            continue
        group = [o for o in names if o not in seen and len(curves[o][0]) == len(curves[law][0])
                 and np.allclose(curves[o][0], curves[law][0])
                 and np.allclose(curves[o][1], curves[law][1], equal_nan=True)]
        seen.update(group)
        if len(group) > 1:
            groups.append(group)
    for j, law in enumerate(names):
        lx, share = curves[law]
        label = law
        if roa is not None:
            label += f" (ROA {roa[law]:.3f} rad)" if roa.get(law) is not None else " (no ROA)"
        line, = ax.plot(lx, share, ms=4, lw=1.2, alpha=0.85, markevery=(j % max(1, len(lx)), len(names)),
                        label=label, **_STYLES[j % len(_STYLES)])
        if roa is not None and roa.get(law) is not None:
            a = roa[law]
            ax.plot([-a, a], [-0.03 - 0.015 * j] * 2, color=line.get_color(), lw=3, solid_capstyle="butt")
    if not groups:
        return ""
    same = "; ".join(" = ".join(g) for g in groups)
    return f"identical curves: {same} (drawn one over another; see the markers)"


def _share_figure(plt, cols, key, is_grid, names, title, path, roa=None) -> None:
    fig, ax = plt.subplots(figsize=(8, 5))
    note = _share_lines(ax, cols, key, is_grid, names, roa)
    ax.set_xlabel(axis_label(key) + ("" if is_grid else " (binned)"))
    ax.set_ylabel("share upright [-]")
    ax.set_ylim(-0.05 - (0.015 * len(names) if roa is not None else 0.0), 1.05)
    ax.set_title(title + ("\n" + textwrap.fill(note, 95) if note else ""), fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=min(len(names), 2 if roa else 4), fontsize=9,
              frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _upright_rms(cols: dict, law: str) -> np.ndarray:
    """theta_b RMS of ``law``'s upright runs (finite, > 0: a log axis)."""
    ctrl = np.asarray(cols["controller"])
    up = np.asarray(cols["upright"], dtype=bool)
    rms = np.asarray(cols["theta_b_rms"], dtype=float)
    return rms[up & np.isfinite(rms) & (rms > 0) & (ctrl == law)]


def rms_histograms(cols: dict, bins) -> dict:
    """Per law: (its upright runs' theta_b RMS, counts in ``bins``, the laws before it with the same counts).

    Laws whose histograms are the same bar for bar (LQR, LQR+NDO and an unconstrained MPC: the same gain) would
    be drawn one exactly under the other; the figure says so instead."""
    out = {}
    for law in laws(cols):
        vals = _upright_rms(cols, law)
        counts = np.histogram(vals, bins=bins)[0]
        same = [o for o, (_, c, _) in out.items() if len(vals) and np.array_equal(c, counts)]
        out[law] = (vals, counts, same)
    return out


def _rms_panel(ax, law: str, hist, bins, colour) -> None:
    vals, counts, same = hist
    ax.hist(vals, bins=bins, histtype="stepfilled", color=colour, alpha=0.35, edgecolor=colour, lw=1.2)
    note = f", the same histogram as {' and '.join(same)}" if same else ""
    ax.text(0.01, 0.92, f"{law}: {len(vals)} upright{note}", transform=ax.transAxes, va="top", fontsize=8)
    ax.set_xscale("log")
    ax.grid(True, alpha=0.3)


def _rms_bins(all_cols):
    vals = np.concatenate([np.asarray(c["theta_b_rms"], dtype=float)[np.asarray(c["upright"], dtype=bool)]
                           for c in all_cols])
    vals = vals[np.isfinite(vals) & (vals > 0)]
    return np.geomspace(vals.min(), vals.max() * 1.0001, 50) if len(vals) else np.geomspace(1e-3, 1.0, 50)


def sweep_rms_distribution(cols: dict, path) -> None:
    """The distribution of theta_b RMS over the window per law (upright runs)."""
    sweep_rms_panels([("Distribution of $\\theta_b$ RMS", cols)], path)


def sweep_rms_panels(named: Sequence, path) -> None:
    """The theta_b RMS distributions as small multiples: a row per law, a column per (title, results columns)
    (e.g. ideal and realistic sensing), every panel on the same bins and axes, so no law's histogram hides
    under another's; a law whose histogram equals an earlier law's says so in its panel."""
    plt = _plt()
    rows = list(dict.fromkeys(law for _, cols in named for law in laws(cols)))
    fig, axes = plt.subplots(max(1, len(rows)), len(named), figsize=(7 * len(named), 0.6 + 1.25 * max(1, len(rows))),
                             sharex=True, sharey=True, squeeze=False)
    bins = _rms_bins([c for _, c in named])
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for j, (title, cols) in enumerate(named):
        hists = rms_histograms(cols, bins)
        for i, law in enumerate(rows):
            if law in hists:
                _rms_panel(axes[i][j], law, hists[law], bins, colours[i % len(colours)])
            else:
                axes[i][j].text(0.01, 0.92, f"{law}: not in this sweep", transform=axes[i][j].transAxes,
                                va="top", fontsize=8)
        axes[0][j].set_title(title)
        axes[-1][j].set_xlabel(r"$\theta_b$ RMS over the window [rad]")
    for i in range(len(axes)):
        axes[i][0].set_ylabel("runs", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def sweep_roa(cols: dict, key: str, roa: dict, path) -> None:
    """Share upright against theta_b(0) per law, with each law's region of attraction as a bar (in the law's
    colour) below the curves."""
    _share_figure(_plt(), cols, key, True, laws(cols), "Region of attraction (bars: every scenario within "
                  "recovered)", path, roa=roa)
