"""Stage 6: when candidates fit about equally, which new measurement tells them apart?

For each tied candidate the forward model simulates every proposed condition on the candidate's
own design; one GP per condition gives the posterior predictive distribution of the outcome over
the candidate's posterior (importance samples of :mod:`validation.evidence`),

    mean_A(c) = E_post[mu_A(c; u)],   var_A(c) = Var_post[mu_A(c; u)] + E_post[s_A(c; u)^2],

and the separation of two candidates at condition c (design doc: Delta^2 over the predictive
variances of both plus the measurement variance) is

    S_AB(c) = |mean_A(c) - mean_B(c)| / sqrt(var_A(c) + var_B(c) + SE_c^2),

with SE_c the expected standard error of the new measurement (given by the proposal, else the
DEM fill-to-fill sd over sqrt(n_repeats)); a proposal's separation is its smallest pairwise one.

Ranking (:func:`rank_forecasts`): the proposals whose separation reaches ``separation_sigma`` (2)
come first, by separation per lab hour (the proposal's ``lab_hours``, :mod:`validation.proposals`:
the cheapest sigma first), then the others by separation. The first of them is recommended when it
separates; if none does, the diagnosis says plainly that the effects are indistinguishable with
these experiments and what each candidate predicts at the closest proposals, instead of guessing.
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

__all__ = ["Forecast", "Discrimination", "discriminate", "rank_forecasts"]

#: proposals whose predictions the "indistinguishable" sentence lists
PREDICTIONS_LISTED = 3


@dataclass(frozen=True)
class Forecast:
    """Predicted outcome of one proposed measurement under each tied candidate."""

    proposal: ProposedMeasurement
    means: dict[str, float]
    sds: dict[str, float]
    measurement_sd: float
    separation: float
    least_separated: tuple[str, str]

    @property
    def lab_hours(self) -> float | None:
        """Lab effort [h] of the proposed measurement (None: not known)."""
        return self.proposal.lab_hours

    @property
    def separation_per_lab_hour(self) -> float:
        """Separation [sigma] per lab hour; a proposal of unknown effort counts as one hour."""
        return self.separation / (self.lab_hours if self.lab_hours is not None else 1.0)

    def predictions(self, labels: Mapping[str, str], names: Sequence[str]) -> str:
        """``"A predicts 41.2 ± 0.8 deg; B predicts 43.0 ± 0.9 deg"``."""
        return "; ".join(f"{labels.get(n, n)} predicts {self.means[n]:.3g} ± {self.sds[n]:.2g} {self.proposal.unit}"
                         for n in names)

    def to_dict(self) -> dict:
        return {"proposal": self.proposal.to_dict(), "means": self.means, "predictive_sds": self.sds,
                "measurement_sd": self.measurement_sd, "separation_sigma": self.separation,
                "least_separated_pair": list(self.least_separated), "lab_hours": self.lab_hours,
                "separation_sigma_per_lab_hour": None if self.lab_hours is None else self.separation_per_lab_hour}


@dataclass(frozen=True)
class Discrimination:
    """Forecasts for every proposal (ranked, :func:`rank_forecasts`: the recommended one first), the
    recommendation (None: nothing separates), a sentence, and the conditions the proposal search
    left out (one line each: where, its lab effort, why)."""

    candidates: tuple[str, ...]
    forecasts: tuple[Forecast, ...]
    recommended: str | None
    threshold: float
    sentence: str
    not_forecast: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {"candidates": list(self.candidates), "forecasts": [f.to_dict() for f in self.forecasts],
                "recommended": self.recommended, "threshold_sigma": self.threshold, "sentence": self.sentence,
                "ranked_by": "separation per lab hour among those reaching the threshold, then separation",
                "separating": sum(f.separation >= self.threshold for f in self.forecasts),
                "not_forecast": list(self.not_forecast)}


def rank_forecasts(forecasts: Sequence[Forecast], threshold: float) -> list[Forecast]:
    """Those reaching ``threshold`` [sigma] by separation per lab hour (then by separation), then the
    rest by separation: the first is the measurement to recommend when it separates."""
    good = [f for f in forecasts if f.separation >= threshold]
    rest = [f for f in forecasts if not f.separation >= threshold]
    good.sort(key=lambda f: (-f.separation_per_lab_hour, -f.separation, f.proposal.key))
    rest.sort(key=lambda f: (-np.nan_to_num(f.separation, nan=-np.inf), f.proposal.key))
    return good + rest


def _predictive(study: ModelStudy, keys: Sequence[str], runner: ForwardRunner, replicates: int,
                n_posterior: int, seed: int, replicated_fraction: float = 1.0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, str]]:
    """Posterior predictive mean, sd (per key) and DEM noise sd at the proposed conditions (the
    study's design sets, ``replicates`` fills on the ``replicated_fraction`` of them), and why a key
    could not be forecast (NaN in the arrays): too few DEM runs measured it."""
    version = study.version
    counts = design_replicates(len(study.design.X), replicates, replicated_fraction)
    Y = runner(version.effect_names, version.parameter_sets(study.design.X), counts, tuple(keys))
    ok = np.isfinite(Y)
    failed: dict[str, str] = {}
    for j, key in enumerate(keys):
        measured_sets = int(np.sum(ok[:, :, j].any(axis=1)))
        if not np.any(ok[:, :, j].sum(axis=1) >= 2):
            failed[key] = "no design set has two runs that measured it, so its DEM noise is unknown"
        elif measured_sets < 3:
            failed[key] = f"only {measured_sets} design set(s) measured it (a forecast needs 3)"
    use = [j for j, k in enumerate(keys) if k not in failed]
    mean, sd_out, noise_out = (np.full(len(keys), np.nan) for _ in range(3))
    if use:
        fit_keys = tuple(keys[j] for j in use)
        design = DesignData(study.design.X, Y[:, :, use], fit_keys)
        noise, _ = pooled_noise_sd(design.Y, fit_keys)
        space: ParameterSpace = version.space
        sur = fit_surrogates(space, design, noise, restarts=1, folds=3, seed=seed)
        U = study.evidence.posterior_sample(n_posterior, seed)
        mu, sd = sur.predict_unit(U)
        mean[use], sd_out[use], noise_out[use] = mu.mean(axis=0), np.sqrt(mu.var(axis=0) + np.mean(sd ** 2, axis=0)), noise
    return mean, sd_out, noise_out, failed


def _left_out(not_forecast: Sequence[str]) -> str:
    if not not_forecast:
        return ""
    n = len(not_forecast)
    return (f" {n} more proposal{'s were' if n > 1 else ' was'} not forecast (beyond "
            "max_proposed_conditions, not simulable, or too few DEM runs measured it; diagnosis.json lists "
            "them under not_forecast).")


def discriminate(studies: Mapping[str, ModelStudy], labels: Mapping[str, str],
                 proposals: Sequence[ProposedMeasurement], runner: ForwardRunner, replicates: int = 2,
                 threshold: float = 2.0, n_posterior: int = 2000, seed: int = 0,
                 replicated_fraction: float = 1.0, not_forecast: Sequence[str] | None = None) -> Discrimination:
    """Forecast every proposal under every tied candidate; recommend the cheapest that separates them.

    studies : candidate name -> its study (at least two).
    labels : candidate name -> words for sentences.
    replicates, replicated_fraction : fills per design set at the proposed conditions, as in the
        designs (:func:`validation.design.design_replicates`).
    threshold : separation [sigma] a proposal must reach to be recommended.
    not_forecast : conditions the proposal search left out, one line each; None: the forward
        model's ``proposals_not_forecast`` (none when it has no such attribute).
    """
    names = tuple(studies)
    if len(names) < 2:
        raise ValueError(f"discrimination needs at least two candidates, got {list(names)}")
    if not_forecast is None:
        not_forecast = getattr(getattr(runner, "model", None), "proposals_not_forecast", None) or ()
    not_forecast = tuple(str(x) for x in not_forecast)
    words = " and ".join(labels.get(n, n) for n in names) if len(names) == 2 else ", ".join(labels.get(n, n) for n in names)
    remain = "both remain possible" if len(names) == 2 else "all remain possible"
    if not proposals:
        return Discrimination(names, (), None, float(threshold),
                              f"The data cannot separate {words}, and the forward model offers no further condition "
                              f"to measure; {remain}.{_left_out(not_forecast)}", not_forecast)
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
    unforecast = []
    for c, p in enumerate(proposals):
        why = [f"under {labels.get(n, n)} {pred[n][3][p.key]}" for n in names if p.key in pred[n][3]]
        if why:
            unforecast.append(f"{p.name}: no forecast, {'; '.join(why)}")
            continue
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
    not_forecast = (*unforecast, *not_forecast)
    if not forecasts:
        return Discrimination(names, (), None, float(threshold),
                              f"The data cannot separate {words}, and none of the {len(proposals)} proposed "
                              f"measurements could be forecast (too few DEM runs measured them); {remain}."
                              f"{_left_out(not_forecast)}", not_forecast)
    forecasts = rank_forecasts(forecasts, threshold)
    top = forecasts[0]
    if top.separation >= threshold:
        p = top.proposal
        hours = f", about {p.lab_hours:.2g} lab hours" if p.lab_hours is not None else ""
        sentence = (f"{words[0].upper() + words[1:]} fit the present data about equally; measure the {p.name} "
                    f"({p.n_repeats} repeats{hours}, expected SE {top.measurement_sd:.2g} {p.unit}) to tell them "
                    f"apart: {top.predictions(labels, names)} (separation {top.separation:.1f} sigma).")
        separating = [f for f in forecasts if f.separation >= threshold]
        if len(separating) > 1 and p.lab_hours is not None:
            widest = max(separating, key=lambda f: f.separation)
            sentence += (f" Of the {len(separating)} proposed measurements that would separate them it gives the "
                         "most separation per lab hour")
            if widest is not top and widest.lab_hours is not None:
                sentence += (f"; the {widest.proposal.name} separates them more ({widest.separation:.1f} sigma) "
                             f"for about {widest.lab_hours:.2g} lab hours")
            sentence += "."
        return Discrimination(names, tuple(forecasts), p.key, float(threshold), sentence, not_forecast)
    listed = "; ".join(f"at the {f.proposal.name}, {f.predictions(labels, names)} ({f.separation:.1f} sigma apart)"
                       for f in forecasts[:PREDICTIONS_LISTED])
    sentence = (f"The data cannot separate {words}, and none of the {len(forecasts)} proposed measurements forecast would "
                f"(largest separation {top.separation:.1f} sigma at the {top.proposal.name}, below {threshold:g}): "
                f"these effects are indistinguishable with these experiments. What each predicts: {listed}. "
                f"{remain[0].upper() + remain[1:]}.{_left_out(not_forecast)}")
    return Discrimination(names, tuple(forecasts), None, float(threshold), sentence, not_forecast)
