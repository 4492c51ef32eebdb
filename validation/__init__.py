"""Model versus measurement: see where the model fails, find the missing physical effect (issue 11).

Entry point: :func:`diagnose` (observables, base parameter box, candidate effects, forward model,
settings) -> :class:`DiagnosisResult`; ``write_diagnosis(result, folder)`` saves JSON, figures and an
HTML report.  Stages live in their own modules: observables, effects, forward, design, surrogates,
misfit, search, adequacy, evidence, study, ranking, discrimination, history, plots, report.
"""

from .adequacy import Adequacy, Conflict, judge_adequacy, minimal_conflicts
from .design import DesignData, pooled_noise_sd, run_design
from .diagnose import DiagnosisResult, RankingRound, diagnose
from .discrimination import Discrimination, Forecast, discriminate
from .effects import CandidateEffect, EffectParameter, ModelVersion
from .evidence import Evidence, bayes_factor_words, estimate_log_evidence
from .forward import ForwardModel, ForwardRunner, ProposedMeasurement
from .history import ErrorHistory, VersionErrors
from .misfit import Misfit
from .observables import Observable, Observations
from .ranking import CandidateResult, Signature
from .report import write_diagnosis
from .settings import DiagnosisSettings
from .study import Confirmation, ModelStudy

__all__ = [
    "diagnose", "DiagnosisResult", "DiagnosisSettings", "RankingRound", "write_diagnosis",
    "Observable", "Observations", "CandidateEffect", "EffectParameter", "ModelVersion",
    "ForwardModel", "ForwardRunner", "ProposedMeasurement",
    "DesignData", "run_design", "pooled_noise_sd", "Misfit", "Adequacy", "Conflict", "judge_adequacy",
    "minimal_conflicts", "Evidence", "estimate_log_evidence", "bayes_factor_words", "ModelStudy", "Confirmation",
    "CandidateResult", "Signature", "Discrimination", "Forecast", "discriminate", "ErrorHistory", "VersionErrors",
]
