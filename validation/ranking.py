"""Stage 5: rank the candidate effects by evidence, with each effect's signature and a sentence.

Ranking criterion: the Bayes factor of the augmented model against the current one,
``ln B = ln Z_{current+effect} - ln Z_current`` (:mod:`validation.evidence`: why a Bayes factor
rather than BIC/AIC).  The candidates are listed by ln Z, best first.

Signature of an effect: at the current model's best fit, the augmented surrogate's change of each
observable when the effect's parameters move from "off" (their reference values) to mid range
and to full strength (the bound farthest from the reference), in units of the observable's
sigma (``sqrt(SE^2 + s_DEM^2/n + Var_disc)``).  Set next to the current residuals
``z = (measured - simulated) / sigma``, a signature of the same sign and size explains them;
``alignment`` is the cosine between the full-strength signature and the residual vector
(+1: the effect points exactly where the data are).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .effects import CandidateEffect
from .evidence import bayes_factor_words
from .study import ModelStudy

__all__ = ["Signature", "CandidateResult", "effect_signature", "candidate_sentence", "rank_candidates"]


@dataclass(frozen=True)
class Signature:
    """Shifts of every observable (units of sigma) with the effect at mid range and at full strength."""

    keys: tuple[str, ...]
    mid: np.ndarray
    full: np.ndarray
    alignment: float

    def to_dict(self) -> dict:
        return {"keys": list(self.keys), "mid_sigma": self.mid.tolist(), "full_sigma": self.full.tolist(),
                "alignment": self.alignment}


def effect_signature(current: ModelStudy, augmented: ModelStudy, effect: CandidateEffect,
                     residual_z: np.ndarray) -> Signature:
    """Signature of ``effect`` at ``current``'s best fit, predicted by ``augmented``'s surrogates."""
    space = augmented.version.space
    base_values = current.best_parameters
    rows = []
    for level in (0.0, 0.5, 1.0):
        vals = dict(base_values)
        for p in effect.parameters:
            vals[p.name] = p.reference + level * (p.far_bound - p.reference)
        missing = [n for n in space.names if n not in vals]
        if missing:
            raise ValueError(f"signature of {effect.name!r}: no value for {missing}")
        rows.append([vals[n] for n in space.names])
    mu, _ = augmented.surrogates.predict(np.array(rows))
    sigma = current.misfit.fixed_sd
    mid, full = (mu[1] - mu[0]) / sigma, (mu[2] - mu[0]) / sigma
    r = np.asarray(residual_z, float)
    den = float(np.linalg.norm(full) * np.linalg.norm(r))
    alignment = float(np.dot(full, r) / den) if den > 0 else 0.0
    return Signature(current.misfit.observations.keys, mid, full, alignment)


@dataclass(frozen=True)
class CandidateResult:
    """One candidate effect added to the current model: best fit, evidence, signature, sentence."""

    effect: CandidateEffect
    study: ModelStudy
    log_bayes: float
    signature: Signature
    sentence: str
    rank: int = 0

    @property
    def name(self) -> str:
        return self.effect.name

    @property
    def z(self) -> np.ndarray:
        """Residuals at the best fit from the DEM confirmation (surrogate where a run failed)."""
        zc = self.study.confirmation.z
        return np.where(np.isfinite(zc), zc, self.study.best.z)

    @property
    def dem_chi2(self) -> float:
        """chi^2 = sum z^2 of :attr:`z` over the observables with a finite z."""
        z = self.z
        return float(np.sum(z[np.isfinite(z)] ** 2))

    @property
    def log_evidence(self) -> float:
        return self.study.evidence.log_evidence

    def to_dict(self) -> dict:
        ic = self.study.information_criteria()
        return {
            "rank": self.rank, "effect": self.effect.to_dict(), "log_evidence": self.log_evidence,
            "log_evidence_se": self.study.evidence.standard_error, "log_bayes_vs_current": self.log_bayes,
            "bayes_factor_reading": bayes_factor_words(self.log_bayes), "bic": ic["bic"], "aic": ic["aic"],
            "best_fit": self.study.best_parameters, "chi2_surrogate": self.study.best.chi2,
            "z_surrogate": self.study.best.z.tolist(), "z_dem": self.study.confirmation.z.tolist(),
            "max_abs_z": float(np.nanmax(np.abs(self.z))), "adequate": self.study.adequacy.adequate,
            "min_max_implausibility": self.study.adequacy.min_max_implausibility,
            "signature": self.signature.to_dict(), "sentence": self.sentence,
        }


def _join(items: Sequence[str]) -> str:
    items = list(items)
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def candidate_sentence(effect: CandidateEffect, labels: Sequence[str], z_before: np.ndarray, z_after: np.ndarray,
                       log_bayes: float, within: float = 2.0, current_name: str = "base model") -> str:
    """One plain sentence: which observables the effect brings within ``within`` sigma, which it leaves off."""
    zb, za = np.abs(np.asarray(z_before, float)), np.abs(np.asarray(z_after, float))
    m = len(labels)
    params = ", ".join(effect.parameter_names)
    head = f"Adding {effect.words} ({params})"
    evidence = f"ln B = {log_bayes:+.1f} against the {current_name} ({bayes_factor_words(log_bayes)})"
    off = [i for i in range(m) if not za[i] <= within]
    if not off:
        return f"{head} brings all {m} observables within {within:g} sigma (largest |z| {np.nanmax(za):.1f}); {evidence}."
    fixed = [labels[i] for i in range(m) if za[i] <= within and not zb[i] <= within]
    off_sorted = sorted(off, key=lambda i: -np.nan_to_num(za[i], nan=math.inf))
    left = _join([f"the {labels[i]} {za[i]:.1f} sigma off" if np.isfinite(za[i]) else f"the {labels[i]} (run failed)"
                  for i in off_sorted[:3]])
    more = f" (and {len(off) - 3} more)" if len(off) > 3 else ""
    if fixed:
        return f"{head} brings the {_join(fixed)} within {within:g} sigma but leaves {left}{more}; {evidence}."
    return f"{head} brings no further observable within {within:g} sigma and leaves {left}{more}; {evidence}."


def rank_candidates(results: Sequence[CandidateResult]) -> tuple[CandidateResult, ...]:
    """Sort by ln Z (best first) and number the ranks."""
    ordered = sorted(results, key=lambda r: -r.log_evidence)
    return tuple(CandidateResult(r.effect, r.study, r.log_bayes, r.signature, r.sentence, i + 1)
                 for i, r in enumerate(ordered))
