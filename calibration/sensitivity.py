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


#: resamples per batch of the bootstrap and of its jackknife (BCa): bounds the memory of the
#: intervals to a few ``BOOTSTRAP_BATCH x n`` arrays (about 17 MB at n = 2**14) instead of scipy's
#: ``SobolResult.bootstrap``, which jackknifes all n samples at once (n x (n - 1) index and value
#: arrays: a 6.9 GB peak at n = 2**14)
BOOTSTRAP_BATCH = 128


def _resampled_indices(Q: np.ndarray, m: int, d: int, idx: np.ndarray) -> np.ndarray:
    """Saltelli et al. (2010) first-order and total indices (Table 2 (b) and (f), the estimators
    of :func:`scipy.stats.sobol_indices`) of resamples ``idx`` (..., k) of the n samples.

    Every term is a mean over the samples of a per-sample quantity, stacked in ``Q`` (K, n):
    f_A + f_B and f_A^2 + f_B^2 (m rows each, mean-centred outputs), f_B (f_AB_i - f_A) and
    (f_A - f_AB_i)^2 / 2 (d*m rows each). A resample's means are its sample counts times ``Q``
    (one matrix product per batch). Returns shape (2, m, d, ...)."""
    n, k = Q.shape[1], idx.shape[-1]
    rows = idx.reshape(-1, k)
    r = len(rows)
    counts = np.bincount((rows + n * np.arange(r)[:, None]).ravel(), minlength=r * n).reshape(r, n)
    M = (counts.astype(float) @ Q.T) / k  # (r, K) resample means
    mean, mean_sq = M[:, :m] / 2, M[:, m:2 * m] / 2  # over the 2k outputs of A and B
    var = (mean_sq - mean**2)[:, None, :]
    s1 = M[:, 2 * m:2 * m + d * m].reshape(r, d, m) / var
    st = M[:, 2 * m + d * m:].reshape(r, d, m) / var
    out = np.stack([s1, st]).transpose(0, 3, 2, 1)  # (2, m, d, r)
    return out.reshape(2, m, d, *idx.shape[:-1])


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
    n : base sample size, a power of 2; the model is called on ``n * (d + 2)`` points, ``n`` at
        a time.
    seed : seed of the (scrambled Sobol') sampling and of the bootstrap resampling.
    bootstrap : also compute 95 % BCa bootstrap confidence intervals (999 resamples;
        :func:`scipy.stats.bootstrap` in batches of :data:`BOOTSTRAP_BATCH` resamples).

    The sample matrices A, B, AB are scipy's (``sample_A_B``: a 2d-dimensional scrambled Sobol'
    sequence split in two); the indices come from :func:`scipy.stats.sobol_indices` on the
    model outputs.
    """
    if not isinstance(space, ParameterSpace):
        raise TypeError(f"space must be a ParameterSpace, got {type(space).__name__}")
    if n < 2 or (n & (n - 1)) != 0:
        raise ValueError(f"n must be a power of 2 (>= 2), got {n}")
    f = _as_function(model)
    d = space.dim
    rng = np.random.default_rng(seed)

    def evaluate(x: np.ndarray) -> np.ndarray:  # (d, N) -> (m, N)
        y = np.asarray(f(x.T), dtype=float)
        y = y.reshape(x.shape[1], -1).T
        if not np.all(np.isfinite(y)):
            raise ValueError("model returned NaN or infinite values")
        return y

    # A, B as scipy.stats.sobol_indices draws them (same rng use, same numbers)
    A_B = stats.qmc.Sobol(d=2 * d, seed=rng, bits=64).random(n).T.reshape(2, d, -1)
    for k, (lo, hi) in enumerate(zip(space.lower, space.upper)):
        A_B[:, k] = stats.uniform(loc=lo, scale=hi - lo).ppf(A_B[:, k])
    A, B = A_B
    f_A, f_B = evaluate(A), evaluate(B)
    f_AB = np.empty((d, *f_A.shape))
    for k in range(d):  # AB_k: A with its k-th row taken from B; one n-point call each
        AB_k = A.copy()
        AB_k[k] = B[k]
        f_AB[k] = evaluate(AB_k)
    res = stats.sobol_indices(func={"f_A": f_A, "f_B": f_B, "f_AB": f_AB}, n=n)
    S1 = np.atleast_2d(res.first_order)
    ST = np.atleast_2d(res.total_order)
    m = S1.shape[0]
    names = list(response_names) if response_names is not None else [f"y{j}" for j in range(m)]
    if len(names) != m:
        raise ValueError(f"{len(names)} response names for {m} model outputs")
    ci1 = ciT = None
    if bootstrap:
        mean = np.mean([f_A, f_B], axis=(0, -1)).reshape(-1, 1)  # centred as scipy centres them
        cA, cB, cAB = f_A - mean, f_B - mean, f_AB - mean
        Q = np.concatenate([cA + cB, cA**2 + cB**2, (cB * (cAB - cA)).reshape(d * m, n),
                            (0.5 * (cA - cAB) ** 2).reshape(d * m, n)])

        def statistic(idx: np.ndarray, axis: int = -1) -> np.ndarray:  # idx (..., k) -> (2, m, d, ...)
            return _resampled_indices(Q, m, d, np.asarray(idx))

        with np.errstate(divide="ignore", invalid="ignore"):
            b = stats.bootstrap((np.arange(n),), statistic, n_resamples=999, batch=BOOTSTRAP_BATCH, vectorized=True,
                                method="BCa", confidence_level=0.95, rng=rng)
        low, high = b.confidence_interval.low, b.confidence_interval.high
        ci1, ciT = np.stack([low[0], high[0]]), np.stack([low[1], high[1]])
    return SobolResult(space.names, names, S1, ST, n, n * (d + 2), ci1, ciT)


def plot_sensitivity(result: SobolResult, path: str | None = None, kind: str = "total",
                     reference: dict[tuple[str, str], float] | None = None, warning: str | None = None):
    """Grouped bars of percent contribution per response (paper Figure 13 style).

    ``reference`` maps ``(response, parameter) -> percent`` to overlay published values.
    ``warning``: a sentence printed in an amber box above the panels (e.g. the indices come from
    surrogates that predict poorly). Saves to ``path`` if given; returns the Figure.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    P = result.percent_contribution(kind)
    m, d = P.shape
    fig, axes = plt.subplots(1, m, figsize=(4.2 * m, 4.0), squeeze=False, layout="constrained")
    for j in range(m):
        ax = axes[0, j]
        bars = ax.bar(result.parameter_names, P[j], color="tab:blue", alpha=0.8, label=f"this calibration ({kind}-order index, %)")
        tall = P[j] > 15  # values inside tall bars, above short ones: clear of the markers
        ax.bar_label(bars, labels=[f"{v:.1f}" if t else "" for v, t in zip(P[j], tall)], label_type="center",
                     fontsize=8, color="white", fontweight="bold")
        ax.bar_label(bars, labels=["" if t else f"{v:.1f}" for v, t in zip(P[j], tall)], fontsize=8, padding=2)
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
    handles, labels = axes[0, 0].get_legend_handles_labels()
    for ax in axes[0, 1:]:  # a reference marker may appear in one panel only
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    seen = dict(zip(labels, handles))  # one entry per name
    fig.legend(seen.values(), seen.keys(), loc="outside lower center", ncols=min(3, len(seen)), fontsize=8)
    if warning:
        import textwrap

        fig.suptitle("\n".join(textwrap.wrap(f"Warning: {warning}", width=int(11 * 4.2 * m))), fontsize=9,
                     color="#9a6700", fontweight="bold",
                     bbox=dict(boxstyle="round,pad=0.4", facecolor="#fff4d6", edgecolor="#9a6700"))
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
