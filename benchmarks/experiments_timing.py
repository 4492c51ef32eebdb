"""Timing of the standard experiments (docs/experiments.md, A, B, C).

Runs each experiment once per requested world count and prints one JSON line per run:
experiment, scale, device, worlds, spheres, steps, simulated and wall seconds, and the
measured angles (a sanity check, not a result). World w gets contact parameters drawn
uniformly in [0.5, 1.5] x the contact law's default for every parameter of the law except
the restitution coefficients (spec default 0.6), seeded.

    python benchmarks/experiments_timing.py                                   # quick scale, CPU
    python benchmarks/experiments_timing.py --scale paper --worlds 1 64 --device cuda
    python benchmarks/experiments_timing.py --experiment drum --scale paper --material spheres \
        --settings '{"discard": 2, "record": 4}' --device cuda

Paper scale uses the gravel clump mix (medium fill) unless --material says otherwise; its
smallest member spheres set a small recommended time step (see the dt field).
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import warpdem as wd  # noqa: E402
from calibration.experiments import EXPERIMENTS, make_experiment  # noqa: E402
from calibration.materials import BulkMaterial  # noqa: E402
from warpdem.bench_settled_bed import quiet_warp  # noqa: E402

MATERIALS = {
    "default": None,
    "spheres": lambda: BulkMaterial.spheres(0.016, 0.020),
    "quick-spheres": lambda: BulkMaterial.spheres(0.024, 0.030),
    "gravel-low": lambda: BulkMaterial.gravel("low"),
    "gravel-medium": lambda: BulkMaterial.gravel("medium"),
}


def parameter_sets(law: wd.ContactLaw, worlds: int, seed: int = 0) -> list[dict[str, float]]:
    """Per-world contact parameters around the law's defaults (names from the experiment's law)."""
    rng = np.random.default_rng(seed)
    specs = law.specs
    sets = []
    for _ in range(worlds):
        s = {}
        for name in law.parameter_names:
            base, _pt = law.split_name(name)
            if base == "restitution":
                continue
            lo, hi = specs[base].bounds
            s[name] = float(np.clip(specs[base].default * rng.uniform(0.5, 1.5), lo, hi))
        sets.append(s)
    return sets


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--experiment", default="all", choices=["all", *EXPERIMENTS])
    ap.add_argument("--scale", default="quick", help="quick | paper (drum also: short)")
    ap.add_argument("--worlds", type=int, nargs="+", default=[1], help="world counts to time, e.g. 1 64")
    ap.add_argument("--device", default=None, help="cpu or cuda (default: Warp's default)")
    ap.add_argument("--material", default="default", choices=sorted(MATERIALS))
    ap.add_argument("--dt", type=float, default=None, help="time step [s] (default: recommended)")
    ap.add_argument("--settings", default="{}", help="JSON object of experiment settings to override")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--progress", action="store_true")
    args = ap.parse_args(argv)
    quiet_warp()
    device = args.device or str(wp.get_preferred_device())
    names = list(EXPERIMENTS) if args.experiment == "all" else [args.experiment]
    extra = json.loads(args.settings)
    if MATERIALS[args.material] is not None:
        extra["material"] = MATERIALS[args.material]()
    if args.dt is not None:
        extra["dt"] = args.dt
    lines = []
    for name in names:
        for worlds in args.worlds:
            exp = make_experiment(name, args.scale, **extra)
            t0 = time.perf_counter()
            res = exp.run(parameter_sets(exp.contact_law, worlds, args.seed), device=device, progress=args.progress)
            wall = time.perf_counter() - t0
            t = res[0].timing
            angles = np.array([r.angle_deg for r in res if r.ok], dtype=float)
            line = dict(
                case=f"experiment-{name}", experiment=name, scale=args.scale, device=t["device"],
                device_name=wp.get_device(device).name, host=platform.node(), worlds=worlds,
                spheres=t["spheres"], spheres_per_world=t["spheres_per_world"], bodies=t["bodies"],
                material=exp.bulk_material().name, steps=t["steps"], dt=t["dt_s"], simulated_s=t["simulated_s"],
                phases_s=t["phases_s"], wall_s=round(wall, 3), build_s=t["build_s"], simulate_s=t["simulate_s"],
                sphere_steps_per_s=float(f"{t['spheres'] * t['steps'] / max(t['simulate_s'], 1e-9):.4g}"),
                ok_worlds=int(angles.size), angle_name=res[0].angle_name,
                angle_mean_deg=round(float(angles.mean()), 3) if angles.size else None,
                angle_min_deg=round(float(angles.min()), 3) if angles.size else None,
                angle_max_deg=round(float(angles.max()), 3) if angles.size else None,
                deviations_from_paper=sorted(res[0].protocol["deviations_from_paper"]),
                warp=wp.config.version, date=time.strftime("%Y-%m-%d"))
            if not angles.size:
                line["first_error"] = res[0].error
            print(json.dumps(line), flush=True)
            lines.append(line)
    return lines


if __name__ == "__main__":
    main()
