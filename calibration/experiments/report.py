"""HTML report of one ``warpdem experiment`` run (``report.html`` next to ``results.json``).

Verdict first (every world measured, or which failed and why), then the observables of every
world with their units, the protocol (scale, deviations from the paper's settings, timing), the
per-world pictures, and what to do next. Built with :mod:`calibration.reporting`.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

from ..reporting import Cell, Figure, Report, Section, Table, Verdict

__all__ = ["experiment_report", "write_experiment_report"]


def _fmt(v: Any, digits: int = 4) -> Any:
    if isinstance(v, float):
        return float(f"{v:.{digits}g}") if math.isfinite(v) else None
    return v


def experiment_report(results: Sequence[Any], experiment: Any, folder: str | Path) -> Report:
    """The report of one run (``results``: its :class:`ExperimentResult` s, one per world)."""
    folder = Path(folder)
    ok = [r for r in results if r.ok]
    failed = [r for r in results if not r.ok]
    units = dict(type(experiment).OBSERVABLES)
    first = results[0] if results else None
    timing = first.timing if first is not None else {}
    if failed:
        headline = f"{len(failed)} of {len(results)} world(s) could not be measured"
        details = [f"world {r.world}: {r.error}" for r in failed[:8]]
    else:
        headline = f"All {len(results)} world(s) measured: {experiment.name} ({experiment.scale} scale)"
        details = []
    angles = [r.angle_deg for r in ok if r.angle_deg is not None]
    numbers = [("worlds", len(results)), ("wall time (s)", timing.get("wall_s")),
               ("simulated (s)", timing.get("simulated_s")), ("device", timing.get("device"))]
    if angles:
        numbers.insert(1, (f"{first.angle_name} range (deg)", f"{min(angles):.1f}-{max(angles):.1f}"))
    no_pile = [r.world for r in ok if r.diagnostics.get("no_pile")]
    if no_pile:
        details.append(f"no pile formed in world(s) {no_pile} (reported as angle 0 with pile_formed = 0)")
    verdict = Verdict(not failed, headline, details, numbers)

    pnames = sorted({k for r in results for k in r.parameters})
    qnames = list(units)
    rows = []
    for r in results:
        row: list[Any] = [r.world, Cell(r.status, "good" if r.ok else "bad")]
        row += [_fmt(r.parameters.get(p)) for p in pnames]
        row += [_fmt(r.observables.get(q)) if r.ok else None for q in qnames]
        rows.append(row)
    cols = ["world", "status", *pnames, *[f"{q} [{u}]" for q, u in units.items()]]
    sections = [Section("Observables per world", [
        "Contact parameters as given to each world (the law's other parameters at their defaults), and what "
        "each world measured. Definitions: docs/experiments.md.", Table(cols, rows)])]
    dev = first.protocol.get("deviations_from_paper", {}) if first is not None else {}
    prot_rows = [[k, _fmt(v.get("value")), _fmt(v.get("paper"))] for k, v in dev.items()]
    blocks: list[Any] = [f"Contact law: {first.protocol.get('contact_law') if first else '?'}; material: "
                         f"{(first.protocol.get('material') or {}).get('name', '?') if first else '?'}."]
    if prot_rows:
        blocks.append(Table(["setting", "this run", "paper"], prot_rows,
                            caption="Settings that differ from the paper-scale protocol"))
    blocks.append(Table(["item", "value"], [[k, _fmt(v) if not isinstance(v, (dict, list)) else str(v)]
                                            for k, v in timing.items() if k not in ("phases_s", "retries", "note")]))
    sections.append(Section("Protocol and timing", blocks))
    figs = [Figure.from_path(p, f"World {p.stem.split('_')[-1]}: side view of the particles, the surface bins and the "
                                "fitted line(s).") for p in sorted(folder.glob("world_*.png"))[:12]]
    if figs:
        sections.append(Section("Pictures", figs))
    steps = []
    if failed:
        steps.append("Read each failed world's error above; a measurement error usually means too few profile bins "
                     "(a small fill, or a slope shorter than the fit window): use more material or paper scale.")
    steps.append("Calibrate against measurements with `warpdem calibrate CONFIG`, or ask which physical effect is "
                 "missing with `warpdem diagnose CONFIG`.")
    return Report(f"Experiment: {experiment.name}", verdict, sections, steps,
                  subtitle=f"{len(results)} world(s), scale {experiment.scale}")


def write_experiment_report(results: Sequence[Any], experiment: Any, folder: str | Path) -> Path:
    """Write ``report.html`` into ``folder``; returns its path."""
    return experiment_report(results, experiment, folder).write(Path(folder) / "report.html")
