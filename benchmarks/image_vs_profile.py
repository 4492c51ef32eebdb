"""Camera view against particle profile on simulated baffle piles (issue 4, spec A "Images").

Runs the baffle lifting box for N worlds (a different loose fill and friction per world), renders
each pile as the camera sees it (orthographic side view of the measured slab, 2 px/mm, pixel
noise) and measures it with the OpenCV pipeline (every edge column, the photograph default), then
compares with the spec's particle profile (highest particle top per bin). Prints one JSON line
per world and a summary line.

    python benchmarks/image_vs_profile.py --scale quick --worlds 16                # CPU, 24-30 mm spheres, 28 kg
    python benchmarks/image_vs_profile.py --scale paper --material spheres --worlds 16 --device cuda
    python benchmarks/image_vs_profile.py --scale paper --material fine-spheres --worlds 8 --device cuda
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calibration.experiments import make_experiment  # noqa: E402
from calibration.materials import BulkMaterial  # noqa: E402
from calibration.measurement import MeasurementError, measure_image, render_side_view  # noqa: E402
from warpdem.bench_settled_bed import quiet_warp  # noqa: E402

MATERIALS = {"default": None, "spheres": lambda: BulkMaterial.spheres(0.016, 0.020),
             "fine-spheres": lambda: BulkMaterial.spheres(0.008, 0.010)}


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scale", default="quick")
    ap.add_argument("--material", default="default", choices=sorted(MATERIALS))
    ap.add_argument("--worlds", type=int, default=6)
    ap.add_argument("--device", default=None)
    ap.add_argument("--scale-px-per-mm", type=float, default=2.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--processes", default="auto", help="CPU: worlds split over this many processes")
    ap.add_argument("--save-dir", default=None, help="write each pile (positions, radii, h_fill) as .npz here")
    args = ap.parse_args(argv)
    quiet_warp()
    extra = {} if MATERIALS[args.material] is None else {"material": MATERIALS[args.material]()}
    exp = make_experiment("baffle", args.scale, fill_per_world=True, seed=args.seed, **extra)
    rng = np.random.default_rng(args.seed)
    sets = [{"mu_s_pp": float(rng.uniform(0.3, 0.7)), "mu_s_pw": float(rng.uniform(0.3, 0.7)),
             "mu_r_pp": 0.15, "mu_r_pw": 0.15} for _ in range(args.worlds)]
    t0 = time.perf_counter()
    results = exp.run(sets, device=args.device,
                      processes=args.processes if args.processes == "auto" else int(args.processes))
    wall = time.perf_counter() - t0
    lines, diffs = [], []
    for r in results:
        line = dict(case="image-vs-profile", scale=args.scale, material=exp.bulk_material().name, world=r.world,
                    parameters={k: round(v, 3) for k, v in r.parameters.items()}, profile_deg=r.angle_deg)
        if r.ok:
            pos, rad = r.particles
            h_fill = r.diagnostics["h_fill_m"]
            if args.save_dir:
                Path(args.save_dir).mkdir(parents=True, exist_ok=True)
                np.savez_compressed(Path(args.save_dir) / f"pile_{args.scale}_{args.material}_{r.world:03d}.npz",
                                    positions=pos, radii=rad, h_fill=h_fill, profile_deg=r.angle_deg)
            view = render_side_view(pos, rad, slab=exp.measure_y, scale_px_per_mm=args.scale_px_per_mm,
                                    extent_m=(-0.02, exp.floor_length + 0.02, -0.02, exp.box_height),
                                    noise_std=6.0, rng=r.world)
            try:
                img = measure_image(view.image, scale_px_per_mm=args.scale_px_per_mm, origin_px=view.origin_px,
                                    window=(0.0, exp.box_length * 1000.0, -5.0, exp.box_height * 1000.0),
                                    fit_band=exp.band, h_ref=h_fill * 1000.0)
                line.update(image_deg=img.angle_deg, difference_deg=img.angle_deg - r.angle_deg,
                            profile_bins=int(r.diagnostics["fit"]["n_bins"]) if "fit" in r.diagnostics else None)
                diffs.append(img.angle_deg - r.angle_deg)
            except MeasurementError as exc:
                line["image_error"] = str(exc)
        else:
            line["error"] = r.error
        print(json.dumps(line), flush=True)
        lines.append(line)
    d = np.array(diffs)
    summary = dict(case="image-vs-profile-summary", scale=args.scale, material=exp.bulk_material().name,
                   worlds=args.worlds, compared=int(d.size), device=results[0].timing["device"],
                   mean_difference_deg=round(float(d.mean()), 3) if d.size else None,
                   mean_abs_difference_deg=round(float(np.abs(d).mean()), 3) if d.size else None,
                   max_abs_difference_deg=round(float(np.abs(d).max()), 3) if d.size else None,
                   within_1_deg=int(np.sum(np.abs(d) < 1.0)), dem_wall_s=round(wall, 1), date=time.strftime("%Y-%m-%d"))
    print(json.dumps(summary), flush=True)
    return lines + [summary]


if __name__ == "__main__":
    main()
