"""Stage 3 core: standardised residuals, implausibility, chi^2 and the likelihood.

History matching (Craig, Goldstein, Seheult & Smith 1997; Vernon, Goldstein & Bower,
Bayesian Analysis 5, 2010, Eq. 3): for observable i at parameters x,

    z_i(x) = (y_i - E[f_i(x)]) / sigma_i(x),        I_i(x) = |z_i(x)|,
    sigma_i(x)^2 = SE_i^2 + s_DEM,i^2 / n_i + Var_disc,i + Var_sim,i(x),

with y_i the measured mean of n_i repeats and SE_i its standard error; s_DEM,i the DEM's pooled
fill-to-fill sd (the model's own prediction of the scatter of an n_i-fill mean: with 3 repeats
the lab SE is itself uncertain -- a chi^2 with 2 dof falls below a quarter of its mean 22 % of
the time -- and adding the model's estimate is conservative, at most doubling the noise
variance); Var_disc,i the model-discrepancy variance (Kennedy & O'Hagan 2001): how far two DEM
codes with the same named law differ, by default from the fidelity suite against LIGGGHTS
(:mod:`validation.model_error`; ``"none"``: zero, the simulator treated as exact); and Var_sim,i(x) the
variance of the simulated value -- the surrogate's latent variance, or ``s_DEM,i^2 / R`` for the
mean of R confirmation runs.  ``z > 0``: the model is too low.

Censored observables ("no pile formed": true value below the limit L) get a one-sided residual,
``z = min(0, L - E[f]) / sigma`` (zero while the model also stays below L).

Likelihood.  sigma_i^2 is itself estimated (SE_i from n_i - 1 dof, s_DEM from the pooled
replicate dof), so z_i follows a Student t rather than a normal distribution (the classical
``(mean - mu) / (s / sqrt(n)) ~ t_{n-1}``) with the Welch-Satterthwaite degrees of freedom
(Welch, Biometrika 34, 1947)

    nu_i = (sum_k v_k)^2 / sum_k (v_k^2 / nu_k),   v = (SE^2, s_DEM^2 / n, Var_disc),

(the discrepancy counts as known, nu_k = inf; an SE set by the reading resolution too).  nu_i
leaves the surrogate variance out (adding a known variance would raise it): that is slightly
conservative, and keeps nu_i a property of the measurement, the same for every model version
and parameter set -- otherwise a badly wrong version's evidence would follow its surrogate's
uncertainty through the t tail.  Then

    ln L(x) = sum_i [ln G((nu+1)/2) - ln G(nu/2) - 1/2 ln(nu pi sigma_i^2)
                     - (nu+1)/2 ln(1 + z_i^2 / nu)]

(Gaussian where nu = inf).  Besides being the right distribution, the t keeps the evidence of a
badly wrong model from hinging on a 10 % change of an estimated variance: at z = 40 a Gaussian
ln L moves by 80 for that, the t (nu = 7) by about 0.5.  The ln sigma^2 term keeps the best fit
away from regions where the surrogate is merely uncertain.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.special import gammaln

from .observables import Observations

__all__ = ["Misfit", "welch_satterthwaite_dof"]


def welch_satterthwaite_dof(variances: np.ndarray, dofs: np.ndarray) -> np.ndarray:
    """``(sum v)^2 / sum(v^2 / nu)`` over the last axis; ``inf`` where every estimated term is zero."""
    v = np.asarray(variances, float)
    nu = np.asarray(dofs, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.where((v > 0) & np.isfinite(nu), v ** 2 / np.where(nu > 0, nu, np.inf), 0.0)
        den = terms.sum(axis=-1)
        return np.where(den > 0, v.sum(axis=-1) ** 2 / np.where(den > 0, den, 1.0), np.inf)


@dataclass(frozen=True)
class Misfit:
    """The variance budget of every observable and the statistics built on it.

    dem_noise_dof : degrees of freedom of the pooled DEM noise estimate (inf: treat as known).
    """

    observations: Observations
    dem_noise_sd: np.ndarray
    discrepancy_sd: np.ndarray
    dem_noise_dof: np.ndarray

    @classmethod
    def build(cls, observations: Observations, dem_noise_sd: np.ndarray,
              discrepancy_sd: str | Mapping[str, float] | None = None,
              dem_noise_dof: np.ndarray | None = None) -> "Misfit":
        m = len(observations)
        noise = np.asarray(dem_noise_sd, float)
        if noise.shape != (m,) or not np.all(np.isfinite(noise)) or np.any(noise < 0):
            raise ValueError(f"dem_noise_sd must be {m} finite values >= 0, got {noise}")
        dof = np.full(m, np.inf) if dem_noise_dof is None else np.asarray(dem_noise_dof, float)
        if dof.shape != (m,) or np.any(dof < 0):
            raise ValueError(f"dem_noise_dof must be {m} values >= 0, got {dof}")
        if isinstance(discrepancy_sd, str):  # "fidelity" / "none": resolved against these observables
            from .model_error import resolve_model_discrepancy

            discrepancy_sd = resolve_model_discrepancy(discrepancy_sd, observations)[0]
        disc = dict(discrepancy_sd or {})
        unknown = sorted(set(disc) - set(observations.keys))
        if unknown:
            raise ValueError(f"model_discrepancy names unknown observables {unknown}; known: {list(observations.keys)}")
        d = np.array([float(disc.get(k, 0.0)) for k in observations.keys])
        if np.any(~np.isfinite(d)) or np.any(d < 0):
            raise ValueError(f"model_discrepancy values must be >= 0, got {disc}")
        out = cls(observations, noise, d, dof)
        zero = [k for k, v in zip(observations.keys, out.fixed_variance) if not v > 0]
        if zero:
            raise ValueError(f"observables {zero} have zero measurement error and zero DEM noise: every misfit would "
                             "be infinite; give them a reading resolution (censored ones too) or a model_discrepancy")
        return out

    def variance_shares(self, sim_sd: np.ndarray) -> dict[str, np.ndarray]:
        """What each observable's sigma^2 is made of, as fractions summing to 1 (m,) each:
        ``measurement`` SE^2, ``dem_noise`` s_DEM^2 / n, ``model_error`` Var_disc and ``simulation``
        the simulated value's variance (surrogate or confirmation mean)."""
        o = self.observations
        parts = {"measurement": o.standard_errors ** 2, "dem_noise": self.dem_noise_sd ** 2 / o.n,
                 "model_error": self.discrepancy_sd ** 2,
                 "simulation": np.broadcast_to(np.asarray(sim_sd, float) ** 2, (len(o),))}
        total = sum(parts.values())
        return {k: np.where(total > 0, v / np.where(total > 0, total, 1.0), 0.0) for k, v in parts.items()}

    @property
    def fixed_variance(self) -> np.ndarray:
        """``SE^2 + s_DEM^2 / n + Var_disc`` per observable (unit^2), shape (m,)."""
        o = self.observations
        return o.standard_errors ** 2 + self.dem_noise_sd ** 2 / o.n + self.discrepancy_sd ** 2

    @property
    def fixed_sd(self) -> np.ndarray:
        return np.sqrt(self.fixed_variance)

    def _se_dof(self) -> np.ndarray:
        o = self.observations
        dof = []
        for ob in o:
            sample_se = 0.0 if ob.is_censored or len(ob.repeats) < 2 else float(np.std(ob.repeats, ddof=1)) / np.sqrt(ob.n)
            dof.append(float(ob.n - 1) if sample_se > ob.resolution else np.inf)  # the resolution floor is known
        return np.array(dof)

    @property
    def dof(self) -> np.ndarray:
        """Welch-Satterthwaite degrees of freedom of the fixed variance per observable, shape (m,)."""
        o = self.observations
        parts = np.stack([o.standard_errors ** 2, self.dem_noise_sd ** 2 / o.n, self.discrepancy_sd ** 2], axis=-1)
        dofs = np.stack([self._se_dof(), self.dem_noise_dof, np.full(len(o), np.inf)], axis=-1)
        return welch_satterthwaite_dof(parts, dofs)

    def variance(self, sim_sd: np.ndarray) -> np.ndarray:
        """Total variance ``sigma^2`` given the sd of the simulated value (n, m) or (m,)."""
        return self.fixed_variance + np.asarray(sim_sd, float) ** 2

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
        """Student-t log-likelihood of the measured means, summed over the last axis (module docstring)."""
        var = self.variance(sim_sd)
        z2 = self.z(sim_mean, sim_sd) ** 2
        nu = np.broadcast_to(self.dof, z2.shape)
        gauss = -0.5 * (z2 + np.log(2.0 * np.pi * var))
        nu_f = np.where(np.isfinite(nu), nu, 1.0)
        student = (gammaln((nu_f + 1) / 2) - gammaln(nu_f / 2) - 0.5 * np.log(nu_f * np.pi * var)
                   - (nu_f + 1) / 2 * np.log1p(z2 / nu_f))
        return np.sum(np.where(np.isfinite(nu), student, gauss), axis=-1)
