"""Parameter spaces and space-filling designs for DEM calibration.

The seed paper (Zhang et al. 2023, Section 3.1, Table 6) samples the four
friction coefficients ``mu_s_pp, mu_r_pp, mu_s_pw, mu_r_pw`` (each in
[0, 0.8], dimensionless) with an "optimal" Latin hypercube of 140 points.
:func:`latin_hypercube` reproduces that step with
:class:`scipy.stats.qmc.LatinHypercube` (centred-discrepancy optimised).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.stats import qmc

__all__ = ["Parameter", "ParameterSpace", "latin_hypercube", "paper_parameter_space", "pairwise_support"]


@dataclass(frozen=True)
class Parameter:
    """One calibration parameter with closed bounds ``[lower, upper]`` in ``unit``."""

    name: str
    lower: float
    upper: float
    unit: str = "-"
    description: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"parameter name must be a non-empty string, got {self.name!r}")
        lo, hi = float(self.lower), float(self.upper)
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise ValueError(f"parameter {self.name!r}: bounds must be finite, got lower={lo}, upper={hi}")
        if not lo < hi:
            raise ValueError(f"parameter {self.name!r}: lower bound {lo} must be < upper bound {hi}")


@dataclass(frozen=True)
class ParameterSpace:
    """An ordered box of named parameters.

    Columns of every design / data matrix follow the order of ``parameters``.
    """

    parameters: tuple[Parameter, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        params = tuple(self.parameters)
        if len(params) == 0:
            raise ValueError("ParameterSpace needs at least one parameter")
        for p in params:
            if not isinstance(p, Parameter):
                raise TypeError(f"ParameterSpace expects Parameter objects, got {type(p).__name__}")
        names = [p.name for p in params]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"parameter names must be unique; duplicated: {dup}")
        object.__setattr__(self, "parameters", params)

    @classmethod
    def from_bounds(
        cls,
        names: Sequence[str],
        lower: Sequence[float],
        upper: Sequence[float],
        units: Sequence[str] | None = None,
    ) -> "ParameterSpace":
        """Build a space from parallel lists of names, lower and upper bounds (and units)."""
        n = len(names)
        if len(lower) != n or len(upper) != n or (units is not None and len(units) != n):
            raise ValueError(
                f"names, lower, upper (and units) must have the same length; got "
                f"{n}, {len(lower)}, {len(upper)}" + ("" if units is None else f", {len(units)}")
            )
        units = ["-"] * n if units is None else list(units)
        return cls(tuple(Parameter(nm, lo, hi, u) for nm, lo, hi, u in zip(names, lower, upper, units)))

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    @property
    def units(self) -> list[str]:
        return [p.unit for p in self.parameters]

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.parameters], dtype=float)

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.parameters], dtype=float)

    @property
    def dim(self) -> int:
        return len(self.parameters)

    def __len__(self) -> int:
        return self.dim

    def _check(self, X: np.ndarray | Sequence, what: str) -> np.ndarray:
        X = np.asarray(X, dtype=float)
        single = X.ndim == 1
        X2 = np.atleast_2d(X)
        if X2.ndim != 2 or X2.shape[1] != self.dim:
            raise ValueError(
                f"{what} must have {self.dim} columns ({', '.join(self.names)}), got shape {X.shape}"
            )
        if not np.all(np.isfinite(X2)):
            raise ValueError(f"{what} contains NaN or infinite values")
        return X2[0] if single else X2

    def to_unit(self, X: np.ndarray | Sequence) -> np.ndarray:
        """Map physical values to the unit cube: ``(X - lower) / (upper - lower)``."""
        X = self._check(X, "X")
        return (X - self.lower) / (self.upper - self.lower)

    def from_unit(self, U: np.ndarray | Sequence) -> np.ndarray:
        """Map unit-cube coordinates to physical values: ``lower + U * (upper - lower)``."""
        U = self._check(U, "U")
        return self.lower + U * (self.upper - self.lower)

    def contains(self, X: np.ndarray | Sequence, atol: float = 1e-12) -> np.ndarray:
        """Boolean mask of rows of ``X`` inside the box (bounds inclusive, tolerance ``atol``)."""
        X = np.atleast_2d(self._check(X, "X"))
        return np.all((X >= self.lower - atol) & (X <= self.upper + atol), axis=1)

    def as_dict(self, x: np.ndarray | Sequence) -> dict[str, float]:
        """One parameter vector as ``{name: value}``."""
        x = np.asarray(self._check(x, "x"), dtype=float).ravel()
        return {n: float(v) for n, v in zip(self.names, x)}


def paper_parameter_space(upper: float = 0.8) -> ParameterSpace:
    """The four friction coefficients of Zhang et al. (2023), Table 6 / Eq. (16): each in [0, 0.8]."""
    return ParameterSpace(
        (
            Parameter("mu_s_pp", 0.0, upper, "-", "particle-particle sliding friction"),
            Parameter("mu_r_pp", 0.0, upper, "-", "particle-particle rolling friction"),
            Parameter("mu_s_pw", 0.0, upper, "-", "particle-wall (geometry) sliding friction"),
            Parameter("mu_r_pw", 0.0, upper, "-", "particle-wall (geometry) rolling friction"),
        )
    )


def latin_hypercube(
    space: ParameterSpace,
    n: int,
    seed: int | np.random.Generator | None = 0,
    optimization: str | None = "random-cd",
    scramble: bool = True,
) -> np.ndarray:
    """Space-filling Latin hypercube design in physical units (paper Section 3.1).

    Parameters
    ----------
    space : the parameter box.
    n : number of samples (rows); each of the ``n`` equal strata per dimension is hit
        exactly once.
    seed : seed or Generator for reproducibility.
    optimization : ``"random-cd"`` (default; permutes columns to lower the centred
        discrepancy, keeps the Latin-hypercube property), ``None`` (plain LHS) or
        ``"lloyd"`` (Lloyd-Max relaxation; *breaks* exact stratification).
    scramble : if False, points sit at stratum centres.

    Returns
    -------
    ``(n, space.dim)`` array in the units of ``space``.
    """
    if not isinstance(space, ParameterSpace):
        raise TypeError(f"space must be a ParameterSpace, got {type(space).__name__}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise ValueError(f"n (number of samples) must be an integer, got {n!r}")
    if n < 1:
        raise ValueError(f"n (number of samples) must be >= 1, got {n}")
    if optimization not in (None, "random-cd", "lloyd"):
        raise ValueError(f"optimization must be None, 'random-cd' or 'lloyd', got {optimization!r}")
    sampler = qmc.LatinHypercube(d=space.dim, scramble=scramble, optimization=optimization, rng=seed)
    U = sampler.random(int(n))
    return space.from_unit(U)


def pairwise_support(
    X: np.ndarray,
    design: np.ndarray,
    space: ParameterSpace,
    half_width: float = 0.1,
    chunk: int = 4096,
) -> tuple[np.ndarray, list[tuple[str, str]]]:
    """How many design points lie near each row of ``X`` in every 2-D projection.

    For each parameter pair (i, j) counts the design points inside the square of
    half-width ``half_width`` (unit-cube units) centred on ``(x_i, x_j)``.  A zero count
    means that combination of two parameters was never sampled, i.e. a surrogate
    evaluated there extrapolates, even if the point is close to the data in each
    coordinate separately.

    Returns ``(counts, pairs)``: counts of shape (len(X), n_pairs) and the pair names.
    """
    if not 0 < half_width <= 1:
        raise ValueError(f"half_width must be in (0, 1], got {half_width}")
    U = np.atleast_2d(space.to_unit(X))
    D = np.atleast_2d(space.to_unit(design))
    pairs = [(i, j) for i in range(space.dim) for j in range(i + 1, space.dim)]
    counts = np.empty((len(U), len(pairs)), dtype=int)
    for s in range(0, len(U), chunk):
        near = np.abs(U[s:s + chunk, None, :] - D[None, :, :]) <= half_width  # (c, n_design, d)
        for k, (i, j) in enumerate(pairs):
            counts[s:s + chunk, k] = np.sum(near[:, :, i] & near[:, :, j], axis=1)
    names = [(space.names[i], space.names[j]) for i, j in pairs]
    return counts, names
