"""LIGGGHTS as the lab of the hidden-effects proof (issue 28, item 5).

    python -m validation.reference.liggghts_labs --out docs/results/liggghts_labs_quick --scale quick \\
        --cases base rolling cohesion rolling+cohesion wide_psd --fills 3 --jobs 2
    python -m validation.reference.liggghts_labs --out docs/results/liggghts_labs_first --scale first \\
        --cases base rolling cohesion rolling+cohesion wide_psd --fills 3 --jobs 2   # ~80 s on 2 cores
    warpdem diagnose docs/results/liggghts_labs_first/diagnose_*.yaml    # all five in one process (CPU)

:mod:`validation.hidden_effects` lets warpdem play the lab; here LIGGGHTS-PUBLIC 3.8 does, through
the fidelity harness (:mod:`validation.reference.liggghts_experiments` writes the deck of each
standard experiment, :mod:`validation.reference.liggghts_readback` measures its dumps with the
project's own measurement code). Every repeat is its own LIGGGHTS run, poured by LIGGGHTS under the
case's full contact law (``fill_mode="poured"``: a real lab never starts from the simulator's fill),
seeded by a fill index from :data:`LAB_FILL_START` on. Cases (:data:`LAB_CASES`):

- ``base``: sliding friction only (the base model is right);
- ``rolling``: LIGGGHTS ``rolling_friction epsd2``, mu_r = 0.15 (pp and pw);
- ``cohesion``: LIGGGHTS ``cohesion sjkr`` (its default ``tangential_reduce off``), k = 3e5 J/m^3;
- ``rolling_cohesion`` (also spelled ``rolling+cohesion``): both at once, the cohesion at 1e5 J/m^3
  (:data:`TWO_EFFECT_COHESION`: with 3e5 the quick-scale material did not flow);
- ``wide_psd``: an effect outside the candidates: the spheres' diameters are uniform by number over
  a range 4x as wide (relative half-width 0.45 instead of 0.11-0.125) at the same number-mean
  diameter as the material the measurement file and the diagnosis config state. None of the
  candidates (rolling resistance, cohesion, particle shape) changes the size distribution.

The true sliding frictions are :data:`validation.hidden_effects.TRUE_FRICTION`, the restitution
each experiment's default (0.6, as the diagnosis config fixes it). Per case it writes, mirroring
:mod:`validation.hidden_effects` (same conditions per scale, reading resolutions and
diagnosis config, with room for two added effects):

Scales (:func:`validation.hidden_effects.conditions`): ``quick`` (the quick presets, 7 observables:
baffle test, drum at 15/30/45 rpm, hollow cylinder; its diagnosis is for a GPU) and ``first`` (the
README's first diagnosis on 2 CPU cores: a 9 kg baffle test of the quick 24-30 mm spheres, static
angle and bulk density, and a 3 kg quick hollow cylinder, pile angle and pile height; the diagnosis
config takes the small ``diagnosis:`` settings of ``validation/configs/first_diagnosis.yaml`` and its
cohesion range, with the three :data:`CANDIDATES`); ``tiny`` (the 9 kg baffle test alone, a smoke
test) and ``paper`` as there.

- ``lab_<case>.yaml``: the measurement file (``warpdem-measurements/2``; a neutral title and source,
  nothing that names the case), the ONLY file a diagnosis reads;
- ``diagnose_<case>.yaml``: the diagnosis config of the base model;
- ``truth_<case>.json``: the hidden model, LIGGGHTS version, deck folder, fills, every run's record
  and wall times, read afterwards by ``benchmarks/score_hidden_effects.py`` alone.

Runs go to ``--runs`` (default ``OUT/runs``): one folder per run with its deck, STL walls and log
(the dumps are deleted once measured unless ``--keep-dumps``); ``OUT/decks/<case>/`` keeps a copy of
the first fill's deck of every condition (5-15 kB each; the other fills differ only in their
insertion seeds).
"""
from __future__ import annotations

import argparse
import concurrent.futures
import datetime as _dt
import json
import math
import platform
import re
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml

import warpdem as wd
from calibration.experiments import make_experiment
from calibration.experiments.common import Experiment
from calibration.materials import BulkMaterial
from warpdem.config_io import load_config_file, write_atomic

from ..hidden_effects import CASES as ENGINE_CASES
from ..hidden_effects import TRUE_FRICTION, _experiment_scale, _observables, conditions, diagnosis_config, lab_material
from .liggghts import INSTALL_HINT, LiggghtsNotFound, liggghts_executable, liggghts_version
from .liggghts_experiments import FILL_MODES, ExperimentDeck, fill_for_index, warpdem_time_step, write_deck
from .liggghts_readback import LiggghtsMeasurement, run_and_measure

__all__ = ["LabCase", "LAB_CASES", "CANDIDATES", "LAB_FILL_START", "canonical_case", "case_material",
           "LabRun", "plan_runs", "lab_deck", "lab_document", "truth_document", "lab_diagnosis_config",
           "generate_labs", "means_table", "main"]

#: the diagnosis's candidate effects (validation.dem_effects names); a lab case is "outside" when
#: what it hides is none of them
CANDIDATES = ("rolling_resistance", "cohesion", "shape")
#: fill index of the first lab repeat: index = start + 1000 * experiment + 100 * condition + repeat
#: (LIGGGHTS insertion seeds grow with it and must stay below 2^31: see _max_fill_index)
LAB_FILL_START = 7000
MAX_FILLS = 100
#: relative half-width of the wide size distribution of ``wide_psd`` (half-width / number-mean diameter)
WIDE_PSD_HALF_WIDTH = 0.45
#: solid volume poured per batch / insertion region volume: the harness's 0.15 left whole batches
#: uninserted in the quick baffle box (27.0-27.3 of 28 kg poured), 0.10 pours the full mass
POUR_BATCH_FRACTION = 0.10
#: cohesion energy density [J/m^3] of the two-effect case: with mu_r = 0.15 and the one-effect
#: case's 3e5 the quick-scale material did not flow (11 of 15 runs unmeasurable: the baffle box's
#: fill stood as a block, the hollow cylinder lifted its fill, the drum's bed slid as a plug), so a
#: third of it (the fidelity harness's sjkr value), which piles at 40 deg in the baffle test
TWO_EFFECT_COHESION = 1.0e5


@dataclass(frozen=True)
class LabCase:
    """One hidden model the lab runs.

    law: warpdem sub-models (a ``wd.ContactLaw`` config mapping; the deck writer maps them to LIGGGHTS);
    parameters: the effect's contact parameters (on top of TRUE_FRICTION); hidden_effects: the
    candidate effects it hides (empty: none of them); psd_half_width: None = the stated size
    distribution, else diameters uniform by number over mean * [1 - w, 1 + w] at the stated
    number-mean diameter; size_classes: equal-number classes the poured fill represents it with;
    outside: words for a hidden effect that is not among :data:`CANDIDATES` (None: there is none)."""

    name: str
    words: str
    law: Mapping[str, str]
    parameters: Mapping[str, float] = field(default_factory=dict)
    hidden_effects: tuple[str, ...] = ()
    psd_half_width: float | None = None
    size_classes: int = 6
    outside: str | None = None

    def contact_parameters(self) -> dict[str, float]:
        """Every contact parameter the deck sets beyond the experiment's defaults."""
        return {**TRUE_FRICTION, **self.parameters}


LAB_CASES: dict[str, LabCase] = {c.name: c for c in (
    LabCase("base", "sliding friction only (the base model is right)", {"rolling": "none"}),
    LabCase("rolling", "hidden rolling resistance (LIGGGHTS rolling_friction epsd2, mu_r = 0.15)",
            {"rolling": "epsd2"}, ENGINE_CASES["rolling"]["parameters"], ("rolling_resistance",)),
    LabCase("cohesion", "hidden cohesion (LIGGGHTS cohesion sjkr, tangential_reduce off, k = 3e5 J/m^3)",
            {"rolling": "none", "cohesion": "sjkr"}, ENGINE_CASES["cohesion"]["parameters"], ("cohesion",)),
    LabCase("rolling_cohesion", "two hidden effects: rolling resistance (epsd2, mu_r = 0.15) and cohesion "
            f"(sjkr, tangential_reduce off, k = {TWO_EFFECT_COHESION:.0e} J/m^3)", {"rolling": "epsd2", "cohesion": "sjkr"},
            {**ENGINE_CASES["rolling"]["parameters"], "cohesion_energy_density_pp": TWO_EFFECT_COHESION,
             "cohesion_energy_density_pw": TWO_EFFECT_COHESION}, ("rolling_resistance", "cohesion")),
    LabCase("wide_psd", f"hidden wide size distribution (diameters uniform by number over mean x "
            f"[{1 - WIDE_PSD_HALF_WIDTH:g}, {1 + WIDE_PSD_HALF_WIDTH:g}] instead of the stated range, same "
            "number-mean diameter): outside the candidates", {"rolling": "none"}, {}, (), WIDE_PSD_HALF_WIDTH, 12,
            "a wider particle-size distribution than the stated one (no candidate changes the sizes)"),
)}
#: other spellings accepted on the command line
CASE_ALIASES = {"rolling+cohesion": "rolling_cohesion"}


def canonical_case(name: str) -> str:
    """The case name used in file names (``rolling+cohesion`` -> ``rolling_cohesion``); ValueError
    for an unknown case."""
    case = CASE_ALIASES.get(name, name)
    if case not in LAB_CASES:
        raise ValueError(f"unknown lab case {name!r}; valid: {sorted(LAB_CASES)} (or {sorted(CASE_ALIASES)})")
    return case


def case_material(case: LabCase, stated: BulkMaterial) -> BulkMaterial:
    """The material the lab pours: the stated one, or spheres of the same particle, solids fraction
    and number-mean diameter over the case's wider range."""
    if case.psd_half_width is None:
        return stated
    if not stated.is_spheres:
        raise ValueError(f"case {case.name}: a size distribution of spheres only, the stated material is {stated.name}")
    d_lo, d_hi = stated.diameter
    mean = 0.5 * (d_lo + d_hi)
    w = float(case.psd_half_width)
    if not 0.0 < w < 1.0:
        raise ValueError(f"case {case.name}: psd_half_width must lie in (0, 1), got {w}")
    lo, hi = mean * (1.0 - w), mean * (1.0 + w)
    return BulkMaterial.spheres(lo, hi, particle=stated.particle, solids_fraction=stated.solids_fraction,
                                name=f"spheres d={lo * 1e3:.3g}-{hi * 1e3:.3g} mm (lab's wide size distribution)")


# --------------------------------------------------------------------------- runs
@dataclass
class LabRun:
    """One LIGGGHTS run: a case, an experiment's condition (its protocol ``settings``) and one fill."""

    case: str
    experiment: str
    condition: str
    settings: dict[str, Any]
    fill_index: int
    folder: Path

    @property
    def label(self) -> str:
        return f"{self.case}/{self.experiment}/{self.condition}/fill{self.fill_index}"


def _max_fill_index(size_classes: int) -> int:
    """Largest fill index whose LIGGGHTS insertion seeds (``_prime_seed(7 * classes * index + k)``,
    about 15485863 + 2000 * that) stay below 2^31."""
    return int((2**31 - 1 - 15485863 - 2000 * (size_classes + 2) - 10_000) / (2000 * 7 * size_classes)) - 1


def plan_runs(cases: list[str], scale: str, fills: int, runs_dir: Path) -> list[LabRun]:
    """Every run of ``cases`` at ``scale`` (:func:`validation.hidden_effects.conditions`), ``fills``
    repeats each; the cases share fill indices (the same insertion seeds, each settling under its
    own law). Longest experiments first within a case (drum, then cylinder, then baffle)."""
    if not 2 <= int(fills) <= MAX_FILLS:
        raise ValueError(f"fills must lie in [2, {MAX_FILLS}] (a standard error needs repeats), got {fills}")
    conds = conditions(scale)
    top = LAB_FILL_START + 1000 * (len(conds) - 1) + 100 * (max(len(c) for c in conds.values()) - 1) + fills - 1
    for c in cases:
        limit = _max_fill_index(LAB_CASES[c].size_classes)
        if top > limit:
            raise ValueError(f"fill index {top} of case {c} exceeds {limit} (LIGGGHTS seeds must stay below 2^31)")
    order = {"drum": 0, "cylinder": 1, "baffle": 2}
    runs = []
    for case in cases:
        mine = []
        for e_i, (exp_name, conds_e) in enumerate(conds.items()):
            for c_i, (cname, settings) in enumerate(conds_e.items()):
                for k in range(int(fills)):
                    index = LAB_FILL_START + 1000 * e_i + 100 * c_i + k
                    mine.append(LabRun(case, exp_name, cname, dict(settings), index,
                                       runs_dir / case / f"{exp_name}_{cname}_fill{index}"))
        runs += sorted(mine, key=lambda r: order.get(r.experiment, 9))
    return runs


def _stated_material(exp_name: str, scale: str) -> BulkMaterial:
    cfg = lab_material(scale)
    if cfg is not None:
        return BulkMaterial.from_config(cfg)
    return make_experiment(exp_name, _experiment_scale(exp_name, scale)).bulk_material()


def lab_deck(run: LabRun, scale: str, fill_mode: str = "poured", dt: float | None = None
             ) -> tuple[Experiment, ExperimentDeck]:
    """The experiment whose protocol measures ``run`` (the stated material) and the LIGGGHTS deck
    that runs it (the case's law, parameters and material; ``dt`` [s]: None = warpdem's
    recommended step for the case's material). The hollow cylinder's lift clearance stays the
    stated material's largest diameter when the lab's material differs (the protocol is the same)."""
    if fill_mode not in FILL_MODES:
        raise ValueError(f"fill_mode must be one of {FILL_MODES}, got {fill_mode!r}")
    case = LAB_CASES[run.case]
    preset = _experiment_scale(run.experiment, scale)
    common = {k: v for k, v in run.settings.items() if k != "rpm"}
    law = wd.ContactLaw.from_config(case.law, f"lab case {run.case}: law")
    stated = _stated_material(run.experiment, scale)
    protocol = make_experiment(run.experiment, preset, contact_law=law, material=stated, fill_per_world=True,
                               first_fill_index=run.fill_index, **common)
    true_material = case_material(case, stated)
    extra: dict[str, Any] = {}
    if true_material is not stated and run.experiment == "cylinder" and protocol.lift_clearance is None:
        extra["lift_clearance"] = 2.0 * stated.max_bounding_radius
    lab = make_experiment(run.experiment, preset, contact_law=law, material=true_material, fill_per_world=True,
                          first_fill_index=run.fill_index, **common, **extra)
    if dt is None:
        dt = warpdem_time_step(lab, fill_for_index(lab, run.fill_index))
    params = case.contact_parameters()
    deck = write_deck(lab, params, fill_mode=fill_mode, fill_index=run.fill_index, dt=dt,
                      rpm=run.settings.get("rpm"), size_classes=case.size_classes,
                      pour_batch_fraction=POUR_BATCH_FRACTION)
    deck.settings["fill_mass_kg"] = float(lab.fill_amount(lab.bulk_material())["mass"])
    return protocol, deck


def _run_one(run: LabRun, protocol: Experiment, deck: ExperimentDeck, keep_dumps: bool,
             timeout_s: float) -> dict[str, Any]:
    """Run one deck and measure it -> its record (a failed LIGGGHTS run is a record with status "failed")."""
    t0 = time.perf_counter()
    poured: dict[str, Any] = {}
    try:
        m, finished = run_and_measure(protocol, deck, run.folder, timeout_s=timeout_s)
        poured = poured_amount(finished.log)
    except Exception as exc:  # noqa: BLE001 - one run failed (error, time-out, unreadable dump): recorded, the rest go on
        m = LiggghtsMeasurement(run.experiment, "failed", f"LIGGGHTS run failed: {type(exc).__name__}: {exc}"[:2000],
                                {k: None for k in protocol.OBSERVABLES})
        m.timing = {"wall_s": round(time.perf_counter() - t0, 3)}
    if not keep_dumps:
        for p in run.folder.glob("*.dump"):
            p.unlink()
        (run.folder / "screen.txt").unlink(missing_ok=True)
    d = m.diagnostics
    keep = {k: d.get(k) for k in ("fill_settled", "fill_settle_s", "particles_after_fill", "particles_before_lift",
                                  "particles_final", "lost_atoms_warnings", "timestep_warnings", "h_fill_m",
                                  "peak_height_m", "mean_diameter_m", "no_pile", "snapshot_std_deg",
                                  "skipped_snapshots") if k in d}
    if poured and deck.fill_mode == "poured":
        keep["poured_mass_kg"] = poured["mass_kg"]
        keep["poured_particles"] = poured["particles"]
        keep["fill_mass_kg"] = deck.settings.get("fill_mass_kg")
        keep["short_insertions"] = poured["short_insertions"]
    return {"case": run.case, "experiment": run.experiment, "condition": run.condition, "settings": run.settings,
            "fill_index": run.fill_index, "status": m.status, "error": m.error, "observables": m.observables,
            "diagnostics": keep, "wall_s": m.timing.get("wall_s"), "dt_s": deck.dt, "n_particles_deck": deck.n_particles,
            "folder": str(run.folder)}


_INSERTED = re.compile(r"a total of (\d+) particle templates \(mass ([0-9.eE+-]+)\) inserted so far")


def poured_amount(log: str) -> dict[str, Any]:
    """What LIGGGHTS poured, from its log: particles and mass [kg] inserted in all, and how many
    batches it could not insert whole ("Less insertions than requested"); {} when nothing was poured."""
    found = _INSERTED.findall(log)
    if not found:
        return {}
    n, mass = found[-1]
    return {"particles": int(n), "mass_kg": float(mass),
            "short_insertions": log.count("Less insertions than requested")}


# --------------------------------------------------------------------------- the three files
#: how the lab file words each fill mode
FILL_WORDS = {"poured": "poured fills", "identical": "started from warpdem's own loose fills"}

def lab_document(records: list[dict[str, Any]], scale: str, observables: Mapping[str, Mapping[str, str]],
                 fill_mode: str = "poured") -> dict[str, Any]:
    """The v2 measurement file of one case's run records (a condition needs 2 measured repeats).
    Nothing in it names the case or the hidden model: failures are given as "not measurable" with
    the measurement's reason (a failed LIGGGHTS run as "the run failed")."""
    experiments: dict[str, Any] = {}
    notes = []
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in records:
        groups.setdefault((r["experiment"], r["condition"]), []).append(r)
    for exp_name, conds in conditions(scale).items():
        for cname, settings in conds.items():
            rs = groups.get((exp_name, cname), [])
            if not rs:
                continue
            ok = [r for r in rs if r["status"] == "ok"]
            failed = [r for r in rs if r["status"] != "ok"]
            if failed:
                why = failed[0]["error"] or "unknown"
                why = "the run failed" if why.startswith("LIGGGHTS run failed") else why
                notes.append(f"{exp_name}/{cname}: {len(failed)} of {len(rs)} repeat(s) not measurable: {why}")
            if len(ok) < 2:
                continue
            measured = [_Observed(r["observables"]) for r in ok]
            experiments.setdefault(exp_name, {"conditions": {}})["conditions"][cname] = {
                "settings": dict(settings), "observables": _observables(dict(observables[exp_name]), measured)}
    doc: dict[str, Any] = {
        "format": "warpdem-measurements/2", "title": f"lab data ({scale} scale)",
        "source": f"validation/reference/liggghts_labs.py: LIGGGHTS-PUBLIC as the lab, {FILL_WORDS[fill_mode]}, "
                  "measured by calibration.measurement; the hidden model is in truth_*.json",
        "experiments": experiments}
    mat = lab_material(scale)
    if mat is not None:
        doc["material"] = mat
    if notes:
        doc["notes"] = "; ".join(notes)
    return doc


@dataclass
class _Observed:
    """A run's observables as :func:`validation.hidden_effects._observables` reads them."""

    observables: dict[str, Any]


def truth_document(case: str, records: list[dict[str, Any]], scale: str, fills: int, fill_mode: str,
                   runs_dir: Path, elapsed_s: float, version: str) -> dict[str, Any]:
    """The truth of one case: the hidden model, where its decks ran and what each run gave."""
    spec = LAB_CASES[case]
    materials = {}
    for exp_name in conditions(scale):
        stated = _stated_material(exp_name, scale)
        true = case_material(spec, stated)
        masses = [r["diagnostics"]["poured_mass_kg"] for r in records
                  if r["experiment"] == exp_name and "poured_mass_kg" in r.get("diagnostics", {})]
        targets = {r["diagnostics"].get("fill_mass_kg") for r in records
                   if r["experiment"] == exp_name and "poured_mass_kg" in r.get("diagnostics", {})}
        materials[exp_name] = {"stated_diameter_m": list(stated.diameter), "lab_diameter_m": list(true.diameter),
                               "size_classes": spec.size_classes,
                               "poured_mass_kg": [min(masses), max(masses)] if masses else None,
                               "fill_mass_kg": sorted(targets)[0] if len(targets) == 1 else sorted(targets) or None}
    return {
        "format": "warpdem-liggghts-lab-truth/1", "case": case, "words": spec.words,
        "hidden": {"law": dict(spec.law), "parameters": dict(spec.parameters), "psd_half_width": spec.psd_half_width},
        "hidden_effects": list(spec.hidden_effects), "outside_candidates": spec.outside,
        "candidates": list(CANDIDATES), "parameters": spec.contact_parameters(), "materials": materials,
        "lab": "LIGGGHTS", "liggghts_version": version, "deck_folder": str(runs_dir / case),
        "fill_mode": fill_mode, "fills": int(fills), "fill_indices": sorted({r["fill_index"] for r in records}),
        "scale": scale, "wall_s": round(elapsed_s, 1),
        "run_wall_s_sum": round(sum(r["wall_s"] or 0.0 for r in records), 1),
        "runs_failed": sum(r["status"] != "ok" for r in records),
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "machine": f"{platform.node()} ({platform.machine()}, {platform.system()})", "runs": records,
    }


#: experiments whose fills warpdem can pour as LIGGGHTS does (``fill_mode: poured``; the drum keeps
#: its own settled fill)
POURED_EXPERIMENTS = ("baffle", "cylinder")


def lab_diagnosis_config(case: str, scale: str, out: Path, fill_mode: str = "poured") -> dict[str, Any]:
    """The diagnosis config of one case: :func:`validation.hidden_effects.diagnosis_config` (the base
    model, sliding frictions calibrated; at ``first`` its small ``diagnosis:`` settings, those of
    ``validation/configs/first_diagnosis.yaml``), the three candidates named, and room for two added
    effects (every case gets the same settings: the diagnosis must not know which case it reads).
    A lab that pours its fills (``fill_mode`` "poured") says so, as a lab's protocol would, and the
    diagnosis pours its fills too where warpdem can (:data:`POURED_EXPERIMENTS`)."""
    cfg = diagnosis_config(case, scale)
    cfg["name"] = f"liggghts-lab-{case}"
    cfg["output"] = str(out / f"diagnosis_{case}")
    cfg["candidates"] = list(CANDIDATES)
    cfg["diagnosis"] = {**cfg.get("diagnosis", {}), "max_added_effects": 2}
    if fill_mode == "poured":
        experiments = dict(cfg.get("experiments") or {})
        for e in POURED_EXPERIMENTS:
            experiments[e] = {**experiments.get(e, {}), "fill_mode": "poured"}
        cfg["experiments"] = experiments
    return cfg


# --------------------------------------------------------------------------- the whole lab
def generate_labs(cases: list[str], out: Path, scale: str = "quick", fills: int = 3, jobs: int = 2,
                  fill_mode: str = "poured", runs_dir: Path | None = None, keep_dumps: bool = False,
                  timeout_s: float = 3600.0, progress: bool = True) -> dict[str, Any]:
    """Run the LIGGGHTS lab for ``cases`` (one case after another, ``jobs`` LIGGGHTS processes at a
    time) and write each case's three files to ``out``. Returns {case: elapsed wall [s]}."""
    exe = liggghts_executable()
    if exe is None:
        raise LiggghtsNotFound(f"the LIGGGHTS lab needs LIGGGHTS; {INSTALL_HINT}")
    if int(jobs) < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    cases = [canonical_case(c) for c in cases]
    out = Path(out)
    runs_dir = Path(runs_dir) if runs_dir is not None else out / "runs"
    plan = plan_runs(cases, scale, fills, runs_dir)
    version = liggghts_version(exe)
    out.mkdir(parents=True, exist_ok=True)
    observables = {e: make_experiment(e, _experiment_scale(e, scale)).OBSERVABLES for e in conditions(scale)}
    walls: dict[str, float] = {}
    for case in cases:
        runs = [r for r in plan if r.case == case]
        t0 = time.perf_counter()
        dts: dict[str, float] = {}
        decks = []
        for run in runs:  # decks first (warpdem's time step per experiment, on the CPU), then LIGGGHTS
            protocol, deck = lab_deck(run, scale, fill_mode, dts.get(run.experiment))
            dts[run.experiment] = deck.dt
            decks.append((run, protocol, deck))
        records = []
        with concurrent.futures.ThreadPoolExecutor(max_workers=int(jobs)) as pool:
            futures = {pool.submit(_run_one, run, protocol, deck, keep_dumps, timeout_s): run
                       for run, protocol, deck in decks}
            for fut in concurrent.futures.as_completed(futures):
                rec = fut.result()
                records.append(rec)
                if progress:
                    obs = ", ".join(f"{k} {v:.4g}" for k, v in rec["observables"].items() if v is not None)
                    print(f"[{len(records)}/{len(decks)}] {futures[fut].label}: {rec['status']} {obs or rec['error']} "
                          f"({rec['wall_s']} s)", flush=True)
        elapsed = time.perf_counter() - t0
        walls[case] = round(elapsed, 1)
        records.sort(key=lambda r: (r["experiment"], r["condition"], r["fill_index"]))
        deck_copies = out / "decks" / case
        deck_copies.mkdir(parents=True, exist_ok=True)
        first = {}
        for run, _, _ in decks:  # the fills of one condition differ only in their insertion seeds
            first.setdefault((run.experiment, run.condition), run)
        for run in first.values():
            if (run.folder / "in.deck").exists():
                shutil.copyfile(run.folder / "in.deck", deck_copies / f"{run.experiment}_{run.condition}_fill{run.fill_index}.deck")
        write_atomic(out / f"lab_{case}.yaml", yaml.safe_dump(lab_document(records, scale, observables, fill_mode),
                                                               sort_keys=False))
        truth = truth_document(case, records, scale, fills, fill_mode, runs_dir, elapsed, version)
        truth["deck_copies"] = str(deck_copies)
        write_atomic(out / f"truth_{case}.json", json.dumps(truth, indent=1, default=str))
        write_atomic(out / f"diagnose_{case}.yaml", yaml.safe_dump(lab_diagnosis_config(case, scale, out, fill_mode),
                                                                    sort_keys=False))
        if progress:
            print(f"case {case}: {len(records)} runs, {truth['runs_failed']} failed, {elapsed:.0f} s", flush=True)
    return {"cases": cases, "wall_s": walls, "liggghts_version": version}


def means_table(out: Path, cases: list[str]) -> str:
    """Markdown table of the lab files in ``out``: per case, the mean of every observable's repeats
    ("no pile n/n" where no repeat formed one), with the repeats' standard deviation."""
    docs = {c: load_config_file(Path(out) / f"lab_{c}.yaml", "measurement file") for c in cases}
    keys: list[tuple[str, str, str, str]] = []
    for doc in docs.values():
        for e, ex in doc.get("experiments", {}).items():
            for cn, cond in ex.get("conditions", {}).items():
                for q, ob in cond.get("observables", {}).items():
                    if (e, cn, q, ob.get("unit", "")) not in keys:
                        keys.append((e, cn, q, ob.get("unit", "")))
    lines = ["| case | " + " | ".join(f"{e} {cn} {q} [{u}]" for e, cn, q, u in keys) + " |",
             "|---|" + "---|" * len(keys)]
    for c, doc in docs.items():
        cells = []
        for e, cn, q, u in keys:
            ob = doc.get("experiments", {}).get(e, {}).get("conditions", {}).get(cn, {}).get("observables", {}).get(q)
            if ob is None:
                cells.append("not measured")
            elif "no_pile" in ob:
                cells.append(f"no pile {ob['no_pile']}/{ob['no_pile']}")
            else:
                v = [float(x) for x in ob["repeats"]]
                mean = sum(v) / len(v)
                sd = math.sqrt(sum((x - mean) ** 2 for x in v) / (len(v) - 1)) if len(v) > 1 else float("nan")
                digits = 3 if u == "m" else 0 if u == "kg/m^3" else 1
                cells.append(f"{mean:.{digits}f} ± {sd:.{digits}f}")
        lines.append(f"| {c} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="folder for lab_/diagnose_/truth_<case> files")
    ap.add_argument("--scale", default="quick", choices=["quick", "first", "tiny", "paper"],
                    help="quick: 7 observables (diagnose on a GPU); first: a 9 kg baffle test and a 3 kg hollow "
                         "cylinder, 4 observables (diagnose on 2 CPU cores); tiny: the baffle test alone")
    ap.add_argument("--cases", nargs="+", default=list(LAB_CASES), metavar="CASE",
                    help=f"cases (default all): {', '.join(LAB_CASES)} (rolling+cohesion = rolling_cohesion)")
    ap.add_argument("--fills", type=int, default=3, help="repeats (poured fills) per condition, >= 2")
    ap.add_argument("--jobs", type=int, default=2, help="LIGGGHTS processes at a time")
    ap.add_argument("--fill-mode", default="poured", choices=list(FILL_MODES),
                    help="poured: LIGGGHTS pours its own fills (default); identical: warpdem's fills")
    ap.add_argument("--runs", default=None, help="folder for the run folders (default OUT/runs)")
    ap.add_argument("--keep-dumps", action="store_true", help="keep the dump files of every run")
    ap.add_argument("--timeout", type=float, default=3600.0, help="limit per LIGGGHTS run [s]")
    ap.add_argument("--table", action="store_true", help="print the observables' means of OUT's lab files, run nothing")
    args = ap.parse_args(argv)
    try:
        cases = [canonical_case(c) for c in args.cases]
    except ValueError as e:
        ap.error(str(e))
    if args.table:
        print(means_table(Path(args.out), [c for c in cases if (Path(args.out) / f"lab_{c}.yaml").exists()]), end="")
        return 0
    if not 2 <= args.fills <= MAX_FILLS:
        ap.error(f"--fills must lie in [2, {MAX_FILLS}]")
    if args.jobs < 1:
        ap.error("--jobs must be >= 1")
    try:
        res = generate_labs(cases, Path(args.out), args.scale, args.fills, args.jobs, args.fill_mode,
                            Path(args.runs) if args.runs else None, args.keep_dumps, args.timeout)
    except LiggghtsNotFound as e:
        print(f"liggghts_labs: {e}")
        return 2
    print(json.dumps(res), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
