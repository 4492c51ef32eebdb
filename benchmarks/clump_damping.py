"""Clump contact damping convention, measured on the drum (issue 10, "Time step and damping").

Rods of aspect ratio 2 (the ``elongated`` shape family, 5 members; the material of
``timestep_convergence.CASES["rods_ar2"]``) in the rotating drum, with the contact damping of
each clump sized for the mass felt at the contact point (``clump_damping_mass: contact_point``,
the default) or for the whole-body mass (``body``, LIGGGHTS multisphere), on the same fills.
One JSON line per (convention, rpm): mean dynamic angle, its standard error over the fills,
and the per-fill angles (fill k is the same packing in both conventions), then one line per
rpm with the paired difference body - contact_point.

    python benchmarks/clump_damping.py --scale quick --device cpu --rpms 45 15 --fills 3 | grep '^{'

(worker processes print Warp's start-up lines on stdout; ``grep '^{'`` keeps the JSON.)
Measured: docs/notes/physical_effects.md, "Clump contact damping" (about 19 min on 2 shared CPU cores).
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
from warpdem.contact.law import CLUMP_DAMPING_MASSES
from warpdem.bench_settled_bed import quiet_warp

ROD_MATERIAL = {"shape": "elongated", "aspect_ratio": 2.0, "diameter": [0.016, 0.020], "size_classes": 2}
ROD_MATERIAL_QUICK = {**ROD_MATERIAL, "diameter": [0.024, 0.030]}  # as timestep_convergence.py at quick scale
PARAMETERS = {"mu_s_pp": 0.45, "mu_s_pw": 0.35}  # rolling: none (rods_ar2)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None)
    ap.add_argument("--scale", default="quick", choices=["paper", "quick"])
    ap.add_argument("--rpms", nargs="+", type=float, default=[45.0, 15.0])
    ap.add_argument("--fills", type=int, default=3)
    ap.add_argument("--conventions", nargs="+", default=list(CLUMP_DAMPING_MASSES), choices=list(CLUMP_DAMPING_MASSES))
    ap.add_argument("--dt-rayleigh-fraction", type=float, default=None,
                    help="time step as a fraction of the Rayleigh time (default: the experiment's)")
    ap.add_argument("--processes", default="auto")
    args = ap.parse_args(argv)
    quiet_warp()  # stdout carries only the JSON lines
    material = BulkMaterial.from_config(ROD_MATERIAL if args.scale == "paper" else ROD_MATERIAL_QUICK)
    per_fill: dict[tuple[str, float], list[float | None]] = {}
    for convention in args.conventions:
        law = wd.ContactLaw(rolling="none", clump_damping_mass=convention)
        kw = {} if args.dt_rayleigh_fraction is None else {"dt_rayleigh_fraction": args.dt_rayleigh_fraction}
        exp = make_experiment("drum", args.scale, contact_law=law, material=material, fill_per_world=True,
                              first_fill_index=0, **kw)
        sets = [{**PARAMETERS, "rpm": r} for r in args.rpms for _ in range(args.fills)]  # one launch, all speeds
        t0 = time.perf_counter()
        res = exp.run(sets, device=args.device, processes=args.processes)
        wall = time.perf_counter() - t0
        for k, rpm in enumerate(args.rpms):
            chunk = res[k * args.fills:(k + 1) * args.fills]
            angles = [float(x.angle_deg) if x.ok else None for x in chunk]
            per_fill[(convention, rpm)] = angles
            vals = [a for a in angles if a is not None]
            print(json.dumps({"case": "rods_ar2", "experiment": "drum", "scale": args.scale, "rpm": rpm,
                              "clump_damping_mass": convention, "law": law.describe(), "fills": len(vals),
                              "angle_mean_deg": None if not vals else round(float(np.mean(vals)), 3),
                              "angle_sem_deg": None if len(vals) < 2 else
                              round(float(np.std(vals, ddof=1) / np.sqrt(len(vals))), 3),
                              "angles_deg": [None if a is None else round(a, 3) for a in angles],
                              "failed": [x.error for x in chunk if not x.ok], "dt_s": res[0].timing["dt_s"],
                              "wall_s": round(wall, 1), "device": res[0].timing["device"]}), flush=True)
    if set(CLUMP_DAMPING_MASSES) <= set(args.conventions):
        for rpm in args.rpms:
            pairs = [(b, c) for b, c in zip(per_fill[("body", rpm)], per_fill[("contact_point", rpm)])
                     if b is not None and c is not None]
            d = [b - c for b, c in pairs]
            print(json.dumps({"case": "rods_ar2", "experiment": "drum", "scale": args.scale, "rpm": rpm,
                              "paired_difference_body_minus_contact_point_deg":
                                  None if not d else round(float(np.mean(d)), 3),
                              "difference_sem_deg": None if len(d) < 2 else
                              round(float(np.std(d, ddof=1) / np.sqrt(len(d))), 3),
                              "pairs": len(d)}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
