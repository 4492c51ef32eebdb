"""Everything learned about one model version: design, noise, surrogates, best fit, adequacy,
evidence and a DEM confirmation at the best fit (stages 1-4 for one version).

The DEM noise is measured on the base model's design and then used by every model version
(``noise=`` of :func:`study_model`): one variance model for all versions is what makes their
likelihoods, evidences and error histories comparable -- separate estimates from a few replicates
each differ by 20-30 % by chance, and a badly wrong model's likelihood follows that, not the
physics.  A version's own replicates are used for an observable whose base-model replicates
never varied (e.g. a pile angle where the base model forms no pile), and for one where they
reject the base's noise (:func:`version_noise`: a two-sided F test at level
:data:`NOISE_TEST_ALPHA`): cohesive gravel at k ~ 3e5 J/m^3 scatters 5-8 times as much from fill
to fill in the static angle as the frictional base model (5.7 against 0.70 deg, 5 and 5 degrees
of freedom, p ~ 3e-4), and holding it to the base's scatter puts its confirmations "beyond
2 sigma" for noise it really has.

The confirmation runs the forward model at the surrogate's best fit with ``confirm_replicates``
fresh fills; its residuals use the mean of those runs in place of the surrogate
(``Var_sim = s_DEM^2 / R``, :mod:`validation.misfit`), so every number reported as "after
adding the effect" is a simulation, not a surrogate prediction.

DEM scatter also varies within a version's box (cohesive gravel near its best fit scattered 5x the
pooled noise at 45 rpm): where the confirmation's own fills scatter beyond the pooled noise by the upper
tail of the same F test, ``confirm_extra_replicates`` more fills run there and the observables still
flagged are judged with that local spread (:func:`local_noise`; the verdict says so).

Every study also checks its surrogate against that confirmation (:func:`check_surrogate`), and
:func:`refine_study` adds history-matching waves while the two disagree: a surrogate that is
wrong near the optimum otherwise puts the "best fit" where the DEM is not best, and the misfit
left there reads as a failure of the model when it is one of the surrogate.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np
from scipy import stats

from .adequacy import Adequacy, judge_adequacy
from .design import DesignData, design_replicates, design_size, evaluate_sets, pooled_noise_sd, run_design
from .effects import ModelVersion
from .evidence import Evidence, estimate_log_evidence, information_criteria
from .forward import ForwardRunner
from .misfit import Misfit
from .observables import Observations
from .search import BestFit, SurrogateScan, find_best_fit, scan_box
from .settings import DiagnosisSettings
from .surrogates import SurrogateSet, fit_surrogates

# a refinement wave "stalls" when the largest DEM-vs-surrogate disagreement at the best fit fell by
# less than this fraction of the previous wave's (a judgement: 10 % is within the wave-to-wave
# scatter of a two-fill confirmation, so smaller gains do not justify another design wave)
STALL_FRACTION = 0.10

#: level of the two-sided F test by which a version's own replicates overrule the base model's noise
NOISE_TEST_ALPHA = 0.01

__all__ = ["Confirmation", "SurrogateCheck", "RefinementWave", "ModelStudy", "study_model", "refine_study",
           "confirm", "check_surrogate", "local_noise", "version_noise", "own_noise_sentence", "local_noise_sentence"]


@dataclass(frozen=True)
class Confirmation:
    """DEM runs at one parameter set: per observable mean, spread (sample sd), successful runs, z;
    ``x`` the set in physical units and ``runs`` (replicates, m) every fill's value (NaN = failed).

    noise_sd : the fill-to-fill sd the z-scores used per observable (the study's pooled noise, or
        the spread of these fills where :func:`local_noise` chose it); None: the study's.
    noise_source : ``"pooled"`` or ``"local"`` per observable (empty: all pooled).
    """

    parameters: dict[str, float]
    replicates: int
    mean: np.ndarray
    spread: np.ndarray
    n_ok: np.ndarray
    z: np.ndarray
    x: np.ndarray | None = None
    runs: np.ndarray | None = None
    noise_sd: np.ndarray | None = None
    noise_source: tuple[str, ...] = ()

    @property
    def local_noise(self) -> tuple[int, ...]:
        """Indices of the observables judged with these fills' own scatter."""
        return tuple(j for j, s in enumerate(self.noise_source) if s == "local")

    def as_design(self, keys: tuple[str, ...]) -> DesignData:
        """The confirmation runs as a one-set design (to join a refit: DEM results are never thrown away)."""
        if self.x is None or self.runs is None:
            raise ValueError("this confirmation kept no runs to join a design")
        return DesignData(np.asarray(self.x, float)[None], np.asarray(self.runs, float)[None], keys)

    def to_dict(self) -> dict:
        return {"parameters": self.parameters, "replicates": self.replicates, "mean": self.mean.tolist(),
                "spread": self.spread.tolist(), "n_ok": self.n_ok.tolist(), "z": self.z.tolist(),
                "runs": None if self.runs is None else self.runs.tolist(),
                "noise_sd": None if self.noise_sd is None else self.noise_sd.tolist(),
                "noise_source": list(self.noise_source)}


def _mean_spread(Y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column of ``Y`` (runs, m): successful runs, mean and sample sd (0 with fewer than 2)."""
    n_ok = np.sum(np.isfinite(Y), axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(Y, axis=0)
        spread = np.where(n_ok > 1, np.nanstd(Y, axis=0, ddof=1), 0.0)
    return n_ok, mean, spread


def local_noise(spread: np.ndarray, n_ok: np.ndarray, noise_sd: np.ndarray, noise_dof: np.ndarray,
                alpha: float = NOISE_TEST_ALPHA) -> np.ndarray:
    """Per observable, True where the fills at one parameter set scatter MORE than the pooled noise
    they are judged with: the upper tail of the same variance-ratio test as :func:`version_noise`
    (F = spread^2 / noise^2 beyond the 1 - alpha/2 quantile of F(n_ok - 1, noise dof)), or the
    pooled noise is 0 with no degrees of freedom (it never varied) while these fills did.

    DEM scatter is heteroscedastic: cohesive gravel at 45 rpm gave 43.3 and 52.8 deg at one best fit
    while the pooled noise was 1.2 deg (F = 33 on 1 and 5 dof, p ~ 0.002). Judging that point's mean
    with the pooled noise overstates how well two fills pin it down. Only the upper tail counts: a
    point whose few fills happen to agree closely keeps the pooled (larger) noise."""
    spread, n_ok, noise_sd, noise_dof = (np.asarray(a, float) for a in (spread, n_ok, noise_sd, noise_dof))
    dof = n_ok - 1
    pooled_dof = np.minimum(np.where(np.isfinite(noise_dof), noise_dof, 1e9), 1e9)
    testable = (dof > 0) & (pooled_dof > 0) & (noise_sd > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(testable, spread ** 2 / np.where(noise_sd > 0, noise_sd, 1.0) ** 2, 0.0)
    hi = stats.f.isf(alpha / 2, np.maximum(dof, 1), np.maximum(pooled_dof, 1))
    never_varied = (pooled_dof <= 0) & (noise_sd <= 0) & (dof > 0) & (spread > 0)
    return (testable & (ratio > hi)) | never_varied


def confirm(version: ModelVersion, x: np.ndarray, runner: ForwardRunner, misfit: Misfit, replicates: int,
            extra_replicates: int = 0) -> Confirmation:
    """Run ``replicates`` fills at physical point ``x`` and compare with the measurements.

    Where those fills scatter more than the pooled noise (:func:`local_noise`), ``extra_replicates``
    more fills run at the same point (one call for ``replicates + extra_replicates`` fills whose last
    ``extra_replicates`` are kept: a model that replays fills by index, as the DEM's cache does,
    serves the first ones again; one that draws fresh fills draws them), the test is repeated on
    all of them, and the observables it still flags are judged with the spread of these fills
    (``sim_sd = spread / sqrt(n)``) instead of the pooled noise."""
    keys = misfit.observations.keys
    params = version.space.as_dict(x)
    Y = runner(version.effect_names, [params], replicates, keys)[0]  # (R, m)
    n_ok, mean, spread = _mean_spread(Y)
    local = local_noise(spread, n_ok, misfit.dem_noise_sd, misfit.dem_noise_dof)
    if extra_replicates > 0 and np.any(local):
        more = runner(version.effect_names, [params], replicates + extra_replicates, keys)[0]
        Y = np.concatenate([Y, more[replicates:]], axis=0)
        n_ok, mean, spread = _mean_spread(Y)
        local = local_noise(spread, n_ok, misfit.dem_noise_sd, misfit.dem_noise_dof)
    noise_sd = np.where(local, spread, misfit.dem_noise_sd)
    sim_sd = noise_sd / np.sqrt(np.maximum(n_ok, 1))
    z = np.where(n_ok > 0, misfit.z(np.nan_to_num(mean), sim_sd), np.nan)
    return Confirmation(params, int(len(Y)), mean, spread, n_ok, z, np.array(x, float), np.array(Y, float),
                        noise_sd, tuple("local" if b else "pooled" for b in local))


@dataclass(frozen=True)
class SurrogateCheck:
    """The surrogate's prediction at the best fit against the DEM confirmation there, per observable.

    disagreement : ``|DEM mean - surrogate mean| / sqrt(sd_surrogate^2 + s_DEM^2 / n_runs)`` (censored
        observables: both values raised to the detection limit first, where every value below it is
        the same "no pile"); NaN where every confirmation run failed.
    z_surrogate, z_dem : residuals against the measurements from the surrogate and from the DEM.
    disagreeing : keys where the DEM contradicts the surrogate: a disagreement beyond ``cutoff``
        (3: as unlikely as an implausible point; 2 would flag one of 7 honest observables in about
        a quarter of the checks), or the DEM beyond ``within_sigma`` where the surrogate said within,
        by more than ``within_sigma`` combined sd (the verdict would rest on a wrong prediction).
    """

    keys: tuple[str, ...]
    disagreement: np.ndarray
    z_surrogate: np.ndarray
    z_dem: np.ndarray
    disagreeing: tuple[str, ...]
    within_sigma: float

    @property
    def agrees(self) -> bool:
        return not self.disagreeing

    @property
    def max_disagreement(self) -> float:
        d = self.disagreement[np.isfinite(self.disagreement)]
        return float(np.max(d)) if d.size else float("nan")

    @property
    def max_abs_z_dem(self) -> float:
        z = self.z_dem[np.isfinite(self.z_dem)]
        return float(np.max(np.abs(z))) if z.size else float("nan")

    @property
    def dem_within(self) -> bool:
        """Every observable within ``within_sigma`` by the DEM (then a better surrogate changes nothing)."""
        return bool(np.all(np.abs(self.z_dem) <= self.within_sigma))

    def to_dict(self) -> dict[str, Any]:
        return {"agrees": self.agrees, "disagreeing": list(self.disagreeing),
                "max_disagreement": self.max_disagreement, "max_abs_z_dem": self.max_abs_z_dem,
                "dem_within": self.dem_within, "disagreement": self.disagreement.tolist(),
                "z_surrogate": self.z_surrogate.tolist(), "z_dem": self.z_dem.tolist()}


def check_surrogate(misfit: Misfit, best: BestFit, confirmation: Confirmation,
                    settings: DiagnosisSettings) -> SurrogateCheck:
    """Compare the surrogate at ``best`` with the DEM ``confirmation`` there (:class:`SurrogateCheck`)."""
    obs = misfit.observations
    limit = np.where(obs.censored, obs.means, -np.inf)
    sur, dem = np.maximum(best.mu, limit), np.maximum(confirmation.mean, limit)
    n = np.maximum(confirmation.n_ok, 1)
    noise = misfit.dem_noise_sd if confirmation.noise_sd is None else confirmation.noise_sd
    sd = np.sqrt(best.sd ** 2 + noise ** 2 / n)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(confirmation.n_ok > 0, np.abs(dem - sur) / sd, np.nan)
        d = np.where((sd == 0) & (dem == sur), 0.0, d)
    w = settings.within_sigma
    flipped = (np.abs(confirmation.z) > w) & (np.abs(best.z) <= w) & (d > w)
    bad = (d > settings.cutoff) | flipped
    keys = obs.keys
    return SurrogateCheck(tuple(keys), d, np.array(best.z, float), np.array(confirmation.z, float),
                          tuple(k for k, b in zip(keys, bad) if b), float(w))


@dataclass(frozen=True)
class RefinementWave:
    """One history-matching wave: what joined the design, and the refit's check at its best fit.

    wave : the study's wave number after it (the first design is wave 1).
    new_sets : maximin sets placed in the non-implausible region.
    confirmation_sets : earlier DEM confirmations (runs at earlier best fits) that joined the design.
    design_sets : parameter sets in the design after the wave.
    stalled : its largest disagreement fell by less than ``STALL_FRACTION`` of the previous wave's
        (no further wave was run).
    kept : this wave's study is the one returned (see :func:`refine_study`).
    """

    wave: int
    new_sets: int
    confirmation_sets: int
    design_sets: int
    best_parameters: dict[str, float]
    check: SurrogateCheck
    stalled: bool = False
    kept: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {"wave": self.wave, "new_sets": self.new_sets, "confirmation_sets": self.confirmation_sets,
                "design_sets": self.design_sets, "best_parameters": self.best_parameters,
                "stalled": self.stalled, "kept": self.kept, "agrees": self.check.agrees, "disagreeing": list(self.check.disagreeing),
                "max_disagreement": self.check.max_disagreement, "max_abs_z_dem": self.check.max_abs_z_dem}


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
    confirmation: Confirmation | None  # None until :func:`confirm_study` ran (``study_model(confirm_now=False)``)
    seconds: float
    waves: int = 1
    check: SurrogateCheck | None = None
    refinement: tuple[RefinementWave, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)
    noise_source: tuple[str, ...] = ()  # per observable: "base" (the base model's noise) or "own" (version_noise)

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
        c = self.confirmation
        conf_noise = self.noise_sd if c.noise_sd is None else c.noise_sd
        dem_sim_sd = conf_noise / np.sqrt(np.maximum(c.n_ok, 1))
        shares = m.variance_shares(dem_sim_sd)
        dem_sigma = np.sqrt(m.variance(dem_sim_sd))
        rows = []
        for j, o in enumerate(obs):
            rows.append({
                "key": o.key, "label": o.name, "unit": o.unit, "censored": o.is_censored,
                "measured_mean": None if o.is_censored else o.mean,
                "detection_limit": o.detection_limit, "measured_se": o.standard_error, "n": o.n,
                "surrogate_mean": float(self.best.mu[j]), "surrogate_sd": float(self.best.sd[j]),
                "dem_noise_sd": float(self.noise_sd[j]), "sigma": float(sigma[j]), "z": float(self.best.z[j]),
                "dem_mean": float(c.mean[j]), "dem_spread": float(c.spread[j]), "dem_runs": int(c.n_ok[j]),
                "dem_z": float(c.z[j]), "dem_sigma": float(dem_sigma[j]),
                "model_error_sd": float(m.discrepancy_sd[j]),
                # what the DEM z's sigma^2 is made of (fractions): lab repeats, the DEM's fill noise at the
                # lab's n, model error (validation.model_error), the confirmation mean's own noise
                "dem_sigma_shares": {k: float(v[j]) for k, v in shares.items()},
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
            "dem_noise_source": list(self.noise_source),
            "fixed_sd": self.misfit.fixed_sd.tolist(),
            "surrogate_quality": [q.to_dict() for q in self.surrogates.quality],
            "best_fit": {"parameters": self.best_parameters, "chi2": self.best.chi2,
                         "log_likelihood": self.best.log_likelihood, "z": self.best.z.tolist()},
            "comparison": self.comparison_rows(), "adequacy": self.adequacy.to_dict(),
            "evidence": self.evidence.to_dict(), "information_criteria": self.information_criteria(),
            "confirmation": self.confirmation.to_dict(),
            "surrogate_check": None if self.check is None else self.check.to_dict(),
            "refinement": [w.to_dict() for w in self.refinement], "seconds": self.seconds,
        }


def version_noise(own_sd: np.ndarray, own_dof: np.ndarray, base_sd: np.ndarray, base_dof: np.ndarray,
                  alpha: float = NOISE_TEST_ALPHA) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Per observable, the fill-to-fill noise a model version is judged with: the base model's
    (``base_sd`` with ``base_dof``), unless the base's replicates never varied (dof 0) or the
    version's own replicates reject it: F = s_own^2 / s_base^2 outside the central 1 - ``alpha``
    of the F(own_dof, base_dof) distribution (two-sided variance-ratio test, e.g. Montgomery &
    Runger, Applied Statistics and Probability for Engineers, Sec. 10-5). Returns
    ``(sd, dof, source)``, source ``"base"`` or ``"own"`` per observable."""
    own_sd, own_dof, base_sd, base_dof = (np.asarray(a, float) for a in (own_sd, own_dof, base_sd, base_dof))
    testable = (own_dof > 0) & (base_dof > 0) & (base_sd > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(testable, own_sd ** 2 / np.where(base_sd > 0, base_sd, 1.0) ** 2, 1.0)
    lo = stats.f.ppf(alpha / 2, np.maximum(own_dof, 1), np.maximum(base_dof, 1))
    hi = stats.f.isf(alpha / 2, np.maximum(own_dof, 1), np.maximum(base_dof, 1))
    own = (base_dof <= 0) | (testable & ((ratio < lo) | (ratio > hi)))
    return (np.where(own, own_sd, base_sd), np.where(own, own_dof, base_dof),
            tuple("own" if o else "base" for o in own))


def own_noise_sentence(version: "ModelStudy", base: "ModelStudy") -> str | None:
    """Where ``version`` is judged with its own DEM noise although the base model's replicates
    measured one (:func:`version_noise` rejected the base's), in one sentence with both sds; None
    where it keeps the base's."""
    obs = version.misfit.observations
    parts = [f"{obs[j].name}: {version.noise_sd[j]:.2g} against {base.noise_sd[j]:.2g} {obs[j].unit}"
             for j, src in enumerate(version.noise_source) if src == "own" and base.noise_dof[j] > 0]
    if not parts:
        return None
    return (f"The model '{version.name}' scatters differently from fill to fill than the base model (DEM noise "
            f"sd, {'; '.join(parts)}; a two-sided F test at level {NOISE_TEST_ALPHA:g} rejects the base's), so it "
            "is judged with its own noise there.")


def local_noise_sentence(version: "ModelStudy") -> str | None:
    """Where the DEM confirmation at ``version``'s best fit was judged with its own fills' scatter
    (:func:`local_noise`), in one sentence with both sds and the number of fills; None elsewhere."""
    c = version.confirmation
    if c is None or not c.local_noise:
        return None
    obs = version.misfit.observations
    parts = [f"{obs[j].name}: sd {c.spread[j]:.2g} {obs[j].unit} over {int(c.n_ok[j])} fills against "
             f"{version.misfit.dem_noise_sd[j]:.2g}" for j in c.local_noise]
    return (f"At the best fit of '{version.name}' the DEM's fills scatter more than the pooled noise ({'; '.join(parts)}; "
            f"F test at level {NOISE_TEST_ALPHA:g}), so the confirmation's mean there is judged with that scatter: "
            "its z says the data cannot tell that mean from the measurement, not that the model matches it closely.")


def study_model(version: ModelVersion, observations: Observations, runner: ForwardRunner,
                settings: DiagnosisSettings, seed: int, design: DesignData | None = None, waves: int = 1,
                noise: tuple[np.ndarray, np.ndarray] | None = None, confirm_now: bool = True) -> ModelStudy:
    """Design (unless given), noise, surrogates, scan, best fit, adequacy, evidence, confirmation.

    noise : the base model's (sd, dof) per observable, used instead of this design's own estimate
        where :func:`version_noise` keeps it (module docstring).
    confirm_now : False leaves the DEM confirmation (and the surrogate check) to :func:`confirm_study`,
        so that a caller can run it beside other work (its DEM worlds then share launches).
    """
    t0 = time.perf_counter()
    keys = observations.keys
    space = version.space
    if design is None:
        design = run_design(version, runner, keys, design_size(version, settings), settings.replicates, seed,
                            settings.replicated_fraction)
    # with the base's noise to fall back on, an observable whose replicates all failed here (e.g. a
    # pile too steep to measure over most of this version's box) takes the base's (version_noise)
    noise_sd, noise_dof = pooled_noise_sd(design.Y, keys, require=noise is None)
    noise_source = ("own",) * len(keys)
    if noise is not None:
        noise_sd, noise_dof, noise_source = version_noise(noise_sd, noise_dof, *noise)
        if np.any(np.isnan(noise_sd)):
            pooled_noise_sd(design.Y, keys)  # neither measured: the same NoiseNotMeasurable as without a base
    misfit = Misfit.build(observations, noise_sd, settings.model_discrepancy, noise_dof)
    surrogates = fit_surrogates(space, design, noise_sd, settings.gp_restarts, settings.cv_folds, seed)
    scan = scan_box(surrogates, misfit, settings.scan_points, seed)
    best = find_best_fit(surrogates, misfit, scan)
    adequacy = judge_adequacy(surrogates, misfit, scan, best, settings.cutoff, settings.max_conflict_size)

    def log_likelihood(U):
        return misfit.log_likelihood(*surrogates.predict_unit(U))

    evidence = estimate_log_evidence(log_likelihood, best.u, settings.evidence_samples, seed)
    study = ModelStudy(version, design, noise_sd, noise_dof, misfit, surrogates, scan, best, adequacy, evidence,
                       None, time.perf_counter() - t0, waves, None, noise_source=noise_source)
    return confirm_study(study, runner, settings) if confirm_now else study


def confirm_study(study: ModelStudy, runner: ForwardRunner, settings: DiagnosisSettings) -> ModelStudy:
    """``study`` with its DEM confirmation at the best fit and the surrogate check there (the
    last step of :func:`study_model`); its ``seconds`` include them."""
    t0 = time.perf_counter()
    confirmation = confirm(study.version, study.best.x, runner, study.misfit, settings.confirm_replicates,
                           settings.confirm_extra_replicates)
    check = check_surrogate(study.misfit, study.best, confirmation, settings)
    return replace(study, confirmation=confirmation, check=check, seconds=study.seconds + time.perf_counter() - t0)


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
                 settings: DiagnosisSettings, seed: int, noise: tuple[np.ndarray, np.ndarray] | None = None,
                 first_wave_unconditional: bool = True, say: Callable[[str], None] | None = None) -> ModelStudy:
    """History-matching waves until the DEM at the best fit agrees with the surrogate there.

    A wave places ``refine_points`` new sets (maximin) in the non-implausible part of the scan (or
    its lowest-implausibility 2 % if that is too small), joins the DEM confirmations of earlier
    best fits that are not in the design yet, and redoes the whole study on the joined design
    (refit, re-optimise, re-confirm).  The loop stops when the new study's :class:`SurrogateCheck`
    agrees, or the DEM already puts every observable within ``within_sigma``, or a wave has stalled
    (its largest DEM-vs-surrogate disagreement fell by less than ``STALL_FRACTION`` of the previous
    wave's: more DEM in the same region is not paying), or after the limit.

    first_wave_unconditional : True (the recalibration of a chosen effect): the first wave always
        runs, without the confirmation (it is the single wave of the diagnosis before this loop),
        and up to ``max(1, max_refine_waves)`` waves run in all.  False (a study whose surrogate
        is only doubted: the adequate base model): waves run only while the check disagrees, at
        most ``max_refine_waves - 1`` of them, so 0 and 1 add none in either case.
    say : progress callback, one line per wave.
    Returns the last study if its DEM agrees with its surrogate or lies within every measurement;
    otherwise the wave whose DEM confirmation has the smallest largest |z| (a later wave can land on
    a worse best fit; every confirmation is a real DEM run, so the best confirmed fit is kept, ties
    to the later wave), with ``refinement`` recording every wave (the kept one marked);
    ``refine_points = 0``: ``study``.
    """
    if settings.refine_points == 0:
        return study
    t0 = time.perf_counter()
    keys = observations.keys
    version = study.version
    limit = max(1, settings.max_refine_waves) if first_wave_unconditional else max(0, settings.max_refine_waves - 1)
    current, pending, records = study, [study.confirmation], []
    stalled = False
    studies: list[ModelStudy] = []
    for k in range(limit):
        unconditional = first_wave_unconditional and k == 0
        if not unconditional and (current.check.agrees or current.check.dem_within or stalled):
            break
        design = current.design
        joined = [] if unconditional else pending
        for c in joined:
            design = design.extended(c.as_design(keys))
        mi = current.scan.max_implausibility
        pool = current.scan.U[mi <= settings.cutoff]
        if len(pool) < settings.refine_points:
            pool = current.scan.U[np.argsort(mi)[:max(settings.refine_points * 4, len(mi) // 50)]]
        U_new = _maximin_subset(pool, settings.refine_points, version.space.to_unit(design.X))
        new = evaluate_sets(version, runner, keys, version.space.from_unit(U_new),
                            design_replicates(len(U_new), settings.replicates, settings.replicated_fraction, minimum=0))
        refined = study_model(version, observations, runner, settings, seed + 7919 * k, design.extended(new),
                              waves=current.waves + 1, noise=noise)
        pending = (pending if unconditional else []) + [refined.confirmation]
        stalled = (not unconditional and current.check is not None and refined.check is not None
                   and not (refined.check.agrees or refined.check.dem_within)
                   and refined.check.max_disagreement > (1.0 - STALL_FRACTION) * current.check.max_disagreement)
        records.append(RefinementWave(refined.waves, len(U_new), len(joined), len(refined.design.X),
                                      refined.best_parameters, refined.check, stalled))
        current = refined
        studies.append(refined)
        if say is not None:
            c = refined.check
            state = ("agrees" if c.agrees else "DEM within every measurement" if c.dem_within
                     else "disagrees" + (": wave limit (max_refine_waves) reached" if k + 1 >= limit
                                         else ": stalled (disagreement fell by < "
                                              f"{100 * STALL_FRACTION:.0f} %), no further wave" if stalled else ""))
            say(f"{version.name}: wave {refined.waves}: +{len(U_new)} sets, +{len(joined)} confirmation set(s), "
                f"{len(refined.design.X)} in all; DEM vs surrogate at the best fit: largest disagreement "
                f"{c.max_disagreement:.1f} sd{' (' + ', '.join(c.disagreeing) + ')' if c.disagreeing else ''}, "
                f"largest |z| DEM {c.max_abs_z_dem:.1f}: {state}")
    if current is study:
        return study
    kept = current
    if not (current.check.agrees or current.check.dem_within):
        candidates = studies if first_wave_unconditional else [study] + studies
        kept = min(reversed(candidates), key=lambda s: s.check.max_abs_z_dem)
        if say is not None and kept is not current:
            say(f"{version.name}: keeping wave {kept.waves}'s best fit (its DEM confirmation has the smallest "
                f"largest |z|, {kept.check.max_abs_z_dem:.1f}, against {current.check.max_abs_z_dem:.1f} at the last wave)")
    records = [replace(r, kept=(r.wave == kept.waves)) for r in records]
    kept.refinement = study.refinement + tuple(records)
    kept.seconds = study.seconds + (time.perf_counter() - t0)
    return kept
