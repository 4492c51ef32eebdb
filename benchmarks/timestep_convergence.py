"""Time-step convergence of the standard experiments (issue 10, "Time step and damping").

For each material/law (spheres + epsd2 rolling resistance, spheres + epsd, rods of aspect ratio 2 (5 members),
...) and each experiment (A; B at 15, 30 and 45 rpm in one launch; C), run the same fills at
several time steps given as fractions of the smallest sphere's Rayleigh time, and report the
mean angle and its change against the smallest step. One JSON line per (case, experiment, step).

    python benchmarks/timestep_convergence.py --device cuda --fractions 0.2 0.1 0.05 --fills 4
    python benchmarks/timestep_convergence.py --scale quick --experiments baffle --fractions 0.2 0.1
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import warp as wp

import warpdem as wd
from calibration.experiments import make_experiment
from calibration.materials import BulkMaterial

CASES = {
    # name: (contact law, material config or None = preset, parameters)
    "spheres_epsd2": ({"rolling": "epsd2"}, {"type": "spheres", "diameter": [0.016, 0.020]},
                      {"mu_s_pp": 0.45, "mu_s_pw": 0.35, "mu_r_pp": 0.15, "mu_r_pw": 0.15}),
    "spheres_epsd": ({"rolling": "epsd"}, {"type": "spheres", "diameter": [0.016, 0.020]},
                     {"mu_s_pp": 0.45, "mu_s_pw": 0.35, "mu_r_pp": 0.15, "mu_r_pw": 0.15}),
    "spheres_none": ({"rolling": "none"}, {"type": "spheres", "diameter": [0.016, 0.020]},
                     {"mu_s_pp": 0.45, "mu_s_pw": 0.35}),
    "rods_ar2": ({"rolling": "none"}, {"shape": "elongated", "aspect_ratio": 2.0, "diameter": [0.016, 0.020],
                                     "size_classes": 2},
               {"mu_s_pp": 0.45, "mu_s_pw": 0.35}),
}
SETTINGS = {"paper": {"baffle": {}, "drum": {"discard": 1, "record": 3}, "cylinder": {"lift_speed": 0.05}},
            "quick": {"baffle": {}, "drum": {}, "cylinder": {}}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None)
    ap.add_argument("--scale", default="paper", choices=["paper", "quick"])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--experiments", nargs="+", default=["baffle", "drum", "cylinder"])
    ap.add_argument("--fractions", nargs="+", type=float, default=[0.2, 0.1, 0.05])
    ap.add_argument("--fills", type=int, default=3)
    ap.add_argument("--processes", default="auto")
    args = ap.parse_args(argv)
    wp.config.quiet = True  # stdout carries only the JSON lines
    for case in args.cases:
        law_cfg, mat_cfg, params = CASES[case]
        law = wd.ContactLaw(**law_cfg)
        material = BulkMaterial.from_config(mat_cfg) if args.scale == "paper" else None
        if args.scale == "quick" and "shape" in mat_cfg:
            material = BulkMaterial.from_config({**mat_cfg, "diameter": [0.024, 0.030]})
        for exp_name in args.experiments:
            rpms = [15.0, 30.0, 45.0] if exp_name == "drum" else [None]
            angles = {}
            for frac in sorted(args.fractions, reverse=True):
                kw = dict(SETTINGS[args.scale][exp_name])
                if material is not None:
                    kw["material"] = material
                exp = make_experiment(exp_name, args.scale, contact_law=law, fill_per_world=True,
                                      first_fill_index=0, dt_rayleigh_fraction=frac, **kw)
                sets = [{**params, **({"rpm": r} if r is not None else {})} for r in rpms for _ in range(args.fills)]
                t0 = time.perf_counter()
                res = exp.run(sets, device=args.device, processes=args.processes)
                wall = time.perf_counter() - t0
                for k, r in enumerate(rpms):
                    chunk = res[k * args.fills:(k + 1) * args.fills]
                    vals = [x.angle_deg for x in chunk if x.ok]
                    dens = [x.bulk_density for x in chunk if x.ok and x.bulk_density is not None]
                    angles[(frac, r)] = float(np.mean(vals)) if vals else None
                    print(json.dumps({"case": case, "experiment": exp_name, "rpm": r, "dt_rayleigh_fraction": frac,
                                      "dt_s": res[0].timing["dt_s"], "fills": len(vals),
                                      "angle_mean_deg": None if not vals else round(float(np.mean(vals)), 3),
                                      "angle_sem_deg": None if len(vals) < 2 else
                                      round(float(np.std(vals, ddof=1) / np.sqrt(len(vals))), 3),
                                      "bulk_density": None if not dens else round(float(np.mean(dens)), 1),
                                      "failed": [x.error for x in chunk if not x.ok], "wall_s": round(wall, 1),
                                      "device": res[0].timing["device"]}), flush=True)
            f_min = min(args.fractions)
            for (frac, r), a in angles.items():
                ref = angles.get((f_min, r))
                if a is not None and ref is not None and frac != f_min:
                    print(json.dumps({"case": case, "experiment": exp_name, "rpm": r, "dt_rayleigh_fraction": frac,
                                      "change_vs_smallest_deg": round(a - ref, 3)}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
