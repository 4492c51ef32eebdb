"""Stage 6: when candidates fit about equally, which new measurement tells them apart?

For each tied candidate the forward model simulates every proposed condition on the candidate's
own design; one GP per condition gives the posterior predictive distribution of the outcome over
the candidate's posterior (importance samples of :mod:`validation.evidence`),

    mean_A(c) = E_post[mu_A(c; u)],   var_A(c) = Var_post[mu_A(c; u)] + E_post[s_A(c; u)^2],

and the separation of two candidates at condition c (design doc: Delta^2 over the predictive
variances of both plus the measurement variance) is

    S_AB(c) = |mean_A(c) - mean_B(c)| / sqrt(var_A(c) + var_B(c) + SE_c^2),

with SE_c the expected standard error of the new measurement (given by the proposal, else the
DEM fill-to-fill sd over sqrt(n_repeats)).  The recommended condition maximises the smallest
pairwise separation; if that is below ``separation_sigma`` (2) no proposal separates the
candidates and the diagnosis says so instead of guessing.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from itertools import combinations
from typing import Mapping, Sequence

import numpy as np

from calibration.designs import ParameterSpace

from .design import DesignData, design_replicates, pooled_noise_sd
from .forward import ForwardRunner, ProposedMeasurement
from .pooled import run_as_workers
from .study import ModelStudy
from .surrogates import fit_surrogates

__all__ = ["Forecast", "Discrimination", "discriminate"]


@dataclass(frozen=True)
class Forecast:
    """Predicted outcome of one proposed measurement under each tied candidate."""

    proposal: ProposedMeasurement
    means: dict[str, float]
    sds: dict[str, float]
    measurement_sd: float
    separation: float
    least_separated: tuple[str, str]

    def to_dict(self) -> dict:
        return {"proposal": self.proposal.to_dict(), "means": self.means, "predictive_sds": self.sds,
                "measurement_sd": self.measurement_sd, "separation_sigma": self.separation,
                "least_separated_pair": list(self.least_separated)}


@dataclass(frozen=True)
class Discrimination:
    """Forecasts for every proposal (best first), the recommendation (None: nothing separates) and a sentence."""

    candidates: tuple[str, ...]
    forecasts: tuple[Forecast, ...]
    recommended: str | None
    threshold: float
    sentence: str

    def to_dict(self) -> dict:
        return {"candidates": list(self.candidates), "forecasts": [f.to_dict() for f in self.forecasts],
                "recommended": self.recommended, "threshold_sigma": self.threshold, "sentence": self.sentence}


def _predictive(study: ModelStudy, keys: Sequence[str], runner: ForwardRunner, replicates: int,
                n_posterior: int, seed: int, replicated_fraction: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Posterior predictive mean, sd (per key) and DEM noise sd at the proposed conditions (the
    study's design sets, ``replicates`` fills on the ``replicated_fraction`` of them)."""
    version = study.version
    counts = design_replicates(len(study.design.X), replicates, replicated_fraction)
    Y = runner(version.effect_names, version.parameter_sets(study.design.X), counts, tuple(keys))
    design = DesignData(study.design.X, Y, tuple(keys))
    noise, _ = pooled_noise_sd(Y, keys)
    space: ParameterSpace = version.space
    sur = fit_surrogates(space, design, noise, restarts=1, folds=3, seed=seed)
    U = study.evidence.posterior_sample(n_posterior, seed)
    mu, sd = sur.predict_unit(U)
    return mu.mean(axis=0), np.sqrt(mu.var(axis=0) + np.mean(sd ** 2, axis=0)), noise


def discriminate(studies: Mapping[str, ModelStudy], labels: Mapping[str, str],
                 proposals: Sequence[ProposedMeasurement], runner: ForwardRunner, replicates: int = 2,
                 threshold: float = 2.0, n_posterior: int = 2000, seed: int = 0,
                 replicated_fraction: float = 1.0) -> Discrimination:
    """Forecast every proposal under every tied candidate; name the one that separates them best.

    studies : candidate name -> its study (at least two).
    labels : candidate name -> words for sentences.
    replicates, replicated_fraction : fills per design set at the proposed conditions, as in the
        designs (:func:`validation.design.design_replicates`).
    """
    names = tuple(studies)
    if len(names) < 2:
        raise ValueError(f"discrimination needs at least two candidates, got {list(names)}")
    words = " and ".join(labels.get(n, n) for n in names) if len(names) == 2 else ", ".join(labels.get(n, n) for n in names)
    if not proposals:
        return Discrimination(names, (), None, float(threshold),
                              f"The data cannot separate {words}, and the forward model offers no further condition "
                              "to measure; both remain possible.")
    keys = [p.key for p in proposals]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise ValueError(f"proposed measurement keys must be unique; duplicated: {dup}")
    # one task per candidate: with a pooled forward model (validation.pooled) their runs at the
    # proposed conditions go into one launch per experiment instead of one per candidate
    tasks = [functools.partial(_predictive, studies[n], keys, runner, replicates, n_posterior, seed, replicated_fraction)
             for n in names]
    pred = dict(zip(names, run_as_workers(getattr(runner, "model", None), tasks)))
    forecasts = []
    for c, p in enumerate(proposals):
        if p.expected_standard_error is not None:
            se = float(p.expected_standard_error)
        else:
            se = float(np.mean([pred[n][2][c] for n in names]) / np.sqrt(p.n_repeats))
        worst, pair = np.inf, (names[0], names[1])
        for a, b in combinations(names, 2):
            s = abs(pred[a][0][c] - pred[b][0][c]) / np.sqrt(pred[a][1][c] ** 2 + pred[b][1][c] ** 2 + se ** 2)
            if s < worst:
                worst, pair = float(s), (a, b)
        forecasts.append(Forecast(p, {n: float(pred[n][0][c]) for n in names}, {n: float(pred[n][1][c]) for n in names},
                                  se, worst, pair))
    forecasts.sort(key=lambda f: -f.separation)
    top = forecasts[0]
    if top.separation >= threshold:
        p = top.proposal
        preds = "; ".join(f"{labels.get(n, n)} predicts {top.means[n]:.3g} ± {top.sds[n]:.2g} {p.unit}" for n in names)
        sentence = (f"{words[0].upper() + words[1:]} fit the present data about equally; measure the {p.name} "
                    f"({p.n_repeats} repeats, expected SE {top.measurement_sd:.2g} {p.unit}) to tell them apart: {preds} "
                    f"(separation {top.separation:.1f} sigma).")
        return Discrimination(names, tuple(forecasts), p.key, float(threshold), sentence)
    sentence = (f"The data cannot separate {words}, and none of the {len(proposals)} proposed measurements would "
                f"(largest separation {top.separation:.1f} sigma at the {top.proposal.name}, below {threshold:g}); "
                "both remain possible.")
    return Discrimination(names, tuple(forecasts), None, float(threshold), sentence)
