"""Synthetic "lab" data with a hidden physical effect, for proving the diagnosis honestly.

    python -m validation.hidden_effects --out lab --scale paper --device cuda        # 4 cases
    python -m validation.hidden_effects --out lab --scale quick --cases base rolling

For every case the engine plays the lab: the true model (sliding friction only, or with hidden
rolling resistance, cohesion or elongated particles) runs the experiments the measurement file
lists, each repeat with its own loose fill drawn from a block of fill indices that no diagnosis
design uses. It writes, per case,

- ``lab_<case>.yaml``: the measurement file (``warpdem-measurements/2``): A static angle and bulk
  density, B dynamic angle at 15, 30 and 45 rpm, C pile angle (or "no pile") and pile height,
  each with its protocol settings and its repeats; this is the ONLY file a diagnosis reads;
- ``diagnose_<case>.yaml``: a diagnosis config of the base model (sliding frictions only);
- ``truth_<case>.json``: the hidden model and parameters, kept apart for the scoring afterwards.

Scales: "paper" (spheres 16-20 mm by number, 16 kg box, paper drum, 10 kg hollow cylinder lifted
at 0.05 m/s; GPU), "quick" (the quick presets; a few minutes on 2 CPU cores) and "tiny" (a 9 kg
baffle test only, for the smoke test of the whole chain).
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
from calibration.model_description import contact_law_to_dict
import warpdem as wd

__all__ = ["CASES", "generate_case", "main"]

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
                 "parameters": {"cohesion_energy_density_pp": 8.0e4, "cohesion_energy_density_pw": 8.0e4},
                 "shape": None, "words": "hidden cohesion (SJKR, k = 8e4 J/m^3)"},
    "shape": {"law": {"rolling": "none"}, "parameters": {}, "shape": {"family": "elongated", "aspect_ratio": 1.8},
              "words": "hidden particle shape (rods of aspect ratio 1.8)"},
}


def conditions(scale: str) -> dict[str, dict[str, dict[str, Any]]]:
    """Experiment -> condition name -> protocol settings the lab used (and the model must use)."""
    if scale == "paper":
        return {"baffle": {"16kg": {"fill_mass": 16.0}},
                "drum": {f"{r}rpm": {"rpm": float(r), "discard": 1, "record": 3} for r in (15, 30, 45)},
                "cylinder": {"10kg": {"fill_mass": 10.0, "lift_speed": 0.05}}}
    if scale == "tiny":  # a smoke test of the whole chain in seconds (quick presets, small fills)
        return {"baffle": {"9kg": {"fill_mass": 9.0, "lift_to": 0.25, "max_time_after_lift": 1.5, "min_bins": 2}}}
    return {"baffle": {"quick": {}}, "drum": {f"{r}rpm": {"rpm": float(r)} for r in (15, 30, 45)},
            "cylinder": {"quick": {}}}


def lab_material(scale: str) -> dict[str, Any] | None:
    """The material the lab measured, as a config (None: each quick preset's own)."""
    return {"type": "spheres", "diameter": [0.016, 0.020]} if scale == "paper" else None


def _experiment_scale(exp: str, scale: str) -> str:
    """The experiment preset of a lab scale ("tiny" runs the quick presets with small fills)."""
    return "quick" if scale == "tiny" else scale


def generate_case(case: str, out: Path, scale: str = "paper", repeats: int = 3, device: str | None = None,
                  processes: Any = "auto", progress: bool = False) -> dict[str, Any]:
    """Run the lab for one case and write its measurement file, diagnosis config and truth."""
    spec = CASES[case]
    law = wd.ContactLaw(**spec["law"])
    mat_cfg = lab_material(scale)
    params = {**TRUE_FRICTION, **spec["parameters"]}
    t0 = time.perf_counter()
    experiments: dict[str, Any] = {}
    launches = []
    for exp_name, conds in conditions(scale).items():
        # conditions differing only in drum speed run in one launch (rpm is per world)
        groups: dict[str, list[tuple[str, dict]]] = {}
        for cname, settings in conds.items():
            key = json.dumps({k: v for k, v in settings.items() if k != "rpm"}, sort_keys=True)
            groups.setdefault(key, []).append((cname, settings))
        for gi, (key, members) in enumerate(groups.items()):
            common = json.loads(key)
            base_mat = (BulkMaterial.from_config(mat_cfg) if mat_cfg is not None
                        else make_experiment(exp_name, _experiment_scale(exp_name, scale)).bulk_material())
            material = base_mat
            if spec["shape"] is not None:
                shape = dict(spec["shape"])
                fam = shape.pop("family")
                d = base_mat.diameter
                material = BulkMaterial.shaped(fam, d[0], d[1], particle=base_mat.particle,
                                               solids_fraction=base_mat.solids_fraction, **shape)
            first = LAB_FILLS + 100_000 * (list(CASES).index(case)) + 1000 * gi + 10_000 * list(conditions(scale)).index(exp_name)
            exp = make_experiment(exp_name, _experiment_scale(exp_name, scale), contact_law=law, material=material,
                                  fill_per_world=True, first_fill_index=first, **common)
            sets = []
            for cname, settings in members:
                for _ in range(repeats):
                    s = dict(params)
                    if "rpm" in settings:
                        s["rpm"] = settings["rpm"]
                    sets.append(s)
            t1 = time.perf_counter()
            results = exp.run(sets, device=device, progress=progress, processes=processes)
            launches.append({"experiment": exp_name, "worlds": len(sets), "wall_s": round(time.perf_counter() - t1, 1),
                             "spheres": results[0].timing.get("spheres") if results else None})
            for m_i, (cname, settings) in enumerate(members):
                rs = results[m_i * repeats:(m_i + 1) * repeats]
                failed = [r.error for r in rs if not r.ok]
                if failed:
                    raise RuntimeError(f"lab case {case}: {exp_name}/{cname} failed: {failed}")
                obs: dict[str, Any] = {}
                for q, unit in type(exp).OBSERVABLES.items():
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
                experiments.setdefault(exp_name, {"conditions": {}})["conditions"][cname] = {
                    "settings": dict(settings), "observables": obs}
    doc = {"format": "warpdem-measurements/2",
           "title": f"synthetic lab data, case '{case}' ({scale} scale)",
           "source": "validation/hidden_effects.py: the engine as the lab; the hidden model is in truth_*.json",
           "experiments": experiments}
    if mat_cfg is not None:
        doc["material"] = mat_cfg
    out.mkdir(parents=True, exist_ok=True)
    (out / f"lab_{case}.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    truth = {"case": case, "words": spec["words"], "contact_law": contact_law_to_dict(law), "parameters": params,
             "shape": spec["shape"], "scale": scale, "repeats": repeats, "wall_s": round(time.perf_counter() - t0, 1),
             "launches": launches, "device": str(device or "default")}
    (out / f"truth_{case}.json").write_text(json.dumps(truth, indent=1, default=str))
    (out / f"diagnose_{case}.yaml").write_text(yaml.safe_dump(diagnosis_config(case, scale), sort_keys=False))
    return truth


def diagnosis_config(case: str, scale: str) -> dict[str, Any]:
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
    if scale != "paper":
        cfg["model"]["material"] = None
    if scale == "tiny":
        cfg["candidates"] = ["rolling_resistance"]
        cfg["diagnosis"] = {"design_points_per_parameter": 2, "min_design_points": 5, "replicates": 2,
                            "confirm_replicates": 2, "refine_points": 0, "scan_points": 512,
                            "evidence_samples": 512, "gp_restarts": 0, "cv_folds": 2}
    return cfg


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/hidden_effects")
    ap.add_argument("--scale", default="paper", choices=["paper", "quick", "tiny"])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--device", default=None)
    ap.add_argument("--processes", default="auto")
    ap.add_argument("--progress", action="store_true")
    args = ap.parse_args(argv)
    if args.repeats < 2:
        ap.error("--repeats must be >= 2 (a standard error needs repeats)")
    for case in args.cases:
        truth = generate_case(case, Path(args.out), args.scale, args.repeats, args.device, args.processes,
                              args.progress)
        print(json.dumps({"case": case, "wall_s": truth["wall_s"], "launches": truth["launches"]}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
