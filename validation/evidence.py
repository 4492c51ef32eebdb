"""Model evidence from the surrogates: the Bayes factor that ranks candidate effects.

Choice and why.  The evidence (marginal likelihood) of a model version M with parameters u in
the unit cube and a uniform prior over its box is

    Z_M = integral_{[0,1]^k} L(u) du

with L the likelihood of the measured means on the surrogates (Student t in z_i(u), with the
measurement's and DEM noise's degrees of freedom: :mod:`validation.misfit`), and ``B = Z_{M+effect} / Z_M`` is the Bayes factor.  It charges for
added parameters by the **Occam factor** -- the fraction of the effect's prior range the data
allow -- rather than by a count: BIC (k ln n) is an asymptotic approximation that is meaningless
with as few data as parameters (6 observables, 4-6 parameters here), and AIC/BIC charge the same
for a parameter the data pin down and one they leave free.  The effect's declared range is thus
its prior: widening it tenfold costs up to ln 10 per constrained parameter.  BIC and AIC are
reported next to it for reference.

Integration: defensive importance sampling (Hesterberg, Technometrics 37, 1995) with the mixture
``q(u) = 1/2 Uniform([0,1]^k) + 1/2 N(u*, 4 H^-1)`` around the maximum-likelihood point u*
(H: finite-difference Hessian of -ln L; the Laplace approximation's Gaussian, widened twofold in
sd), ``Z ~ mean_j L(u_j) 1[u_j in box] / q(u_j)``.  The uniform half keeps the estimate unbiased
and of bounded variance where the posterior is not Gaussian; the Gaussian half puts samples
where a peaked posterior is.  The Monte-Carlo standard error of ln Z is reported.

Reading (Kass & Raftery, JASA 90, 1995, Sec. 3.2): B 1-3 "not worth more than a bare mention",
3-20 "positive", 20-150 "strong", > 150 "very strong".
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.special import logsumexp
from scipy.stats import multivariate_normal, qmc

__all__ = ["Evidence", "estimate_log_evidence", "bayes_factor_words", "information_criteria"]


@dataclass(frozen=True)
class Evidence:
    """ln Z with its Monte-Carlo standard error, effective sample size, and weighted samples of the
    posterior (unit-cube points ``U`` with normalised ``weights``)."""

    log_evidence: float
    standard_error: float
    effective_sample_size: float
    n_samples: int
    U: np.ndarray
    weights: np.ndarray

    def to_dict(self) -> dict:
        return {"log_evidence": self.log_evidence, "standard_error": self.standard_error,
                "effective_sample_size": self.effective_sample_size, "n_samples": self.n_samples}

    def posterior_sample(self, n: int, seed: int = 0) -> np.ndarray:
        """``n`` unit-cube points resampled with the importance weights."""
        rng = np.random.default_rng(seed)
        return self.U[rng.choice(len(self.U), size=n, replace=True, p=self.weights)]


def _hessian(f: Callable[[np.ndarray], np.ndarray], u: np.ndarray, h: float = 0.01) -> np.ndarray:
    """Central-difference Hessian of a batched scalar function at ``u`` (one batch call)."""
    d = len(u)
    E = np.eye(d) * h
    pts = [u]
    for i in range(d):
        pts += [u + E[i], u - E[i]]
    for i in range(d):
        for j in range(i + 1, d):
            pts += [u + E[i] + E[j], u + E[i] - E[j], u - E[i] + E[j], u - E[i] - E[j]]
    v = f(np.array(pts))
    H = np.empty((d, d))
    f0 = v[0]
    for i in range(d):
        H[i, i] = (v[1 + 2 * i] - 2 * f0 + v[2 + 2 * i]) / h ** 2
    k = 1 + 2 * d
    for i in range(d):
        for j in range(i + 1, d):
            a, b, c, e = v[k:k + 4]
            H[i, j] = H[j, i] = (a - b - c + e) / (4 * h * h)
            k += 4
    return H


def estimate_log_evidence(log_likelihood: Callable[[np.ndarray], np.ndarray], u_best: np.ndarray,
                          n_samples: int = 8192, seed: int = 0) -> Evidence:
    """ln of ``integral_{[0,1]^k} L(u) du`` by defensive importance sampling around ``u_best``.

    log_likelihood : batched, unit-cube points (n, k) -> ln L (n,).
    """
    u_best = np.asarray(u_best, float)
    k = len(u_best)
    H = _hessian(lambda U: -log_likelihood(U), u_best)
    lam, V = np.linalg.eigh(0.5 * (H + H.T))
    var = 4.0 / np.clip(lam, 1.0, 1e8)  # sd between 2e-4 and 2 box widths
    cov = (V * var) @ V.T
    n_half = int(n_samples) // 2
    rng = np.random.default_rng(seed)
    U_gauss = rng.multivariate_normal(u_best, cov, size=n_half)
    U_unif = qmc.Sobol(k, scramble=True, rng=seed).random(int(n_samples) - n_half)
    U = np.vstack([U_gauss, U_unif])
    inside = np.all((U >= 0.0) & (U <= 1.0), axis=1)
    log_q = np.logaddexp(np.log(0.5), np.log(0.5) + multivariate_normal(u_best, cov, allow_singular=True).logpdf(U))
    log_w = np.full(len(U), -np.inf)
    log_w[inside] = log_likelihood(U[inside]) - log_q[inside]
    n = len(U)
    log_z = float(logsumexp(log_w) - math.log(n))
    w = np.exp(log_w - np.max(log_w))
    mean_w = float(np.mean(w))
    se = float(np.std(w) / (math.sqrt(n) * mean_w)) if mean_w > 0 else float("inf")
    weights = w / np.sum(w)
    ess = float(1.0 / np.sum(weights ** 2))
    keep = weights > 0
    return Evidence(log_z, se, ess, n, U[keep], weights[keep] / np.sum(weights[keep]))


def bayes_factor_words(log_b: float) -> str:
    """Kass & Raftery (1995) reading of a Bayes factor ``B = exp(log_b)`` in favour of the effect."""
    b = abs(log_b)
    if b < math.log(3.0):
        strength = "not worth more than a bare mention"
    elif b < math.log(20.0):
        strength = "positive"
    elif b < math.log(150.0):
        strength = "strong"
    else:
        strength = "very strong"
    if b < math.log(3.0):
        return strength
    return f"{strength} {'for' if log_b > 0 else 'against'}"


def information_criteria(chi2: float, n_observables: int, n_parameters: int) -> dict[str, float]:
    """``BIC = chi2 + k ln m`` and ``AIC = chi2 + 2k`` (-2 ln L up to a constant; Schwarz 1978; Akaike 1974)."""
    return {"bic": float(chi2 + n_parameters * math.log(n_observables)), "aic": float(chi2 + 2.0 * n_parameters)}
