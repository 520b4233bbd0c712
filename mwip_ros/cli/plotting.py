"""Figures: the paper's Fig. 3 layout and the observer's estimate against the truth."""
from __future__ import annotations

from typing import Sequence

import numpy as np


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
