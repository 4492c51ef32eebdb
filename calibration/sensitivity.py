"""Global (Sobol') sensitivity of surrogate responses to the calibration parameters.

Zhang et al. (2023), Section 4.1 / Figure 13 report the "contribution" (%) of each
friction coefficient to the static and dynamic angle of repose (e.g. mu_s_pw -> dynamic
angle 54.10 %, mu_s_pp -> static angle 48.22 %) without stating the estimator.  Here
first-order and total Sobol' indices are estimated on the surrogate with
:func:`scipy.stats.sobol_indices` (Saltelli 2010 sampling, Saltelli/Jansen estimators),
parameters uniform on their box; the percent view normalises the indices of one
response to sum to 100 %.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
from scipy import stats

from .designs import ParameterSpace

__all__ = ["SobolResult", "sobol_indices", "plot_sensitivity"]


@dataclass
class SobolResult:
    """First-order ``S1`` and total ``ST`` indices, shape (n_responses, n_parameters).

    ``*_ci`` hold bootstrap 95 % intervals, shape (2, n_responses, n_parameters), when
    requested.  ``n_evaluations`` = ``n * (d + 2)`` model calls.
    """

    parameter_names: list[str]
    response_names: list[str]
    first_order: np.ndarray
    total_order: np.ndarray
    n: int
    n_evaluations: int
    first_order_ci: np.ndarray | None = None
    total_order_ci: np.ndarray | None = None

    def percent_contribution(self, kind: str = "total") -> np.ndarray:
        """Indices of each response normalised to sum to 100 % (paper Figure 13 view).

        ``kind="total"`` normalises ``ST`` (interactions shared among the parameters
        involved), ``kind="first"`` normalises ``max(S1, 0)``.
        """
        if kind == "total":
            S = np.maximum(self.total_order, 0.0)
        elif kind == "first":
            S = np.maximum(self.first_order, 0.0)
        else:
            raise ValueError(f"kind must be 'total' or 'first', got {kind!r}")
        return 100.0 * S / S.sum(axis=1, keepdims=True)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"n_base_samples": self.n, "n_evaluations": self.n_evaluations}
        pt, pf = self.percent_contribution("total"), self.percent_contribution("first")
        for j, r in enumerate(self.response_names):
            out[r] = {
                p: {"S1": float(self.first_order[j, i]), "ST": float(self.total_order[j, i]),
                    "percent_total": float(pt[j, i]), "percent_first": float(pf[j, i])}
                for i, p in enumerate(self.parameter_names)
            }
            if self.first_order_ci is not None:
                for i, p in enumerate(self.parameter_names):
                    out[r][p]["S1_ci95"] = self.first_order_ci[:, j, i].tolist()
                    out[r][p]["ST_ci95"] = self.total_order_ci[:, j, i].tolist()
        return out


def _as_function(model: Any) -> Callable[[np.ndarray], np.ndarray]:
    if hasattr(model, "predict"):
        return model.predict
    if callable(model):
        return model
    raise TypeError("model must be callable or have a predict(X) method")


def sobol_indices(
    model: Any,
    space: ParameterSpace,
    n: int = 2**14,
    seed: int = 0,
    response_names: Sequence[str] | None = None,
    bootstrap: bool = False,
) -> SobolResult:
    """Sobol' first-order and total indices of ``model`` over the uniform box ``space``.

    Parameters
    ----------
    model : ``predict(X)``-object or callable mapping X (N, d) in physical units to
        (N,) or (N, m) responses.
    n : base sample size, a power of 2; the model is called on ``n * (d + 2)`` points.
    seed : seed of the (scrambled Sobol') sampling.
    bootstrap : also compute 95 % bootstrap confidence intervals.
    """
    if not isinstance(space, ParameterSpace):
        raise TypeError(f"space must be a ParameterSpace, got {type(space).__name__}")
    if n < 2 or (n & (n - 1)) != 0:
        raise ValueError(f"n must be a power of 2 (>= 2), got {n}")
    f = _as_function(model)

    def func(x: np.ndarray) -> np.ndarray:  # scipy passes (d, N), wants (m, N)
        y = np.asarray(f(x.T), dtype=float)
        y = y.reshape(len(x.T), -1).T
        if not np.all(np.isfinite(y)):
            raise ValueError("model returned NaN or infinite values")
        return y

    dists = [stats.uniform(loc=lo, scale=hi - lo) for lo, hi in zip(space.lower, space.upper)]
    res = stats.sobol_indices(func=func, n=n, dists=dists, rng=np.random.default_rng(seed))
    S1 = np.atleast_2d(res.first_order)
    ST = np.atleast_2d(res.total_order)
    m = S1.shape[0]
    names = list(response_names) if response_names is not None else [f"y{j}" for j in range(m)]
    if len(names) != m:
        raise ValueError(f"{len(names)} response names for {m} model outputs")
    ci1 = ciT = None
    if bootstrap:
        b = res.bootstrap(confidence_level=0.95, n_resamples=999)
        ci1 = np.stack([np.atleast_2d(b.first_order.confidence_interval.low), np.atleast_2d(b.first_order.confidence_interval.high)])
        ciT = np.stack([np.atleast_2d(b.total_order.confidence_interval.low), np.atleast_2d(b.total_order.confidence_interval.high)])
    return SobolResult(space.names, names, S1, ST, n, n * (space.dim + 2), ci1, ciT)


def plot_sensitivity(result: SobolResult, path: str | None = None, kind: str = "total",
                     reference: dict[tuple[str, str], float] | None = None):
    """Grouped bars of percent contribution per response (paper Figure 13 style).

    ``reference`` maps ``(response, parameter) -> percent`` to overlay published values.
    Saves to ``path`` if given; returns the Figure.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    P = result.percent_contribution(kind)
    m, d = P.shape
    fig, axes = plt.subplots(1, m, figsize=(4.2 * m, 3.6), squeeze=False)
    for j in range(m):
        ax = axes[0, j]
        bars = ax.bar(result.parameter_names, P[j], color="tab:blue", alpha=0.8, label=f"this calibration ({kind}-order index, %)")
        ax.bar_label(bars, fmt="%.1f", fontsize=8)
        ax.plot(result.parameter_names, 100 * result.first_order[j] / max(np.maximum(result.total_order[j], 0).sum(), 1e-12),
                "o", color="tab:orange", label="S1 share of sum ST (%)")
        if reference:
            for i, p in enumerate(result.parameter_names):
                v = reference.get((result.response_names[j], p))
                if v is not None:
                    ax.plot(i, v, "k*", ms=12, label="paper (Fig. 13 text)")
        ax.set_title(result.response_names[j])
        ax.set_ylabel("contribution (%)")
        ax.set_ylim(0, 100)
        ax.tick_params(axis="x", rotation=30)
        ax.legend(fontsize=7)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
