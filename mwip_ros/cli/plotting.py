"""Figures: the paper's Fig. 3 layout and the observer's estimate against the truth."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from mwip_ros.sweep.results import laws


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


FIG3_PANELS = [("theta_b", r"$\theta_b$ [rad]"), ("dtheta_b", r"$\dot\theta_b$ [rad/s]"),
               ("dtheta_w", r"$\dot\theta_w$ [rad/s]"), ("u", r"$u$ [N m]")]


def fig3(runs: Sequence, path, title: str = "MWIP: DSC vs DSCNDO") -> None:
    """theta_b, theta_b', theta_w' and u against time, one line per run (paper Fig. 3).

    ``runs`` are objects with ``label`` and ``__getitem__(column)`` (SimResult or a bag run).
    """
    plt = _plt()
    fig, axes = plt.subplots(len(FIG3_PANELS), 1, sharex=True, figsize=(8, 9))
    for ax, (col, ylabel) in zip(axes, FIG3_PANELS):
        for run in runs:
            ax.plot(run["t"], run[col], label=run.label, lw=1.0)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="upper right")
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def observer_plot(runs: Sequence, path) -> None:
    """tau_hat against the true lumped disturbance tau_d, both components, per run."""
    plt = _plt()
    runs = [r for r in runs if np.isfinite(np.asarray(r["tau_hat1"])).any()]
    fig, axes = plt.subplots(2, max(1, len(runs)), sharex=True, figsize=(6 * max(1, len(runs)), 6), squeeze=False)
    for j, run in enumerate(runs):
        for i in (1, 2):
            ax = axes[i - 1][j]
            ax.plot(run["t"], run[f"tau_d{i}"], label=rf"$\tau_{{d{i}}}$ (true)", lw=1.2)
            ax.plot(run["t"], run[f"tau_hat{i}"], "--", label=rf"$\hat\tau_{{d{i}}}$ (observer)", lw=1.0)
            ax.set_ylabel("[N m]")
            ax.set_title(f"{run.label}: component {i}")
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper right")
        axes[-1][j].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


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


def sweep_upright_map(cols: dict, axes: Sequence, path) -> bool:
    """Share upright over the first two varied axes (a heat map per law, cells labelled; a line for one
    axis).  ``axes`` are (key, is_grid) of the numeric varied parameters; False when there is none.  Grid
    axes show their own values, one cell each; random axes are binned."""
    if not axes:
        return False
    plt = _plt()
    names = laws(cols)
    ctrl = np.asarray(cols["controller"])
    up = np.asarray(cols["upright"], dtype=float)
    (kx, gx), *rest = axes[:2]
    fig, panels = plt.subplots(1, len(names), figsize=(5.4 * len(names) + (1.2 if rest else 0), 4.4), squeeze=False,
                               constrained_layout=True)
    im = None
    for ax, law in zip(panels[0], names):
        sel = ctrl == law
        lx, ix = _axis_values(np.asarray(cols[kx])[sel], gx)
        if rest:
            ky, gy = rest[0]
            ly, iy = _axis_values(np.asarray(cols[ky])[sel], gy)
            share = np.full((len(ly), len(lx)), np.nan)
            for a in range(len(lx)):
                for b in range(len(ly)):
                    m = (ix == a) & (iy == b)
                    if m.any():
                        share[b, a] = up[sel][m].mean()
            im = ax.imshow(share, origin="lower", vmin=0, vmax=1, cmap="RdYlGn", aspect="auto")
            ax.set_xticks(range(len(lx)), [f"{v:.3g}" for v in lx], rotation=45 if len(lx) > 8 else 0)
            ax.set_yticks(range(len(ly)), [f"{v:.3g}" for v in ly])
            if share.size <= 150:
                for (b, a), v in np.ndenumerate(share):
                    if np.isfinite(v):
                        ax.text(a, b, f"{v:.2f}", ha="center", va="center", fontsize=7)
            ax.set_ylabel(ky + ("" if gy else " (binned)"))
        else:
            share = [up[sel][ix == a].mean() if (ix == a).any() else np.nan for a in range(len(lx))]
            ax.plot(lx, share, "o-")
            ax.set_ylim(-0.05, 1.05)
            ax.set_ylabel("share upright")
        ax.set_xlabel(kx + ("" if gx else " (binned)"))
        ax.set_title(f"{law}: share upright")
    if im is not None:
        fig.colorbar(im, ax=list(panels[0]), label="share upright")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def _rms_histogram(ax, cols: dict, bins) -> None:
    ctrl = np.asarray(cols["controller"])
    up = np.asarray(cols["upright"], dtype=bool)
    rms = np.asarray(cols["theta_b_rms"], dtype=float)
    ok = up & np.isfinite(rms) & (rms > 0)
    for law in laws(cols):
        sel = ok & (ctrl == law)
        ax.hist(rms[sel], bins=bins, histtype="step", lw=1.5, label=f"{law} ({sel.sum()} upright)")
    ax.set_xscale("log")
    ax.set_xlabel(r"$\theta_b$ RMS over the window [rad]")
    ax.legend(fontsize=8)


def _rms_bins(all_cols):
    vals = np.concatenate([np.asarray(c["theta_b_rms"], dtype=float)[np.asarray(c["upright"], dtype=bool)]
                           for c in all_cols])
    vals = vals[np.isfinite(vals) & (vals > 0)]
    return np.geomspace(vals.min(), vals.max() * 1.0001, 50) if len(vals) else 10


def sweep_rms_distribution(cols: dict, path) -> None:
    """The distribution of theta_b RMS over the window per law (upright runs)."""
    sweep_rms_panels([("Distribution of $\\theta_b$ RMS", cols)], path)


def sweep_rms_panels(named: Sequence, path) -> None:
    """One panel per (title, results columns), side by side with a shared axis: e.g. ideal and realistic
    sensing."""
    plt = _plt()
    fig, axes = plt.subplots(1, len(named), figsize=(7 * len(named), 4), sharex=True, sharey=True, squeeze=False)
    bins = _rms_bins([c for _, c in named])
    for ax, (title, cols) in zip(axes[0], named):
        _rms_histogram(ax, cols, bins)
        ax.set_title(title)
    axes[0][0].set_ylabel("scenarios")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def sweep_roa(cols: dict, key: str, roa: dict, path) -> None:
    """Share upright against theta_b(0) per law, with each law's region of attraction marked."""
    plt = _plt()
    ctrl = np.asarray(cols["controller"])
    up = np.asarray(cols["upright"], dtype=float)
    th = np.asarray(cols[key], dtype=float)
    fig, ax = plt.subplots(figsize=(7, 4))
    for law in laws(cols):
        sel = ctrl == law
        levels = np.unique(th[sel])
        line, = ax.plot(levels, [up[sel][th[sel] == v].mean() for v in levels], "o-", ms=3, label=law)
        a = roa.get(law)
        if a is not None:
            ax.axvspan(-a, a, color=line.get_color(), alpha=0.12)
    ax.set_xlabel(r"$\theta_b(0)$ [rad]")
    ax.set_ylabel("share upright")
    ax.set_ylim(-0.05, 1.05)
    ax.set_title("Region of attraction (shaded: every scenario recovered)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
