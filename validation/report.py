"""The diagnosis as a self-contained HTML report (built with :mod:`calibration.reporting`).

Reading order (issue 11): verdict, comparison table, where it fails, ranking with sentences,
what to measure next, error history; then surrogate quality and the forward-model cost.
:func:`write_diagnosis` writes a result's JSON, figures and this report into a folder (the result
does not render itself: :mod:`validation.diagnose` stays below its report).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Mapping

import numpy as np

from calibration.reporting import Cell, Figure, Report, Section, Table, Verdict
from warpdem.config_io import write_atomic

from .evidence import bayes_factor_words
from .plots import diagnosis_figures
from .study import STALL_FRACTION, local_noise_sentence, own_noise_sentence

if TYPE_CHECKING:  # pragma: no cover
    from .diagnose import DiagnosisResult

__all__ = ["build_report", "write_diagnosis"]


def _refinement_blocks(result, within: float, cutoff: float) -> list:
    """A table of the history-matching waves of every model version that had any (none: nothing)."""
    rows = [[v.name, f"{r.wave} (kept)" if r.kept and len(v.refinement) > 1 else r.wave, r.new_sets, r.confirmation_sets, r.design_sets,
             Cell(round(r.check.max_disagreement, 1), "good" if r.check.agrees else "bad"),
             ", ".join(r.check.disagreeing) + (" (stalled)" if r.stalled else "") or "none", _z_cell(r.check.max_abs_z_dem, within, cutoff)]
            for v in result.versions for r in v.refinement]
    if not rows:
        return []
    return ["Refinement waves: each adds sets in the non-implausible region and the DEM runs at earlier best "
            "fits, refits and re-confirms, until the DEM at the best fit agrees with the surrogate there, "
            "or a wave stalls (its largest disagreement fell by less than "
            f"{100 * STALL_FRACTION:.0f} % of the previous wave's; marked 'stalled'); if the last wave's DEM "
            "still disagrees, the wave whose DEM confirmation fits best is kept (marked 'kept') "
            f"(max_refine_waves = {result.settings.max_refine_waves}).",
            Table(["model version", "wave", "new sets", "confirmation sets joined", "design sets",
                   "largest DEM − surrogate (combined sd)", "surrogate contradicted on", "largest |z| (DEM)"], rows,
                  caption="History-matching waves")]


def _z_cell(z: float, within: float, cutoff: float) -> Cell:
    if not np.isfinite(z):
        return Cell(None, "warn")
    tone = "good" if abs(z) <= within else ("warn" if abs(z) <= cutoff else "bad")
    return Cell(round(float(z), 2), tone)


def _dem_cell(c, j: int) -> str:
    """DEM mean ± spread of observable ``j`` at a confirmation, saying how many fills gave a value
    when some did not (a measurement that failed on a fill: its error is in the DEM records)."""
    n, reps = int(c.n_ok[j]), int(c.replicates)
    if n == 0:
        return f"no value (0 of {reps} fills)"
    value = f"{c.mean[j]:.4g}" + (f" ± {c.spread[j]:.2g}" if n > 1 and np.isfinite(c.spread[j]) else "")
    return value if n >= reps else f"{value} ({n} of {reps} fills)"


def _fig(paths: Mapping[str, os.PathLike], name: str, caption: str) -> list[Figure]:
    return [Figure.from_path(paths[name], caption, name.replace("_", " "))] if name in paths else []


def write_diagnosis(result: "DiagnosisResult", folder: str | os.PathLike) -> dict[str, Path]:
    """Write ``diagnosis.json``, ``error_history.json``, the figures (PNG) and ``report.html`` of
    ``result`` into ``folder``; returns their paths by name (``json``, ``error_history_json``,
    one per figure, ``report``)."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    paths["json"] = out / "diagnosis.json"
    write_atomic(paths["json"], json.dumps(result.to_dict(), indent=1, allow_nan=False))
    paths["error_history_json"] = result.history.write(out / "error_history.json")
    figures = diagnosis_figures(result)
    import matplotlib.pyplot as plt

    for name, fig in figures.items():
        p = out / f"{name}.png"
        fig.savefig(p, dpi=110, bbox_inches="tight")
        plt.close(fig)
        paths[name] = p
    paths["report"] = build_report(result, {n: paths[n] for n in figures}).write(out / "report.html")
    return paths


def build_report(result: "DiagnosisResult", figure_paths: Mapping[str, str | os.PathLike]) -> Report:
    """The report of ``result``; ``figure_paths`` maps figure stems to PNG files (embedded). Read
    top-down: verdict, comparison, where the base model fails (or its plausible set), each ranking
    round with what to measure next, the error history, surrogates and DEM noise."""
    obs = result.observations
    base = result.base
    sections = [_comparison_section(result, figure_paths), *_unreached_sections(result),
                _model_error_section(result), *_adequacy_sections(result, figure_paths)]
    for i, rnd in enumerate(result.rounds):
        sections += _ranking_sections(result, rnd, i, figure_paths)
    if len(result.history.versions) > 1:
        sections.append(_error_history_section(result, figure_paths))
    sections.append(_surrogate_section(result))
    return Report(title="Model versus measurement: diagnosis", verdict=_verdict(result), sections=sections,
                  next_steps=result.next_steps,
                  subtitle=f"{len(obs)} observables · base parameters: {', '.join(base.version.space.names)} · "
                           f"candidates: {', '.join(c.words for c in result.candidates) or 'none'}",
                  footer=_footer(result))


def _verdict(result: "DiagnosisResult") -> Verdict:
    """The headline, its first detail and the key numbers: largest |z| and chi^2 per observable
    of the base and final versions, observables within 2 sigma, and what the verdict rests on (the
    base model's plausible share of the box when it is adequate, the final version's lowest surrogate
    CV R²), DEM runs, wall time. Amber with the reasons when ``result.caveats`` holds any: "cannot
    tell" when the data cannot tell whether an effect is missing
    (:func:`validation.diagnose.data_cannot_tell`), "met on a weak basis" when an effect was added on a
    weak choice (:func:`validation.diagnose.weak_choice`)."""
    first, last = result.history.versions[0], result.history.versions[-1]
    numbers = [("base model: largest |z| (DEM)", first.max_abs_z),
               ("base model: χ² per observable", first.chi2_per_observable)]
    if len(result.versions) > 1:
        numbers += [(f"{result.final.name}: largest |z|", last.max_abs_z),
                    (f"{result.final.name}: χ² per observable", last.chi2_per_observable)]
    numbers.append(("observables within 2σ (final)", f"{last.n_within} of {last.n_observables}"))
    if result.base.adequacy.adequate:
        numbers.append(("plausible share of the box (base)", f"{result.base.adequacy.plausible_fraction:.0%}"))
    cv = [(q.r2, q.key) for q in result.final.surrogates.quality if q.r2 is not None and np.isfinite(q.r2)]
    if cv:
        r2, key = min(cv)
        numbers.append((f"lowest surrogate CV R² ({result.final.name})",
                        f"{r2:.2f} ({result.observations[result.observations.index(key)].name})"))
    numbers += [("DEM runs (set × fill, each in every experiment)", result.forward["runs"]),
                ("wall time (s)", round(result.seconds["total"], 1))]
    caveats = list(result.caveats)
    # "cannot tell" when the data cannot show whether an effect is missing (one version); an effect
    # added on a weak choice is "met on a weak basis" (validation.diagnose.weak_choice)
    status = ("Cannot tell" if len(result.versions) == 1 else
              "Met on a weak basis" if result.met else "Not met, on a weak basis") if caveats else (
        "Not met: none of the candidates" if result.none_of_candidates else "")
    return Verdict(met=result.met, headline=result.headline, details=result.details[:1], numbers=numbers,
                   caveats=caveats, status=status)


def _comparison_section(result: "DiagnosisResult", figure_paths: Mapping[str, os.PathLike]) -> Section:
    """Measured against simulated at each version's best fit, with z-scores."""
    s = result.settings
    w, cut = s.within_sigma, s.cutoff
    cols = ["observable", "unit", "measured (mean ± SE, n)"]
    for v in result.versions:
        cols += [f"{v.name}: DEM mean ± spread", f"{v.name}: z"]
    rows = []
    for j, o in enumerate(result.observations):
        meas = (f"< {o.detection_limit:g} (no value, n={o.n})" if o.is_censored
                else f"{o.mean:.4g} ± {o.standard_error:.2g} (n={o.n})")
        row = [o.name, o.unit, meas]
        for v in result.versions:
            c = v.confirmation
            row += [_dem_cell(c, j), _z_cell(c.z[j], w, cut)]
        rows.append(row)
    return Section("Comparison at the best fit", [
        "Each model version is calibrated on all observables at once and then re-simulated at its best fit "
        f"({s.confirm_replicates} fresh fills; {s.confirm_extra_replicates} more where they scatter beyond the pooled "
        "noise). z = (measured − simulated) / σ, with σ² = SE² + s_DEM²/n + Var_model + "
        "Var(simulated mean) (history matching, Vernon et al. 2010; Var_model the model error, next section). "
        "Green: |z| ≤ 2, amber: ≤ 3, red: beyond.",
        *filter(None, (local_noise_sentence(v) for v in result.versions)),
        Table(cols, rows, caption="Measured against simulated"),
        *_fig(figure_paths, "comparison", "Measured (black, mean ± standard error) and simulated (DEM mean ± "
                                          "spread over fills) values per experiment."),
    ])


def _unreached_sections(result: "DiagnosisResult") -> list[Section]:
    """The observables no candidate reaches (none when a candidate explains the data)."""
    if not result.unreached:
        return []
    cut = result.settings.cutoff
    rows = [[u.label, Cell(round(u.final_z, 1), "bad"), round(u.best_abs_z, 1), u.best_version] for u in result.unreached]
    return [Section("Observables no candidate reaches", [
        f"These observables stay beyond {cut:g} σ whatever candidate is added (alone or as a pair): the closest "
        "any studied model version came is listed, DEM-confirmed at its own best fit. The missing physics is "
        "not among the candidates, or these measurements deserve a second look.",
        Table(["observable", f"z ({result.final.name})", "smallest |z| of any candidate", "reached by"], rows,
              caption="No candidate reaches these"),
    ])]


def _model_error_section(result: "DiagnosisResult") -> Section:
    """What each final DEM z's sigma is made of: measurement noise, DEM noise, model error."""
    final = result.final
    rows = []
    terms = {t.key: t for t in result.model_error}
    for o, r in zip(result.observations, final.comparison_rows()):
        sh = r["dem_sigma_shares"]
        t = terms.get(o.key)
        rows.append([o.name, o.unit, f"{r['dem_sigma']:.3g}", f"{sh['measurement']:.0%}",
                     f"{sh['dem_noise'] + sh['simulation']:.0%}", f"{sh['model_error']:.0%}",
                     f"{r['model_error_sd']:.3g}", t.source if t else ""])
    setting = result.settings.model_discrepancy
    how = ("taken from the fidelity suite (warpdem against LIGGGHTS-PUBLIC 3.8, same named law, same fills; "
           "validation/model_error.py)" if setting == "fidelity" else
           "off (model_discrepancy: none): the simulator is treated as exact" if setting == "none" else
           "set in the config (model_discrepancy)")
    return Section("What each z is made of: measurement, DEM noise, model error", [
        "Two DEM codes with the same named contact law differ by 1-2° on a repose angle (docs/liggghts_reference.md), "
        "so the simulator is not exact: following Kennedy & O'Hagan (2001) each observable gets a model-error sd, "
        f"here {how}. The shares below split σ² of the final version's DEM z (Comparison) into the lab's "
        "repeat scatter (SE²), the DEM's fill-to-fill noise (at the lab's n, plus the confirmation mean's own) and "
        "the model error. A large model-error share means that observable's z says little about missing physics.",
        Table(["observable", "unit", "σ of the DEM z", "measurement", "DEM noise", "model error",
               "model-error sd", "source"], rows, caption=f"Variance shares at the best fit of {final.name}"),
    ])


def _adequacy_sections(result: "DiagnosisResult", figure_paths: Mapping[str, os.PathLike]) -> list[Section]:
    """Where the base model fails (the observables in conflict), or, when it is adequate, its
    plausible set."""
    obs, base = result.observations, result.base
    a = base.adequacy
    fail_blocks: list = [a.sentence]
    if a.unreachable or a.conflicts:
        fail_blocks.append(Table(["observables in conflict", "best compromise (max implausibility)", "meaning"],
                                 [[", ".join(obs[obs.index(k)].name for k in c.keys), Cell(round(c.best_max_implausibility, 2), "bad"),
                                   "unreachable on its own" if len(c.keys) == 1 else "reachable alone, never together"]
                                  for c in a.unreachable + a.conflicts],
                                 caption="Minimal sets of observables that no parameter setting makes plausible together"))
    fail_blocks += list(a.notes)
    fail_blocks += _fig(figure_paths, "residuals", "Residual of every observable for each model version; "
                                                    "the green band is the target |z| ≤ 2, red dashes the cut-off 3.")
    sections = [Section("Where the base model fails" if not a.adequate else "Adequacy of the base model", fail_blocks)]
    if a.adequate:
        sp = base.version.space
        sections.append(Section("Plausible set (the ambiguity the data leave)", [
            *result.caveats,
            Table(["parameter", "unit", "box", "plausible range", "best fit"],
                  [[n, u, f"{lo:.3g} – {hi:.3g}", f"{a.plausible_ranges[n][0]:.3g} – {a.plausible_ranges[n][1]:.3g}",
                    base.best_parameters[n]] for n, u, lo, hi in zip(sp.names, sp.units, sp.lower, sp.upper)]),
            *_fig(figure_paths, "plausible_set", "Parameter ranges in which every observable stays within "
                                                 "implausibility 3."),
        ]))
    return sections


def _ranking_sections(result: "DiagnosisResult", r, i: int, figure_paths: Mapping[str, os.PathLike]) -> list[Section]:
    """Ranking round ``i`` (``r``): the candidates' table and sentences, the choice, and what to
    measure next when candidates tied."""
    w, cut = result.settings.within_sigma, result.settings.cutoff
    obs = result.observations
    suffix = "" if i == 0 else f"_{i + 1}"
    rows = []
    for c in r.candidates:
        d = c.to_dict()
        eff = ", ".join(f"{k} = {c.study.best_parameters[k]:.3g}" for k in c.effect.parameter_names)
        rows.append([c.rank, c.effect.words, eff, f"{c.log_evidence:.1f} ± {c.study.evidence.standard_error:.2f}",
                     Cell(round(c.log_bayes, 1), "good" if c.log_bayes > np.log(20) else ""),
                     bayes_factor_words(c.log_bayes), round(d["bic"], 1), round(d["aic"], 1),
                     _z_cell(d["max_abs_z"], w, cut), f"{int(np.sum(np.abs(c.z) <= w))} of {len(obs)}",
                     round(c.signature.alignment, 2)])
    blocks: list = [
        f"Each candidate is added to the {r.current.name} model and calibrated with its own design; the ranking is "
        "by the Bayes factor B from the surrogate-integrated evidence Z (uniform prior over each parameter "
        "box), which charges for the part of an added parameter's range the data rule out (Kass & Raftery "
        "1995 reading). BIC and AIC are listed for reference; the alignment is the cosine between the "
        "effect's signature and the current residuals (+1: points exactly at the data).",
        Table(["rank", "effect", "calibrated effect parameters", "ln Z ± MC error", f"ln B vs {r.current.name}",
               "reading", "BIC", "AIC", "largest |z| (DEM)", f"within {w:g}σ", "alignment"], rows,
              caption=f"Candidate effects on top of the {r.current.name}"),
        *[c.sentence for c in r.candidates],
        *_fig(figure_paths, "signatures" + suffix,
              "How each effect moves every observable (full strength, at the current best fit) beside what "
              "the current model misses."),
    ]
    if r.chosen:
        blocks.append(f"Chosen: {r.reason}.")
    elif r.reason:
        blocks.append(r.reason[0].upper() + r.reason[1:] + ".")
    sections = [Section("Ranking of the candidate effects" + (f" (round {i + 1})" if i else ""), blocks)]
    if r.discrimination is not None:
        d = r.discrimination
        words = {c.name: c.effect.words for c in r.candidates}
        frows = [[f.proposal.name, f.proposal.unit] + [f"{f.means[n]:.4g} ± {f.sds[n]:.2g}" for n in d.candidates]
                 + [round(f.measurement_sd, 3), "" if f.lab_hours is None else f"{f.lab_hours:.2g}",
                    Cell(round(f.separation, 2), "good" if f.separation >= d.threshold else ""),
                    "" if f.lab_hours is None else round(f.separation_per_lab_hour, 2)]
                 for f in d.forecasts]
        sections.append(Section("What to measure next", [
            d.sentence,
            *([Table(["proposed measurement", "unit"] + [words[n] for n in d.candidates]
                     + ["expected SE", "lab hours", "separation (σ)", "σ per lab hour"], frows,
                     caption=f"Predicted outcomes (posterior mean ± predictive sd) of each proposed measurement, "
                             f"ranked: those reaching {d.threshold:g} σ by σ per lab hour, then by separation")]
              if frows else []),
            *(["Not forecast: " + "; ".join(d.not_forecast)] if d.not_forecast else []),
            *_fig(figure_paths, "discrimination" + suffix, "Predictions of the tied candidates at the best "
                                                           "proposed conditions."),
        ]))
    return sections


def _error_history_section(result: "DiagnosisResult", figure_paths: Mapping[str, os.PathLike]) -> Section:
    """The DEM-confirmed errors of every model version, in order."""
    w, cut = result.settings.within_sigma, result.settings.cutoff
    hrows = [[v.version, v.n_parameters, round(v.chi2, 2), v.dof, v.chi2_per_dof, round(v.chi2_per_observable, 3),
              _z_cell(v.max_abs_z, w, cut), f"{v.n_within} of {v.n_observables}"] for v in result.history.versions]
    return Section("Error history: add the effect and watch the error fall", [
        Table(["model version", "parameters", "χ²", "dof", "χ²/dof", "χ² per observable", "largest |z|",
               f"within {w:g}σ"], hrows, caption="DEM-confirmed errors of each model version"),
        *_fig(figure_paths, "error_history", "Error of every observable and in total across model versions."),
    ])


def _surrogate_section(result: "DiagnosisResult") -> Section:
    """Cross-validated quality of every surrogate and the DEM noise, then the refinement waves."""
    obs = result.observations
    qrows = []
    for v in result.versions:
        sources = v.noise_source or ("own",) * len(v.noise_sd)
        for q, sd, src in zip(v.surrogates.quality, v.noise_sd, sources):
            o = obs[obs.index(q.key)]
            qrows.append([v.name, o.name, o.unit, q.n_train, q.r2, q.rmse, q.coverage_2sd, sd,
                          "base model's" if src == "base" else "own"])
    return Section("Surrogates and DEM noise", [
        "One Gaussian process per observable (Matern 5/2 with one length scale per parameter + white noise); "
        "quality from k-fold cross-validation; the DEM noise is the pooled fill-to-fill sd over the design's "
        "replicates. Every version is judged with the base model's noise, so that their likelihoods compare, "
        "except where its own replicates reject it (two-sided F test at level 0.01: \"own\").",
        *filter(None, (own_noise_sentence(v, result.base) for v in result.versions[1:])),
        Table(["model version", "observable", "unit", "design sets", "CV R²", "CV RMSE", "CV coverage of ±2 sd",
               "DEM noise sd", "noise of"], qrows),
        *_refinement_blocks(result, result.settings.within_sigma, result.settings.cutoff),
    ])


def _footer(result: "DiagnosisResult") -> str:
    """The forward model's calls, runs and time, and the total."""
    f = result.forward
    up = f.get("designs_up_front") or {}
    up_words = (f" (designs up front in one call: {up['worlds_used']} of {up['worlds_run']} worlds used)"
                if up.get("on") and "worlds_run" in up else "")
    missing = (f"; {f['missing_values']} of {f['values']} values not measured"
               if f.get("missing_values") else "")
    return (f"warpdem diagnosis · forward model: {f['calls']} calls{up_words}, {f['runs']} runs "
            f"({f['failed_runs']} failed{missing}), {f['seconds']:.1f} s · total {result.seconds['total']:.1f} s · "
            "every number is in diagnosis.json")
