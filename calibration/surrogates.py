"""Surrogate models mapping DEM parameters to macroscopic responses.

The seed paper (Zhang et al. 2023, Section 3.2, Figure 10) fits an RBF neural network
to 100 DEM runs and checks it on 40 held-out runs with R^2 (Eq. 17).  Here:

* :class:`RBFRegressor` -- :class:`scipy.interpolate.RBFInterpolator` on inputs scaled
  to the unit cube, with optional power warping and per-dimension length scales.
* :class:`GaussianProcessRegressor` -- kriging with an anisotropic (ARD) Matern or
  squared-exponential kernel, linear trend and noise; length scales, signal and noise
  variance maximise the restricted log marginal likelihood (scipy L-BFGS-B, analytic
  gradient).  The kernel is itself a radial basis function, so this is an RBF network
  whose centres are the training points and whose metric is learned.
* :func:`select_model` / :class:`CVSurrogate` / :func:`cross_validated_surrogate` --
  choose, per response, the candidate with the lowest repeated k-fold cross-validated
  RMSE on the *training set only*, then refit it on the whole training set.

All estimators follow the scikit-learn convention ``fit(X, y) -> self``,
``predict(X) -> ndarray`` with plain numpy arrays and no global state.
"""

from __future__ import annotations

import ctypes
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Iterator, Mapping, Sequence

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.linalg import LinAlgError, cho_factor, cho_solve
from scipy.optimize import minimize

from .designs import ParameterSpace

__all__ = [
    "r2_score",
    "rmse",
    "relative_errors",
    "max_abs_relative_error",
    "RBFRegressor",
    "GaussianProcessRegressor",
    "default_candidates",
    "cross_validate",
    "select_model",
    "ModelSelection",
    "CVSurrogate",
    "cross_validated_surrogate",
    "limit_blas_threads",
]


# --------------------------------------------------------------------------- metrics
def _check_pair(y_true, y_pred) -> tuple[np.ndarray, np.ndarray]:
    y_true = np.asarray(y_true, dtype=float)
    y_pred = np.asarray(y_pred, dtype=float)
    if y_true.shape != y_pred.shape:
        raise ValueError(f"y_true and y_pred must have the same shape, got {y_true.shape} and {y_pred.shape}")
    if y_true.size == 0:
        raise ValueError("y_true is empty")
    if not (np.all(np.isfinite(y_true)) and np.all(np.isfinite(y_pred))):
        raise ValueError("y_true or y_pred contains NaN or infinite values")
    return y_true, y_pred


def r2_score(y_true, y_pred) -> float | np.ndarray:
    """Coefficient of determination, paper Eq. (17): ``1 - SS_res / SS_tot``.

    For 2-D input returns one value per column.
    """
    y_true, y_pred = _check_pair(y_true, y_pred)
    ss_res = np.sum((y_true - y_pred) ** 2, axis=0)
    ss_tot = np.sum((y_true - y_true.mean(axis=0)) ** 2, axis=0)
    out = 1.0 - ss_res / ss_tot
    return float(out) if np.ndim(out) == 0 else out


def rmse(y_true, y_pred) -> float | np.ndarray:
    """Root-mean-square error (units of y); per column for 2-D input."""
    y_true, y_pred = _check_pair(y_true, y_pred)
    out = np.sqrt(np.mean((y_true - y_pred) ** 2, axis=0))
    return float(out) if np.ndim(out) == 0 else out


def relative_errors(y_true, y_pred) -> np.ndarray:
    """Signed relative errors ``(y_pred - y_true) / y_true`` in percent (paper Figure 12)."""
    y_true, y_pred = _check_pair(y_true, y_pred)
    if np.any(y_true == 0):
        raise ValueError("relative error undefined: y_true contains zeros")
    return 100.0 * (y_pred - y_true) / y_true


def max_abs_relative_error(y_true, y_pred) -> float | np.ndarray:
    """Largest absolute relative error in percent; per column for 2-D input."""
    out = np.max(np.abs(relative_errors(y_true, y_pred)), axis=0)
    return float(out) if np.ndim(out) == 0 else out


# --------------------------------------------------------------------------- BLAS threads
_BLAS_THREAD_FUNCS: list[tuple[Any, Any]] | None = None


def _openblas_thread_funcs() -> list[tuple[Any, Any]]:
    """(setter, getter) pairs of the OpenBLAS libraries loaded by numpy/scipy (Linux only)."""
    global _BLAS_THREAD_FUNCS
    if _BLAS_THREAD_FUNCS is None:
        funcs = []
        try:
            with open("/proc/self/maps") as fh:
                paths = sorted({ln.split()[-1] for ln in fh if "openblas" in ln.lower() and ".so" in ln})
        except OSError:
            paths = []
        for path in paths:
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for prefix in ("openblas", "scipy_openblas"):
                for suffix in ("", "64_"):
                    get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                    put = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                    if get is not None and put is not None:
                        funcs.append((put, get))
        _BLAS_THREAD_FUNCS = funcs
    return _BLAS_THREAD_FUNCS


@contextmanager
def limit_blas_threads(n: int = 1) -> Iterator[None]:
    """Temporarily limit OpenBLAS to ``n`` threads.

    The GP likelihood search makes thousands of LAPACK calls on ~100x100 matrices; on a
    busy 2-core machine multithreaded OpenBLAS made model selection ~6x slower
    (measured 107 s vs 17 s).  Uses ``threadpoolctl`` when installed, otherwise the
    OpenBLAS C API via ctypes; a no-op where neither is available.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        threadpool_limits = None
    if threadpool_limits is not None:
        with threadpool_limits(limits=n, user_api="blas"):
            yield
        return
    funcs = _openblas_thread_funcs()
    old = [get() for _, get in funcs]
    for put, _ in funcs:
        put(int(n))
    try:
        yield
    finally:
        for (put, _), o in zip(funcs, old):
            put(int(o))


# --------------------------------------------------------------------------- input checks
def _check_X(X, n_features: int | None = None, what: str = "X") -> np.ndarray:
    X = np.asarray(X, dtype=float)
    if X.ndim == 1 and n_features is not None:
        X = X.reshape(1, -1) if X.size == n_features else X.reshape(-1, 1)
    if X.ndim != 2:
        raise ValueError(f"{what} must be a 2-D array (n_samples, n_features), got shape {X.shape}")
    if n_features is not None and X.shape[1] != n_features:
        raise ValueError(f"{what} has {X.shape[1]} columns but the model was fitted with {n_features} features")
    if X.shape[0] == 0:
        raise ValueError(f"{what} has no rows")
    if not np.all(np.isfinite(X)):
        raise ValueError(f"{what} contains NaN or infinite values")
    return X


def _check_y(y, n_samples: int, what: str = "y") -> np.ndarray:
    y = np.asarray(y, dtype=float)
    if y.ndim not in (1, 2):
        raise ValueError(f"{what} must be 1-D or 2-D, got shape {y.shape}")
    if y.shape[0] != n_samples:
        raise ValueError(f"{what} has {y.shape[0]} rows but X has {n_samples}")
    if not np.all(np.isfinite(y)):
        raise ValueError(f"{what} contains NaN or infinite values")
    return y


def _bounds_from(space: ParameterSpace | None, bounds, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit-cube scaling bounds: from ``space``, explicit ``(lower, upper)``, or the data."""
    if space is not None:
        if space.dim != X.shape[1]:
            raise ValueError(f"X has {X.shape[1]} columns but the ParameterSpace has {space.dim} parameters")
        return space.lower, space.upper
    if bounds is not None:
        lo, hi = (np.asarray(b, dtype=float).ravel() for b in bounds)
        if lo.size != X.shape[1] or hi.size != X.shape[1]:
            raise ValueError(f"bounds must have {X.shape[1]} entries each")
        if np.any(lo >= hi):
            raise ValueError("bounds: every lower bound must be < its upper bound")
        return lo, hi
    lo, hi = X.min(axis=0), X.max(axis=0)
    if np.any(hi <= lo):
        raise ValueError(f"X column(s) {np.flatnonzero(hi <= lo).tolist()} are constant; cannot scale")
    return lo, hi


class _ScaledInputs:
    """Shared unit-cube scaling + power warping ``u -> u**warp`` (warp < 1 stretches small values).

    Warping encodes that the angle of repose saturates with friction (steep near 0,
    flat at high friction, see paper Figure 13 discussion); ``warp=1`` disables it.
    When warping, scaled inputs are clipped to [0, 1] (constant extrapolation).
    """

    def _init_scaling(self, X: np.ndarray) -> None:
        self.lower_, self.upper_ = _bounds_from(self.space, self.bounds, X)
        w = np.broadcast_to(np.asarray(self.warp, dtype=float), (X.shape[1],)).copy()
        if np.any(w <= 0):
            raise ValueError(f"warp exponents must be > 0, got {self.warp}")
        self.warp_ = w
        self.n_features_in_ = X.shape[1]

    def _transform(self, X: np.ndarray) -> np.ndarray:
        U = (X - self.lower_) / (self.upper_ - self.lower_)
        if np.any(self.warp_ != 1.0):
            U = np.clip(U, 0.0, 1.0) ** self.warp_
        return U

    def get_params(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self._param_names}

    def clone(self):
        """Unfitted copy with the same hyper-parameters."""
        return type(self)(**self.get_params())

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items() if k not in ("space", "bounds"))
        return f"{type(self).__name__}({args})"


# --------------------------------------------------------------------------- RBF
class RBFRegressor(_ScaledInputs):
    """RBF interpolation / smoothing on unit-cube-scaled inputs (paper Section 3.2).

    Parameters
    ----------
    kernel : any :class:`~scipy.interpolate.RBFInterpolator` kernel.
    epsilon : shape parameter (required by multiquadric, inverse_multiquadric,
        inverse_quadratic, gaussian; ignored in effect by the scale-free kernels).
    smoothing : ridge smoothing (0 = interpolation).
    degree : degree of the added polynomial (None = scipy default for the kernel).
    warp : exponent(s) of the power warping of scaled inputs (1 = none).
    length_scales : per-dimension divisors of the (warped) unit-cube coordinates
        (anisotropy); None = isotropic.
    space / bounds : scaling box; defaults to the training-data min/max.
    """

    _param_names = ("kernel", "epsilon", "smoothing", "degree", "warp", "length_scales", "space", "bounds")

    def __init__(
        self,
        kernel: str = "thin_plate_spline",
        epsilon: float | None = None,
        smoothing: float = 0.0,
        degree: int | None = None,
        warp: float | Sequence[float] = 1.0,
        length_scales: Sequence[float] | None = None,
        space: ParameterSpace | None = None,
        bounds: tuple[Sequence[float], Sequence[float]] | None = None,
    ) -> None:
        self.kernel = kernel
        self.epsilon = epsilon
        self.smoothing = smoothing
        self.degree = degree
        self.warp = warp
        self.length_scales = length_scales
        self.space = space
        self.bounds = bounds

    def _features(self, X: np.ndarray) -> np.ndarray:
        U = self._transform(X)
        return U if self.length_scales is None else U / np.asarray(self.length_scales, dtype=float)

    def fit(self, X, y) -> "RBFRegressor":
        """Fit to ``X`` (n, d) in physical units and ``y`` (n,) or (n, m)."""
        X = _check_X(X)
        y = _check_y(y, X.shape[0])
        self._init_scaling(X)
        self.model_ = RBFInterpolator(
            self._features(X), y, kernel=self.kernel, epsilon=self.epsilon,
            smoothing=self.smoothing, degree=self.degree,
        )
        return self

    def predict(self, X) -> np.ndarray:
        X = _check_X(X, self.n_features_in_)
        return self.model_(self._features(X))


# --------------------------------------------------------------------------- GP
def _matern(D2: np.ndarray, nu: float) -> tuple[np.ndarray, np.ndarray]:
    """Correlation R(r) and factor g with dR/dlog(l_k) = g * D2_k, for scaled squared distance r^2."""
    r = np.sqrt(np.maximum(D2, 0.0))
    if nu == 0.5:
        e = np.exp(-r)
        return e, np.divide(e, r, out=np.zeros_like(r), where=r > 0)
    if nu == 1.5:
        s = np.sqrt(3.0) * r
        e = np.exp(-s)
        return (1.0 + s) * e, 3.0 * e
    if nu == 2.5:
        s = np.sqrt(5.0) * r
        e = np.exp(-s)
        return (1.0 + s + s * s / 3.0) * e, (5.0 / 3.0) * (1.0 + s) * e
    if np.isinf(nu):
        R = np.exp(-0.5 * D2)
        return R, R
    raise ValueError(f"nu must be 0.5, 1.5, 2.5 or inf, got {nu}")


class GaussianProcessRegressor(_ScaledInputs):
    """Universal kriging with an anisotropic Matern kernel (numpy/scipy only).

    ``y(x) = h(x)^T b + f(x) + noise``, ``h = [1, u]`` (linear trend in scaled inputs,
    or constant), ``f ~ GP(0, s_f^2 R(x, x'))`` with ARD length scales ``l_k``
    (unit-cube units), white noise variance ``s_n^2`` (in units of var(y)).  The
    hyper-parameters maximise the restricted (REML) log marginal likelihood of the
    *training* data (Rasmussen & Williams 2006, Sections 2.7 and 5.4).

    Parameters
    ----------
    nu : Matern smoothness 0.5, 1.5, 2.5 or ``inf`` (squared exponential).
    mean : ``"linear"`` or ``"constant"`` trend.
    warp : power warping of scaled inputs (see :class:`RBFRegressor`).
    n_restarts : random restarts of the optimiser (plus one deterministic start).
    seed : seed of the restarts.
    noise_bounds : bounds of ``s_n^2 / var(y)``.
    length_scale_bounds : bounds of ``l_k`` in unit-cube units.
    """

    _param_names = ("nu", "mean", "warp", "n_restarts", "seed", "noise_bounds", "length_scale_bounds", "space", "bounds")

    def __init__(
        self,
        nu: float = 2.5,
        mean: str = "linear",
        warp: float | Sequence[float] = 1.0,
        n_restarts: int = 1,
        seed: int = 0,
        noise_bounds: tuple[float, float] = (1e-6, 1.0),
        length_scale_bounds: tuple[float, float] = (0.02, 50.0),
        space: ParameterSpace | None = None,
        bounds: tuple[Sequence[float], Sequence[float]] | None = None,
    ) -> None:
        self.nu = nu
        self.mean = mean
        self.warp = warp
        self.n_restarts = n_restarts
        self.seed = seed
        self.noise_bounds = noise_bounds
        self.length_scale_bounds = length_scale_bounds
        self.space = space
        self.bounds = bounds

    def _trend(self, U: np.ndarray) -> np.ndarray:
        if self.mean == "linear":
            return np.column_stack([np.ones(len(U)), U])
        if self.mean == "constant":
            return np.ones((len(U), 1))
        raise ValueError(f"mean must be 'linear' or 'constant', got {self.mean!r}")

    @staticmethod
    def _sqdist(A: np.ndarray, B: np.ndarray, ls: np.ndarray) -> np.ndarray:
        """Per-dimension scaled squared differences, shape (len(A), len(B), d)."""
        return ((A[:, None, :] - B[None, :, :]) / ls) ** 2

    def _nll(self, theta: np.ndarray, U: np.ndarray, y: np.ndarray, H: np.ndarray, Dk: np.ndarray):
        """Negative restricted log marginal likelihood and its gradient w.r.t. log-hyper-parameters."""
        d = U.shape[1]
        ls2 = np.exp(2.0 * theta[:d])
        sf2, sn2 = np.exp(theta[d]), np.exp(theta[d + 1])
        D = Dk / ls2  # (n, n, d) scaled squared differences
        R, g = _matern(D.sum(-1), self.nu)
        n = len(y)
        K = sf2 * R + (sn2 + 1e-10) * np.eye(n)
        try:
            c = cho_factor(K, lower=True)
            Ki = cho_solve(c, np.eye(n))
            KiH = Ki @ H
            A = H.T @ KiH
            cA = cho_factor(A, lower=True)
        except LinAlgError:
            return 1e25, np.zeros_like(theta)
        P = Ki - KiH @ cho_solve(cA, KiH.T)  # projected inverse (REML)
        alpha = P @ y
        nll = 0.5 * y @ alpha + np.sum(np.log(np.diag(c[0]))) + np.sum(np.log(np.diag(cA[0])))
        M = P - np.outer(alpha, alpha)  # d nll / d theta_j = 0.5 * sum(M * dK_j)
        grad = np.empty_like(theta)
        gM = sf2 * g * M
        grad[:d] = 0.5 * np.einsum("ij,ijk->k", gM, D)
        grad[d] = 0.5 * np.sum(M * (sf2 * R))
        grad[d + 1] = 0.5 * sn2 * np.trace(M)
        return nll, grad

    def fit(self, X, y) -> "GaussianProcessRegressor":
        """Fit to ``X`` (n, d) in physical units and 1-D ``y`` (n,)."""
        X = _check_X(X)
        y = _check_y(y, X.shape[0])
        if y.ndim == 2:
            if y.shape[1] != 1:
                raise ValueError("GaussianProcessRegressor takes a single response; fit one model per column")
            y = y[:, 0]
        self._init_scaling(X)
        U = self._transform(X)
        n, d = U.shape
        H = self._trend(U)
        if n <= H.shape[1] + 1:
            raise ValueError(f"need more than {H.shape[1] + 1} samples, got {n}")
        self.y_mean_, self.y_std_ = float(y.mean()), float(y.std()) or 1.0
        yn = (y - self.y_mean_) / self.y_std_
        Dk = (U[:, None, :] - U[None, :, :]) ** 2
        lsb = np.log(np.asarray(self.length_scale_bounds, dtype=float))
        nb = np.log(np.asarray(self.noise_bounds, dtype=float))
        opt_bounds = [tuple(lsb)] * d + [(np.log(1e-3), np.log(1e2)), tuple(nb)]
        rng = np.random.default_rng(self.seed)
        starts = [np.r_[np.full(d, np.log(0.5)), 0.0, max(np.log(1e-2), nb[0])]]
        for _ in range(int(self.n_restarts)):
            starts.append(np.r_[rng.uniform(np.log(0.1), np.log(3.0), d), rng.uniform(-1, 1), rng.uniform(nb[0], np.log(0.1))])
        best = None
        with limit_blas_threads(1):
            for th0 in starts:
                res = minimize(self._nll, th0, args=(U, yn, H, Dk), jac=True, method="L-BFGS-B",
                               bounds=opt_bounds, options={"maxiter": 500})
                if best is None or res.fun < best.fun:
                    best = res
        self.theta_ = best.x
        self.length_scales_ = np.exp(best.x[:d])
        self.signal_variance_ = float(np.exp(best.x[d]))
        self.noise_variance_ = float(np.exp(best.x[d + 1]))
        self.log_marginal_likelihood_ = -float(best.fun)
        # Posterior quantities (GLS trend coefficients and weights of the kernel basis).
        R, _ = _matern(self._sqdist(U, U, self.length_scales_).sum(-1), self.nu)
        K = self.signal_variance_ * R + (self.noise_variance_ + 1e-10) * np.eye(n)
        self._cK = cho_factor(K, lower=True)
        KiH = cho_solve(self._cK, H)
        self._cA = cho_factor(H.T @ KiH, lower=True)
        self.beta_ = cho_solve(self._cA, KiH.T @ yn)
        self.alpha_ = cho_solve(self._cK, yn - H @ self.beta_)
        self._U, self._H = U, H
        return self

    def predict(self, X, return_std: bool = False):
        """Posterior mean (units of y); with ``return_std`` also the latent-function std."""
        X = _check_X(X, self.n_features_in_)
        U = self._transform(X)
        Hs = self._trend(U)
        out = np.empty(len(U))
        std = np.empty(len(U)) if return_std else None
        for s in range(0, len(U), 2048):  # chunk to bound memory of the (m, n, d) array
            sl = slice(s, s + 2048)
            Ks = self.signal_variance_ * _matern(self._sqdist(U[sl], self._U, self.length_scales_).sum(-1), self.nu)[0]
            out[sl] = Hs[sl] @ self.beta_ + Ks @ self.alpha_
            if return_std:
                V = cho_solve(self._cK, Ks.T)
                Wt = Hs[sl].T - self._H.T @ V
                var = self.signal_variance_ - np.sum(Ks.T * V, axis=0) + np.sum(Wt * cho_solve(self._cA, Wt), axis=0)
                std[sl] = np.sqrt(np.maximum(var, 0.0)) * self.y_std_
        out = out * self.y_std_ + self.y_mean_
        return (out, std) if return_std else out


# --------------------------------------------------------------------------- model selection
def default_candidates(space: ParameterSpace | None = None) -> dict[str, Any]:
    """Unfitted candidate surrogates searched by :func:`select_model`.

    * scipy RBF with the scale-free kernels (thin-plate spline, cubic, quintic, linear;
      smoothing 0 / 0.01 / 0.1, default or quadratic polynomial tail) and the
      shape-parameter kernels (multiquadric, inverse multiquadric, gaussian) over an
      epsilon grid 0.5-4 (unit-cube units), without or with a linear tail;
    * anisotropic GP/kriging with Matern 3/2, 5/2 and squared-exponential kernels;
    * each with and without square-root input warping (``warp=0.5``).
    """
    c: dict[str, Any] = {}
    for warp in (1.0, 0.5):
        tag = "" if warp == 1.0 else "|sqrt-warp"
        for k in ("thin_plate_spline", "cubic", "quintic", "linear"):
            for sm in (0.0, 1e-2, 1e-1):
                c[f"rbf:{k}:s={sm:g}{tag}"] = RBFRegressor(kernel=k, smoothing=sm, warp=warp, space=space)
        for k in ("thin_plate_spline", "cubic"):
            c[f"rbf:{k}:deg=2{tag}"] = RBFRegressor(kernel=k, degree=2, warp=warp, space=space)
        for k in ("multiquadric", "inverse_multiquadric", "gaussian"):
            for eps in (0.5, 1.0, 2.0, 4.0):
                for deg in (None, 1):
                    c[f"rbf:{k}:eps={eps:g}{'' if deg is None else ':deg=1'}{tag}"] = RBFRegressor(
                        kernel=k, epsilon=eps, degree=deg, warp=warp, space=space)
        for nu, nm in ((1.5, "matern32"), (2.5, "matern52"), (np.inf, "sqexp")):
            c[f"gp:{nm}:ard{tag}"] = GaussianProcessRegressor(nu=nu, warp=warp, space=space)
    return c


def _kfold_indices(y: np.ndarray, n_splits: int, rng: np.random.Generator, stratify: bool = True) -> list[np.ndarray]:
    """Random k-fold split; with ``stratify`` the samples sorted by y are dealt in random
    order within consecutive blocks of ``n_splits``, so that every fold spans the whole
    response range (fewer folds whose test points all lie outside the training range)."""
    n = len(y)
    if not stratify:
        return np.array_split(rng.permutation(n), n_splits)
    order = np.argsort(y, kind="stable")
    fold_of = np.empty(n, dtype=int)
    for start in range(0, n, n_splits):
        block = order[start:start + n_splits]
        fold_of[block] = rng.permutation(n_splits)[: len(block)]
    return [np.flatnonzero(fold_of == k) for k in range(n_splits)]


def cross_validate(
    estimator, X, y, n_splits: int = 5, n_repeats: int = 1, seed: int = 0, stratify: bool = True
) -> dict[str, Any]:
    """Repeated k-fold cross-validation of a single-response estimator.

    Returns ``{"rmse", "r2", "rmse_repeats", "oof"}``: mean RMSE / R^2 over repeats
    and the out-of-fold predictions, shape (n_repeats, n).
    """
    X = _check_X(X)
    y = _check_y(y, X.shape[0])
    if y.ndim != 1:
        raise ValueError("cross_validate expects a 1-D y (one response)")
    if not 2 <= n_splits <= len(y):
        raise ValueError(f"n_splits must be in [2, n_samples={len(y)}], got {n_splits}")
    rng = np.random.default_rng(seed)
    oof = np.empty((n_repeats, len(y)))
    for r in range(n_repeats):
        for test in _kfold_indices(y, n_splits, rng, stratify):
            train = np.setdiff1d(np.arange(len(y)), test)
            oof[r, test] = estimator.clone().fit(X[train], y[train]).predict(X[test])
    rm = np.sqrt(np.mean((oof - y) ** 2, axis=1))
    r2 = 1.0 - np.sum((oof - y) ** 2, axis=1) / np.sum((y - y.mean()) ** 2)
    return {"rmse": float(rm.mean()), "r2": float(r2.mean()), "rmse_repeats": rm, "oof": oof}


@dataclass
class ModelSelection:
    """Outcome of :func:`select_model` for one response.

    ``scores`` maps candidate name -> ``{"cv_rmse", "cv_r2"}`` (units of y), sorted
    best first; ``estimator`` is the winner refitted on all training data.
    """

    best_name: str
    estimator: Any
    scores: dict[str, dict[str, float]]
    n_splits: int
    n_repeats: int

    def table(self, top: int | None = None) -> str:
        rows = list(self.scores.items())[:top]
        w = max(len(k) for k, _ in rows)
        lines = [f"{'candidate':<{w}}  cv_rmse  cv_r2"]
        lines += [f"{k:<{w}}  {v['cv_rmse']:7.3f}  {v['cv_r2']:.4f}" for k, v in rows]
        return "\n".join(lines)


def select_model(
    X,
    y,
    candidates: Mapping[str, Any] | None = None,
    space: ParameterSpace | None = None,
    n_splits: int = 5,
    n_repeats: int = 2,
    seed: int = 0,
) -> ModelSelection:
    """Pick the candidate with the lowest repeated k-fold CV RMSE, then refit it on all data.

    Every candidate sees identical folds.  Only ``(X, y)`` -- the training set -- is used.
    """
    X = _check_X(X)
    y = _check_y(y, X.shape[0])
    if y.ndim != 1:
        raise ValueError("select_model expects a 1-D y (one response)")
    candidates = default_candidates(space) if candidates is None else candidates
    if not candidates:
        raise ValueError("no candidate models given")
    scores = {}
    with limit_blas_threads(1):
        for name, est in candidates.items():
            try:
                cv = cross_validate(est, X, y, n_splits=n_splits, n_repeats=n_repeats, seed=seed)
                scores[name] = {"cv_rmse": cv["rmse"], "cv_r2": cv["r2"]}
            except (LinAlgError, ValueError, np.linalg.LinAlgError):  # e.g. singular RBF system
                scores[name] = {"cv_rmse": float("inf"), "cv_r2": float("-inf")}
    scores = dict(sorted(scores.items(), key=lambda kv: kv[1]["cv_rmse"]))
    best = next(iter(scores))
    if not np.isfinite(scores[best]["cv_rmse"]):
        raise RuntimeError("all candidate surrogates failed during cross-validation")
    return ModelSelection(best, candidates[best].clone().fit(X, y), scores, n_splits, n_repeats)


class CVSurrogate:
    """Multi-response surrogate: one CV-selected model per response column.

    Parameters
    ----------
    candidates : name -> unfitted estimator; default :func:`default_candidates`.
    space : parameter box used for unit-cube scaling of default candidates.
    n_splits, n_repeats, seed : repeated k-fold CV settings.
    response_names : optional labels of the columns of ``Y``.
    """

    def __init__(
        self,
        candidates: Mapping[str, Any] | None = None,
        space: ParameterSpace | None = None,
        n_splits: int = 5,
        n_repeats: int = 2,
        seed: int = 0,
        response_names: Sequence[str] | None = None,
    ) -> None:
        self.candidates = candidates
        self.space = space
        self.n_splits = n_splits
        self.n_repeats = n_repeats
        self.seed = seed
        self.response_names = response_names

    def fit(self, X, Y) -> "CVSurrogate":
        """``X`` (n, d) physical units; ``Y`` (n,) or (n, m). Selection uses only these data."""
        X = _check_X(X)
        if self.space is not None and X.shape[1] != self.space.dim:
            raise ValueError(f"X has {X.shape[1]} columns but the ParameterSpace has {self.space.dim} parameters")
        Y = _check_y(Y, X.shape[0], "Y")
        self._1d = Y.ndim == 1
        Y2 = Y.reshape(-1, 1) if self._1d else Y
        names = list(self.response_names) if self.response_names is not None else [f"y{j}" for j in range(Y2.shape[1])]
        if len(names) != Y2.shape[1]:
            raise ValueError(f"response_names has {len(names)} entries but Y has {Y2.shape[1]} columns")
        self.response_names_ = names
        self.n_features_in_ = X.shape[1]
        self.selections_ = {
            nm: select_model(X, Y2[:, j], self.candidates, self.space, self.n_splits, self.n_repeats, self.seed)
            for j, nm in enumerate(names)
        }
        return self

    @property
    def estimators_(self) -> list[Any]:
        return [s.estimator for s in self.selections_.values()]

    def predict(self, X) -> np.ndarray:
        """Predictions, shape (n, m) (or (n,) if fitted on a 1-D y)."""
        X = _check_X(X, self.n_features_in_)
        P = np.column_stack([e.predict(X) for e in self.estimators_])
        return P[:, 0] if self._1d else P

    __call__ = predict

    def summary(self) -> dict[str, Any]:
        """Winner, its hyper-parameters and all CV scores per response (JSON-friendly)."""
        out = {}
        for nm, s in self.selections_.items():
            est = s.estimator
            info = {"winner": s.best_name, "cv_rmse": s.scores[s.best_name]["cv_rmse"],
                    "cv_r2": s.scores[s.best_name]["cv_r2"], "n_splits": s.n_splits, "n_repeats": s.n_repeats,
                    "scores": s.scores}
            if isinstance(est, GaussianProcessRegressor):
                info["length_scales_unit_cube"] = est.length_scales_.tolist()
                info["noise_std"] = float(np.sqrt(est.noise_variance_) * est.y_std_)
                info["log_marginal_likelihood"] = est.log_marginal_likelihood_
            out[nm] = info
        return out


def cross_validated_surrogate(
    X,
    Y,
    space: ParameterSpace | None = None,
    candidates: Mapping[str, Any] | None = None,
    n_splits: int = 5,
    n_repeats: int = 2,
    seed: int = 0,
    response_names: Sequence[str] | None = None,
) -> CVSurrogate:
    """Fit a :class:`CVSurrogate` on the training data ``(X, Y)`` and return it."""
    return CVSurrogate(candidates, space, n_splits, n_repeats, seed, response_names).fit(X, Y)
