"""Stage 2: one Gaussian-process surrogate per observable, with its predictive uncertainty.

scikit-learn's :class:`~sklearn.gaussian_process.GaussianProcessRegressor` (Rasmussen & Williams,
*Gaussian Processes for Machine Learning*, 2006, Alg. 2.1) on inputs scaled to the unit cube,

    k(u, u') = C * Matern_{5/2}(u, u'; l_1..l_d) + sigma_n^2 * delta(u, u'),

with one length scale per parameter (ARD), ``normalize_y=True`` and the hyperparameters
maximising the log marginal likelihood (a few optimizer restarts).  The white-noise term absorbs
the DEM's fill-to-fill noise of the replicate means it is trained on; the surrogate variance used
in the implausibility is that of the **latent** mean (the white term left out): the uncertainty
about E[f(x)], not the noise of one more run, which is counted separately.

Quality: k-fold cross-validation with the hyperparameters fixed at the full-data fit: R^2,
RMSE (unit of the observable) and the fraction of held-out means within 2 predictive sd
(about 0.95 for a well-calibrated surrogate).
"""

from __future__ import annotations

import copy
import warnings
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel
from sklearn.model_selection import KFold

from calibration.designs import ParameterSpace

from .design import DesignData

__all__ = ["SurrogateQuality", "ObservableSurrogate", "SurrogateSet", "fit_surrogates"]


@dataclass(frozen=True)
class SurrogateQuality:
    """Cross-validated quality of one surrogate (``rmse`` in the observable's unit; ``r2`` None if y is constant)."""

    key: str
    n_train: int
    r2: float | None
    rmse: float
    coverage_2sd: float
    noise_sd: float
    kernel: str

    def to_dict(self) -> dict:
        return dict(self.__dict__)


class ObservableSurrogate:
    """GP of one observable on unit-cube inputs; :meth:`predict_unit` gives mean and latent sd."""

    def __init__(self, key: str, dim: int, restarts: int = 2, seed: int = 0):
        self.key, self.dim, self.restarts, self.seed = key, int(dim), int(restarts), int(seed)
        self.gp: GaussianProcessRegressor | None = None
        self._latent: GaussianProcessRegressor | None = None
        self.n_train = 0

    def _kernel(self, noise_fraction: float):
        # the replicates measured the noise of the training means: the white term may not fall far below it
        # (else the GP explains noise as signal with short length scales)
        start = float(np.clip(noise_fraction, 1e-6, 0.5))
        lower = float(np.clip(0.5 * noise_fraction, 1e-8, 0.9))
        return (ConstantKernel(1.0, (1e-3, 1e3))
                * Matern(length_scale=np.full(self.dim, 0.5), length_scale_bounds=(0.1, 30.0), nu=2.5)
                + WhiteKernel(noise_level=max(start, lower), noise_level_bounds=(lower, max(1.0, 2.0 * noise_fraction))))

    def fit(self, U: np.ndarray, y: np.ndarray, noise_var_hint: float = 0.0) -> "ObservableSurrogate":
        """Fit on unit-cube inputs ``U`` (n, d) and responses ``y`` (n,); NaN rows are dropped.

        noise_var_hint : variance of the training means from the replicates (unit^2): start of the white
            term, and half of it is its lower bound.
        """
        U, y = np.atleast_2d(np.asarray(U, float)), np.asarray(y, float)
        keep = np.isfinite(y)
        U, y = U[keep], y[keep]
        if len(y) < 3:
            raise ValueError(f"surrogate of {self.key!r}: only {len(y)} successful design points (need >= 3)")
        var_y = float(np.var(y))
        frac = noise_var_hint / var_y if var_y > 0 else 1e-3
        gp = GaussianProcessRegressor(self._kernel(frac), normalize_y=True, n_restarts_optimizer=self.restarts,
                                      random_state=self.seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            warnings.simplefilter("ignore", UserWarning)
            gp.fit(U, y)
        self.gp, self.n_train = gp, len(y)
        self._U, self._y = U, y
        latent = copy.copy(gp)
        latent.kernel_ = gp.kernel_.k1  # the white term only adds to the diagonal: leaving it out gives the latent mean's sd
        self._latent = latent
        return self

    def _require(self) -> GaussianProcessRegressor:
        if self.gp is None:
            raise RuntimeError(f"surrogate of {self.key!r} is not fitted")
        return self.gp

    def predict_unit(self, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and latent standard deviation (observable's unit) at unit-cube points ``U`` (n, d)."""
        self._require()
        mean, sd = self._latent.predict(np.atleast_2d(U), return_std=True)
        return np.asarray(mean, float), np.asarray(sd, float)

    @property
    def noise_sd(self) -> float:
        """Fitted white-noise sd of the training means (observable's unit)."""
        gp = self._require()
        return float(np.sqrt(gp.kernel_.k2.noise_level) * gp._y_train_std)

    def cross_validate(self, folds: int = 5, seed: int = 0) -> SurrogateQuality:
        """k-fold CV with the fitted hyperparameters held fixed."""
        gp = self._require()
        n = len(self._y)
        k = int(min(max(2, folds), n))
        pred, sd = np.empty(n), np.empty(n)
        for train, test in KFold(k, shuffle=True, random_state=seed).split(self._U):
            g = GaussianProcessRegressor(gp.kernel_, normalize_y=True, optimizer=None)
            g.fit(self._U[train], self._y[train])
            pred[test], sd[test] = g.predict(self._U[test], return_std=True)
        err = self._y - pred
        ss_tot = float(np.sum((self._y - self._y.mean()) ** 2))
        r2 = None if ss_tot <= 1e-12 * max(1.0, float(np.sum(self._y ** 2))) else 1.0 - float(np.sum(err ** 2)) / ss_tot
        coverage = float(np.mean(np.abs(err) <= 2.0 * np.maximum(sd, 1e-300)))
        return SurrogateQuality(self.key, n, r2, float(np.sqrt(np.mean(err ** 2))), coverage, self.noise_sd,
                                str(gp.kernel_))


class SurrogateSet:
    """The surrogates of all observables of one model version, in the order of ``keys``."""

    def __init__(self, space: ParameterSpace, surrogates: Sequence[ObservableSurrogate],
                 quality: Sequence[SurrogateQuality]):
        self.space = space
        self.surrogates = tuple(surrogates)
        self.quality = tuple(quality)
        self.keys = tuple(s.key for s in self.surrogates)

    def predict_unit(self, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Means and latent sds at unit-cube points, each (n, m)."""
        U = np.atleast_2d(U)
        out = [s.predict_unit(U) for s in self.surrogates]
        return np.stack([o[0] for o in out], axis=1), np.stack([o[1] for o in out], axis=1)

    def predict(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Means and latent sds at physical points ``X`` (n, d)."""
        return self.predict_unit(self.space.to_unit(np.atleast_2d(X)))


def fit_surrogates(space: ParameterSpace, design: DesignData, noise_sd: np.ndarray, restarts: int = 2,
                   folds: int = 5, seed: int = 0) -> SurrogateSet:
    """One GP per observable on the replicate means of ``design``; with CV quality."""
    U = space.to_unit(design.X)
    means = design.set_means()
    n_rep = np.maximum(np.sum(np.isfinite(design.Y), axis=1), 1)  # (n, m)
    sur, qual = [], []
    for j, key in enumerate(design.keys):
        hint = float(np.mean(noise_sd[j] ** 2 / n_rep[:, j]))
        s = ObservableSurrogate(key, space.dim, restarts, seed + j).fit(U, means[:, j], hint)
        sur.append(s)
        qual.append(s.cross_validate(folds, seed))
    return SurrogateSet(space, sur, qual)
