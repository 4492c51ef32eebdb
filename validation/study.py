"""Everything learned about one model version: design, noise, surrogates, best fit, adequacy,
evidence and a DEM confirmation at the best fit (stages 1-4 for one version).

The DEM noise is measured on the base model's design and then used by every model version
(``noise=`` of :func:`study_model`): one variance model for all versions is what makes their
likelihoods, evidences and error histories comparable -- separate estimates from a few replicates
each differ by 20-30 % by chance, and a badly wrong model's likelihood follows that, not the
physics.  A version's own replicates are used only for observables whose base-model replicates
never varied (e.g. a pile angle where the base model forms no pile).

The confirmation runs the forward model at the surrogate's best fit with ``confirm_replicates``
fresh fills; its residuals use the mean of those runs in place of the surrogate
(``Var_sim = s_DEM^2 / R``, :mod:`validation.misfit`), so every number reported as "after
adding the effect" is a simulation, not a surrogate prediction.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .adequacy import Adequacy, judge_adequacy
from .design import DesignData, evaluate_sets, pooled_noise_sd, run_design
from .effects import ModelVersion
from .evidence import Evidence, estimate_log_evidence, information_criteria
from .forward import ForwardRunner
from .misfit import Misfit
from .observables import Observations
from .search import BestFit, SurrogateScan, find_best_fit, scan_box
from .settings import DiagnosisSettings
from .surrogates import SurrogateSet, fit_surrogates

__all__ = ["Confirmation", "ModelStudy", "study_model", "refine_study", "confirm"]


@dataclass(frozen=True)
class Confirmation:
    """DEM runs at one parameter set: per observable mean, spread (sample sd), successful runs, z."""

    parameters: dict[str, float]
    replicates: int
    mean: np.ndarray
    spread: np.ndarray
    n_ok: np.ndarray
    z: np.ndarray

    def to_dict(self) -> dict:
        return {"parameters": self.parameters, "replicates": self.replicates, "mean": self.mean.tolist(),
                "spread": self.spread.tolist(), "n_ok": self.n_ok.tolist(), "z": self.z.tolist()}


def confirm(version: ModelVersion, x: np.ndarray, runner: ForwardRunner, misfit: Misfit, replicates: int) -> Confirmation:
    """Run ``replicates`` fills at physical point ``x`` and compare with the measurements."""
    keys = misfit.observations.keys
    params = version.space.as_dict(x)
    Y = runner(version.effect_names, [params], replicates, keys)[0]  # (R, m)
    n_ok = np.sum(np.isfinite(Y), axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(Y, axis=0)
        spread = np.nanstd(Y, axis=0, ddof=1) if replicates > 1 else np.zeros(len(keys))
    sim_sd = misfit.dem_noise_sd / np.sqrt(np.maximum(n_ok, 1))
    z = np.where(n_ok > 0, misfit.z(np.nan_to_num(mean), sim_sd), np.nan)
    return Confirmation(params, int(replicates), mean, spread, n_ok, z)


@dataclass
class ModelStudy:
    """Stages 1-4 for one model version (see module docstring)."""

    version: ModelVersion
    design: DesignData
    noise_sd: np.ndarray
    noise_dof: np.ndarray
    misfit: Misfit
    surrogates: SurrogateSet
    scan: SurrogateScan
    best: BestFit
    adequacy: Adequacy
    evidence: Evidence
    confirmation: Confirmation
    seconds: float
    waves: int = 1
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.version.name

    @property
    def best_parameters(self) -> dict[str, float]:
        return self.version.space.as_dict(self.best.x)

    def information_criteria(self) -> dict[str, float]:
        return information_criteria(self.best.chi2, len(self.misfit.observations), self.version.space.dim)

    def comparison_rows(self) -> list[dict[str, Any]]:
        """One row per observable: measured vs simulated (surrogate and DEM confirmation) with z."""
        obs, m = self.misfit.observations, self.misfit
        sigma = np.sqrt(m.variance(self.best.sd))
        rows = []
        for j, o in enumerate(obs):
            c = self.confirmation
            rows.append({
                "key": o.key, "label": o.name, "unit": o.unit, "censored": o.is_censored,
                "measured_mean": None if o.is_censored else o.mean,
                "detection_limit": o.detection_limit, "measured_se": o.standard_error, "n": o.n,
                "surrogate_mean": float(self.best.mu[j]), "surrogate_sd": float(self.best.sd[j]),
                "dem_noise_sd": float(self.noise_sd[j]), "sigma": float(sigma[j]), "z": float(self.best.z[j]),
                "dem_mean": float(c.mean[j]), "dem_spread": float(c.spread[j]), "dem_runs": int(c.n_ok[j]),
                "dem_z": float(c.z[j]),
            })
        return rows

    def to_dict(self) -> dict[str, Any]:
        space = self.version.space
        return {
            "name": self.name, "effects": list(self.version.effect_names),
            "parameters": [{"name": p.name, "unit": p.unit, "lower": p.lower, "upper": p.upper}
                           for p in space.parameters],
            "design": {"parameter_sets": self.design.X.tolist(), "responses": self.design.Y.tolist(),
                       "keys": list(self.design.keys), "waves": self.waves},
            "dem_noise_sd": self.noise_sd.tolist(), "dem_noise_dof": self.noise_dof.tolist(),
            "fixed_sd": self.misfit.fixed_sd.tolist(),
            "surrogate_quality": [q.to_dict() for q in self.surrogates.quality],
            "best_fit": {"parameters": self.best_parameters, "chi2": self.best.chi2,
                         "log_likelihood": self.best.log_likelihood, "z": self.best.z.tolist()},
            "comparison": self.comparison_rows(), "adequacy": self.adequacy.to_dict(),
            "evidence": self.evidence.to_dict(), "information_criteria": self.information_criteria(),
            "confirmation": self.confirmation.to_dict(), "seconds": self.seconds,
        }


def study_model(version: ModelVersion, observations: Observations, runner: ForwardRunner,
                settings: DiagnosisSettings, seed: int, design: DesignData | None = None, waves: int = 1,
                noise: tuple[np.ndarray, np.ndarray] | None = None) -> ModelStudy:
    """Design (unless given), noise, surrogates, scan, best fit, adequacy, evidence, confirmation.

    noise : (sd, dof) per observable to use instead of this design's own estimate (module
        docstring); observables with dof 0 there fall back to this design's estimate.
    """
    t0 = time.perf_counter()
    keys = observations.keys
    space = version.space
    if design is None:
        n = max(settings.min_design_points, settings.design_points_per_parameter * space.dim)
        design = run_design(version, runner, keys, n, settings.replicates, seed)
    noise_sd, noise_dof = pooled_noise_sd(design.Y, keys)
    if noise is not None:
        given_sd, given_dof = (np.asarray(a, float) for a in noise)
        use = given_dof > 0
        noise_sd, noise_dof = np.where(use, given_sd, noise_sd), np.where(use, given_dof, noise_dof)
    misfit = Misfit.build(observations, noise_sd, settings.model_discrepancy, noise_dof)
    surrogates = fit_surrogates(space, design, noise_sd, settings.gp_restarts, settings.cv_folds, seed)
    scan = scan_box(surrogates, misfit, settings.scan_points, seed)
    best = find_best_fit(surrogates, misfit, scan)
    adequacy = judge_adequacy(surrogates, misfit, scan, best, settings.cutoff, settings.max_conflict_size)

    def log_likelihood(U):
        return misfit.log_likelihood(*surrogates.predict_unit(U))

    evidence = estimate_log_evidence(log_likelihood, best.u, settings.evidence_samples, seed)
    confirmation = confirm(version, best.x, runner, misfit, settings.confirm_replicates)
    return ModelStudy(version, design, noise_sd, noise_dof, misfit, surrogates, scan, best, adequacy, evidence,
                      confirmation, time.perf_counter() - t0, waves)


def _maximin_subset(U: np.ndarray, n: int, first: np.ndarray) -> np.ndarray:
    """Greedy maximin choice of ``n`` rows of ``U``, starting from the point farthest from ``first``'s rows."""
    chosen: list[int] = []
    dmin = np.min(np.linalg.norm(U[:, None, :] - np.atleast_2d(first)[None], axis=2), axis=1)
    for _ in range(min(n, len(U))):
        i = int(np.argmax(dmin))
        chosen.append(i)
        dmin = np.minimum(dmin, np.linalg.norm(U - U[i], axis=1))
    return U[chosen]


def refine_study(study: ModelStudy, observations: Observations, runner: ForwardRunner,
                 settings: DiagnosisSettings, seed: int, noise: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> ModelStudy:
    """A second history-matching wave: ``refine_points`` new sets spread (maximin) over the
    non-implausible part of the scan (or the lowest-implausibility 2 % if it is empty), then the
    whole study is redone on the joined design."""
    if settings.refine_points == 0:
        return study
    mi = study.scan.max_implausibility
    pool = study.scan.U[mi <= settings.cutoff]
    if len(pool) < settings.refine_points:
        pool = study.scan.U[np.argsort(mi)[:max(settings.refine_points * 4, len(mi) // 50)]]
    U_new = _maximin_subset(pool, settings.refine_points, study.version.space.to_unit(study.design.X))
    new = evaluate_sets(study.version, runner, observations.keys, study.version.space.from_unit(U_new),
                        settings.replicates)
    refined = study_model(study.version, observations, runner, settings, seed, study.design.extended(new),
                          waves=study.waves + 1, noise=noise)
    refined.seconds += study.seconds
    return refined
