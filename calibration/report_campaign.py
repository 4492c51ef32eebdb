"""HTML report of a calibration campaign (``report.html`` next to ``summary.md``).

Built with the generic :mod:`calibration.reporting` builder from the ``results`` dict that
:meth:`calibration.campaign.Campaign.run` returns (and writes as ``results.json``): verdict
first (every confirmation run within ``tolerance_deg`` of its target), warnings in plain
words, the material and contact law, tables, the campaign's figures, what to do next.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .reporting import Cell, Figure, Report, Section, Table, Verdict

__all__ = ["write_campaign_report", "campaign_report", "campaign_verdict", "campaign_basis", "CampaignBasis"]

#: acceptable ranges spanning more than this share of the design box in every parameter: a weak basis
BOX_COVERAGE_WARNING = 0.80
#: a surrogate whose held-out R² is below this predicts too little to base a verdict on (0: nothing)
WEAK_SURROGATE_R2 = 0.5

_FIGURES = (
    ("acceptable_set.png", "Parameter sets whose predicted angles lie within the tolerance (colour: largest "
                           "error as a share of the tolerance); star: the compromise."),
    ("surrogate_held_out.png", "Surrogate prediction against DEM on the held-out samples; points on the "
                               "diagonal are predicted exactly."),
    ("sensitivity.png", "Sobol indices: how much of each angle's variance each parameter explains."),
)


def _num(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _tolerances(results: Mapping[str, Any]) -> dict[str, float | None]:
    tol = (results.get("optimisation") or {}).get("tolerance_deg") or {}
    return {n: _num(tol.get(n)) for n in (results.get("confirmation") or {}).get("responses", {})}


def _box_coverage(results: Mapping[str, Any]) -> dict[str, float]:
    """Share of the design box [0-1] each parameter's acceptable range spans (box = design extent)."""
    ranges = (results.get("optimisation") or {}).get("acceptable_ranges") or {}
    X = np.asarray((results.get("design") or {}).get("X", []), dtype=float)
    names = list(results.get("parameters") or [])
    out = {}
    if X.ndim != 2 or X.shape[1] != len(names):
        return out
    for k, n in enumerate(names):
        width = float(X[:, k].max() - X[:, k].min())
        if n in ranges and width > 0:
            lo, hi = map(float, ranges[n])
            out[n] = min(1.0, (hi - lo) / width)
    return out


@dataclass(frozen=True)
class CampaignBasis:
    """What a campaign's verdict rests on, and why that basis is weak (if it is).

    held_out_r2 : per response, the surrogate's R² on the held-out design samples (empty: none held out).
    held_out_n : how many samples were held out.
    validation : the validation experiment's name (None: no validation).
    validation_error_deg, validation_error_pct : |DEM - measured| of the validation (None: failed or none).
    validation_criterion_deg : the calibration's tolerance, which the validation is held to.
    acceptable_share : per parameter, the share of the design box the acceptable set spans.
    weak : one sentence per weakness (the verdict's caveats); short : the same, a few words each.
    """

    held_out_r2: dict[str, float]
    held_out_n: int | None
    validation: str | None
    validation_error_deg: float | None
    validation_error_pct: float | None
    validation_criterion_deg: float | None
    acceptable_share: dict[str, float]
    weak: tuple[str, ...]
    short: tuple[str, ...]

    @property
    def weak_surrogates(self) -> list[str]:
        """Responses whose surrogate's held-out R² is below :data:`WEAK_SURROGATE_R2`."""
        return [n for n, r2 in self.held_out_r2.items() if not r2 >= WEAK_SURROGATE_R2]

    def sentence(self) -> str:
        """The basis in one sentence, weak or not."""
        parts = []
        if self.held_out_r2:
            r2 = ", ".join(f"{n} {v:.2f}" for n, v in self.held_out_r2.items())
            parts.append(f"surrogates' held-out R² {r2} on {self.held_out_n} samples (weak below {WEAK_SURROGATE_R2:g})")
        else:
            parts.append("no held-out samples, so the surrogates' accuracy is unknown")
        if self.validation is not None:
            crit = ("" if self.validation_criterion_deg is None
                    else f"; criterion {self.validation_criterion_deg:.2f} deg, the calibration's tolerance")
            parts.append(f"validation on the {self.validation} failed" if self.validation_error_deg is None else
                         f"validation on the {self.validation} {self.validation_error_deg:.2f} deg off "
                         f"({_pct(self.validation_error_pct)}{crit})")
        return "Basis of this verdict: " + "; ".join(parts) + "."


def _pct(v: float | None) -> str:
    return "–" if v is None else f"{v:.1f} %"


def _joined(words: list[str] | tuple[str, ...]) -> str:
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


def campaign_basis(results: Mapping[str, Any]) -> CampaignBasis:
    """The surrogates' held-out R², the validation's error against the calibration's tolerance and
    the acceptable set's share of the box, with a sentence for each that makes the basis weak:
    a held-out R² below :data:`WEAK_SURROGATE_R2`, a validation beyond the tolerance (or failed),
    an acceptable set spanning more than :data:`BOX_COVERAGE_WARNING` of the box in every parameter."""
    conf = (results.get("confirmation") or {}).get("responses") or {}
    held = (results.get("surrogate") or {}).get("held_out") or {}
    r2s = np.atleast_1d(np.asarray(held.get("r2", []), dtype=float)) if held else np.array([])
    held_r2 = {n: float(v) for n, v in zip(conf, r2s)}
    weak, short = [], []
    for name, v in held_r2.items():
        if v < 0:
            weak.append(f"The surrogate for {name} predicts nothing: its held-out R² is {v:.2f}, worse than always "
                        "answering the mean. Its optimum is a guess; run more samples or a larger scale before "
                        "trusting the parameters.")
            short.append(f"the surrogate for {name} predicts nothing (held-out R² {v:.2f})")
        elif not v >= WEAK_SURROGATE_R2:
            weak.append(f"The surrogate for {name} predicts poorly: its held-out R² is {v:.2f} (below "
                        f"{WEAK_SURROGATE_R2:g}), so the optimum and the sensitivity drawn from it are rough; run more "
                        "samples or a larger scale.")
            short.append(f"the surrogate for {name} predicts poorly (held-out R² {v:.2f})")
    tol = [t for t in _tolerances(results).values() if t is not None]
    criterion = max(tol) if tol else None
    val = results.get("validation")
    v_name = v_err = v_pct = None
    if val:
        v_name = str(val.get("name") or val.get("experiment") or "validation experiment")
        dem, measured = _num(val.get("dem_deg")), _num(val.get("measured_deg"))
        v_err = None if dem is None or measured is None else abs(dem - measured)
        v_pct = _num(val.get("relative_error_pct"))
        if v_err is None:
            weak.append(f"The validation on the {v_name} gave no angle, so the calibrated parameters are not validated.")
            short.append(f"the validation on the {v_name} failed")
        elif criterion is not None and v_err > criterion:
            weak.append(f"The validation on the {v_name} is {v_err:.2f} deg ({_pct(v_pct)}) off, beyond the calibration's "
                        f"tolerance of {criterion:.2f} deg: the calibrated parameters do not carry over to an "
                        "experiment they were not calibrated on.")
            short.append(f"the validation on the {v_name} is {_pct(v_pct)} off ({v_err:.2f} deg; criterion "
                         f"{criterion:.2f} deg)")
    cover = _box_coverage(results)
    if cover and all(v > BOX_COVERAGE_WARNING for v in cover.values()):
        weak.append(f"The acceptable set covers more than {BOX_COVERAGE_WARNING:.0%} of the design box in every parameter "
                    f"({', '.join(f'{n} {v:.0%}' for n, v in cover.items())}): the data do not pin the "
                    "parameters down. Many parameter sets reproduce the targets equally well; add an "
                    "experiment that responds differently to them.")
        short.append("the acceptable set spans most of the box")
    return CampaignBasis(held_r2, held.get("n") if held else None, v_name, v_err, v_pct, criterion, cover,
                         tuple(weak), tuple(short))


def campaign_verdict(results: Mapping[str, Any]) -> tuple[Verdict, list[list]]:
    """The verdict of a campaign and the confirmation table's rows. Met when every confirmation
    run is within its tolerance; it states its own basis (:func:`campaign_basis`: held-out R²,
    validation error) and is amber, "met on a weak basis", when that basis is weak; failed design
    runs are named. Shared by the HTML report, ``summary.md`` and the command line."""
    conf = (results.get("confirmation") or {}).get("responses") or {}
    if not conf:
        raise ValueError("campaign report: results hold no confirmation runs ('confirmation' -> 'responses')")
    tol = _tolerances(results)
    rows, numbers, misses = [], [], []
    for name, c in conf.items():
        dem, err, t = _num(c.get("dem_deg")), _num(c.get("abs_error_deg")), tol.get(name)
        within = None if err is None or t is None else err <= t
        if not within:
            misses.append(name)
        tone = "" if within is None else ("good" if within else "bad")
        rows.append([name, _num(c.get("target_deg")), _num(c.get("surrogate_deg")),
                     Cell("failed" if dem is None else dem, "bad" if dem is None else ""),
                     Cell(err, tone), t, Cell("—" if within is None else ("yes" if within else "no"), tone)])
        numbers.append((f"{name}: DEM error (tolerance)",
                        f"{'failed' if err is None else f'{err:.2f}'} deg ({'–' if t is None else f'{t:.2f}'} deg)"))
    basis = campaign_basis(results)
    if basis.held_out_r2:
        numbers.append(("surrogate held-out R² (lowest)",
                        "{1:.2f} ({0})".format(*min(basis.held_out_r2.items(), key=lambda kv: kv[1]))))
    if basis.validation is not None:
        numbers.append((f"validation {basis.validation}: error (criterion)",
                        "failed" if basis.validation_error_deg is None else
                        f"{basis.validation_error_deg:.2f} deg, {_pct(basis.validation_error_pct)} "
                        f"({'–' if basis.validation_criterion_deg is None else f'{basis.validation_criterion_deg:.2f}'} deg)"))
    met = not misses
    if not met:
        headline = f"Calibration not met: {', '.join(misses)} outside the tolerance (or failed)"
    elif basis.weak:
        headline = ("Calibration met on a weak basis: every confirmation run is within the tolerance of its target, "
                    f"but {_joined(basis.short)}")
    else:
        headline = "Calibration met: every confirmation run is within the tolerance of its target"
    details = list(basis.weak) + [basis.sentence()]
    failed = (results.get("design") or {}).get("failed") or []
    if failed:
        details.append(f"{len(failed)} design run(s) failed and were left out of the surrogate.")
    return Verdict(met, headline, details, numbers, caveats=basis.weak), rows


def campaign_report(results: Mapping[str, Any], folder: str | os.PathLike) -> Report:
    """The :class:`~calibration.reporting.Report` of a campaign; figures are read from ``folder``."""
    folder = Path(folder)
    verdict, rows = campaign_verdict(results)
    basis = campaign_basis(results)
    conf = results["confirmation"]["responses"]
    held = (results.get("surrogate") or {}).get("held_out")
    cover = basis.acceptable_share
    met, warnings = verdict.met, list(verdict.caveats) + list((results.get("design") or {}).get("failed") or [])

    model = results.get("model") or {}
    material = model.get("material")
    law = model.get("contact_law") or results.get("contact_law")
    sections = [Section("Confirmation: DEM at the calibrated parameters", [
        Table(["response", "target (deg)", "surrogate (deg)", "DEM (deg)", "abs. error (deg)", "tolerance (deg)",
               "within"], rows, caption="DEM: mean over the confirmation fills.")])]
    params = (results.get("confirmation") or {}).get("parameters") or {}
    ranges = (results.get("optimisation") or {}).get("acceptable_ranges") or {}
    sections.append(Section("Calibrated parameters", [Table(
        ["parameter", "compromise", "acceptable low", "acceptable high", "share of the box"],
        [[n, _num(v), *(list(map(_num, ranges[n])) if n in ranges else [None, None]),
          None if n not in cover else f"{cover[n]:.0%}"] for n, v in params.items()],
        caption="Acceptable range: parameter sets whose predicted angles are all within the tolerance.")]))
    if held:
        r2 = np.atleast_1d(np.asarray(held.get("r2"), dtype=float))
        rm = np.atleast_1d(np.asarray(held.get("rmse_deg"), dtype=float))
        sections.append(Section("Surrogate accuracy", [Table(
            ["response", "held-out R²", "RMSE (deg)"],
            [[n, Cell(float(a), "bad" if a < 0 else ("warn" if a < 0.8 else "good")), float(b)]
             for n, a, b in zip(conf, r2, rm)],
            caption=f"On {held.get('n', '?')} held-out samples; 1 is perfect, 0 or less predicts nothing.")]))
    if "validation" in results:
        v = results["validation"]
        err, crit = basis.validation_error_deg, basis.validation_criterion_deg
        tone = "" if err is None or crit is None else ("good" if err <= crit else "bad")
        sections.append(Section("Validation on another experiment", [Table(
            ["experiment", "measured (deg)", "DEM (deg)", "abs. error (deg)", "relative error (%)", "criterion (deg)"],
            [[f"{v.get('experiment')} ({v.get('scale')} scale)", _num(v.get("measured_deg")),
              Cell("failed" if _num(v.get("dem_deg")) is None else _num(v.get("dem_deg")), "bad" if err is None else ""),
              Cell(err, tone), Cell(_num(v.get("relative_error_pct")), tone), crit]],
            caption="Criterion: the calibration's tolerance (the largest of the responses').")]))
    figures = _figures(results, folder, basis)
    if figures:
        sections.append(Section("Figures", figures))
    if results.get("vtk_series"):
        sections.append(Section("ParaView time series", [
            "Runs recorded on request (config section vtk): open a folder's particles.pvd and wall_*.pvd "
            "in ParaView (relative to this report's folder).",
            Table(["folder", "files"], [[f, "particles.pvd, wall_*.pvd"] for f in results["vtk_series"]])]))
    mat_text = "each experiment's default material" if not material else (
        material.get("name", json.dumps(material)) if isinstance(material, Mapping) else str(material))
    sections.append(Section("Material and contact law", [
        f"Material: {mat_text}.",
        Table(["item", "description"],
              [[k, json.dumps(v) if not isinstance(v, str) else v] for k, v in
               ((material or {}).items() if isinstance(material, Mapping) else [])] +
              [[f"contact law: {k}", json.dumps(v) if not isinstance(v, str) else v] for k, v in
               ((law or {}).items() if isinstance(law, Mapping) else [("law", str(law))])]),
        f"Calibrated: {', '.join(results.get('parameters') or [])}; fixed: {results.get('fixed')}."]))
    nxt = []
    if not met:
        nxt.append("Run more confirmation rounds (confirmation.refine_rounds) or widen the design around the "
                   "compromise, then confirm again.")
    if warnings:
        nxt.append("Address the warnings above before using the parameters: more samples, a larger scale, or an "
                   "additional experiment that separates the parameters.")
    nxt.append("Validate the calibrated material on an experiment it was not calibrated on (e.g. the hollow cylinder).")
    return Report(f"Calibration: {results.get('name', 'campaign')}", verdict, sections, nxt,
                  subtitle=f"Device {results.get('device', '?')}; total wall time {results.get('wall_s', '?')} s. "
                           "Angles in degrees.")


def sensitivity_warning(basis: CampaignBasis) -> str | None:
    """The warning the sensitivity plot carries when it is drawn from weak surrogates (None: not weak)."""
    weak = basis.weak_surrogates
    if not weak:
        return None
    r2 = ", ".join(f"{n} {basis.held_out_r2[n]:.2f}" for n in weak)
    return (f"drawn from surrogates that predict poorly (held-out R² {r2}; weak below {WEAK_SURROGATE_R2:g}): "
            "these shares describe the surrogates, not the DEM.")


def _figures(results: Mapping[str, Any], folder: Path, basis: CampaignBasis) -> list[Figure]:
    """The campaign's figures from ``folder``; the sensitivity plot is redrawn with a warning on it
    (and saved over ``sensitivity.png``) when the surrogates it comes from are weak."""
    warning = sensitivity_warning(basis)
    sens = results.get("sensitivity") or {}
    if warning and {"first_order", "total_order", "parameters", "responses"} <= set(sens):
        from .sensitivity import SobolResult, plot_sensitivity

        sob = SobolResult(list(sens["parameters"]), list(sens["responses"]), np.asarray(sens["first_order"], float),
                          np.asarray(sens["total_order"], float), int(sens.get("n") or 0), 0)
        folder.mkdir(parents=True, exist_ok=True)
        plot_sensitivity(sob, path=str(folder / "sensitivity.png"), warning=warning)
    figures = []
    for name, caption in _FIGURES:
        if (folder / name).is_file():
            if warning and name == "sensitivity.png":
                caption = f"Warning: {warning} " + caption
            figures.append(Figure.from_path(folder / name, caption))
    return figures


def write_campaign_report(results: Mapping[str, Any], folder: str | os.PathLike) -> Path:
    """Write ``<folder>/report.html`` for a campaign's ``results``; returns its path."""
    return campaign_report(results, folder).write(Path(folder) / "report.html")
