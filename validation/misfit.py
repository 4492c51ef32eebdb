"""Stage 3 core: standardised residuals, implausibility, chi^2 and the likelihood.

History matching (Craig, Goldstein, Seheult & Smith 1997; Vernon, Goldstein & Bower,
Bayesian Analysis 5, 2010, Eq. 3): for observable i at parameters x,

    z_i(x) = (y_i - E[f_i(x)]) / sigma_i(x),        I_i(x) = |z_i(x)|,
    sigma_i(x)^2 = SE_i^2 + s_DEM,i^2 / n_i + Var_disc,i + Var_sim,i(x),

with y_i the measured mean of n_i repeats and SE_i its standard error; s_DEM,i the DEM's pooled
fill-to-fill sd (the model's own prediction of the scatter of an n_i-fill mean: with 3 repeats
the lab SE is itself uncertain -- a chi^2 with 2 dof falls below a quarter of its mean 22 % of
the time -- and adding the model's estimate is conservative, at most doubling the noise
variance); Var_disc,i an optional model-discrepancy variance (Kennedy & O'Hagan 2001; zero by
default: the point here is to explain the discrepancy by a named effect); and Var_sim,i(x) the
variance of the simulated value -- the surrogate's latent variance, or ``s_DEM,i^2 / R`` for the
mean of R confirmation runs.  ``z > 0``: the model is too low.

Censored observables ("no pile formed": true value below the limit L) get a one-sided residual,
``z = -max(0, E[f] - L) / sigma`` (zero while the model also stays below L).

The likelihood of the means is Gaussian in z:
``ln L(x) = -1/2 sum_i [z_i(x)^2 + ln(2 pi sigma_i(x)^2)]``; the ln sigma^2 term keeps the
best fit away from regions where the surrogate is merely uncertain.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from .observables import Observations

__all__ = ["Misfit"]


@dataclass(frozen=True)
class Misfit:
    """The variance budget of every observable and the statistics built on it."""

    observations: Observations
    dem_noise_sd: np.ndarray
    discrepancy_sd: np.ndarray

    @classmethod
    def build(cls, observations: Observations, dem_noise_sd: np.ndarray,
              discrepancy_sd: Mapping[str, float] | None = None) -> "Misfit":
        noise = np.asarray(dem_noise_sd, float)
        if noise.shape != (len(observations),) or not np.all(np.isfinite(noise)) or np.any(noise < 0):
            raise ValueError(f"dem_noise_sd must be {len(observations)} finite values >= 0, got {noise}")
        disc = dict(discrepancy_sd or {})
        unknown = sorted(set(disc) - set(observations.keys))
        if unknown:
            raise ValueError(f"model_discrepancy names unknown observables {unknown}; known: {list(observations.keys)}")
        d = np.array([float(disc.get(k, 0.0)) for k in observations.keys])
        if np.any(~np.isfinite(d)) or np.any(d < 0):
            raise ValueError(f"model_discrepancy values must be >= 0, got {disc}")
        out = cls(observations, noise, d)
        zero = [k for k, v in zip(observations.keys, out.fixed_variance) if not v > 0]
        if zero:
            raise ValueError(f"observables {zero} have zero measurement error and zero DEM noise: every misfit would "
                             "be infinite; give them a reading resolution (censored ones too) or a model_discrepancy")
        return out

    @property
    def fixed_variance(self) -> np.ndarray:
        """``SE^2 + s_DEM^2 / n + Var_disc`` per observable (unit^2), shape (m,)."""
        o = self.observations
        return o.standard_errors ** 2 + self.dem_noise_sd ** 2 / o.n + self.discrepancy_sd ** 2

    @property
    def fixed_sd(self) -> np.ndarray:
        return np.sqrt(self.fixed_variance)

    def variance(self, sim_sd: np.ndarray) -> np.ndarray:
        """Total variance ``sigma^2`` given the sd of the simulated value (n, m) or (m,)."""
        v = self.fixed_variance + np.asarray(sim_sd, float) ** 2
        if np.any(v <= 0):
            bad = [self.observations.keys[j] for j in np.flatnonzero(np.atleast_2d(v <= 0).any(axis=0))]
            raise ValueError(f"zero total variance for {bad}: give a measurement resolution or DEM replicates")
        return v

    def z(self, sim_mean: np.ndarray, sim_sd: np.ndarray) -> np.ndarray:
        """Signed standardised residuals ``(measured - simulated) / sigma``, shape of ``sim_mean``."""
        o = self.observations
        mu = np.asarray(sim_mean, float)
        sd = np.sqrt(self.variance(sim_sd))
        r = o.means - mu
        r = np.where(o.censored, np.minimum(0.0, o.means - mu), r)  # censored: below the limit is a perfect match
        return r / sd

    def implausibility(self, sim_mean: np.ndarray, sim_sd: np.ndarray) -> np.ndarray:
        return np.abs(self.z(sim_mean, sim_sd))

    def chi2(self, sim_mean: np.ndarray, sim_sd: np.ndarray) -> np.ndarray:
        """``sum_i z_i^2`` over the last axis."""
        return np.sum(self.z(sim_mean, sim_sd) ** 2, axis=-1)

    def log_likelihood(self, sim_mean: np.ndarray, sim_sd: np.ndarray) -> np.ndarray:
        """``-1/2 sum_i [z_i^2 + ln(2 pi sigma_i^2)]`` over the last axis."""
        var = self.variance(sim_sd)
        z = self.z(sim_mean, sim_sd)
        return -0.5 * np.sum(z ** 2 + np.log(2.0 * np.pi * var), axis=-1)
