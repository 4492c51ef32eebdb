"""Synthetic "lab" data with a hidden physical effect, for proving the diagnosis honestly.

    python -m validation.hidden_effects --out lab --scale paper --device cuda        # 4 cases
    python -m validation.hidden_effects --out lab --scale quick --cases base rolling
    python -m validation.hidden_effects --measure drum 60rpm '{"rpm": 60, "discard": 1, "record": 2}' \
        --truth lab/truth_cohesion.json --lab lab/lab_cohesion.yaml --into lab/lab_cohesion_60rpm.yaml
    python -m validation.hidden_effects --measure-recommended lab/diagnosis_cohesion/diagnosis.json \
        --truth lab/truth_cohesion.json --lab lab/lab_cohesion.yaml --into lab/lab_cohesion_next.yaml

For every case the engine plays the lab: the true model (sliding friction only, or with hidden
rolling resistance, cohesion or elongated particles) runs the experiments the measurement file
lists, each repeat with its own loose fill drawn from a block of fill indices that no diagnosis
design uses. All cases run in one launch per experiment: the lab model is the union of the
effects (LIGGGHTS epsd2 rolling, SJKR cohesion, elongated clumps), each case's absent effects at
their off value, which adds exactly nothing. It writes, per case,

- ``lab_<case>.yaml``: the measurement file (``warpdem-measurements/2``): A static angle and bulk
  density, B dynamic angle at 15, 30 and 45 rpm, C pile angle (or "no pile") and pile height,
  each with its protocol settings and its repeats; this is the ONLY file a diagnosis reads;
- ``diagnose_<case>.yaml``: a diagnosis config of the base model (sliding frictions only);
- ``truth_<case>.json``: the hidden model and parameters, kept apart for the scoring afterwards.

Scales: "paper" (spheres 16-20 mm by number, 16 kg box, paper drum (one revolution discarded, two
recorded), 10 kg hollow cylinder lifted at 0.1 m/s; GPU), "quick" (the quick presets; a few minutes on 2 CPU cores),
"first" (the 9 kg baffle test and a 3 kg quick hollow cylinder: the README's first diagnosis on 2 CPU
cores) and "tiny" (a 9 kg baffle test only, for the smoke test of the whole chain).
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from calibration.experiments import make_experiment
from calibration.materials import BulkMaterial
import warpdem as wd
from warpdem.config_io import load_config_file, write_atomic

__all__ = ["CASES", "generate_case", "generate_cases", "measure_later", "recommended_measurement", "main"]

#: loose-fill indices of the "lab" repeats: far from the diagnosis designs (validation.dem_forward)
LAB_FILLS = 50_000_000

#: the true sliding frictions of every case, and what each case hides
TRUE_FRICTION = {"mu_s_pp": 0.45, "mu_s_pw": 0.35}
CASES: dict[str, dict[str, Any]] = {
    "base": {"law": {"rolling": "none"}, "parameters": {}, "shape": None,
             "words": "sliding friction only (the base model is right)"},
    "rolling": {"law": {"rolling": "epsd2"}, "parameters": {"mu_r_pp": 0.15, "mu_r_pw": 0.15}, "shape": None,
                "words": "hidden rolling resistance (LIGGGHTS epsd2, mu_r = 0.15)"},
    "cohesion": {"law": {"rolling": "none", "cohesion": "sjkr"},
                 "parameters": {"cohesion_energy_density_pp": 3.0e5, "cohesion_energy_density_pw": 3.0e5},
                 "shape": None, "words": "hidden cohesion (SJKR, k = 3e5 J/m^3)"},
    "shape": {"law": {"rolling": "none"}, "parameters": {}, "shape": {"family": "elongated", "aspect_ratio": 1.8},
              "words": "hidden particle shape (rods of aspect ratio 1.8)"},
}


def conditions(scale: str) -> dict[str, dict[str, dict[str, Any]]]:
    """Experiment -> condition name -> protocol settings the lab used (and the model must use)."""
    if scale == "paper":
        return {"baffle": {"16kg": {"fill_mass": 16.0}},
                "drum": {f"{r}rpm": {"rpm": float(r), "discard": 1, "record": 2} for r in (15, 30, 45)},
                "cylinder": {"10kg": {"fill_mass": 10.0, "lift_speed": 0.1}}}
    tiny_baffle = {"9kg": {"fill_mass": 9.0, "lift_to": 0.25, "max_time_after_lift": 1.5, "min_bins": 2}}
    if scale == "tiny":  # a smoke test of the whole chain in seconds (quick presets, small fills)
        return {"baffle": tiny_baffle}
    if scale == "first":  # the README's first diagnosis: the tiny baffle test and a small pile (2 CPU cores)
        return {"baffle": tiny_baffle, "cylinder": {"3kg": {"fill_mass": 3.0}}}
    return {"baffle": {"quick": {}}, "drum": {f"{r}rpm": {"rpm": float(r)} for r in (15, 30, 45)},
            "cylinder": {"quick": {}}}


def lab_material(scale: str) -> dict[str, Any] | None:
    """The material the lab measured, as a config (None: each quick preset's own)."""
    return {"type": "spheres", "diameter": [0.016, 0.020]} if scale == "paper" else None


def _experiment_scale(exp: str, scale: str) -> str:
    """The experiment preset of a lab scale ("tiny" and "first" run the quick presets with small fills)."""
    return "quick" if scale in ("tiny", "first") else scale


#: the lab holds every case in one model: the union of the effects, each case's absent effects at
#: their off value (rolling friction 0, cohesion 0, aspect ratio 1), which adds exactly nothing
LAB_LAW = {"rolling": "epsd2", "cohesion": "sjkr"}
OFF = {"mu_r_pp": 0.0, "mu_r_pw": 0.0, "cohesion_energy_density_pp": 0.0, "cohesion_energy_density_pw": 0.0,
       "aspect_ratio": 1.0}


def case_parameters(case: str) -> dict[str, float]:
    """Every parameter of the lab's union model for one case."""
    spec = CASES[case]
    shape = {k: v for k, v in (spec["shape"] or {}).items() if k != "family"}
    return {**TRUE_FRICTION, **OFF, **spec["parameters"], **shape}


def _run_lab(cases: list[str], conds: dict[str, dict[str, dict[str, Any]]], scale: str, repeats: int,
             device: str | None, processes: Any, progress: bool, dt: float | None,
             first_fill: int) -> tuple[dict[str, Any], dict[str, list[str]], list[dict[str, Any]]]:
    """Run the lab's union model for ``cases`` at ``conds`` (experiment -> condition -> settings):
    one launch per experiment and condition group (every case, drum speed and repeat is a world),
    loose fills numbered from ``first_fill``. Returns each case's v2 ``experiments`` section, the
    notes on repeats that could not be measured, and one record per launch."""
    numerics = {} if dt is None else {"dt": float(dt), "force_dt": True}
    law = wd.ContactLaw.from_config(LAB_LAW)
    mat_cfg = lab_material(scale)
    experiments: dict[str, dict[str, Any]] = {c: {} for c in cases}
    notes: dict[str, list[str]] = {}
    launches = []
    for e_i, (exp_name, conds_e) in enumerate(conds.items()):
        # conditions differing only in drum speed run in one launch (rpm is per world)
        groups: dict[str, list[tuple[str, dict]]] = {}
        for cname, settings in conds_e.items():
            key = json.dumps({k: v for k, v in settings.items() if k != "rpm"}, sort_keys=True)
            groups.setdefault(key, []).append((cname, settings))
        for gi, (key, members) in enumerate(groups.items()):
            common = json.loads(key)
            base_mat = (BulkMaterial.from_config(mat_cfg) if mat_cfg is not None
                        else make_experiment(exp_name, _experiment_scale(exp_name, scale)).bulk_material())
            d = base_mat.diameter
            material = BulkMaterial.shaped("elongated", d[0], d[1], particle=base_mat.particle,
                                           solids_fraction=base_mat.solids_fraction, aspect_ratio=1.0)
            first = first_fill + 10_000 * e_i + 1000 * gi
            exp = make_experiment(exp_name, _experiment_scale(exp_name, scale), contact_law=law, material=material,
                                  fill_per_world=True, first_fill_index=first, **common, **numerics)
            sets, where = [], []
            for case in cases:
                for cname, settings in members:
                    for _ in range(repeats):
                        s = case_parameters(case)
                        if "rpm" in settings:
                            s["rpm"] = settings["rpm"]
                        sets.append(s)
                        where.append((case, cname))
            t1 = time.perf_counter()
            results = exp.run(sets, device=device, progress=progress, processes=processes)
            launches.append({"experiment": exp_name, "worlds": len(sets), "wall_s": round(time.perf_counter() - t1, 1),
                             "spheres": results[0].timing.get("spheres") if results else None,
                             "dt_s": results[0].timing.get("dt_s") if results else None})
            for case in cases:
                for cname, settings in members:
                    rs = [r for r, w in zip(results, where) if w == (case, cname)]
                    failed = [r.error for r in rs if not r.ok]
                    if failed:  # a lab that could not read a repeat reports the others, and says so
                        notes.setdefault(case, []).append(f"{exp_name}/{cname}: {len(failed)} of {len(rs)} "
                                                          f"repeat(s) not measurable: {failed[0]}")
                    rs = [r for r in rs if r.ok]
                    if len(rs) < 2:
                        continue
                    experiments[case].setdefault(exp_name, {"conditions": {}})["conditions"][cname] = {
                        "settings": dict(settings), "observables": _observables(type(exp).OBSERVABLES, rs)}
    return experiments, notes, launches


#: fill indices between two lab seeds (a lab uses fewer than 100,000: 10,000 per experiment)
LAB_SEED_STRIDE = 100_000


def generate_cases(cases: list[str], out: Path, scale: str = "paper", repeats: int = 3, device: str | None = None,
                   processes: Any = "auto", progress: bool = False, dt: float | None = None,
                   lab_seed: int = 0) -> dict[str, Any]:
    """Run the lab for several cases at once (one launch per experiment and condition group: every
    case, drum speed and repeat is a world) and write each case's measurement file, diagnosis
    config and truth. ``dt`` [s]: a fixed time step for every launch (the diagnosis config then
    uses the same), else each batch's recommended step. ``lab_seed``: another lab of the same
    material and hidden model, i.e. other fills (block ``lab_seed`` of :data:`LAB_SEED_STRIDE`
    fill indices from :data:`LAB_FILLS`; 0: the shipped labs)."""
    if isinstance(lab_seed, bool) or not isinstance(lab_seed, int) or not 0 <= lab_seed < 50:
        raise ValueError(f"lab_seed must be a whole number in [0, 50), got {lab_seed!r}")
    law = wd.ContactLaw.from_config(LAB_LAW)
    mat_cfg = lab_material(scale)
    t0 = time.perf_counter()
    experiments, notes, launches = _run_lab(cases, conditions(scale), scale, repeats, device, processes, progress,
                                            dt, LAB_FILLS + LAB_SEED_STRIDE * lab_seed)
    wall = round(time.perf_counter() - t0, 1)
    out.mkdir(parents=True, exist_ok=True)
    for case in cases:
        doc = {"format": "warpdem-measurements/2",
               "title": f"synthetic lab data ({scale} scale)",  # no case name: the truth stays in truth_*.json
               "source": "validation/hidden_effects.py: the engine as the lab; the hidden model is in truth_*.json",
               "experiments": experiments[case]}
        if mat_cfg is not None:
            doc["material"] = mat_cfg
        if notes.get(case):
            doc["notes"] = "; ".join(notes[case])
        write_atomic(out / f"lab_{case}.yaml", yaml.safe_dump(doc, sort_keys=False))
        truth = {"case": case, "words": CASES[case]["words"], "hidden": CASES[case], "parameters": case_parameters(case),
                 "lab_model": {"contact_law": law.to_record(),
                               "material": "elongated family over the size range, aspect_ratio per case "
                                           "(1 = spheres in 5 equal-number size classes)"},
                 "scale": scale, "repeats": repeats, "dt_s": dt, "lab_seed": lab_seed, "notes": notes.get(case, []),
                 "wall_s_all_cases": wall,
                 "launches": launches,
                 "device": str(device or "default")}
        write_atomic(out / f"truth_{case}.json", json.dumps(truth, indent=1, default=str))
        cfg = diagnosis_config(case, scale, dt)
        cfg["output"] = str(out / f"diagnosis_{case}")
        write_atomic(out / f"diagnose_{case}.yaml", yaml.safe_dump(cfg, sort_keys=False))
    return {"cases": cases, "wall_s": wall, "launches": launches}


#: loose fills of later measurements (what a diagnosis proposed): block k starts here + k * 1e6
LATER_FILLS = LAB_FILLS + 5_000_000


def recommended_measurement(diagnosis_json: Path) -> tuple[str, str, dict[str, Any], int]:
    """``(experiment, condition, settings, repeats)`` of the measurement a diagnosis recommended to tell
    tied candidates apart (the ``recommended`` proposal of its last round with one), from its
    ``diagnosis.json``. The condition is named after the key's middle part (``drum/60rpm/...`` ->
    ``60rpm``). Raises ValueError when the diagnosis recommended none."""
    doc = json.loads(Path(diagnosis_json).read_text())
    for rnd in reversed(doc.get("rounds") or []):
        disc = rnd.get("discrimination") or {}
        key = disc.get("recommended")
        if not key:
            continue
        for f in disc.get("forecasts", []):
            prop = f["proposal"]
            if prop["key"] == key:
                parts = key.split("/")
                condition = parts[1] if len(parts) == 3 else prop.get("label", key).replace(" ", "_")
                return prop["experiment"], condition, dict(prop["condition"]), int(prop.get("n_repeats") or 3)
    raise ValueError(f"{diagnosis_json} recommends no measurement (no tie, or no proposal separates the tied candidates)")


def measure_later(truth_path: Path, lab_path: Path, out_path: Path, experiment: str, condition: str,
                  settings: dict[str, Any], repeats: int | None = None, device: str | None = None,
                  processes: Any = "auto", progress: bool = False, dt: float | None = None,
                  fill_block: int = 0) -> dict[str, Any]:
    """The lab measures one more condition (e.g. the drum at 60 rpm that a diagnosis proposed to tell
    two tied candidates apart) with the hidden model of ``truth_path``, and writes ``lab_path``'s
    measurements plus that condition to ``out_path``. Fresh fills (block ``fill_block`` of
    :data:`LATER_FILLS`), the truth's scale, repeats and fixed time step unless given. Only the lab reads the truth;
    a diagnosis of ``out_path`` reads that file alone."""
    truth = json.loads(Path(truth_path).read_text())
    case, scale = truth["case"], truth["scale"]
    repeats = int(repeats or truth.get("repeats", 3))
    dt = dt if dt is not None else truth.get("dt_s")  # the lab's fixed step, where it recorded one
    doc = load_config_file(lab_path, "measurement file")
    known = doc.get("experiments", {}).get(experiment, {}).get("conditions", {})
    if condition in known:
        raise ValueError(f"{lab_path} already holds {experiment}/{condition}; name the new condition differently")
    t0 = time.perf_counter()
    experiments, notes, launches = _run_lab([case], {experiment: {condition: dict(settings)}}, scale, repeats, device,
                                            processes, progress, dt, LATER_FILLS + 1_000_000 * int(fill_block))
    got = experiments[case].get(experiment, {}).get("conditions", {}).get(condition)
    if got is None:
        raise RuntimeError(f"the lab could not measure {experiment}/{condition}: {'; '.join(notes.get(case, []))}")
    doc.setdefault("experiments", {}).setdefault(experiment, {"conditions": {}})["conditions"][condition] = got
    if notes.get(case):
        doc["notes"] = "; ".join(filter(None, [doc.get("notes"), *notes[case]]))
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(out_path, yaml.safe_dump(doc, sort_keys=False))
    return {"case": case, "condition": f"{experiment}/{condition}", "observables": got["observables"],
            "wall_s": round(time.perf_counter() - t0, 1), "launches": launches}


def generate_case(case: str, out: Path, scale: str = "paper", repeats: int = 3, device: str | None = None,
                  processes: Any = "auto", progress: bool = False) -> dict[str, Any]:
    """:func:`generate_cases` for one case."""
    return generate_cases([case], out, scale, repeats, device, processes, progress)


# The synthetic lab's instruments: an angle is read to 0.5 deg (a protractor, or a line fitted to
# a photographed slope), a bulk density to 1 kg/m^3 (scale and box volume), a height to 1 mm.
# A "no pile" reading needs one: with every repeat flat there is no scatter to estimate from.
READING_RESOLUTION = {"deg": 0.5, "kg/m^3": 1.0, "m": 0.001}


def add_reading_resolution(doc: dict[str, Any]) -> dict[str, Any]:
    """Give every observable of a v2 measurement document the lab's reading resolution for its unit
    (:data:`READING_RESOLUTION`); an observable that already states one keeps it."""
    for exp in doc.get("experiments", {}).values():
        for cond in exp.get("conditions", {}).values():
            for ob in cond.get("observables", {}).values():
                _state_resolution(ob)
    return doc


def _state_resolution(ob: dict[str, Any]) -> None:
    """Set an observable's ``resolution`` from its unit unless it states one."""
    if "resolution" not in ob and ob.get("unit") in READING_RESOLUTION:
        ob["resolution"] = READING_RESOLUTION[ob["unit"]]


def _observables(reported: dict[str, str], rs: list) -> dict[str, Any]:
    """The v2 observables of one condition from its repeats ("no pile" when no repeat formed one),
    each with the lab's reading resolution."""
    obs: dict[str, Any] = {}
    for q, unit in reported.items():
        if q == "pile_formed":
            continue
        vals = [r.observables.get(q) for r in rs]
        if q == "pile_angle":
            formed = [r.observables.get("pile_formed", 1.0) for r in rs]
            if all(f == 0.0 for f in formed):
                obs[q] = {"unit": unit, "no_pile": len(rs)}
                continue
        if any(v is None for v in vals):
            continue
        obs[q] = {"unit": unit, "repeats": [round(float(v), 6) for v in vals]}
    for ob in obs.values():
        _state_resolution(ob)
    return obs


def diagnosis_config(case: str, scale: str, dt: float | None = None) -> dict[str, Any]:
    """A base-model diagnosis of one case: sliding frictions calibrated, every effect a candidate."""
    cfg: dict[str, Any] = {
        "name": f"hidden-{case}", "measurements": f"lab_{case}.yaml", "output": f"diagnosis_{case}",
        "scale": _experiment_scale("", scale), "model": {"contact_law": {"rolling": "none"}},
        "parameters": {"mu_s_pp": [0.1, 0.9], "mu_s_pw": [0.1, 0.9]},
        "fixed": {"restitution_pp": 0.6, "restitution_pw": 0.6},
        "candidates": "default",
        # every case's diagnosis shares one DEM cache: the designs do not depend on the data
        "cache": "dem_cache.jsonl",
    }
    if dt is not None:  # the lab's fixed step: the model must integrate as the lab did
        cfg["experiments"] = {e: {"dt": float(dt), "force_dt": True} for e in conditions(scale)}
    if scale == "paper":
        cfg["effect_ranges"] = {"cohesion_energy_density_pp": [0.0, 5.0e5], "cohesion_energy_density_pw": [0.0, 5.0e5]}
        cfg["diagnosis"] = {"design_points_per_parameter": 6, "min_design_points": 12, "replicates": 2,
                            "confirm_replicates": 2, "refine_points": 6}
    if scale != "paper":
        cfg["model"]["material"] = None
    if scale == "first":
        cfg["candidates"] = ["rolling_resistance", "cohesion"]
        cfg["effect_ranges"] = {"cohesion_energy_density_pp": [0.0, 3.0e5], "cohesion_energy_density_pw": [0.0, 3.0e5]}
        cfg["diagnosis"] = {"design_points_per_parameter": 2, "min_design_points": 6, "replicates": 2,
                            "confirm_replicates": 2, "refine_points": 0, "scan_points": 1024,
                            "evidence_samples": 1024, "gp_restarts": 0, "cv_folds": 3}
    if scale == "tiny":
        cfg["candidates"] = ["rolling_resistance"]
        cfg["diagnosis"] = {"design_points_per_parameter": 2, "min_design_points": 5, "replicates": 2,
                            "confirm_replicates": 2, "refine_points": 0, "scan_points": 512,
                            "evidence_samples": 512, "gp_restarts": 0, "cv_folds": 2}
    return cfg


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/hidden_effects")
    ap.add_argument("--scale", default="paper", choices=["paper", "quick", "first", "tiny"])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--repeats", type=int, default=None, help="fills per condition (default 3; with --measure: the lab's)")
    ap.add_argument("--device", default=None)
    ap.add_argument("--processes", default="auto")
    ap.add_argument("--progress", action="store_true")
    ap.add_argument("--dt", type=float, default=None, help="fixed time step [s] for the lab and the diagnosis")
    ap.add_argument("--lab-seed", type=int, default=0, help="another lab of the same hidden model: other fills "
                    "(0: the shipped labs; 0-49)")
    ap.add_argument("--measure", nargs=3, metavar=("EXPERIMENT", "CONDITION", "SETTINGS_JSON"), default=None,
                    help="measure one more condition of an existing lab (with --truth, --lab, --into), e.g. "
                         "drum 60rpm '{\"rpm\": 60, \"discard\": 1, \"record\": 2}'")
    ap.add_argument("--measure-recommended", default=None, metavar="DIAGNOSIS_JSON",
                    help="measure what this diagnosis.json recommended (its tie's proposal, with its repeats); "
                         "with --truth, --lab, --into")
    ap.add_argument("--truth", default=None, help="with --measure: the case's truth_<case>.json")
    ap.add_argument("--lab", default=None, help="with --measure: the case's measurement file")
    ap.add_argument("--into", default=None, help="with --measure: the new measurement file to write")
    ap.add_argument("--fill-block", type=int, default=0, help="with --measure: block of fresh fills (0, 1, ...)")
    args = ap.parse_args(argv)
    if args.repeats is not None and args.repeats < 2:
        ap.error("--repeats must be >= 2 (a standard error needs repeats)")
    if args.measure is not None or args.measure_recommended is not None:
        if args.measure is not None and args.measure_recommended is not None:
            ap.error("give --measure or --measure-recommended, not both")
        if not (args.truth and args.lab and args.into):
            ap.error("--measure and --measure-recommended need --truth, --lab and --into")
        repeats = args.repeats
        if args.measure_recommended is not None:
            try:
                experiment, condition, settings, proposed_repeats = recommended_measurement(Path(args.measure_recommended))
            except (ValueError, FileNotFoundError, KeyError) as e:
                print(f"hidden_effects --measure-recommended: {e}")
                return 2
            repeats = repeats or proposed_repeats
        else:
            experiment, condition, settings_json = args.measure
            try:
                settings = json.loads(settings_json)
            except json.JSONDecodeError as e:
                ap.error(f"--measure SETTINGS_JSON is not JSON: {e}")
            if not isinstance(settings, dict):
                ap.error("--measure SETTINGS_JSON must be a JSON object, e.g. '{\"rpm\": 60}'")
        try:
            res = measure_later(Path(args.truth), Path(args.lab), Path(args.into), experiment, condition, settings,
                                repeats, args.device, args.processes, args.progress, args.dt, args.fill_block)
        except (ValueError, FileNotFoundError, RuntimeError) as e:
            print(f"hidden_effects --measure: {e}")
            return 2
        print(json.dumps(res), flush=True)
        return 0
    if not 0 <= args.lab_seed < 50:
        ap.error("--lab-seed must be in 0-49")
    res = generate_cases(list(args.cases), Path(args.out), args.scale, args.repeats or 3, args.device, args.processes,
                         args.progress, args.dt, args.lab_seed)
    print(json.dumps(res), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
