"""Accuracy plots of a surrogate on held-out samples (Zhang et al. 2023, Figures 11-12)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .surrogates import r2_score, relative_errors, rmse

__all__ = ["plot_predicted_vs_simulated", "plot_relative_errors"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _as2d(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    return a.reshape(len(a), -1)


def plot_predicted_vs_simulated(
    Y_sim,
    Y_pred,
    response_names: Sequence[str],
    path: str | None = None,
    Y_ref: np.ndarray | None = None,
    ref_label: str = "paper RBF",
    label: str = "surrogate of this calibration",
):
    """Predicted vs DEM-simulated responses with the 1:1 line (paper Figure 11).

    ``Y_ref`` optionally overlays a second set of predictions (e.g. the paper's).
    R^2 (Eq. 17) and RMSE (deg) are shown in the legend.  Returns the Figure.
    """
    plt = _plt()
    Ys, Yp = _as2d(Y_sim), _as2d(Y_pred)
    m = Ys.shape[1]
    fig, axes = plt.subplots(1, m, figsize=(4.3 * m, 4.0), squeeze=False)
    for j in range(m):
        ax = axes[0, j]
        ax.scatter(Ys[:, j], Yp[:, j], s=18, label=f"{label}: R2={r2_score(Ys[:, j], Yp[:, j]):.3f}, RMSE={rmse(Ys[:, j], Yp[:, j]):.2f}")
        if Y_ref is not None:
            Yr = _as2d(Y_ref)
            ax.scatter(Ys[:, j], Yr[:, j], s=14, marker="x", label=f"{ref_label}: R2={r2_score(Ys[:, j], Yr[:, j]):.3f}, RMSE={rmse(Ys[:, j], Yr[:, j]):.2f}")
        lo, hi = float(np.min(Ys[:, j])), float(np.max(Ys[:, j]))
        pad = 0.05 * (hi - lo)
        ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], "k--", lw=1)
        ax.set_xlabel(f"DEM-simulated {response_names[j]} [deg]")
        ax.set_ylabel(f"surrogate-predicted {response_names[j]} [deg]")
        ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig


def plot_relative_errors(
    Y_sim,
    Y_pred,
    response_names: Sequence[str],
    path: str | None = None,
    Y_ref: np.ndarray | None = None,
    ref_label: str = "paper RBF",
    label: str = "surrogate of this calibration",
    band_percent: float = 5.0,
):
    """Relative error (%) of each held-out sample, sample by sample (paper Figure 12).

    A +-``band_percent`` band (paper Section 4.2 criterion) is shaded.  Returns the Figure.
    """
    plt = _plt()
    Ys, Yp = _as2d(Y_sim), _as2d(Y_pred)
    m, idx = Ys.shape[1], np.arange(1, len(Ys) + 1)
    fig, axes = plt.subplots(1, m, figsize=(4.8 * m, 3.6), squeeze=False)
    for j in range(m):
        ax = axes[0, j]
        e = relative_errors(Ys[:, j], Yp[:, j])
        ax.plot(idx, e, "o-", ms=3, lw=0.8, label=f"{label}: mean |e|={np.mean(np.abs(e)):.1f}%")
        if Y_ref is not None:
            er = relative_errors(Ys[:, j], _as2d(Y_ref)[:, j])
            ax.plot(idx, er, "x--", ms=3, lw=0.8, label=f"{ref_label}: mean |e|={np.mean(np.abs(er)):.1f}%")
        ax.axhspan(-band_percent, band_percent, color="0.9", zorder=0)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlabel("validation sample")
        ax.set_ylabel("relative error (%)")
        ax.set_title(response_names[j])
        ax.legend(fontsize=7)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
