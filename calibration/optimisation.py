"""Multi-objective calibration on a surrogate with NSGA-II (pymoo).

Zhang et al. (2023), Section 3.3 / 4.2: the measured static and dynamic angles of
repose are targets (Eq. 15), the four friction coefficients are the design variables
in [0, 0.8] (Eq. 16), and NSGA-II (Table 8: population 500, 200 generations, SBX
crossover probability 0.9 with distribution index 10, polynomial mutation index 20)
searches the surrogate.  Objective k is ``|y_k(x) - target_k|`` (degrees).

Because 4 parameters are fitted to 2 targets, the exact solutions form a
2-dimensional manifold: many parameter sets hit both targets.  Besides the Pareto set
and one compromise point we therefore report the *acceptable set* -- every evaluated
parameter vector whose predicted responses are all within tolerance -- gathered from
all NSGA-II evaluations (every generation) and from a dense LHS of the surrogate.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
from pymoo.algorithms.moo.nsga2 import NSGA2
from pymoo.core.problem import Problem
from pymoo.operators.crossover.sbx import SBX
from pymoo.operators.mutation.pm import PM
from pymoo.optimize import minimize

from .designs import ParameterSpace, latin_hypercube, pairwise_support

__all__ = [
    "NSGA2Settings",
    "TargetMatchingProblem",
    "CalibrationResult",
    "calibrate",
    "evaluate_point",
    "plot_acceptable_set",
]


@dataclass(frozen=True)
class NSGA2Settings:
    """NSGA-II settings; defaults are the paper's Table 8.

    ``mutation_prob_var`` (per-variable mutation probability) is not given in the paper;
    None = pymoo default ``1 / n_var``.
    """

    pop_size: int = 500
    n_generations: int = 200
    crossover_prob: float = 0.9
    crossover_eta: float = 10.0
    mutation_eta: float = 20.0
    mutation_prob_var: float | None = None
    seed: int = 1

    def __post_init__(self) -> None:
        if self.pop_size < 4 or self.n_generations < 1:
            raise ValueError(f"pop_size must be >= 4 and n_generations >= 1, got {self.pop_size}, {self.n_generations}")
        if not 0.0 <= self.crossover_prob <= 1.0:
            raise ValueError(f"crossover_prob must be in [0, 1], got {self.crossover_prob}")


def _predict2d(surrogate: Any, X: np.ndarray) -> np.ndarray:
    Y = np.asarray(surrogate.predict(X), dtype=float)
    return Y.reshape(len(X), -1)


class TargetMatchingProblem(Problem):
    """pymoo problem: minimise ``|surrogate(x)_k - target_k|`` for every target k (Eq. 15-16).

    Every evaluated ``(X, Y)`` batch is appended to ``archive_X`` / ``archive_Y`` (all
    generations), from which the acceptable set is gathered.
    """

    def __init__(self, surrogate: Any, targets: Sequence[float], space: ParameterSpace, record: bool = True):
        self.surrogate = surrogate
        self.targets = np.asarray(targets, dtype=float)
        self.record = record
        self.archive_X: list[np.ndarray] = []
        self.archive_Y: list[np.ndarray] = []
        super().__init__(n_var=space.dim, n_obj=len(self.targets), xl=space.lower, xu=space.upper)

    def _evaluate(self, x, out, *args, **kwargs):
        Y = _predict2d(self.surrogate, x)
        if self.record:
            self.archive_X.append(np.array(x, dtype=float))
            self.archive_Y.append(Y)
        out["F"] = np.abs(Y - self.targets)


@dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate`. Angles in degrees, parameters in the units of ``space``.

    Attributes
    ----------
    pareto_X, pareto_F, pareto_Y : final non-dominated set, its objectives
        ``|y - target|`` and its predicted responses.
    compromise_x, compromise_y : the chosen point (see ``compromise_rule``) and its prediction.
    acceptable_X, acceptable_Y : all evaluated points with ``|y_k - target_k| <= tol_k``
        for every k (NSGA-II archive of all generations + dense LHS), de-duplicated.
    acceptable_ranges : per-parameter ``(min, max)`` over the acceptable set.
    acceptable_supported : when ``support_X`` was given, True for acceptable points whose
        every 2-D parameter projection has training data nearby (see
        :func:`calibration.designs.pairwise_support`); ``supported_ranges`` and
        ``best_supported_x/y`` (lowest normalised max-error supported point) go with it.
    """

    space: ParameterSpace
    targets: np.ndarray
    tolerance: np.ndarray
    response_names: list[str]
    settings: NSGA2Settings
    pareto_X: np.ndarray
    pareto_F: np.ndarray
    pareto_Y: np.ndarray
    compromise_x: np.ndarray
    compromise_y: np.ndarray
    compromise_rule: str
    acceptable_X: np.ndarray
    acceptable_Y: np.ndarray
    n_acceptable_from_nsga2: int
    n_acceptable_from_dense: int
    n_evaluations: int
    n_dense: int
    acceptable_ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    acceptable_supported: np.ndarray | None = None
    supported_ranges: dict[str, tuple[float, float]] | None = None
    best_supported_x: np.ndarray | None = None
    best_supported_y: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly summary (no full acceptable set, only its size and ranges)."""
        names = self.space.names
        out = {
            "targets_deg": dict(zip(self.response_names, self.targets.tolist())),
            "tolerance_deg": dict(zip(self.response_names, self.tolerance.tolist())),
            "nsga2_settings": self.settings.__dict__,
            "n_evaluations_nsga2": self.n_evaluations,
            "n_dense_samples": self.n_dense,
            "pareto_size": int(len(self.pareto_X)),
            "compromise_rule": self.compromise_rule,
            "compromise_x": dict(zip(names, self.compromise_x.tolist())),
            "compromise_predicted_deg": dict(zip(self.response_names, self.compromise_y.tolist())),
            "compromise_abs_error_deg": dict(zip(self.response_names, np.abs(self.compromise_y - self.targets).tolist())),
            "acceptable_set_size": int(len(self.acceptable_X)),
            "acceptable_from_nsga2": self.n_acceptable_from_nsga2,
            "acceptable_from_dense_lhs": self.n_acceptable_from_dense,
            "acceptable_ranges": {k: list(v) for k, v in self.acceptable_ranges.items()},
        }
        if self.acceptable_supported is not None:
            out["acceptable_supported_size"] = int(self.acceptable_supported.sum())
            out["supported_ranges"] = {k: list(v) for k, v in (self.supported_ranges or {}).items()}
            if self.best_supported_x is not None:
                out["best_supported_x"] = dict(zip(names, self.best_supported_x.tolist()))
                out["best_supported_predicted_deg"] = dict(zip(self.response_names, self.best_supported_y.tolist()))
        return out


def _as_vector(values, names: Sequence[str] | None, what: str) -> np.ndarray:
    if isinstance(values, Mapping):
        if names is None:
            return np.array(list(values.values()), dtype=float)
        missing = [n for n in names if n not in values]
        if missing:
            raise ValueError(f"{what} is missing entries for {missing}")
        return np.array([values[n] for n in names], dtype=float)
    return np.atleast_1d(np.asarray(values, dtype=float))


def evaluate_point(
    surrogate: Any,
    x,
    targets,
    tolerance,
    space: ParameterSpace | None = None,
    acceptable_ranges: Mapping[str, tuple[float, float]] | None = None,
) -> dict[str, Any]:
    """Surrogate prediction at one parameter vector and whether it meets every target.

    ``x`` may be a dict keyed by parameter name (needs ``space``).  Returns predicted
    responses, absolute errors (deg), ``within_tolerance`` and, if ``acceptable_ranges``
    is given, ``inside_ranges`` (inside the per-parameter bounding box of the set).
    """
    xv = _as_vector(x, None if space is None else space.names, "x")
    t = _as_vector(targets, None, "targets")
    tol = np.broadcast_to(_as_vector(tolerance, None, "tolerance"), t.shape)
    y = _predict2d(surrogate, xv.reshape(1, -1))[0]
    err = np.abs(y - t)
    out = {"x": xv.tolist(), "predicted": y.tolist(), "abs_error": err.tolist(),
           "within_tolerance": bool(np.all(err <= tol))}
    if acceptable_ranges is not None and space is not None:
        lo = np.array([acceptable_ranges[n][0] for n in space.names])
        hi = np.array([acceptable_ranges[n][1] for n in space.names])
        out["inside_ranges"] = bool(np.all((xv >= lo) & (xv <= hi)))
    return out


def calibrate(
    surrogate: Any,
    targets,
    space: ParameterSpace,
    tolerance=None,
    settings: NSGA2Settings | None = None,
    n_dense: int = 100_000,
    response_names: Sequence[str] | None = None,
    compromise: str = "max",
    support_X: np.ndarray | None = None,
    support_half_width: float = 0.15,
) -> CalibrationResult:
    """Run NSGA-II on ``surrogate`` to hit ``targets`` and collect the acceptable set.

    Parameters
    ----------
    surrogate : object with ``predict(X) -> (n, m)`` responses (degrees), X in physical units.
    targets : m measured responses (deg); a dict is read in ``response_names`` order.
    space : design-variable box (Eq. 16).
    tolerance : acceptance half-width per target (deg); scalar or length m.  None = 5 %
        of each target, the paper's acceptance criterion (Section 4.2).
    settings : NSGA-II settings (default Table 8).
    n_dense : size of the extra LHS of the surrogate used to fill the acceptable set
        (0 = NSGA-II archive only).
    compromise : rule to pick one point from the Pareto set: ``"max"`` minimises
        ``max_k |y_k - t_k| / tol_k`` (balanced, Chebyshev); ``"sum"`` minimises
        ``sum_k |y_k - t_k| / tol_k``.  Ties broken by the other norm.  When many
        parameter sets hit the targets (near-)exactly the Pareto set shrinks to a few
        of them and the compromise is just one representative of that manifold.
    support_X : training inputs of the surrogate; if given, acceptable points are
        flagged as supported / extrapolated (window ``support_half_width``, unit cube).
    """
    if not isinstance(space, ParameterSpace):
        raise TypeError(f"space must be a ParameterSpace, got {type(space).__name__}")
    settings = NSGA2Settings() if settings is None else settings
    t = _as_vector(targets, response_names, "targets")
    if not np.all(np.isfinite(t)):
        raise ValueError("targets contain NaN or infinite values")
    names = list(response_names) if response_names is not None else (
        list(targets.keys()) if isinstance(targets, Mapping) else [f"y{k}" for k in range(len(t))])
    if len(names) != len(t):
        raise ValueError(f"{len(names)} response names for {len(t)} targets")
    tol = 0.05 * np.abs(t) if tolerance is None else np.broadcast_to(_as_vector(tolerance, response_names, "tolerance"), t.shape).astype(float)
    if np.any(~np.isfinite(tol)) or np.any(tol <= 0):
        raise ValueError(f"tolerance must be positive and finite, got {tol}")
    if compromise not in ("max", "sum"):
        raise ValueError(f"compromise must be 'max' or 'sum', got {compromise!r}")
    y_test = _predict2d(surrogate, space.lower.reshape(1, -1))
    if y_test.shape[1] != len(t):
        raise ValueError(f"surrogate returns {y_test.shape[1]} responses but {len(t)} targets were given")

    problem = TargetMatchingProblem(surrogate, t, space)
    algorithm = NSGA2(
        pop_size=settings.pop_size,
        crossover=SBX(prob=settings.crossover_prob, eta=settings.crossover_eta),
        mutation=PM(eta=settings.mutation_eta, prob_var=settings.mutation_prob_var),
        eliminate_duplicates=True,
    )
    res = minimize(problem, algorithm, ("n_gen", settings.n_generations), seed=settings.seed, verbose=False)
    pX = np.atleast_2d(res.X)
    pY = _predict2d(surrogate, pX)
    pF = np.abs(pY - t)

    # Compromise: normalise errors by the tolerance, then Chebyshev (max) or L1 (sum).
    Z = pF / tol
    primary, secondary = (Z.max(axis=1), Z.sum(axis=1)) if compromise == "max" else (Z.sum(axis=1), Z.max(axis=1))
    i = int(np.lexsort((secondary, primary))[0])
    cx, cy = pX[i], pY[i]

    # Acceptable set from every NSGA-II evaluation (all generations) ...
    aX = np.concatenate(problem.archive_X)
    aY = np.concatenate(problem.archive_Y)
    n_eval = len(aX)
    ok = np.all(np.abs(aY - t) <= tol, axis=1)
    aX, aY = aX[ok], aY[ok]
    n_from_nsga = len(aX)
    # ... plus a dense space-filling sample of the surrogate.
    n_from_dense = 0
    if n_dense > 0:
        D = latin_hypercube(space, int(n_dense), seed=settings.seed, optimization=None)
        DY = _predict2d(surrogate, D)
        okd = np.all(np.abs(DY - t) <= tol, axis=1)
        n_from_dense = int(okd.sum())
        aX, aY = np.concatenate([aX, D[okd]]), np.concatenate([aY, DY[okd]])
    if len(aX):
        aX, idx = np.unique(aX, axis=0, return_index=True)
        aY = aY[idx]
    ranges = _ranges(aX, space)

    supported = sup_ranges = bx = by = None
    if support_X is not None:
        supported = np.zeros(0, dtype=bool)
        if len(aX):
            supported = pairwise_support(aX, support_X, space, support_half_width)[0].min(axis=1) > 0
        sup_ranges = _ranges(aX[supported], space)
        if supported.any():
            zs = np.max(np.abs(aY[supported] - t) / tol, axis=1)
            k = int(np.argmin(zs))
            bx, by = aX[supported][k], aY[supported][k]

    return CalibrationResult(
        space=space, targets=t, tolerance=np.asarray(tol, dtype=float), response_names=names, settings=settings,
        pareto_X=pX, pareto_F=pF, pareto_Y=pY, compromise_x=cx, compromise_y=cy,
        compromise_rule=f"min over Pareto set of {'max' if compromise == 'max' else 'sum'}_k |y_k - t_k| / tol_k",
        acceptable_X=aX, acceptable_Y=aY, n_acceptable_from_nsga2=n_from_nsga,
        n_acceptable_from_dense=n_from_dense, n_evaluations=n_eval, n_dense=int(n_dense),
        acceptable_ranges=ranges, acceptable_supported=supported, supported_ranges=sup_ranges,
        best_supported_x=bx, best_supported_y=by,
    )


def _ranges(A: np.ndarray, space: ParameterSpace) -> dict[str, tuple[float, float]]:
    if len(A) == 0:
        return {}
    return {n: (float(A[:, k].min()), float(A[:, k].max())) for k, n in enumerate(space.names)}


def _tolerance_text(result: CalibrationResult) -> str:
    return "; ".join(f"{n} {t:.2f} ± {e:.2f} deg" for n, t, e in zip(result.response_names, result.targets,
                                                                   result.tolerance))


def _plot_acceptable_interval(result: CalibrationResult, A: np.ndarray, err: np.ndarray, ref, reference_label: str,
                              path: str | None):
    """One calibrated parameter: the acceptable values on its axis against their largest normalised error."""
    import matplotlib.pyplot as plt

    space = result.space
    p = space.parameters[0]
    fig, ax = plt.subplots(figsize=(7.0, 4.2), constrained_layout=True)
    if len(A):
        ax.scatter(A[:, 0], err, s=6, c=err, cmap="viridis", vmin=0, vmax=1, rasterized=True,
                   label="acceptable parameter values")
    ax.axvline(result.compromise_x[0], color="r", lw=2, label="compromise (NSGA-II)")
    if ref is not None:
        ax.axvline(ref[0], color="orange", ls="--", lw=2, label=reference_label)
    ax.set_xlim(space.lower[0], space.upper[0])
    ax.set_ylim(0, 1.05)
    ax.set_xlabel(f"{p.name} [{p.unit}]" if p.unit else p.name)
    ax.set_ylabel("largest |predicted - target| / tolerance (-)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    ax.set_title(f"Acceptable set: {len(result.acceptable_X)} values whose predicted angles all lie within "
                 f"tolerance\ntargets: {_tolerance_text(result)}", fontsize=10)
    if path is not None:
        fig.savefig(path, dpi=130)
        plt.close(fig)
    return fig


def plot_acceptable_set(
    result: CalibrationResult,
    path: str | None = None,
    reference: Mapping[str, float] | Sequence[float] | None = None,
    reference_label: str = "paper optimum",
    max_points: int = 6000,
    seed: int = 0,
):
    """Pairwise scatter of the acceptable set, coloured by the largest normalised error.

    Marks the compromise (star) and optionally a ``reference`` point (cross), e.g. the
    paper's optimum (Section 4.2).  Saves to ``path`` if given; returns the Figure.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    space = result.space
    names, d = space.names, space.dim
    A, AY = result.acceptable_X, result.acceptable_Y
    if len(A) > max_points:
        sel = np.random.default_rng(seed).choice(len(A), max_points, replace=False)
        A, AY = A[sel], AY[sel]
    err = np.max(np.abs(AY - result.targets) / result.tolerance, axis=1) if len(A) else np.empty(0)
    order = np.argsort(-err)  # best points drawn last (on top)
    A, err = A[order], err[order]
    ref = None if reference is None else _as_vector(reference, names, "reference")
    if d == 1:
        return _plot_acceptable_interval(result, A, err, ref, reference_label, path)
    side = max(5.0, 3.0 * (d - 1))
    fig, axes = plt.subplots(d - 1, d - 1, figsize=(side + 1.6, side + 0.8), squeeze=False, constrained_layout=True)
    units = [p.unit for p in space.parameters]

    def label(i: int) -> str:
        return f"{names[i]} [{units[i]}]" if units[i] else names[i]

    sc = None
    for r in range(1, d):
        for c in range(d - 1):
            ax = axes[r - 1, c]
            if c >= r:
                ax.axis("off")
                continue
            if len(A):
                sc = ax.scatter(A[:, c], A[:, r], c=err, s=4, cmap="viridis", vmin=0, vmax=1, rasterized=True,
                                label="acceptable parameter sets")
            ax.plot(result.compromise_x[c], result.compromise_x[r], "r*", ms=14, mec="k", label="compromise (NSGA-II)")
            if ref is not None:
                ax.plot(ref[c], ref[r], "kX", ms=11, mfc="orange", label=reference_label)
            ax.set_xlim(space.lower[c], space.upper[c])
            ax.set_ylim(space.lower[r], space.upper[r])
            ax.grid(alpha=0.3)
            if r == d - 1:
                ax.set_xlabel(label(c))
            if c == 0:
                ax.set_ylabel(label(r))
    handles, labels = axes[0, 0].get_legend_handles_labels()
    frac = len(result.acceptable_X)
    tol_txt = _tolerance_text(result)
    fig.suptitle(f"Acceptable set: {frac} parameter sets whose predicted angles all lie within tolerance\n"
                 f"targets: {tol_txt}", fontsize=10)
    if d > 2:
        axes[0, d - 2].legend(handles, labels, loc="center", fontsize=9)
    else:
        axes[0, 0].legend(handles, labels, loc="upper right", fontsize=8, framealpha=0.9)
    if sc is not None:
        fig.colorbar(sc, ax=axes, shrink=0.8, label="largest |predicted - target| / tolerance (-)")
    if path is not None:
        fig.savefig(path, dpi=130)
        plt.close(fig)
    return fig
