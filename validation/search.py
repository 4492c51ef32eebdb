"""Searching the parameter box on the surrogates: a dense Sobol scan and local optimisation.

Everything works in unit-cube coordinates ``u = (x - lower) / (upper - lower)``.  The box is the
design's hull (a Latin hypercube fills it), so the surrogates are never asked far outside their
data (design doc pitfall: "a surrogate fitted far outside its training data invents plausibility").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import minimize
from scipy.stats import qmc

from .misfit import Misfit
from .surrogates import SurrogateSet

__all__ = ["SurrogateScan", "scan_box", "minimize_on_unit_cube", "BestFit", "find_best_fit", "smooth_max"]


@dataclass(frozen=True)
class SurrogateScan:
    """Surrogate means ``mu``, sds ``sd`` and residuals ``z`` (n, m) at unit-cube points ``U`` (n, d)."""

    U: np.ndarray
    mu: np.ndarray
    sd: np.ndarray
    z: np.ndarray
    log_likelihood: np.ndarray

    @property
    def max_implausibility(self) -> np.ndarray:
        return np.max(np.abs(self.z), axis=1)

    def with_points(self, other: "SurrogateScan") -> "SurrogateScan":
        return SurrogateScan(*(np.concatenate([getattr(self, f), getattr(other, f)])
                               for f in ("U", "mu", "sd", "z", "log_likelihood")))


def evaluate_points(U: np.ndarray, surrogates: SurrogateSet, misfit: Misfit) -> SurrogateScan:
    U = np.atleast_2d(U)
    mu, sd = surrogates.predict_unit(U)
    return SurrogateScan(U, mu, sd, misfit.z(mu, sd), misfit.log_likelihood(mu, sd))


def scan_box(surrogates: SurrogateSet, misfit: Misfit, n_points: int, seed: int) -> SurrogateScan:
    """Scrambled Sobol sample of ``2^ceil(log2 n_points)`` points of the unit cube, evaluated in chunks."""
    d = surrogates.space.dim
    m = int(np.ceil(np.log2(max(2, n_points))))
    U = qmc.Sobol(d, scramble=True, rng=seed).random_base2(m)
    parts = [evaluate_points(U[i:i + 4096], surrogates, misfit) for i in range(0, len(U), 4096)]
    out = parts[0]
    for p in parts[1:]:
        out = out.with_points(p)
    return out


def smooth_max(values: np.ndarray, sharpness: float = 8.0) -> np.ndarray:
    """Differentiable upper bound of ``max`` over the last axis: ``log(sum exp(b v)) / b`` (within ln(m)/b)."""
    b = float(sharpness)
    top = np.max(values, axis=-1, keepdims=True)
    return (top + np.log(np.sum(np.exp(b * (values - top)), axis=-1, keepdims=True)) / b)[..., 0]


def minimize_on_unit_cube(objective: Callable[[np.ndarray], np.ndarray], starts: np.ndarray,
                          step: float = 1e-4, maxiter: int = 200) -> tuple[np.ndarray, float]:
    """Minimise a batched objective ``f(U (n, d)) -> (n,)`` over [0, 1]^d by L-BFGS-B from each start.

    Gradients are forward differences evaluated in one batch per step (one surrogate call per
    iteration).  Returns the best point and value.
    """
    starts = np.atleast_2d(starts)
    d = starts.shape[1]
    eye = np.eye(d) * step

    def fun_grad(u):
        u = np.clip(u, 0.0, 1.0)
        sign = np.where(u + step > 1.0, -1.0, 1.0)
        pts = np.vstack([u, u + eye * sign[:, None]])
        f = objective(pts)
        return float(f[0]), (f[1:] - f[0]) / (step * sign)

    best_u, best_f = starts[0].copy(), float(objective(starts[:1])[0])
    for s in starts:
        res = minimize(fun_grad, s, jac=True, method="L-BFGS-B", bounds=[(0.0, 1.0)] * d,
                       options={"maxiter": maxiter})
        u = np.clip(res.x, 0.0, 1.0)
        f = float(objective(u[None])[0])
        if f < best_f:
            best_u, best_f = u, f
    return best_u, best_f


@dataclass(frozen=True)
class BestFit:
    """The maximum-likelihood point on the surrogates: ``u`` (unit cube), ``x`` (physical) and the
    surrogate mean/sd, residuals z, chi^2 = sum z^2 and ln L there."""

    u: np.ndarray
    x: np.ndarray
    mu: np.ndarray
    sd: np.ndarray
    z: np.ndarray
    chi2: float
    log_likelihood: float


def find_best_fit(surrogates: SurrogateSet, misfit: Misfit, scan: SurrogateScan, starts: int = 4) -> BestFit:
    """Maximise ln L (Misfit.log_likelihood) from the ``starts`` best scan points."""
    order = np.argsort(-scan.log_likelihood)[:max(1, starts)]

    def neg_ll(U):
        mu, sd = surrogates.predict_unit(U)
        return -misfit.log_likelihood(mu, sd)

    u, _ = minimize_on_unit_cube(neg_ll, scan.U[order])
    p = evaluate_points(u[None], surrogates, misfit)
    return BestFit(u, surrogates.space.from_unit(u), p.mu[0], p.sd[0], p.z[0], float(np.sum(p.z[0] ** 2)),
                   float(p.log_likelihood[0]))


def minimize_max_implausibility(surrogates: SurrogateSet, misfit: Misfit, scan: SurrogateScan,
                                columns: np.ndarray | None = None, starts: int = 3) -> tuple[np.ndarray, float]:
    """The point minimising ``max_{i in columns} I_i(u)`` (smooth-max objective from the best scan points);
    returns ``(u, exact max implausibility there)``."""
    cols = np.arange(scan.z.shape[1]) if columns is None else np.asarray(columns)
    order = np.argsort(np.max(np.abs(scan.z[:, cols]), axis=1))[:max(1, starts)]

    def objective(U):
        mu, sd = surrogates.predict_unit(U)
        return smooth_max(np.abs(misfit.z(mu, sd))[:, cols])

    u, _ = minimize_on_unit_cube(objective, scan.U[order])
    p = evaluate_points(u[None], surrogates, misfit)
    exact = float(np.max(np.abs(p.z[0, cols])))
    best_scan = float(np.max(np.abs(scan.z[order[0], cols])))
    if best_scan < exact:
        return scan.U[order[0]], best_scan
    return u, exact
