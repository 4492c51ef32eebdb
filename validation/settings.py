"""Settings of a diagnosis (plain data; every threshold documented where it is used). The one
declaration of each setting: its type, default and bounds; the config's ``diagnosis:`` section
(:class:`validation.config.DiagnosisSection`) is derived from these fields."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Mapping

__all__ = ["BOUNDS", "DiagnosisSettings"]

#: a field's metadata key: its bounds (``ge``, ``gt``, ``le``), checked here and by the config
#: (:class:`validation.config.DiagnosisSection` is built from these fields: a setting is declared once)
BOUNDS = "bounds"


def _setting(default, **bounds):
    """A setting with its default and its ``bounds`` (:data:`BOUNDS`)."""
    return field(default=default, metadata={BOUNDS: bounds})


def _int(name: str, v, lo: int) -> None:
    if isinstance(v, bool) or not isinstance(v, int) or v < lo:
        raise ValueError(f"DiagnosisSettings.{name} must be an integer >= {lo}, got {v!r}")


@dataclass(frozen=True)
class DiagnosisSettings:
    """How much to simulate and which thresholds to apply.

    design_points_per_parameter, min_design_points : Latin-hypercube size per model version,
        ``max(min_design_points, design_points_per_parameter * k)`` for k parameters.
    replicates : independent fills per design set (>= 2: the DEM noise is measured from them).
    confirm_replicates : fills of the DEM confirmation run at each best fit.
    confirm_extra_replicates : more fills run at a best fit whose first ``confirm_replicates``
        scatter more than the pooled noise (:func:`validation.study.local_noise`); the observables
        still flagged on all of them are judged with that local scatter (0: no extra fills; the
        flagged observables still use their fills' scatter).
    refine_points : extra design sets placed in the plausible region when the chosen effect is
        recalibrated (a second history-matching wave; 0: none).
    max_refine_waves : most history-matching waves of that recalibration: the first always runs,
        each further one only while the DEM at the recalibrated best fit disagrees with the
        surrogate there (:func:`validation.study.refine_study`); its confirmation runs join the
        design.  An adequate base model gets up to ``max_refine_waves - 1`` such waves.  0 and 1:
        the single recalibration wave, no re-checks.
    scan_points : Sobol points of the surrogate scan of the box (rounded up to a power of 2).
    evidence_samples : importance samples of the evidence integral.
    cutoff : implausibility cut-off (3: Pukelsheim's 3-sigma rule; Vernon et al. 2010).
    within_sigma : |z| counted as "within" in sentences and the error history (2).
    tie_log_bayes : top candidates whose ln Z differ by less than this are tied and need a new
        measurement (ln 3: Kass & Raftery's "not worth more than a bare mention", B < 3); an
        effect is only added when its ln B over the current model exceeds it.
    strong_log_bayes : an effect chosen by a margin in ln B below this over the runner-up (short of
        Kass & Raftery's "strong", 2 ln B > 6) is provisional: the proposed measurements are forecast
        under the contenders within that margin and the one that would decide is named.
    separation_sigma : a proposed measurement separates two tied candidates when their predicted
        outcomes differ by at least this many combined sds (2).
    max_added_effects : how many effects may be added in turn (base, base+A, base+A+B, ...). A
        second effect is studied only when needed: observables remain beyond ``within_sigma`` at
        the DEM-confirmed best fit with the first, or the first was chosen from a tie (then only the
        tied candidates are tried with it: the pair). Default 2 (pairs).
    add : effect names to add regardless of the ranking (the config line / ``--add EFFECT``).
    rank_when_adequate : rank the candidates even when the base model is adequate.
    model_discrepancy : the model error added to every observable's variance (Kennedy & O'Hagan
        2001; :mod:`validation.model_error`): ``"fidelity"`` (default: per quantity from the
        warpdem-vs-LIGGGHTS fidelity suite, e.g. 1.3 deg on a static angle), ``"none"`` (the
        simulator treated as exact) or a mapping observable key -> sd in its unit (others 0).
    max_conflict_size : largest observable subset searched for conflicts.
    gp_restarts, cv_folds : surrogate hyperparameter restarts and cross-validation folds.
    seed : seed of every design, scan and sample.
    replicated_fraction : the share of each design's sets (Latin hypercube and refinement waves) that
        run ``replicates`` fills; the others run one (1.0, the default: every set). The DEM's
        fill-to-fill noise is pooled over the replicated sets (at least 3 per design, or all), the
        surrogates train on every set's mean with its own noise. 1/3 cuts a design's worlds by a
        third at 2 replicates, at the price of a noise estimate on a third of the degrees of freedom
        (its relative error grows from about 1/sqrt(2 n) to 1/sqrt(2 n / 3)). Confirmation runs keep
        ``confirm_replicates``.
    designs_up_front : ``"auto"``, True or False. On: before the base study, every design
        :func:`validation.diagnose.planned_designs` lists (the base model and each candidate of the
        first ranking round) is requested in ONE call of the forward model (one launch per
        experiment for the DEM), and the studies take their designs from its answer. Only a
        forward model that answers every model version in one call takes part (the superset
        protocol of :class:`validation.forward.ForwardModel`); with another model the setting does
        nothing. The designs, seeds and parameter sets are those of a run with it off; only the
        number and size of forward-model calls change (a model whose runs depend only on the set
        gives the same numbers; the DEM numbers a new world's fill in launch order, so from an empty
        cache its results move within the fill-to-fill noise). When the base model turns out
        adequate, the candidates' designs were run for nothing (the result's
        ``forward_model.designs_up_front`` says how many). ``"auto"``: on when the forward model runs on a CUDA device, where one launch of
        N + M worlds costs far less than launches of N and of M; off on the CPU, where the worlds
        cost the same either way and an adequate base model would waste the candidates' designs.
    """

    design_points_per_parameter: int = _setting(8, ge=1)
    min_design_points: int = _setting(16, ge=4)
    replicates: int = _setting(2, ge=2)
    confirm_replicates: int = _setting(3, ge=1)
    confirm_extra_replicates: int = _setting(2, ge=0)
    refine_points: int = _setting(8, ge=0)
    max_refine_waves: int = _setting(5, ge=0)
    scan_points: int = _setting(2 ** 14, ge=64)
    evidence_samples: int = _setting(2 ** 13, ge=256)
    cutoff: float = _setting(3.0, gt=0)
    within_sigma: float = _setting(2.0, gt=0)
    tie_log_bayes: float = _setting(math.log(3.0), gt=0)
    separation_sigma: float = _setting(2.0, gt=0)
    strong_log_bayes: float = _setting(3.0, gt=0)
    max_added_effects: int = _setting(2, ge=0)
    add: tuple[str, ...] = ()
    rank_when_adequate: bool = False
    model_discrepancy: str | Mapping[str, float] = "fidelity"
    max_conflict_size: int = _setting(3, ge=1)
    gp_restarts: int = _setting(2, ge=0)
    cv_folds: int = _setting(5, ge=2)
    seed: int = _setting(0, ge=0)
    designs_up_front: bool | str = "auto"
    replicated_fraction: float = _setting(1.0, gt=0, le=1)

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.type == "int":
                _int(f.name, getattr(self, f.name), f.metadata[BOUNDS]["ge"])
        for f in fields(self):
            if f.type == "float" and f.metadata[BOUNDS] == {"gt": 0}:
                v = getattr(self, f.name)
                if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                    raise ValueError(f"DiagnosisSettings.{f.name} must be a positive number, got {v!r}")
        v = self.replicated_fraction
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= 1):
            raise ValueError(f"DiagnosisSettings.replicated_fraction must be in (0, 1], got {v!r}")
        v = self.designs_up_front
        if not (isinstance(v, bool) or (isinstance(v, str) and v == "auto")):
            raise ValueError(f"DiagnosisSettings.designs_up_front must be 'auto', True or False, got {v!r}")
        if isinstance(self.add, str):
            raise ValueError(f"DiagnosisSettings.add must be a tuple of effect names, got the string {self.add!r}")
        object.__setattr__(self, "add", tuple(self.add))
        v = self.model_discrepancy
        if isinstance(v, str):
            if v not in ("fidelity", "none"):
                raise ValueError(f"DiagnosisSettings.model_discrepancy must be 'fidelity', 'none' or a mapping "
                                 f"observable key -> sd, got {v!r}")
        else:
            bad = {k: x for k, x in dict(v).items() if isinstance(x, bool) or not isinstance(x, (int, float))
                   or not (math.isfinite(x) and x >= 0)}
            if bad:
                raise ValueError(f"DiagnosisSettings.model_discrepancy values must be finite sds >= 0, got {bad}")
            object.__setattr__(self, "model_discrepancy", MappingProxyType(dict(v)))

    def to_dict(self) -> dict:
        d = dict(self.__dict__)
        d["add"] = list(self.add)
        v = self.model_discrepancy
        d["model_discrepancy"] = v if isinstance(v, str) else dict(v)
        return d
