"""Read a LIGGGHTS experiment run back through the project's own measurement code (issue 27).

A deck written by :mod:`validation.reference.liggghts_experiments` dumps the particles at the
instants the experiment's protocol measures them; here those dumps go through the very functions
(and settings) that :meth:`BaffleBox.protocol`, :meth:`RotatingDrum.protocol` and
:meth:`HollowCylinder.protocol` call, so both codes are measured identically:

* baffle: ``mean_surface_height`` (h_fill) and ``bulk_density`` on the settled fill (as
  ``BaffleBox._measure_fill``), ``baffle_static_angle`` on the final pile;
* drum: ``drum_dynamic_angle`` over the snapshot series (duplicates included: the end of one
  recorded revolution is the start of the next, as in the protocol);
* cylinder: ``_pile_height`` and ``cylinder_pile_angle`` (or "no pile" below
  ``min_pile_layers`` mean diameters) on the final pile.

The mean particle diameter of the cylinder test is the fill's (warpdem: the sample's), here the
mean of the atoms dumped after the fill settled (the same atoms in the identical mode).
"""
from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibration.experiments.common import Experiment, fit_to_dict
from calibration.measurement import (MeasurementError, baffle_static_angle, bulk_density, cylinder_pile_angle,
                                     drum_dynamic_angle, mean_surface_height)

from .liggghts import LiggghtsRun, read_dump, run_deck
from .liggghts_experiments import ExperimentDeck

__all__ = ["LiggghtsMeasurement", "read_phases", "measure_run", "run_and_measure", "measure_particles"]


@dataclass
class LiggghtsMeasurement:
    """Observables of one LIGGGHTS run (names and units as the experiment's ``OBSERVABLES``),
    status "ok"/"failed" (``error``), diagnostics (fits, settling, atom counts) and timing."""

    experiment: str
    status: str = "ok"
    error: str | None = None
    observables: dict[str, float | None] = field(default_factory=dict)
    diagnostics: dict[str, Any] = field(default_factory=dict)
    timing: dict[str, Any] = field(default_factory=dict)


_PHASE = re.compile(r"^PHASE (\S+) (start|end|pile_top)\b(.*)$")


def read_phases(log: str) -> dict[str, dict[str, float]]:
    """``PHASE name start|end key value ...`` lines the deck prints -> {name: {start_step,
    end_step, end_time_s, end_atoms, end_ke_per_particle_J, met, ...}}; the lift plan of the
    cylinder as ``lift_plan``."""
    out: dict[str, dict[str, float]] = {}
    for line in log.splitlines():
        if line.startswith("PHASE lift_plan"):
            words = line.split()[2:]
            out["lift_plan"] = {words[i]: float(words[i + 1]) for i in range(0, len(words) - 1, 2)}
            continue
        m = _PHASE.match(line)
        if not m:
            continue
        name, when, rest = m.groups()
        words = rest.split()
        entry = out.setdefault(name, {})
        for k in range(0, len(words) - 1, 2):
            key = {"step": "step", "time": "time_s", "atoms": "atoms", "ke_per_particle": "ke_per_particle_J",
                   "met": "met"}.get(words[k], words[k])
            entry[f"{when}_{key}" if key != "met" else "met"] = float(words[k + 1])
    return out


def _spheres(frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (n, 3) [m], radii (n,) [m] and masses (n,) [kg] of a dump frame."""
    return frame.vectors("x", "y", "z"), frame["radius"], frame["mass"]


def measure_particles(exp: Experiment, final: tuple[np.ndarray, np.ndarray],
                      before: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                      snapshots: list[tuple[np.ndarray, np.ndarray]] | None = None,
                      mean_diameter: float | None = None, h_fill: float | None = None
                      ) -> tuple[dict[str, float | None], dict[str, Any]]:
    """The experiment's observables from particle data, by its protocol's measurement calls.

    final: (centres, radii) at the end; before: (centres, radii, masses) of the settled fill
    (baffle); h_fill: the fill's mean surface height [m] instead of ``before`` (baffle angle only,
    no bulk density); snapshots: (centres, radii) per drum frame; mean_diameter: the fill's mean
    particle diameter [m] (cylinder). Returns (observables, diagnostics); a measurement that cannot be
    made raises :class:`MeasurementError` (the world fails, as in warpdem)."""
    obs: dict[str, float | None] = {k: None for k in exp.OBSERVABLES}
    diag: dict[str, Any] = {}
    if exp.name == "baffle":
        h = h_fill
        if before is not None:
            xb, rb, mb = before
            dm = exp.density_margin
            h = mean_surface_height(xb, rb, x_range=(0.0, exp.box_length), y_range=(0.0, exp.box_width),
                                    bin_width=exp.bin_width)
            obs["bulk_density"] = bulk_density(xb, np.zeros(len(xb)), mb, box=((dm, exp.box_length - dm),
                                               (dm, exp.box_width - dm)), h=h, z_min=dm,
                                               top_margin=exp.density_top_margin)
        diag["h_fill_m"] = h
        xs, rs = final
        fit = baffle_static_angle(xs, rs, h, x_range=(0.0, exp.box_length), y_range=exp.measure_y,
                                  bin_width=exp.bin_width, band=exp.band, min_bins=int(exp.min_bins))
        obs["static_angle"] = fit.angle_deg
        diag["fit"] = fit_to_dict(fit)
    elif exp.name == "drum":
        res = drum_dynamic_angle(snapshots, axis_xz=(0.0, 0.0), crop_side=exp.crop_side, y_range=exp.measure_y,
                                 bin_width=exp.bin_width, min_bins=int(exp.min_bins),
                                 max_skipped=int(exp.max_skipped_snapshots))
        obs["dynamic_angle"] = res.angle_deg
        diag.update(mean_slope=res.mean_slope, snapshot_angles_deg=res.angles_deg, snapshot_mean_deg=res.mean_deg,
                    snapshot_std_deg=res.std_deg, skipped_snapshots=[dict(index=i, reason=w) for i, w in res.skipped])
    elif exp.name == "cylinder":
        from calibration.experiments.cylinder import _pile_height

        xs, rs = final
        peak = _pile_height(xs, rs, mean_diameter)
        diag.update(peak_height_m=peak, mean_diameter_m=mean_diameter)
        if peak < float(exp.min_pile_layers) * mean_diameter:
            obs.update(pile_angle=0.0, pile_height=peak, pile_formed=0.0)
            diag["no_pile"] = True
        else:
            res = cylinder_pile_angle(xs, rs, mean_diameter, axis_xy=(0.0, 0.0), bin_width=exp.bin_width,
                                      band=exp.band, min_bins=int(exp.min_bins))
            obs.update(pile_angle=res.gamma_s_deg, pile_height=res.peak_height, pile_formed=1.0)
            diag["thetas_deg"] = res.thetas_deg
    else:
        raise ValueError(f"no read-back for experiment '{exp.name}'")
    return obs, diag


def measure_run(exp: Experiment, deck: ExperimentDeck, folder: str | Path) -> LiggghtsMeasurement:
    """Measure a finished run in ``folder`` (its dumps and log) as the experiment's protocol does."""
    folder = Path(folder)
    out = LiggghtsMeasurement(exp.name)
    log = (folder / "log.liggghts").read_text(errors="replace")
    phases = read_phases(log)
    out.diagnostics["phases"] = phases
    out.diagnostics["timestep_warnings"] = sorted({ln.strip() for ln in log.splitlines()
                                                   if ln.startswith("WARNING") and "time" in ln.lower()})[:5]
    out.diagnostics["lost_atoms_warnings"] = sum(1 for ln in log.splitlines() if "Lost atoms" in ln)
    fs = phases.get("fill_settle", {})
    out.diagnostics["fill_settle_s"] = fs.get("end_time_s", math.nan) - fs.get("start_time_s", math.nan)
    out.diagnostics["fill_settled"] = bool(fs.get("met", 0.0))
    out.diagnostics["particles_after_fill"] = fs.get("end_atoms")
    try:
        if exp.name == "baffle":
            before = _spheres(read_dump(folder / "after_fill.dump")[-1])
            final = read_dump(folder / "final.dump")[-1]
            out.diagnostics["particles_before_lift"] = int(len(before[0]))
            out.diagnostics["particles_final"] = int(len(final["id"]))
            obs, diag = measure_particles(exp, _spheres(final)[:2], before=before)
        elif exp.name == "drum":
            frames = {name: read_dump(folder / name)[-1] for name in sorted(set(deck.settings["snapshot_files"]))}
            series = [_spheres(frames[name])[:2] for name in deck.settings["snapshot_files"]]
            out.diagnostics["particles_final"] = int(len(series[-1][0]))
            obs, diag = measure_particles(exp, series[-1], snapshots=series)
        else:
            final = read_dump(folder / "final.dump")[-1]
            out.diagnostics["particles_final"] = int(len(final["id"]))
            d_mean = float(np.mean(2.0 * read_dump(folder / "after_fill.dump")[-1]["radius"]))
            obs, diag = measure_particles(exp, _spheres(final)[:2], mean_diameter=d_mean)
        out.observables = obs
        out.diagnostics.update(diag)
    except MeasurementError as exc:
        out.status, out.error = "failed", str(exc)
        out.observables = {k: None for k in exp.OBSERVABLES}
    return out


def run_and_measure(exp: Experiment, deck: ExperimentDeck, folder: str | Path,
                    timeout_s: float = 3600.0) -> tuple[LiggghtsMeasurement, LiggghtsRun]:
    """Run ``deck`` in ``folder`` (one process) and measure it."""
    t0 = time.perf_counter()
    run = run_deck(deck.deck, folder, deck.files, timeout_s=timeout_s, screen_file="screen.txt")
    m = measure_run(exp, deck, folder)
    m.timing = {"wall_s": round(run.wall_s, 3), "measure_s": round(time.perf_counter() - t0 - run.wall_s, 3),
                "dt_s": deck.dt, "version": run.version}
    return m, run
