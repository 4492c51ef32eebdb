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
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .reporting import Cell, Figure, Report, Section, Table, Verdict

__all__ = ["write_campaign_report", "campaign_report"]

#: acceptable ranges spanning more than this share of the design box in every parameter
BOX_COVERAGE_WARNING = 0.80

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


def campaign_verdict(results: Mapping[str, Any]) -> tuple[Verdict, list[list]]:
    """The verdict of a campaign (met when every confirmation run is within its tolerance; with the
    warnings a reader needs: surrogates that predict nothing, an acceptable set spanning the box,
    failed runs) and the confirmation table's rows. Shared by the HTML report and ``summary.md``."""
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
    met = not misses
    headline = (f"Calibration met: every confirmation run is within the tolerance of its target"
                if met else f"Calibration not met: {', '.join(misses)} outside the tolerance (or failed)")
    details, warnings = [], []
    held = (results.get("surrogate") or {}).get("held_out")
    if held:
        r2 = np.atleast_1d(np.asarray(held.get("r2"), dtype=float))
        for name, v in zip(conf, r2):
            if v < 0:
                warnings.append(f"The surrogate for {name} predicts nothing: its held-out R² is {v:.2f}, worse than "
                                "always answering the mean. Its optimum is a guess; run more samples or a "
                                "larger scale before trusting the parameters.")
    cover = _box_coverage(results)
    if cover and all(v > BOX_COVERAGE_WARNING for v in cover.values()):
        warnings.append("The acceptable set covers more than 80 % of the design box in every parameter "
                        f"({', '.join(f'{n} {v:.0%}' for n, v in cover.items())}): the data do not pin the "
                        "parameters down. Many parameter sets reproduce the targets equally well; add an "
                        "experiment that responds differently to them.")
    failed = (results.get("design") or {}).get("failed") or []
    if failed:
        warnings.append(f"{len(failed)} design run(s) failed and were left out of the surrogate.")
    details += warnings
    return Verdict(met, headline, details, numbers), rows


def campaign_report(results: Mapping[str, Any], folder: str | os.PathLike) -> Report:
    """The :class:`~calibration.reporting.Report` of a campaign; figures are read from ``folder``."""
    folder = Path(folder)
    verdict, rows = campaign_verdict(results)
    conf = results["confirmation"]["responses"]
    held = (results.get("surrogate") or {}).get("held_out")
    cover = _box_coverage(results)
    met, warnings = verdict.met, verdict.details

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
        sections.append(Section("Validation on another experiment", [Table(
            ["experiment", "measured (deg)", "DEM (deg)", "relative error (%)"],
            [[f"{v.get('experiment')} ({v.get('scale')} scale)", _num(v.get("measured_deg")),
              _num(v.get("dem_deg")), _num(v.get("relative_error_pct"))]])]))
    figures = [Figure.from_path(folder / f, cap) for f, cap in _FIGURES if (folder / f).is_file()]
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


def write_campaign_report(results: Mapping[str, Any], folder: str | os.PathLike) -> Path:
    """Write ``<folder>/report.html`` for a campaign's ``results``; returns its path."""
    return campaign_report(results, folder).write(Path(folder) / "report.html")
