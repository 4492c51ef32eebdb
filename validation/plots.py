"""Figures of a diagnosis (matplotlib, Agg): plain arrays in, a Figure out.

* :func:`comparison_figure` -- measured (mean ± SE) against simulated (DEM mean ± spread) per
  experiment and quantity; observables that differ by one numeric condition (drum speed) share
  an axis, so the pattern "error against drum speed" shows.
* :func:`residual_figure` -- z per observable and model version, target band |z| <= 2, cut-off 3.
* :func:`signature_figure` -- each candidate's signature next to what the current model misses.
* :func:`history_figure` -- the error history: |z| per observable and chi^2 per observable.
* :func:`plausible_set_figure` -- the plausible ranges inside the parameter box.
* :func:`discrimination_figure` -- predicted outcomes of the best proposed measurements.
"""

from __future__ import annotations

import textwrap
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from .observables import Observations

if TYPE_CHECKING:  # pragma: no cover
    from .diagnose import DiagnosisResult
    from .discrimination import Discrimination
    from .history import ErrorHistory

__all__ = ["comparison_figure", "residual_figure", "signature_figure", "history_figure", "plausible_set_figure",
           "discrimination_figure", "diagnosis_figures"]

_COLOURS = ["tab:red", "tab:blue", "tab:green", "tab:purple", "tab:orange", "tab:brown"]
_MARKERS = ["s", "^", "D", "v", "P", "X"]
_CONDITION_WORDS = {"rpm": "drum speed (rpm)", "lift_speed": "lift speed", "fill_mass": "fill mass"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _words(s: str) -> str:
    return s.replace("_", " ")


def _wrap(s: str, width: int = 18) -> str:
    return "\n".join(textwrap.wrap(s, width)) or s


def _varying_numeric_condition(obs: Observations, idx: Sequence[int]) -> str | None:
    if len(idx) < 2:
        return None
    common = set(obs[idx[0]].condition)
    for i in idx[1:]:
        common &= set(obs[i].condition)
    for key in sorted(common):
        vals = [obs[i].condition[key] for i in idx]
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals) and len(set(vals)) == len(vals):
            return key
    return None


def comparison_figure(obs: Observations, models: Sequence[tuple[str, np.ndarray, np.ndarray]]):
    """Measured vs simulated, one panel per (experiment, quantity).

    models : (name, DEM mean (m,), DEM spread (m,)) per model version.
    """
    plt = _plt()
    groups: dict[tuple[str, str], list[int]] = {}
    for j, o in enumerate(obs):
        groups.setdefault((o.experiment, o.quantity), []).append(j)
    n = len(groups)
    ncols = min(3, n)
    nrows = int(np.ceil(n / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.9 * ncols, 4.1 * nrows), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax, ((exp, qty), idx) in zip(axes.flat, groups.items()):
        cond = _varying_numeric_condition(obs, idx)
        if cond is not None:
            x = np.array([float(obs[i].condition[cond]) for i in idx])
            span = np.ptp(x) if np.ptp(x) > 0 else 1.0
            dx = 0.025 * span
            ax.set_xlabel(_CONDITION_WORDS.get(cond, _words(cond)))
        else:
            x = np.arange(len(idx), dtype=float)
            dx = 0.12
            ax.set_xticks(x, [_wrap(obs[i].name) for i in idx])
            ax.set_xlim(-0.6, len(idx) - 0.4)
        unit = obs[idx[0]].unit
        meas = np.array([obs[i].mean for i in idx])
        se = np.array([obs[i].standard_error for i in idx])
        cens = np.array([obs[i].is_censored for i in idx])
        if np.any(~cens):
            ax.errorbar(x[~cens], meas[~cens], yerr=se[~cens], fmt="o", color="black", ms=7, capsize=4, zorder=5,
                        label="measured (mean ± SE)")
        if np.any(cens):
            ax.plot(x[cens], meas[cens], "v", color="black", ms=10, mfc="white", mew=2, zorder=5,
                    label="measured: below detection limit")
        k = len(models)
        for m, (name, mean, spread) in enumerate(models):
            off = (m - (k - 1) / 2.0 + 0.5 * (k % 2 == 0)) * dx * 1.6 + dx
            mu, sp = np.asarray(mean)[idx], np.asarray(spread)[idx]
            ax.errorbar(x + off, mu, yerr=np.nan_to_num(sp), fmt=_MARKERS[m % 6], color=_COLOURS[m % 6], ms=6,
                        capsize=3, label=f"{name} (DEM mean ± spread)")
            if cond is not None:
                ax.plot(x + off, mu, "-", color=_COLOURS[m % 6], lw=1, alpha=0.6)
        ax.set_ylabel(f"{_words(qty)} ({unit})")
        ax.set_title(f"{_words(exp)}: {_words(qty)}")
        ax.grid(alpha=0.3)
    handles: dict[str, Any] = {}
    for ax in axes.flat[:n]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    fig.suptitle("Measured against simulated at the best fit", fontsize=13)
    fig.tight_layout(rect=(0, 0.07 if nrows == 1 else 0.05, 1, 1))
    fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=min(4, len(handles)), fontsize=9,
               frameon=False)
    return fig


def _plain_ticks(ax, vmax: float, axis: str = "x", symmetric: bool = True) -> None:
    """Readable ticks (0, 1, 2, 3, 5, 10, 20, 50, ...) on a symlog axis, written as plain numbers."""
    from matplotlib.ticker import FixedLocator, FuncFormatter

    steps = (1, 2, 3, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000)
    ticks = [0.0] + [float(t) for t in steps if t <= vmax * 1.05]
    if symmetric:
        ticks = sorted(set([-t for t in ticks if t > 0] + ticks))
    target = ax.xaxis if axis == "x" else ax.yaxis
    target.set_major_locator(FixedLocator(ticks))
    target.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    target.set_minor_locator(FixedLocator([]))


def _maybe_symlog(ax, values: np.ndarray, axis: str = "x", limit: float = 12.0, symmetric: bool = True) -> bool:
    v = np.abs(np.asarray(values, float))
    v = v[np.isfinite(v)]
    if len(v) and v.max() > limit:
        (ax.set_xscale if axis == "x" else ax.set_yscale)("symlog", linthresh=3.0)
        _plain_ticks(ax, float(v.max()), axis, symmetric)
        return True
    return False


def residual_figure(labels: Sequence[str], versions: Sequence[tuple[str, np.ndarray]], within: float = 2.0,
                    cutoff: float = 3.0, title: str = "Where the model fails: residual of each observable"):
    """Horizontal bars of z = (measured - simulated) / sigma per observable and version."""
    plt = _plt()
    m, k = len(labels), len(versions)
    fig, ax = plt.subplots(figsize=(9.5, 0.62 * m * max(1, k) * 0.75 + 2.2))
    y = np.arange(m)[::-1].astype(float)
    h = 0.8 / k
    allz = np.concatenate([np.asarray(z, float) for _, z in versions])
    for i, (name, z) in enumerate(versions):
        z = np.asarray(z, float)
        yy = y + (k - 1) / 2 * h - i * h
        ax.barh(yy, np.nan_to_num(z), height=h * 0.9, color=_COLOURS[i % 6], alpha=0.85, label=name)
        for yi, zi in zip(yy, z):
            if np.isfinite(zi):
                ax.text(zi, yi, f" {zi:+.1f} ", va="center", ha="left" if zi >= 0 else "right", fontsize=8)
    ax.axvspan(-within, within, color="tab:green", alpha=0.13, label=f"target: |z| ≤ {within:g}")
    for s in (-cutoff, cutoff):
        ax.axvline(s, color="tab:red", ls="--", lw=1, label=f"implausibility cut-off {cutoff:g}" if s > 0 else None)
    ax.axvline(0, color="black", lw=0.8)
    log = _maybe_symlog(ax, np.append(allz, cutoff))
    ax.set_yticks(y, [_wrap(s, 26) for s in labels])
    ax.set_xlabel("z = (measured − simulated) / σ  (σ units; > 0: model too low)"
                  + ("; symmetric log scale beyond ±3" if log else ""))
    lim = np.nanmax(np.abs(np.append(allz, cutoff + 1)))
    ax.set_xlim(-lim * (1.35 if log else 1.2), lim * (1.35 if log else 1.2))
    ax.set_title(title)
    ax.grid(axis="x", alpha=0.3)
    ax.legend(fontsize=8, loc="lower right" if m > 2 else "best")
    fig.tight_layout()
    return fig


def signature_figure(labels: Sequence[str], residual_z: np.ndarray, signatures: Sequence[tuple[str, np.ndarray]],
                     current_name: str = "base model"):
    """Each candidate's full-strength signature beside the current residuals (what is missing)."""
    plt = _plt()
    m, k = len(labels), len(signatures) + 1
    fig, ax = plt.subplots(figsize=(9.5, 0.5 * m * k * 0.8 + 2.4))
    y = np.arange(m)[::-1].astype(float)
    h = 0.84 / k
    rows = [(f"missing from the {current_name}: measured − simulated", np.asarray(residual_z, float))]
    rows += [(f"{name}: shift at full strength", np.asarray(s, float)) for name, s in signatures]
    allv = np.concatenate([r[1] for r in rows])
    for i, (name, v) in enumerate(rows):
        yy = y + (k - 1) / 2 * h - i * h
        colour = "0.35" if i == 0 else _COLOURS[(i - 1) % 6]
        ax.barh(yy, np.nan_to_num(v), height=h * 0.9, color=colour, alpha=0.9 if i else 0.55,
                hatch="//" if i == 0 else None, edgecolor="black" if i == 0 else None, lw=0.5, label=name)
    ax.axvline(0, color="black", lw=0.8)
    log = _maybe_symlog(ax, allv)
    ax.set_yticks(y, [_wrap(s, 26) for s in labels])
    ax.set_xlabel("change of the simulated value in σ units (an effect explains the misfit where its bar matches "
                  "the hatched one)" + ("; symmetric log scale beyond ±3" if log else ""), fontsize=9)
    ax.set_title("Effect signatures against the residual pattern")
    ax.grid(axis="x", alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return fig


def history_figure(history: "ErrorHistory", labels: Mapping[str, str], within: float = 2.0):
    """|z| per observable across model versions (left) and chi^2 per observable (right)."""
    plt = _plt()
    names = [v.version for v in history.versions]
    x = np.arange(len(names))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.8), gridspec_kw={"width_ratios": [1.6, 1]})
    for j, key in enumerate(history.keys):
        z = np.array([abs(v.z[key]) for v in history.versions])
        ax1.plot(x, z, marker=_MARKERS[j % 6], color=plt.cm.tab10(j % 10), lw=1.5, label=labels.get(key, key))
    ax1.plot(x, [v.max_abs_z for v in history.versions], color="black", lw=3, alpha=0.5, label="largest |z|")
    ax1.axhspan(0, within, color="tab:green", alpha=0.13, label=f"target: |z| ≤ {within:g}")
    zmax = max(v.max_abs_z for v in history.versions)
    _maybe_symlog(ax1, np.array([zmax]), axis="y", symmetric=False)
    ax1.set_ylim(0, zmax * (1.6 if zmax > 12 else 1.15) + 0.5)
    ax1.set_xticks(x, [_wrap(n, 22) for n in names])
    ax1.set_ylabel("|z| = |measured − simulated| / σ  (σ units)")
    ax1.set_title("Error of each observable (DEM at the best fit)")
    ax1.grid(alpha=0.3)
    ax1.legend(fontsize=7.5, loc="upper right")
    c2 = [v.chi2_per_observable for v in history.versions]
    ax2.bar(x, c2, color=[_COLOURS[i % 6] for i in range(len(x))], alpha=0.85)
    for xi, ci in zip(x, c2):
        ax2.text(xi, ci, f"{ci:.2g}", ha="center", va="bottom", fontsize=9)
    ax2.axhline(1.0, color="tab:green", ls="--", label="≈ 1 expected for a correct model")
    if max(c2) > 20 * max(min(c2), 1e-3):
        ax2.set_yscale("log")
    ax2.set_xticks(x, [_wrap(n, 22) for n in names])
    ax2.set_ylabel("χ² per observable = mean of z²")
    ax2.set_title("Total error per model version")
    ax2.grid(axis="y", alpha=0.3)
    ax2.legend(fontsize=8)
    fig.suptitle("Add the effect and watch the error fall", fontsize=13)
    fig.tight_layout()
    return fig


def plausible_set_figure(names: Sequence[str], units: Sequence[str], lower: np.ndarray, upper: np.ndarray,
                         ranges: Mapping[str, tuple[float, float]], best: Mapping[str, float], fraction: float):
    """Plausible range of each parameter drawn inside its box."""
    plt = _plt()
    k = len(names)
    fig, ax = plt.subplots(figsize=(9, 0.75 * k + 1.9))
    y = np.arange(k)[::-1]
    for yi, n, u, lo, hi in zip(y, names, units, lower, upper):
        a, b = ranges[n]
        ua, ub = (a - lo) / (hi - lo), (b - lo) / (hi - lo)
        ax.barh(yi, 1.0, left=0.0, height=0.5, color="0.88", label="parameter box" if yi == y[0] else None)
        ax.barh(yi, ub - ua, left=ua, height=0.5, color="tab:blue", alpha=0.8,
                label="plausible (implausibility ≤ 3)" if yi == y[0] else None)
        ax.plot((best[n] - lo) / (hi - lo), yi, "k*", ms=12, label="best fit" if yi == y[0] else None)
        ax.text(ua, yi + 0.32, f"{a:.3g}", ha="center", fontsize=8)
        ax.text(ub, yi + 0.32, f"{b:.3g}", ha="center", fontsize=8)
    ax.set_yticks(y, [f"{n} ({u})" if u and u != "-" else n for n, u in zip(names, units)])
    ax.set_xlim(-0.05, 1.05)
    ax.set_ylim(-0.7, k - 0.1)
    ax.set_xlabel("position in the parameter range (0 = lower bound, 1 = upper bound)")
    ax.set_title(f"Plausible set: {fraction:.1%} of the box reproduces every measurement")
    ax.legend(fontsize=8, loc="lower right", ncol=3)
    fig.tight_layout()
    return fig


def discrimination_figure(disc: "Discrimination", words: Mapping[str, str], top: int = 4):
    """Predicted outcome ± predictive sd under each tied candidate, for the best ``top`` proposals."""
    plt = _plt()
    fc = list(disc.forecasts[:top])
    fig, axes = plt.subplots(1, len(fc), figsize=(4.2 * len(fc), 4.2), squeeze=False)
    for ax, f in zip(axes[0], fc):
        names = list(disc.candidates)
        x = np.arange(len(names))
        for i, n in enumerate(names):
            ax.errorbar(i, f.means[n], yerr=f.sds[n], fmt=_MARKERS[i % 6], color=_COLOURS[i % 6], ms=8,
                        capsize=5, label=f"{words.get(n, n)} (prediction ± sd)")
        ax.errorbar(len(names), np.mean(list(f.means.values())), yerr=f.measurement_sd, fmt="none",
                    ecolor="black", capsize=5, lw=2, label="expected SE of the new measurement")
        ax.set_xticks(np.append(x, len(names)), [_wrap(words.get(n, n), 14) for n in names] + ["measurement\nSE"])
        ax.set_xlim(-0.6, len(names) + 0.6)
        ax.set_ylabel(f"predicted {_words(f.proposal.quantity)} ({f.proposal.unit})")
        good = f.separation >= disc.threshold
        ax.set_title(f"{_wrap(f.proposal.name, 30)}\nseparation {f.separation:.1f} σ" + (" ✓" if good else ""),
                     color="tab:green" if good else "black", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7.5, loc="best")
    fig.suptitle("Which new measurement tells the candidates apart", fontsize=13)
    fig.tight_layout()
    return fig


def diagnosis_figures(result: "DiagnosisResult") -> dict[str, Any]:
    """All figures of a diagnosis, by file stem."""
    obs = result.observations
    labels = [o.name for o in obs]
    figs: dict[str, Any] = {}
    models = [(v.name, v.confirmation.mean, v.confirmation.spread) for v in result.versions]
    figs["comparison"] = comparison_figure(obs, models)
    title = ("Residual of each observable" if result.base.adequacy.adequate and len(result.versions) == 1
             else "Where the model fails: residual of each observable")
    figs["residuals"] = residual_figure(labels, [(v.name, v.confirmation.z) for v in result.versions],
                                        result.settings.within_sigma, result.settings.cutoff, title)
    base = result.base
    if base.adequacy.adequate:
        sp = base.version.space
        figs["plausible_set"] = plausible_set_figure(sp.names, sp.units, sp.lower, sp.upper,
                                                     base.adequacy.plausible_ranges, base.best_parameters,
                                                     base.adequacy.plausible_fraction)
    for i, r in enumerate(result.rounds):
        suffix = "" if i == 0 else f"_{i + 1}"
        zc = r.current.confirmation.z
        resid = np.where(np.isfinite(zc), zc, r.current.best.z)
        cur = "base model" if not r.current.version.effects else r.current.name
        figs["signatures" + suffix] = signature_figure(labels, resid, [(c.effect.words, c.signature.full)
                                                                       for c in r.candidates], cur)
        if r.discrimination is not None and r.discrimination.forecasts:
            figs["discrimination" + suffix] = discrimination_figure(
                r.discrimination, {c.name: c.effect.words for c in r.candidates})
    if len(result.history.versions) > 1:
        figs["error_history"] = history_figure(result.history, {o.key: o.name for o in obs},
                                               result.settings.within_sigma)
    return figs
