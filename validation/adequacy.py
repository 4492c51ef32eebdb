"""Stage 4: is there any parameter set for which every observable is plausible?

History matching (Vernon et al. 2010, Sec. 3; Craig et al. 1997): x is non-implausible when
``max_i I_i(x) <= 3`` (Pukelsheim's 3-sigma rule: any unimodal density puts < 5 % beyond 3 sd;
the maximum is the hmer package's choice below 10 targets).  The box is searched on the
surrogates by a dense Sobol scan plus local minimisation of the (smoothed) maximum.

* Some point plausible: "no effect is needed"; the plausible set (its ranges and the fraction of
  the box it fills) is the ambiguity the data leave.
* None: "this model cannot reproduce these measurements"; the **minimal conflicting subsets**
  name why: an observable no setting reaches on its own ("unreachable"), or a pair (triple, ...)
  of observables each reachable but never together.  A subset S conflicts when
  ``min_x max_{i in S} I_i(x) > 3``; every flagged subset is confirmed by a local minimisation
  before it is reported.  The best joint misfit is ``chi^2 = sum_i z_i^2`` at the maximum-likelihood
  point, with ``dof = m - k`` (m observables, k parameters).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations
from typing import Sequence

import numpy as np

from .misfit import Misfit
from .search import BestFit, SurrogateScan, evaluate_points, minimize_max_implausibility
from .surrogates import SurrogateSet

__all__ = ["Conflict", "Adequacy", "judge_adequacy", "minimal_conflicts"]


@dataclass(frozen=True)
class Conflict:
    """Observables that no parameter set makes plausible together (one key: unreachable on its own)."""

    keys: tuple[str, ...]
    best_max_implausibility: float
    sentence: str

    def to_dict(self) -> dict:
        return {"keys": list(self.keys), "best_max_implausibility": self.best_max_implausibility,
                "sentence": self.sentence}


@dataclass(frozen=True)
class Adequacy:
    """The adequacy verdict of one model version and the numbers behind it."""

    adequate: bool
    cutoff: float
    min_max_implausibility: float
    best_compromise: dict[str, float]
    n_scanned: int
    n_plausible: int
    plausible_fraction: float
    plausible_ranges: dict[str, tuple[float, float]]
    unreachable: tuple[Conflict, ...]
    conflicts: tuple[Conflict, ...]
    chi2: float
    n_observables: int
    n_parameters: int
    sentence: str
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def dof(self) -> int:
        return self.n_observables - self.n_parameters

    @property
    def chi2_per_dof(self) -> float | None:
        return self.chi2 / self.dof if self.dof > 0 else None

    def to_dict(self) -> dict:
        return {
            "adequate": self.adequate, "cutoff": self.cutoff, "min_max_implausibility": self.min_max_implausibility,
            "best_compromise": self.best_compromise, "n_scanned": self.n_scanned, "n_plausible": self.n_plausible,
            "plausible_fraction": self.plausible_fraction,
            "plausible_ranges": {k: list(v) for k, v in self.plausible_ranges.items()},
            "unreachable": [c.to_dict() for c in self.unreachable], "conflicts": [c.to_dict() for c in self.conflicts],
            "chi2": self.chi2, "n_observables": self.n_observables, "n_parameters": self.n_parameters,
            "dof": self.dof, "chi2_per_dof": self.chi2_per_dof, "sentence": self.sentence, "notes": list(self.notes),
        }


def _names_text(names: Sequence[str]) -> str:
    names = list(names)
    if len(names) > 4:
        return f"the {len(names)} parameters"
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def minimal_conflicts(plausible: np.ndarray, max_size: int) -> list[tuple[int, ...]]:
    """Minimal column subsets (size <= ``max_size``) with no row plausible in all of them.

    plausible : boolean (n_points, m).  A subset is minimal when none of its proper subsets conflicts.
    """
    P = np.asarray(plausible, bool)
    m = P.shape[1]
    found: list[tuple[int, ...]] = []
    for size in range(1, min(max_size, m) + 1):
        for S in combinations(range(m), size):
            if any(set(f) <= set(S) for f in found):
                continue
            if not np.any(np.all(P[:, S], axis=1)):
                found.append(S)
    return found


def judge_adequacy(surrogates: SurrogateSet, misfit: Misfit, scan: SurrogateScan, best: BestFit,
                   cutoff: float = 3.0, max_conflict_size: int = 3, max_confirmations: int = 40) -> Adequacy:
    """Search for non-implausible points; describe the plausible set or the conflicts."""
    space, obs = surrogates.space, misfit.observations
    names_text = _names_text(space.names)
    n_scanned = len(scan.U)
    u_mm, mm = minimize_max_implausibility(surrogates, misfit, scan)
    pts = scan.with_points(evaluate_points(np.vstack([u_mm, best.u]), surrogates, misfit))
    plausible_rows = pts.max_implausibility <= cutoff
    adequate = bool(np.any(plausible_rows))
    mm = float(min(mm, pts.max_implausibility.min()))
    u_best_comp = pts.U[int(np.argmin(pts.max_implausibility))]
    compromise = space.as_dict(space.from_unit(u_best_comp))
    m, k = len(obs), space.dim
    notes: list[str] = []
    ranges: dict[str, tuple[float, float]] = {}
    unreachable: list[Conflict] = []
    conflicts: list[Conflict] = []
    if adequate:
        X = space.from_unit(pts.U[plausible_rows])
        ranges = {n: (float(X[:, j].min()), float(X[:, j].max())) for j, n in enumerate(space.names)}
        n_pl = int(np.sum(plausible_rows[:n_scanned]))
        frac = n_pl / n_scanned
        span = "; ".join(f"{n} {lo:.3g}-{hi:.3g}" for n, (lo, hi) in ranges.items())
        sentence = (f"The model is adequate: {frac:.1%} of the parameter box reproduces every measurement within "
                    f"implausibility {cutoff:g} (smallest maximum implausibility {mm:.2f}); plausible ranges: {span}.")
    else:
        n_pl, frac = 0, 0.0
        absz = np.abs(pts.z)
        confirmed: dict[tuple[int, ...], float] = {}  # subset -> its minimised max implausibility
        confirmations = 0
        while True:
            subsets = minimal_conflicts(absz <= cutoff, max_conflict_size)
            unconfirmed = [S for S in subsets if S not in confirmed]
            if not unconfirmed or confirmations >= max_confirmations:
                break
            S = unconfirmed[0]
            confirmations += 1
            u, val = minimize_max_implausibility(surrogates, misfit, pts, columns=np.array(S))
            if val <= cutoff:  # the scan missed a point: add it and look again
                p = evaluate_points(u[None], surrogates, misfit)
                pts = pts.with_points(p)
                absz = np.abs(pts.z)
            else:
                confirmed[S] = val
        for S in minimal_conflicts(absz <= cutoff, max_conflict_size):
            val = confirmed.get(S, float(np.min(np.max(absz[:, S], axis=1))))
            labels = [obs[i].name for i in S]
            keys = tuple(obs[i].key for i in S)
            if len(S) == 1:
                unreachable.append(Conflict(keys, val, (
                    f"No setting of {names_text} brings the {labels[0]} within implausibility {cutoff:g} "
                    f"(closest: {val:.1f}): the model cannot reach it at all.")))
            else:
                both = "both " if len(S) == 2 else "all of "
                joined = " and ".join(labels) if len(S) == 2 else ", ".join(labels[:-1]) + " and " + labels[-1]
                conflicts.append(Conflict(keys, val, (
                    f"No setting of {names_text} gives {both}the {joined} (best compromise: implausibility "
                    f"{val:.1f} > {cutoff:g}).")))
        unreachable.sort(key=lambda c: -c.best_max_implausibility)
        conflicts.sort(key=lambda c: -c.best_max_implausibility)
        if not unreachable and not conflicts:
            notes.append(f"No conflict among {max_conflict_size} or fewer observables: the conflict involves more "
                         "observables jointly.")
        dof = m - k
        chi_text = f"chi2/dof {best.chi2 / dof:.2f} ({dof} dof)" if dof > 0 else f"chi2 {best.chi2:.1f} (m <= k)"
        named = [c.sentence for c in (unreachable + conflicts)[:3]]
        sentence = (f"This model cannot reproduce these measurements: no parameter set keeps every observable within "
                    f"implausibility {cutoff:g} (smallest maximum {mm:.2f}); best joint misfit {chi_text}. "
                    + " ".join(named))
    return Adequacy(adequate, float(cutoff), mm, compromise, n_scanned, n_pl, float(frac), ranges,
                    tuple(unreachable), tuple(conflicts), float(best.chi2), m, k, sentence, tuple(notes))

