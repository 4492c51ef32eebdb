"""Stage 1: a space-filling design, its batched evaluation, and the DEM noise from replicates.

The design is a Latin hypercube over the parameter box (:func:`calibration.designs.latin_hypercube`,
scipy.stats.qmc).  Every set runs ``replicates`` independent fills in one forward-model call (or a
share of the sets does and the rest one fill: :func:`design_replicates`).
The fill-to-fill noise of each observable is the pooled standard deviation over all sets,

    s_p^2 = sum_k sum_r (y_kr - mean_k)^2 / sum_k (n_k - 1),

the textbook pooled variance (e.g. Montgomery, *Design and Analysis of Experiments*, Sec. 2.4),
which assumes the noise does not depend on the parameters.  Sets whose replicates are all
identical are left out: that is a clipped output (no pile: angle 0 in every fill), not a
noiseless one, and counting it would shrink the estimate.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from calibration.designs import latin_hypercube

from .effects import ModelVersion
from .forward import ForwardRunner
from .settings import DiagnosisSettings

__all__ = ["DesignData", "run_design", "evaluate_sets", "design_replicates", "pooled_noise_sd"]


@dataclass(frozen=True)
class DesignData:
    """Parameter sets ``X`` (n, d; physical units) and responses ``Y`` (n, replicates, m), NaN = failed."""

    X: np.ndarray
    Y: np.ndarray
    keys: tuple[str, ...]

    def __post_init__(self) -> None:
        X, Y = np.atleast_2d(np.asarray(self.X, float)), np.asarray(self.Y, float)
        if Y.ndim != 3 or Y.shape[0] != X.shape[0] or Y.shape[2] != len(self.keys):
            raise ValueError(f"design responses have shape {Y.shape}; expected ({X.shape[0]}, replicates, {len(self.keys)})")
        object.__setattr__(self, "X", X)
        object.__setattr__(self, "Y", Y)
        object.__setattr__(self, "keys", tuple(self.keys))

    def set_means(self) -> np.ndarray:
        """Mean over the replicates of each set, shape (n, m); NaN where every replicate failed."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.nanmean(self.Y, axis=1)

    def extended(self, other: "DesignData") -> "DesignData":
        """This design followed by ``other`` (same keys; replicates may differ, padded with NaN)."""
        if other.keys != self.keys:
            raise ValueError(f"cannot join designs with different keys: {self.keys} vs {other.keys}")
        r = max(self.Y.shape[1], other.Y.shape[1])

        def pad(Y):
            return np.concatenate([Y, np.full((Y.shape[0], r - Y.shape[1], Y.shape[2]), np.nan)], axis=1)

        return DesignData(np.vstack([self.X, other.X]), np.concatenate([pad(self.Y), pad(other.Y)]), self.keys)


# a design that measures the DEM noise replicates at least this many of its sets (all when it has fewer)
MIN_REPLICATED_SETS = 3


def design_replicates(n_sets: int, replicates: int, replicated_fraction: float = 1.0,
                      minimum: int = MIN_REPLICATED_SETS) -> tuple[int, ...]:
    """Fills per set of a design of ``n_sets``: ``replicates`` for ceil(fraction * n_sets) sets (at
    least ``minimum``, at most all), spread evenly through the design's order (a Latin hypercube's
    order is random), one fill for the others. Deterministic, so a design planned up front and the
    same design drawn by its study ask for the same worlds."""
    n = int(n_sets)
    k = min(n, max(int(minimum), math.ceil(float(replicated_fraction) * n - 1e-9)))
    if k >= n or replicates <= 1:
        return (int(replicates),) * n
    chosen = set(np.round(np.linspace(0, n - 1, k)).astype(int).tolist())
    return tuple(int(replicates) if i in chosen else 1 for i in range(n))


def run_design(version: ModelVersion, runner: ForwardRunner, keys: Sequence[str], n_sets: int,
               replicates: int, seed: int, replicated_fraction: float = 1.0) -> DesignData:
    """Latin hypercube of ``n_sets`` over ``version.space``, evaluated in one batched call
    (``replicates`` fills for the share ``replicated_fraction`` of the sets, one for the rest)."""
    X = latin_hypercube(version.space, int(n_sets), seed=seed)
    return evaluate_sets(version, runner, keys, X, design_replicates(len(X), replicates, replicated_fraction))


def evaluate_sets(version: ModelVersion, runner: ForwardRunner, keys: Sequence[str], X: np.ndarray,
                  replicates: int | Sequence[int]) -> DesignData:
    """Evaluate given parameter sets ``X`` (physical units) in one batched call (``replicates``:
    fills for every set, or one count per set)."""
    X = np.atleast_2d(np.asarray(X, float))
    Y = runner(version.effect_names, version.parameter_sets(X), replicates, tuple(keys))
    return DesignData(X, Y, tuple(keys))


class NoiseNotMeasurable(ValueError):
    """No design set has two successful fills of an observable, so its DEM noise is unknown (a
    user-fixable setting: ``replicates``, ``replicated_fraction``)."""


def design_size(version: ModelVersion, settings: DiagnosisSettings) -> int:
    """Latin-hypercube size of one model version's design:
    ``max(min_design_points, design_points_per_parameter * parameters)``."""
    return max(settings.min_design_points, settings.design_points_per_parameter * version.space.dim)


def pooled_noise_sd(Y: np.ndarray, keys: Sequence[str] = (), require: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Pooled fill-to-fill standard deviation per observable and its degrees of freedom.

    Y : (n_sets, replicates, m), NaN ignored.  Returns ``(sd (m,), dof (m,))``; an observable whose
    replicates are identical in every set gets sd 0 and dof 0.
    An observable with no set of two successful replicates: :class:`NoiseNotMeasurable` with
    ``require``, else sd NaN and dof 0 (for a caller that has another estimate to fall back on).
    """
    Y = np.asarray(Y, float)
    ok = np.isfinite(Y)
    n_k = ok.sum(axis=1)  # (n, m)
    unmeasured = np.all(n_k < 2, axis=0)
    if require and np.any(unmeasured):
        bad = [keys[j] if j < len(keys) else str(j) for j in np.flatnonzero(np.all(n_k < 2, axis=0))]
        raise NoiseNotMeasurable(f"cannot measure the DEM fill-to-fill noise of {bad}: no parameter set has two successful "
                         "replicates (use replicates >= 2; with diagnosis.replicated_fraction below 1, a larger "
                         "fraction gives more replicated sets)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mean_k = np.nanmean(Y, axis=1, keepdims=True)
        spread = np.nanmax(Y, axis=1) - np.nanmin(Y, axis=1)  # (n, m)
    varying = (n_k >= 2) & (spread > 0)
    ss = np.sum(np.where(varying, np.nansum(np.where(ok, (Y - mean_k) ** 2, 0.0), axis=1), 0.0), axis=0)
    dof = np.sum(np.where(varying, n_k - 1, 0), axis=0).astype(float)
    sd = np.sqrt(np.divide(ss, dof, out=np.zeros_like(ss), where=dof > 0))
    return np.where(unmeasured, np.nan, sd), dof
