"""The diagnosis: model versus measurement, the missing effect, and the error falling.

:func:`diagnose` runs, in order (issue 11):

0. with ``designs_up_front`` on (``auto``: when the forward model runs on a CUDA device and
   answers every model version in one call), every design :func:`planned_designs` lists -- the
   base model's and each first-round candidate's -- in ONE forward-model call
   (:func:`run_planned_designs`, also behind ``warpdem diagnose --prefetch``); the studies below
   take their designs from its answer. Same designs, seeds and parameter sets, so the same numbers
   from a model whose runs do not depend on when they are made (the DEM numbers a new world's fill
   in run order: ``docs/diagnosis.md``); fewer, larger calls (on a GPU one launch of N + M worlds
   should cost much less than a launch of N and one of M). If the base model then needs no
   ranking, the candidates' designs were run for nothing: a progress line and
   ``forward_model.designs_up_front`` in the result say how many worlds;
1. the base model's study (:mod:`validation.study`: design, DEM noise, surrogates, best fit,
   comparison, adequacy, evidence, DEM confirmation);
2. if the base model is inadequate (or ``rank_when_adequate``), every candidate effect's
   augmented study, ranked by Bayes factor with signature and sentence (:mod:`validation.ranking`);
3. if the top candidates are tied (ln B gap < ``tie_log_bayes``), the forward model's proposed
   conditions are forecast under each and the most separating one is named
   (:mod:`validation.discrimination`); the one added (provisionally) is the top by evidence unless
   the DEM at the tied candidates' best fits puts another clearly closer to the measurements
   (:func:`_break_tie`);
4. the chosen effect (the top candidate, or ``settings.add``) is recalibrated with a second
   design wave and confirmed by DEM, and with further waves (up to ``max_refine_waves``) while
   the DEM at the best fit disagrees with the surrogate there; the error history records every
   version (:mod:`validation.history`); repeated up to ``max_added_effects`` (2) times while
   needed: the version is inadequate, or observables remain beyond ``within_sigma`` at its
   DEM-confirmed best fit, or its effect was chosen from a tie (then only the tied candidates are
   tried on top of it: the pair); a second effect is added only when it raises the evidence;
5. when an observable stays beyond the cut-off whatever was added (:func:`unreached_observables`),
   the verdict is "none of the candidate effects explains these measurements", with the closest
   any studied version came, instead of offering the best of the losers as the explanation.

Which studies get the disagreement-driven waves (:func:`validation.study.refine_study`): the
recalibrated version always, and the base model when it is judged adequate -- in both cases that
study is the verdict's, and its DEM-confirmed residuals are what the user reads.  The candidates
of a ranking round get none: they are ranked by surrogate evidence over the whole box, which a
local miss at one best fit moves little, and a wave costs every candidate ``refine_points x
replicates + confirm_replicates`` DEM runs (on a GPU about one launch pair, ~8 min at paper
scale, per wave); the chosen candidate is refined anyway, and a candidate whose surrogate
disagrees with its own confirmation is named in the details.  An inadequate base model gets none
either: it is only the "before" of the error history, and its misfit is DEM-confirmed.

:class:`DiagnosisResult` holds every number; :meth:`DiagnosisResult.write` saves the JSON, the
figures and the HTML report.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from calibration.designs import ParameterSpace, latin_hypercube
from warpdem.json_io import jsonable as _jsonable

from .adequacy import Adequacy
from .design import DesignData, design_replicates, design_size, evaluate_sets
from .discrimination import Discrimination, discriminate
from .effects import CandidateEffect, ModelVersion
from .forward import ForwardModel, ForwardRunner, merges_versions, runs_on_cuda, worlds_per_run
from .history import ErrorHistory, VersionErrors, version_errors
from .model_error import DiscrepancyTerm, resolve_model_discrepancy
from .observables import Observable, Observations
from .pooled import run_as_workers
from .ranking import CandidateResult, candidate_sentence, effect_signature, rank_candidates
from .settings import DiagnosisSettings
from .study import ModelStudy, confirm_study, local_noise_sentence, own_noise_sentence, refine_study, study_model

__all__ = ["RankingRound", "DiagnosisResult", "Unreached", "unreached_observables", "diagnose", "planned_designs", "run_planned_designs",
           "PlannedRun", "version_name", "data_cannot_tell", "CANNOT_TELL_PLAUSIBLE_SHARE", "provisional_choice"]


@dataclass(frozen=True)
class Unreached:
    """An observable no candidate brings within the cut-off: its residual at the final best fit and
    the smallest |z| any studied version reached (DEM-confirmed), with that version's name."""

    key: str
    label: str
    final_z: float
    best_abs_z: float
    best_version: str

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "label": self.label, "final_z": self.final_z, "best_abs_z": self.best_abs_z,
                "best_version": self.best_version}


def unreached_observables(versions: Sequence["ModelStudy"], rounds: Sequence["RankingRound"],
                          settings: DiagnosisSettings, unsettled: Sequence[str] = ()) -> tuple[Unreached, ...]:
    """Observables beyond ``settings.cutoff`` at the final version's DEM-confirmed best fit, when an
    effect was added or an inadequate base model was ranked and none was (none raised the evidence), leaving out
    those where the surrogate still disagrees with the DEM there (a better fit may exist: ``unsettled``).
    The cut-off, not ``within_sigma``: with 7 honest observables one lies beyond 2 sigma in about a
    third of the cases, beyond 3 sigma (Student t of the few repeats aside) in about 2 %."""
    if len(versions) < 2 and (versions[0].adequacy.adequate or not rounds):
        return ()
    final = versions[-1]
    obs = final.misfit.observations
    z_final = _residual(final)
    studies = list(versions) + [c.study for r in rounds for c in r.candidates]
    out = []
    for j, key in enumerate(obs.keys):
        if not (np.isfinite(z_final[j]) and abs(z_final[j]) > settings.cutoff) or key in unsettled:
            continue
        best = min(((abs(float(_residual(st)[j])), st.name) for st in studies if np.isfinite(_residual(st)[j])),
                   default=(abs(float(z_final[j])), final.name))
        out.append(Unreached(key, obs[j].name, float(z_final[j]), best[0], best[1]))
    return tuple(out)


@dataclass(frozen=True)
class RankingRound:
    """The candidates tried on top of one model version, ranked; the tie, its discrimination, the choice."""

    current: ModelStudy
    candidates: tuple[CandidateResult, ...]
    tied: tuple[str, ...]
    discrimination: Discrimination | None
    chosen: str | None
    reason: str
    contenders: tuple[str, ...] = ()

    @property
    def top(self) -> CandidateResult:
        return self.candidates[0]

    @property
    def discriminated(self) -> tuple[str, ...]:
        """The candidates whose forecasts the discrimination compares: the tied ones, or, when the chosen
        effect won by less than ``strong_log_bayes``, the contenders within that margin (one name: none)."""
        return self.tied if len(self.tied) >= 2 else self.contenders if len(self.contenders) >= 2 else ()

    def to_dict(self) -> dict[str, Any]:
        return {"current_version": self.current.name, "candidates": [c.to_dict() for c in self.candidates],
                "tied": list(self.tied), "contenders": list(self.contenders),
                "discrimination": None if self.discrimination is None
                else self.discrimination.to_dict(), "chosen": self.chosen, "reason": self.reason}


@dataclass
class DiagnosisResult:
    """Everything a diagnosis found.

    observations : the measurements.  settings : the settings used.
    versions : studies of the model versions built in turn (``versions[0]`` is the base model).
    rounds : one ranking round per attempt to add an effect.
    history : error history across ``versions`` (DEM-confirmed residuals).
    met : True when the final version has every observable within ``within_sigma`` (DEM).
    headline, details : the verdict in words.  next_steps : what to do next.
    forward : forward-model calls, runs, failed runs and seconds.  seconds : wall time per stage.
    caveats : why the verdict's basis is weak (:func:`data_cannot_tell`); the report shows it amber.
    model_error : the model-discrepancy sd given to each observable and its source (:mod:`validation.model_error`).
    """

    observations: Observations
    settings: DiagnosisSettings
    versions: list[ModelStudy]
    rounds: list[RankingRound]
    history: ErrorHistory
    met: bool
    headline: str
    details: list[str]
    next_steps: list[str]
    forward: dict[str, Any]
    seconds: dict[str, float]
    candidates: tuple[CandidateEffect, ...] = field(default_factory=tuple)
    caveats: list[str] = field(default_factory=list)
    model_error: tuple[DiscrepancyTerm, ...] = ()
    unreached: tuple[Unreached, ...] = ()

    @property
    def none_of_candidates(self) -> bool:
        """True when no candidate (alone or with a second one) brings the data within reach: some
        observable stays beyond the cut-off at the final DEM-confirmed best fit (:func:`unreached`)."""
        return bool(self.unreached) or (not self.base_adequate and len(self.versions) == 1 and bool(self.rounds))

    @property
    def base(self) -> ModelStudy:
        return self.versions[0]

    @property
    def final(self) -> ModelStudy:
        return self.versions[-1]

    @property
    def base_adequate(self) -> bool:
        return self.base.adequacy.adequate

    @property
    def added_effects(self) -> tuple[str, ...]:
        return self.final.version.effect_names

    @property
    def surrogate_disagrees(self) -> list[str]:
        """Observables where the DEM at the final best fit still contradicts the surrogate (none when met)."""
        check = self.final.check
        return [] if self.met or check is None else list(check.disagreeing)

    def to_dict(self) -> dict[str, Any]:
        return _jsonable({
            "verdict": {"met": self.met, "headline": self.headline, "details": self.details,
                        "caveats": self.caveats, "base_adequate": self.base_adequate,
                        "plausible_share": self.base.adequacy.plausible_fraction if self.base_adequate else None,
                        "added_effects": list(self.added_effects),
                        "surrogate_disagrees": self.surrogate_disagrees,
                        "refinement_waves": len(self.final.refinement),
                        "none_of_candidates": self.none_of_candidates,
                        "unreached": [u.to_dict() for u in self.unreached]},
            "observables": [o.to_dict() for o in self.observations],
            "candidates": [c.to_dict() for c in self.candidates],
            "settings": self.settings.to_dict(),
            "model_error": [t.to_dict() for t in self.model_error],
            "versions": [v.to_dict() for v in self.versions],
            "rounds": [r.to_dict() for r in self.rounds],
            "error_history": self.history.to_dict(),
            "next_steps": self.next_steps, "forward_model": self.forward, "seconds": self.seconds,
        })


def _errors(study: ModelStudy, settings: DiagnosisSettings) -> VersionErrors:
    z = study.confirmation.z
    return version_errors(study.name, study.version.effect_names, study.version.space.dim,
                          study.misfit.observations.keys, z, settings.within_sigma)


def _beyond(study: ModelStudy, sigma: float) -> list[str]:
    """Observable keys whose DEM-confirmed residual at ``study``'s best fit lies beyond ``sigma``."""
    z = _residual(study)
    return [k for k, v in zip(study.misfit.observations.keys, z) if np.isfinite(v) and abs(v) > sigma]


def _residual(study: ModelStudy) -> np.ndarray:
    zc = study.confirmation.z
    return np.where(np.isfinite(zc), zc, study.best.z)


def _candidate_seed(round_seed: int, index: int) -> int:
    """Design seed of the ``index``-th candidate of a ranking round."""
    return round_seed + 17 * (index + 1)


def _round_seed(settings: DiagnosisSettings, step: int) -> int:
    """Seed of ranking round ``step`` (0 = the first effect added)."""
    return settings.seed + 1000 * (step + 1)


def planned_designs(base_space: ParameterSpace, candidates: Sequence[CandidateEffect],
                    settings: DiagnosisSettings | None = None) -> list[tuple[ModelVersion, int, int]]:
    """(model version, number of sets, seed) of every design a diagnosis runs before it knows the
    data: the base model and each candidate of the first ranking round. A forward model may run
    them ahead (e.g. in parallel processes) and cache the results; :func:`diagnose` then finds them."""
    settings = settings or DiagnosisSettings()
    base = ModelVersion(base_space)
    out = [(base, design_size(base, settings), settings.seed)]
    for i, eff in enumerate(candidates):
        v = base.with_effect(eff)
        out.append((v, design_size(v, settings), _candidate_seed(_round_seed(settings, 0), i)))
    return out


def version_name(version: ModelVersion) -> str:
    """How a planned design is named (``--prefetch NAME``): ``"base"``, else its last effect's name."""
    return "base" if not version.effects else version.effects[-1].name


@dataclass
class PlannedRun:
    """What :func:`run_planned_designs` ran.

    designs : per version name (:func:`version_name`), its design (the Latin hypercube and the answers).
    calls : one entry per forward-model call: the versions it held, sets, replicates, runs, seconds.
    merged : True when every version went into one call (a model of the superset protocol).
    counts : per version name, the fills of each of its sets (:func:`validation.design.design_replicates`).
    """

    designs: dict[str, DesignData]
    calls: list[dict[str, Any]]
    merged: bool
    counts: dict[str, tuple[int, ...]]


def run_planned_designs(runner: ForwardRunner, keys: Sequence[str], base_space: ParameterSpace,
                        candidates: Sequence[CandidateEffect], settings: DiagnosisSettings,
                        versions: Sequence[str] | None = None, after_call: Any = None) -> PlannedRun:
    """Run the designs :func:`planned_designs` lists (those named in ``versions``, default all) for
    ``keys``: in ONE call of the forward model when it answers every model version in one call
    (:func:`validation.forward.merges_versions`: the DEM's superset model, one launch per
    experiment), else one call per version. The designs are exactly those the studies of
    :func:`diagnose` draw (same sizes and seeds), so a study given one (``study_model(...,
    design=...)``) or finding its worlds in the model's cache computes what it would have computed
    alone. Used by the ``designs_up_front`` step of :func:`diagnose` and by ``warpdem diagnose
    --prefetch``. ``after_call(entry)`` is called after each call (its entry of
    :attr:`PlannedRun.calls`). Unknown version names raise ValueError naming the valid ones."""
    plans = planned_designs(base_space, candidates, settings)
    named = {version_name(v): (v, n, seed) for v, n, seed in plans}
    unknown = [w for w in (versions or ()) if w not in named]
    if unknown:
        raise ValueError(f"unknown version(s) {unknown}; valid: {sorted(named)}")
    chosen = [w for w in named if not versions or w in versions]
    keys = tuple(keys)
    X = {w: latin_hypercube(named[w][0].space, named[w][1], seed=named[w][2]) for w in chosen}
    counts = {w: design_replicates(len(X[w]), settings.replicates, settings.replicated_fraction) for w in chosen}
    model = runner.model
    designs: dict[str, DesignData] = {}
    calls: list[dict[str, Any]] = []

    def record(names: list[str], n_sets: int, t0: float) -> None:
        calls.append({"versions": names, "sets": n_sets, "replicates": settings.replicates,
                      "runs": sum(sum(counts[w]) for w in names), "seconds": time.perf_counter() - t0})
        if after_call is not None:
            after_call(calls[-1])

    if merges_versions(model):
        sets: list[dict[str, float]] = []
        spans: dict[str, tuple[int, int]] = {}
        for w in chosen:
            v = named[w][0]
            start = len(sets)
            sets += [model.padded(v.effect_names, p) for p in v.parameter_sets(X[w])]
            spans[w] = (start, len(sets))
        t0 = time.perf_counter()
        Y = runner(tuple(model.effects), sets, [c for w in chosen for c in counts[w]], keys)
        for w, (a, b) in spans.items():
            designs[w] = DesignData(X[w], Y[a:b], keys)
        record(chosen, len(sets), t0)
        return PlannedRun(designs, calls, True, counts)
    for w in chosen:
        t0 = time.perf_counter()
        designs[w] = evaluate_sets(named[w][0], runner, keys, X[w], counts[w])
        record([w], len(X[w]), t0)
    return PlannedRun(designs, calls, False, counts)


def _up_front_choice(settings: DiagnosisSettings, model: ForwardModel) -> tuple[bool, str]:
    """Whether the designs run up front (``settings.designs_up_front``), and why."""
    want = settings.designs_up_front
    if want is False:
        return False, "designs_up_front: false"
    if not merges_versions(model):
        return False, ("the forward model cannot answer every model version in one call (no superset model): "
                       "each study requests its own design")
    if want == "auto":
        return (True, "auto: the forward model runs on a CUDA device") if runs_on_cuda(model) else \
            (False, "auto: the forward model does not run on a CUDA device")
    return True, "designs_up_front: true"


def _rank_round(current: ModelStudy, candidates: Sequence[CandidateEffect], obs: Observations, runner: ForwardRunner,
                settings: DiagnosisSettings, seed: int, noise: tuple[np.ndarray, np.ndarray],
                designs: dict[str, DesignData] | None = None) -> RankingRound:
    """Study every candidate on top of ``current`` (confirming ``current`` beside them when it is
    not yet), rank, and name the candidates tied with the top one (their forecasts,
    :func:`_discriminate_tie`, run beside the recalibration).
    ``designs`` : candidates' designs already run (by effect name; the up-front step)."""
    labels = [o.name for o in obs]
    current_words = "base model" if not current.version.effects else f"model '{current.name}'"
    # the candidates' studies (and the current model's confirmation, when still to run) are
    # independent: with a pooled forward model their DEM requests share launches
    # (validation.pooled); otherwise they run one after another, the confirmation first
    _say(f"studying {len(candidates)} candidate(s): {', '.join(e.name for e in candidates)}")
    pending = [lambda: confirm_study(current, runner, settings)] if current.confirmation is None else []
    done = run_as_workers(runner.model, pending + [
        (lambda i=i, eff=eff: study_model(current.version.with_effect(eff), obs, runner, settings,
                                          _candidate_seed(seed, i), design=(designs or {}).get(eff.name),
                                          noise=noise))
        for i, eff in enumerate(candidates)])
    if pending:
        current = done.pop(0)
    studies = done
    z_now = _residual(current)
    results = []
    for eff, st in zip(candidates, studies):
        log_b = st.evidence.log_evidence - current.evidence.log_evidence
        sig = effect_signature(current, st, eff, z_now)
        z_after = np.where(np.isfinite(st.confirmation.z), st.confirmation.z, st.best.z)
        sentence = candidate_sentence(eff, labels, z_now, z_after, log_b, settings.within_sigma, current_words)
        results.append(CandidateResult(eff, st, log_b, sig, sentence))
    ranked = rank_candidates(results)
    top = ranked[0]
    tied = tuple(c.name for c in ranked
                 if top.log_evidence - c.log_evidence
                 < max(settings.tie_log_bayes,
                       2.0 * math.hypot(top.study.evidence.standard_error, c.study.evidence.standard_error)))
    # short of "strong" evidence (Kass & Raftery 1995): the choice stands, provisionally, and the
    # discrimination names what would decide
    contenders = tuple(c.name for c in ranked if top.log_evidence - c.log_evidence < settings.strong_log_bayes)
    return RankingRound(current, ranked, tied, None, None, "", contenders if len(contenders) >= 2 else ())


def _discriminate_tie(rnd: RankingRound, model: ForwardModel, runner: ForwardRunner, settings: DiagnosisSettings,
                      seed: int) -> Discrimination:
    """The forecasts of the tied (or contending) candidates of ``rnd`` at the proposed conditions
    (:func:`validation.discrimination.discriminate`; :attr:`RankingRound.discriminated`)."""
    by_name = {c.name: c for c in rnd.candidates}
    names = rnd.discriminated
    return discriminate({n: by_name[n].study for n in names}, {n: by_name[n].effect.words for n in names},
                        tuple(model.proposals()), runner, settings.replicates, settings.separation_sigma,
                        seed=seed, replicated_fraction=settings.replicated_fraction)


def _break_tie(rnd: RankingRound, tie_log_bayes: float) -> tuple[str, str]:
    """The candidate to add when the evidence ties (``rnd.tied``), and why.

    The Bayes factors come from the surrogates over the whole box and differ by less than their
    resolution; what the tied candidates also have is a DEM run at each one's best fit (the
    study's confirmation). A tied candidate whose DEM residuals there are smaller than the top
    one's by more than 2 ``tie_log_bayes`` in chi^2 = sum z^2 (a Gaussian likelihood ratio beyond
    the same threshold that makes a tie) is added instead: the simulator itself shows it closer to
    the measurements. Otherwise the top candidate by evidence is added. Either way provisionally:
    the discrimination still names the measurement that would decide."""
    by_name = {c.name: c for c in rnd.candidates}
    tied = [by_name[n] for n in rnd.tied]
    top = tied[0]
    chi2 = {c.name: c.dem_chi2 for c in tied}
    best = min(tied, key=lambda c: (chi2[c.name], -c.log_evidence))
    pick = best if chi2[top.name] - chi2[best.name] > 2.0 * tie_log_bayes else top
    others = [c for c in tied if c.name != pick.name]
    listing = " and ".join(f"{c.effect.words} (ln B {c.log_bayes:+.1f}, DEM chi2 {chi2[c.name]:.1f})" for c in others)
    why = ("the DEM at each one's best fit puts it clearly closest to the measurements" if pick is not top else
           "it has the highest evidence and the DEM at the best fits does not separate them clearly")
    reason = (f"{pick.effect.words} added provisionally (ln B {pick.log_bayes:+.1f}, DEM chi2 {chi2[pick.name]:.1f}): "
              f"it ties on the evidence with {listing}; {why}")
    return pick.name, reason


def _check_inputs(observables, base_space, candidates, forward_model, settings) -> tuple[Observations, tuple]:
    if isinstance(observables, Observations):
        obs = observables
    else:
        obs = Observations(tuple(observables))
    if not isinstance(base_space, ParameterSpace):
        raise TypeError(f"base_space must be a calibration.designs.ParameterSpace, got {type(base_space).__name__}")
    cands = tuple(candidates)
    for c in cands:
        if not isinstance(c, CandidateEffect):
            raise TypeError(f"candidates must be CandidateEffect objects, got {type(c).__name__}")
        ModelVersion(base_space, (c,))  # raises on a parameter-name clash
    names = [c.name for c in cands]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"candidate effect names must be unique; duplicated: {dup}")
    unknown = [a for a in settings.add if a not in names]
    if unknown:
        raise ValueError(f"settings.add names effects that are not candidates: {unknown}; candidates: {names}")
    if not isinstance(settings.model_discrepancy, str):
        unknown = sorted(set(settings.model_discrepancy) - set(obs.keys))
        if unknown:
            raise ValueError(f"model_discrepancy names unknown observables {unknown}; known: {list(obs.keys)}")
    if not isinstance(forward_model, ForwardModel) and not callable(getattr(forward_model, "evaluate", None)):
        raise TypeError(f"forward_model must implement validation.forward.ForwardModel, got {type(forward_model).__name__}")
    return obs, cands


def diagnose(observables: Sequence[Observable] | Observations, base_space: ParameterSpace,
             candidates: Sequence[CandidateEffect], forward_model: ForwardModel,
             settings: DiagnosisSettings | None = None) -> DiagnosisResult:
    """Judge the base model against the measurements, rank the candidate effects, add the best.

    observables : the measured observables (unique keys).
    base_space : the base model's calibrated parameters and their ranges.
    candidates : effects the base model may lack (their parameters must not clash with the base's).
    forward_model : the simulator (:class:`validation.forward.ForwardModel`).
    settings : :class:`validation.settings.DiagnosisSettings` (defaults if None).
    """
    settings = settings or DiagnosisSettings()
    obs, cands = _check_inputs(observables, base_space, candidates, forward_model, settings)
    # the surrogates solve many tiny systems: one BLAS thread is ~100x faster than a spinning pool there
    with threadpool_limits(limits=1, user_api="blas"):
        return _diagnose(obs, base_space, cands, forward_model, settings)


def _timed(seconds: dict[str, float], key: str, job: Callable[[], Any]) -> Callable[[], Any]:
    """``job`` that adds its own wall time to ``seconds[key]`` (jobs running side by side each count theirs)."""
    def run() -> Any:
        t0 = time.perf_counter()
        try:
            return job()
        finally:
            seconds[key] += time.perf_counter() - t0
    return run


def _say(msg: str) -> None:
    """One progress line on stderr (the report and JSON carry the results); a diagnosis running
    beside others in one process (``warpdem diagnose a.yaml b.yaml``) names its config."""
    thread = threading.current_thread().name
    who = "" if thread == "MainThread" or thread.startswith(("pooled-worker-", "Thread-")) else f" [{thread}]"
    sys.stderr.write(f"diagnose{who}: {msg}\n")  # one write per line: threads do not splice lines
    sys.stderr.flush()


def _diagnose(obs: Observations, base_space: ParameterSpace, cands: tuple[CandidateEffect, ...],
              forward_model: ForwardModel, settings: DiagnosisSettings) -> DiagnosisResult:
    runner = ForwardRunner(forward_model)
    t_start = time.perf_counter()
    seconds: dict[str, float] = {}
    up_front, designs = _designs_up_front(obs, base_space, cands, forward_model, runner, settings)
    if "seconds" in up_front:
        seconds["designs_up_front"] = up_front["seconds"]
    _say("studying the base model")
    base = study_model(ModelVersion(base_space), obs, runner, settings, settings.seed, design=designs.get("base"),
                       confirm_now=False)
    # an inadequate base model is ranked at once: its DEM confirmation then runs beside the
    # candidates' studies (their worlds share launches), otherwise now
    if base.adequacy.adequate or not cands or max(settings.max_added_effects, len(settings.add)) == 0:
        base = confirm_study(base, runner, settings)
    if base.adequacy.adequate and not (base.check.agrees or base.check.dem_within) and settings.max_refine_waves > 1:
        _say(f"the base model's surrogate disagrees with the DEM at its best fit "
             f"({', '.join(base.check.disagreeing)}): refining")
        base = refine_study(base, obs, runner, settings, settings.seed + 500, first_wave_unconditional=False,
                            say=_say)
    seconds["base_study"] = base.seconds
    _say(f"base model studied in {base.seconds:.0f} s: {'adequate' if base.adequacy.adequate else 'inadequate'}")
    base_noise = (base.noise_sd, base.noise_dof)  # one variance model for every version (validation.study)
    versions = [base]
    history = ErrorHistory((_errors(base, settings),)) if base.confirmation is not None else None
    rounds: list[RankingRound] = []
    remaining = list(cands)
    forced = list(settings.add)
    seconds["ranking"] = seconds["recalibration"] = 0.0
    for step in range(max(settings.max_added_effects, len(forced))):
        current = versions[-1]
        inadequate = not current.adequacy.adequate
        # after an effect was added: a second one is studied when observables remain beyond
        # within_sigma at the DEM-confirmed best fit, or when the first was chosen from a tie (the pair)
        leftover = step > 0 and bool(_beyond(current, settings.within_sigma))
        tied_before = rounds[-1].tied if rounds and rounds[-1].chosen is not None else ()
        pair_of_tie = step > 0 and len(tied_before) >= 2
        needs_effect = inadequate or leftover or pair_of_tie
        if not remaining or not (needs_effect or forced or settings.rank_when_adequate):
            break
        pool = remaining
        if pair_of_tie and not (inadequate or leftover or forced):
            pool = [c for c in remaining if c.name in tied_before]  # only the pair(s) of the tie
        if step > 0 and needs_effect and not forced:
            why = (f"observables beyond {settings.within_sigma:g} sigma with {current.name}" if leftover or inadequate
                   else f"'{tied_before[0]}' was chosen from a tie with {', '.join(tied_before[1:])}")
            _say(f"studying a second effect on top of {current.name} ({why}): {', '.join(c.name for c in pool)}")
        t0 = time.perf_counter()
        rnd = _rank_round(current, pool, obs, runner, settings, _round_seed(settings, step), base_noise,
                          designs if step == 0 else None)
        seconds["ranking"] += time.perf_counter() - t0
        if history is None:  # the base model's confirmation ran in the round
            versions[0] = base = rnd.current
            history = ErrorHistory((_errors(base, settings),))
        top = rnd.top
        _say("ranking on top of the " + current.name + ": " + "; ".join(
            f"{c.effect.words} ln B {c.log_bayes:+.1f} (DEM largest |z| {np.nanmax(np.abs(_residual(c.study))):.1f})"
            for c in rnd.candidates) + (f"; tied: {', '.join(rnd.tied)}" if len(rnd.tied) >= 2 else ""))
        forced_pick = bool(forced)
        if forced:
            chosen, reason = forced.pop(0), "added as requested (settings.add)"
        elif not needs_effect:
            chosen, reason = None, f"the {current.name} is adequate: no effect is needed"
        elif top.log_bayes <= settings.tie_log_bayes and step > 0:
            chosen, reason = None, (f"no second effect raises the evidence over the {current.name} by more than a "
                                    f"bare mention (best: {top.effect.words}, ln B = {top.log_bayes:+.1f} <= "
                                    f"{settings.tie_log_bayes:.2f}): the pair is not supported, "
                                    f"{current.name} is kept")
        elif top.log_bayes <= settings.tie_log_bayes:
            chosen, reason = None, (f"no candidate raises the evidence over the {current.name} by more than a bare "
                                    f"mention (best: {top.effect.words}, ln B = {top.log_bayes:+.1f} <= "
                                    f"{settings.tie_log_bayes:.2f}): the missing effect is not among the candidates")
        elif len(rnd.tied) >= 2:
            chosen, reason = _break_tie(rnd, settings.tie_log_bayes)
        else:
            chosen, reason = top.name, f"{top.effect.words} has the highest evidence (ln B = {top.log_bayes:+.1f})"
        # the tie's forecasts and the chosen effect's recalibration do not depend on each other: with a
        # pooled forward model their DEM worlds share launches; otherwise the forecasts run first
        jobs: list[Callable[[], Any]] = []
        compare = len(rnd.discriminated) >= 2 and (len(rnd.tied) >= 2 or (chosen is not None and not forced_pick))
        if compare:
            _say(f"forecasting the proposed measurements under {', '.join(rnd.discriminated)} "
                 f"({'tied' if len(rnd.tied) >= 2 else f'within ln B {settings.strong_log_bayes:g} of the top'})")
            jobs.append(_timed(seconds, "ranking", lambda rnd=rnd, step=step: _discriminate_tie(
                rnd, forward_model, runner, settings, _round_seed(settings, step))))
        if chosen is not None:
            pick = next(c for c in rnd.candidates if c.name == chosen)
            _say(f"recalibrating with '{chosen}' added")
            jobs.append(_timed(seconds, "recalibration", lambda pick=pick, step=step: refine_study(
                pick.study, obs, runner, settings, settings.seed + 1000 * (step + 1) + 500, base_noise, say=_say)))
        done = run_as_workers(runner.model, jobs)
        disc = done.pop(0) if compare else None
        rnd = RankingRound(rnd.current, rnd.candidates, rnd.tied, disc, chosen, reason, rnd.contenders)
        rounds.append(rnd)
        if chosen is None:
            break
        recal = done[0]
        versions.append(recal)
        history = history.appended(_errors(recal, settings))
        before, after = history.versions[-2], history.versions[-1]
        _say(f"{recal.name}: error (DEM) fell from chi2/observable {before.chi2_per_observable:.2f} to "
             f"{after.chi2_per_observable:.2f}, largest |z| {before.max_abs_z:.1f} -> {after.max_abs_z:.1f}; "
             f"{after.n_within} of {after.n_observables} within {settings.within_sigma:g} sigma")
        remaining = [c for c in remaining if c.name != chosen]
    if up_front["on"]:
        _designs_used(up_front, ["base"] + ([c.name for c in cands] if rounds else []))
    seconds["total"] = time.perf_counter() - t_start
    seconds["forward_model"] = runner.seconds
    unsettled = [] if versions[-1].check is None else list(versions[-1].check.disagreeing)
    unreached = unreached_observables(versions, rounds, settings, unsettled)
    met, headline, details, steps = _summarise(versions, rounds, history, settings, unreached)
    cannot_tell = data_cannot_tell(base.adequacy) if len(versions) == 1 else None
    caveats = [cannot_tell] if cannot_tell else []
    caveats += [why for why in map(weak_choice, rounds) if why]
    caveats += [why for why in map(provisional_choice, rounds) if why]
    model_error = tuple(resolve_model_discrepancy(settings.model_discrepancy, obs)[1])
    return DiagnosisResult(obs, settings, versions, rounds, history, met, headline, details, steps,
                           {**runner.to_dict(), "designs_up_front": up_front}, seconds, cands, caveats, model_error,
                           unreached)


def _designs_up_front(obs: Observations, base_space: ParameterSpace, cands: tuple[CandidateEffect, ...],
                      model: ForwardModel, runner: ForwardRunner,
                      settings: DiagnosisSettings) -> tuple[dict[str, Any], dict[str, DesignData]]:
    """Stage 0 (module docstring): the record for ``forward_model.designs_up_front`` and the designs
    by version name (none when off). The candidates' designs are included only when a ranking round
    can happen (``max_added_effects`` or ``add``)."""
    on, why = _up_front_choice(settings, model)
    record: dict[str, Any] = {"setting": settings.designs_up_front, "on": on, "reason": why}
    if not on:
        if settings.designs_up_front is True:
            _say(f"designs_up_front: true, but {why}")
        return record, {}
    names = ["base"]
    if cands and max(settings.max_added_effects, len(settings.add)) > 0:
        names += [c.name for c in cands]
    per_run = worlds_per_run(model, obs.keys)
    _say(f"running the designs of {', '.join(names)} up front, in one forward-model call ({why})")
    t0 = time.perf_counter()
    run = run_planned_designs(runner, obs.keys, base_space, cands, settings, names)
    record.update({
        "calls": len(run.calls), "replicates": settings.replicates, "worlds_per_run": per_run,
        "sets": {w: len(d.X) for w, d in run.designs.items()},
        "worlds": {w: sum(run.counts[w]) * per_run for w in run.designs},
        "seconds": time.perf_counter() - t0})
    return record, run.designs


def _designs_used(record: dict[str, Any], used: Sequence[str]) -> None:
    """Complete the up-front record with the worlds the diagnosis used; say so when some were wasted."""
    worlds = record["worlds"]
    unused = [w for w in worlds if w not in used]
    record["worlds_run"] = sum(worlds.values())
    record["worlds_used"] = sum(n for w, n in worlds.items() if w in used)
    record["unused_versions"] = unused
    if unused:
        _say(f"the base model needs no ranking, so the {record['worlds_run'] - record['worlds_used']} design "
             f"world(s) of {', '.join(unused)} asked for up front were not used ({record['worlds_used']} of "
             f"{record['worlds_run']} were; designs_up_front: {str(record['setting']).lower()})")


#: an adequate base model plausible over at least this share of its parameter box: the data rule out
#: almost nothing, so they cannot tell whether an effect is missing (the paper-scale base-truth labs
#: left 23-34 % plausible, the analytic test model's 62 %, the tiny diagnosis's 3 noisy fills ~100 %)
CANNOT_TELL_PLAUSIBLE_SHARE = 0.9


def data_cannot_tell(adequacy: Adequacy) -> str | None:
    """Why the measurements cannot tell whether the model lacks an effect, or None when they can:
    the model is adequate over :data:`CANNOT_TELL_PLAUSIBLE_SHARE` or more of its parameter box (the
    share of the adequacy scan's points with every observable within the implausibility cut-off)."""
    share = adequacy.plausible_fraction
    if not adequacy.adequate or not share >= CANNOT_TELL_PLAUSIBLE_SHARE:
        return None
    return (f"The base model is plausible over {share:.0%} of its parameter box ({CANNOT_TELL_PLAUSIBLE_SHARE:.0%} or "
            "more: the data rule out almost nothing): these measurements scatter too much, or respond too little to "
            "the parameters, to show whether an effect is missing or to pin the parameters down.")


#: a choice between candidate effects is called weak when its evidence margin is below this ln B
#: ("strong" starts at 2 ln B = 6, Kass & Raftery 1995, J. Am. Stat. Assoc. 90:773) while a surrogate
#: it rests on predicts poorly (cross-validated R^2 below WEAK_CHOICE_R2)
WEAK_CHOICE_LOG_BAYES = 3.0
WEAK_CHOICE_R2 = 0.5


def weak_choice(rnd: RankingRound) -> str | None:
    """Why a ranking round's choice is weak, or None: the chosen effect beat the runner-up by less than
    :data:`WEAK_CHOICE_LOG_BAYES` while a surrogate of either study has a cross-validated R^2 below
    :data:`WEAK_CHOICE_R2` (the Bayes factors come from those surrogates). A tie decided by a
    proposed measurement, or an effect added by the user, is not a weak choice of the data."""
    if rnd.chosen is None or len(rnd.candidates) < 2 or rnd.discrimination is not None:
        return None
    chosen = next((c for c in rnd.candidates if c.name == rnd.chosen), None)
    if chosen is None or chosen is not rnd.candidates[0]:
        return None  # added by the user's 'add', not by the ranking
    runner = rnd.candidates[1]
    margin = chosen.log_bayes - runner.log_bayes
    quality = [(q.r2, q.key) for c in (chosen, runner) for q in c.study.surrogates.quality
               if q.r2 is not None and np.isfinite(q.r2)]
    if not quality or not margin < WEAK_CHOICE_LOG_BAYES:
        return None
    r2, key = min(quality)
    if not r2 < WEAK_CHOICE_R2:
        return None
    return (f"The choice of {chosen.effect.words} over {runner.effect.words} rests on a margin of ln B {margin:.1f} "
            f"(below {WEAK_CHOICE_LOG_BAYES:g}, short of 'strong' evidence) computed from surrogates whose "
            f"cross-validated R² is as low as {r2:.2f} ({key}): these measurements may not tell the two effects "
            f"apart; a measurement that separates them (proposals) or more design points would.")


def provisional_choice(rnd: RankingRound) -> str | None:
    """Why a ranking round's choice is provisional, or None: the effect was chosen from a tie or by a
    margin short of strong evidence, and the proposed measurements were forecast to tell the
    contenders apart (:attr:`RankingRound.discriminated`). Until one of them is measured the data do
    not single the effect out, so the verdict is amber even when every observable is within 2 sigma.
    Not for an effect the user added (``add``)."""
    d = rnd.discrimination
    if rnd.chosen is None or d is None or rnd.chosen not in d.candidates:
        return None
    words = {c.name: c.effect.words for c in rnd.candidates}
    others = " and ".join(words[n] for n in d.candidates if n != rnd.chosen)
    pick = next((f for f in d.forecasts if f.proposal.key == d.recommended), None)
    if pick is not None:
        return (f"The choice of {words[rnd.chosen]} is provisional: {others} fits these measurements about as well; "
                f"measuring the {pick.proposal.name} would tell them apart (separation {pick.separation:.1f} sigma).")
    best = max((f.separation for f in d.forecasts), default=float("nan"))
    return (f"The choice of {words[rnd.chosen]} is provisional: {others} fits these measurements about as well, and "
            f"none of the {len(d.forecasts)} proposed measurements would separate them (largest separation "
            f"{best:.1f} sigma): with these experiments the two effects are indistinguishable.")


def _single_fit_caveats(first, met: bool, within_sigma: float, unsettled: list[str], waves_words: str) -> str:
    """What a base-only headline adds: observables beyond ``within_sigma`` at the single best fit, and
    where the surrogate still disagrees with the DEM there."""
    text = ""
    if not met:
        text += f"; {first.n_observables - first.n_within} lie beyond {within_sigma:g} sigma at the single best fit"
    if unsettled:
        text += f"; the surrogate still disagrees with the DEM there for {', '.join(unsettled)}{waves_words}"
    return text


def _summarise(versions: list[ModelStudy], rounds: list[RankingRound], history: ErrorHistory,
               settings: DiagnosisSettings, unreached: Sequence[Unreached] = ()) -> tuple[bool, str, list[str], list[str]]:
    """Verdict headline, details and next steps in words."""
    base, final = versions[0], versions[-1]
    first, last = history.versions[0], history.versions[-1]
    w = settings.within_sigma
    met = bool(last.n_within == last.n_observables and last.n_observables > 0)
    details = [base.adequacy.sentence]
    steps: list[str] = []
    # the final study's surrogate still contradicted by the DEM at its best fit (after its waves)
    unsettled = [] if met or final.check is None else list(final.check.disagreeing)
    n_waves = len(final.refinement)
    waves_words = f" after {n_waves} refinement wave{'s' if n_waves != 1 else ''}" if n_waves else ""
    if base.adequacy.adequate and len(versions) == 1 and data_cannot_tell(base.adequacy):
        headline = (f"The data cannot tell: the base model is plausible over {base.adequacy.plausible_fraction:.0%} "
                    f"of its parameter box, so these {first.n_observables} observables neither call for an effect nor "
                    f"pin its parameters down (DEM at the best fit: largest |z| {first.max_abs_z:.1f})")
        headline += _single_fit_caveats(first, met, w, unsettled, waves_words)
        steps.append("Measure more before reading this as 'no effect is needed': more repeats, a larger scale "
                     "(less scatter between fills) or observables that respond to the parameters and the candidate "
                     "effects (drum speeds, the pile test, bulk density).")
    elif base.adequacy.adequate and len(versions) == 1:
        headline = (f"No effect is needed: the base model reproduces all {first.n_observables} observables "
                    f"(DEM at the best fit: largest |z| {first.max_abs_z:.1f})")
        headline += _single_fit_caveats(first, met, w, unsettled, waves_words)
        steps.append("Use a parameter set from the plausible set; to narrow it, measure more observables "
                     "(drum speeds, the pile test, bulk density).")
    elif len(versions) == 1:
        headline = "This model cannot reproduce these measurements, and none of the candidate effects explains why"
        if unreached:
            headline += ": " + "; ".join(f"{u.label} (z {u.final_z:+.1f}; the closest any candidate came: |z| "
                                         f"{u.best_abs_z:.1f}, {u.best_version})" for u in unreached)
        if rounds:
            details.append(rounds[-1].reason)
        steps.append("Consider effects beyond the candidates (or a model discrepancy), and check the measurements "
                     "named in the conflicts.")
    elif unreached:
        added = " and ".join(e.words for e in final.version.effects)
        far = "; ".join(f"{u.label} (z {u.final_z:+.1f}; the closest any candidate came: |z| {u.best_abs_z:.1f}, "
                        f"{u.best_version})" for u in unreached)
        headline = (f"None of the candidate effects explains these measurements: even the best they do, "
                    f"{final.name}, leaves {len(unreached)} of {last.n_observables} observables beyond "
                    f"{settings.cutoff:g} sigma: {far}")
        if not base.adequacy.adequate:
            headline = "The base model cannot reproduce these measurements, and n" + headline[1:]
        steps.append(f"Do not read {added} as the explanation: look for an effect beyond the candidates (a "
                     "different particle-size distribution, another shape family, a plug-in sub-model: "
                     "docs/adding_an_effect.md) or check the measurements of "
                     + ", ".join(u.label for u in unreached) + ".")
    else:
        added = " and ".join(e.words for e in final.version.effects)
        no_value = [k for k, z in last.z.items() if not math.isfinite(z)]
        beyond = last.n_observables - last.n_within - len(no_value)
        state = (f"every observable lies within {w:g} sigma" if met
                 else f"{beyond} of {last.n_observables} observables remain beyond {w:g} sigma" if beyond
                 else f"{last.n_within} of {last.n_observables} observables lie within {w:g} sigma")
        if no_value:
            state += (f" and the DEM gave no value for {', '.join(final.misfit.observations[final.misfit.observations.index(k)].name for k in no_value)}"
                      " there (its measurement failed on every fill)")
        lead = ("The base model cannot reproduce these measurements; " if not base.adequacy.adequate else "")
        headline = (f"{lead}with {added} added, {state} (DEM at the recalibrated best fit, largest |z| "
                    f"{last.max_abs_z:.1f})")
        headline = headline[0].upper() + headline[1:]
        noisy = final.confirmation.local_noise if final.confirmation is not None else ()
        if noisy:
            obs = final.misfit.observations
            headline += (f"; the {', '.join(obs[j].name for j in noisy)} judged with the scatter of "
                         f"{'its' if len(noisy) == 1 else 'their'} own fills there, which is large")
        if unsettled:
            headline += (f"; the surrogate still disagrees with the DEM at that best fit for {', '.join(unsettled)}"
                         f"{waves_words}, so a better fit may exist: this is not yet a failure of {added}")
        tied_round = next((r for r in rounds if r.discrimination is not None and r.chosen is not None), None)
        if tied_round is not None:
            d = tied_round.discrimination
            words = {c.name: c.effect.words for c in tied_round.candidates}
            others = " and ".join(words[n] for n in d.candidates if n != tied_round.chosen)
            how = ("fits as well" if len(tied_round.tied) >= 2 else
                   f"fits nearly as well (evidence short of strong: ln B margin below {settings.strong_log_bayes:g})")
            pick = next((f for f in d.forecasts if f.proposal.key == d.recommended), None)
            headline += (f"; provisional: {others} {how}"
                         + (f" -- measure the {pick.proposal.name} to decide" if pick is not None
                            else " and none of the proposed measurements separates them: these effects are "
                                 "indistinguishable with these experiments"))
        steps.append(f"Enable {added} in the model configuration (add: {list(final.version.effect_names)}) with the "
                     "recalibrated parameters: " + ", ".join(f"{k} = {v:.3g}" for k, v in final.best_parameters.items())
                     + ".")
    for r in rounds:
        details.extend(c.sentence for c in r.candidates)
        for c in r.candidates:
            if c.study.check is not None and not c.study.check.agrees and c.name != r.chosen:
                details.append(f"For {c.effect.words} the surrogate disagrees with the DEM at its best fit "
                               f"({', '.join(c.study.check.disagreeing)}): its sentence describes that point, "
                               "which may not be the best this effect can do.")
        if r.discrimination is not None:
            details.append(r.discrimination.sentence)
            d = r.discrimination
            words = {c.name: c.effect.words for c in r.candidates}
            f = next((f for f in d.forecasts if f.proposal.key == d.recommended), None)
            if f is not None:
                steps.insert(0, f"Measure the {f.proposal.name} ({f.proposal.n_repeats} repeats): "
                             + "; ".join(f"{words[n]} predicts {f.means[n]:.3g} ± {f.sds[n]:.2g} {f.proposal.unit}"
                                         for n in d.candidates) + f" (separation {f.separation:.1f} sigma).")
            else:
                closest = "; ".join(
                    f"at the {g.proposal.name}: " + ", ".join(f"{words[n]} {g.means[n]:.3g} ± {g.sds[n]:.2g}"
                                                              for n in d.candidates) + f" {g.proposal.unit}"
                    for g in sorted(d.forecasts, key=lambda g: -g.separation)[:2])
                steps.insert(0, f"These effects are indistinguishable with these experiments: neither the present "
                             f"nor the {len(d.forecasts)} proposed measurements separate "
                             f"{' and '.join(words[n] for n in d.candidates)}"
                             + (f" (closest: {closest})" if closest else "")
                             + "; look for an experiment where they act differently (faster or looser flow, a free "
                               "pile, a smaller scale where cohesion weighs more).")
        if r.chosen is not None:
            details.append(f"Chosen: {r.reason}.")
    details.extend(filter(None, (own_noise_sentence(v, base) for v in versions[1:])))
    details.extend(filter(None, (local_noise_sentence(v) for v in versions)))
    if len(history.versions) > 1:
        details.append(f"Error history (DEM): chi2 per observable {first.chi2_per_observable:.2f} -> "
                       f"{last.chi2_per_observable:.2f}; largest |z| {first.max_abs_z:.1f} -> {last.max_abs_z:.1f}.")
    if unsettled:
        steps.append(f"The surrogate still disagrees with the DEM at the best fit for {', '.join(unsettled)}"
                     f"{waves_words}: add design points (refine_points, max_refine_waves, "
                     "design_points_per_parameter) and rerun before reading the misfit there as the model's.")
    off = [k for k, v in last.z.items() if not abs(v) <= w and k not in unsettled]
    if off and len(versions) > 1 and not unreached:
        steps.append(f"Still beyond {w:g} sigma: {', '.join(off)}; try the next candidate (max_added_effects) or "
                     "review these measurements.")
    weak = [q.key for q in final.surrogates.quality if q.r2 is not None and q.r2 < 0.8]
    if weak:
        steps.append(f"Surrogates with cross-validated R^2 below 0.8 ({', '.join(weak)}): add design points "
                     "(design_points_per_parameter) before trusting fine differences.")
    return met, headline, details, steps
