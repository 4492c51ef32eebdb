"""Time-step convergence of the standard experiments (issue 10, "Time step and damping").

For each material/law (spheres + epsd2 rolling resistance, spheres + epsd, rods of aspect ratio 2 (5 members),
...) and each experiment (A; B at the ``--rpms`` speeds in one launch; C), run the same fills at
several time steps given as fractions of the smallest sphere's Rayleigh time, and report the
mean angle and its change against the smallest step.

Output (stdout, JSON lines only; progress goes to stderr):

* one line per (case, experiment, rpm, step): mean angle and its standard error over the fills, the
  per-fill angles ``angles_deg`` in fill order (None for a failed world), ``fill_indices``, the
  per-fill bulk densities ``bulk_densities`` (A; None elsewhere) and, for the drum, the per-fill
  snapshot scatter ``snapshot_std_deg``, snapshot angles ``snapshot_angles_deg`` and the number of
  ``skipped_snapshots``;
* after all steps of one (case, experiment, rpm), one line per larger step with its change against
  the smallest step: ``change_vs_smallest_deg`` (difference of the means), the paired difference
  (same fill index; ``paired_diff_mean_deg`` +- ``paired_diff_sem_deg`` over ``paired_fills``) and
  the unpaired difference with the combined standard error (``unpaired_diff_sem_deg``).

Options: ``--tangential`` the sliding rule (``history``, the default, or ``mindlin``, the default
before 2026-11-27); ``--rpms`` the drum speeds (default 15 30 45); ``--fills`` fills per step and
``--fill-offset`` the first fill index (default 0), so that a later call can add fills
``offset ... offset + fills - 1`` to an earlier one (with fills per world, a batch's time step
follows its own smallest sphere: compare the steps within one call, pool calls afterwards).

    python benchmarks/timestep_convergence.py --device cuda --fractions 0.2 0.1 0.05 --fills 4
    python benchmarks/timestep_convergence.py --scale quick --experiments baffle --fractions 0.2 0.1
    python benchmarks/timestep_convergence.py --scale quick --cases rods_ar2 --experiments drum --rpms 45 \\
        --fractions 0.2 0.1 0.05 --fills 3 --fill-offset 3 --processes 1 --device cpu >> out.jsonl
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
import warp as wp

import warpdem as wd
from warpdem.bench_settled_bed import quiet_warp
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


def log(msg: str) -> None:
    """Progress on stderr (stdout carries only the JSON lines)."""
    print(msg, file=sys.stderr, flush=True)


def emit(record: dict) -> None:
    print(json.dumps(record), flush=True)


def _r(x, nd=3):
    """Round a float for the JSON line; None and NaN stay None."""
    return None if x is None or not np.isfinite(x) else round(float(x), nd)


def mean_sem(vals) -> tuple[float | None, float | None]:
    """Mean and standard error (ddof=1) of the non-None values (None where too few)."""
    v = np.array([x for x in vals if x is not None], dtype=float)
    if v.size == 0:
        return None, None
    return float(v.mean()), (float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else None)


def case_material(case: str, scale: str) -> BulkMaterial | None:
    """The case's material (None: the quick preset's spheres)."""
    mat_cfg = CASES[case][1]
    if scale == "paper":
        return BulkMaterial.from_config(mat_cfg)
    if "shape" in mat_cfg:
        return BulkMaterial.from_config({**mat_cfg, "diameter": [0.024, 0.030]})
    return None


def per_fill(chunk) -> dict:
    """Per-fill entries of one (rpm, step): angles, bulk densities, drum snapshot scatter."""
    out = {"angles_deg": [_r(x.angle_deg) if x.ok else None for x in chunk],
           "bulk_densities": [_r(x.bulk_density, 1) if x.ok else None for x in chunk]}
    if not any(v is not None for v in out["bulk_densities"]):
        out["bulk_densities"] = None
    if any("snapshot_angles_deg" in x.diagnostics for x in chunk):
        d = [x.diagnostics if x.ok else {} for x in chunk]
        out["snapshot_std_deg"] = [_r(g.get("snapshot_std_deg")) for g in d]
        out["snapshot_angles_deg"] = [None if g.get("snapshot_angles_deg") is None else
                                      [_r(a, 2) for a in g["snapshot_angles_deg"]] for g in d]
        out["skipped_snapshots"] = [len(g["skipped_snapshots"]) if "skipped_snapshots" in g else None for g in d]
    return out


def run_step(case: str, exp_name: str, frac: float, rpms: list, args) -> dict:
    """Run every (rpm, fill) world of one step in one launch; returns {rpm: JSON record}."""
    law_cfg, _, params = CASES[case]
    kw = dict(SETTINGS[args.scale][exp_name])
    material = case_material(case, args.scale)
    if material is not None:
        kw["material"] = material
    law = wd.ContactLaw(**{"tangential": args.tangential, **law_cfg})
    exp = make_experiment(exp_name, args.scale, contact_law=law, fill_per_world=True,
                          first_fill_index=args.fill_offset, dt_rayleigh_fraction=frac, **kw)
    sets = [{**params, **({"rpm": r} if r is not None else {})} for r in rpms for _ in range(args.fills)]
    log(f"{case} {exp_name} rpm={rpms} dt/t_R={frac}: {len(sets)} worlds ...")
    t0 = time.perf_counter()
    res = exp.run(sets, device=args.device, processes=args.processes)
    wall = time.perf_counter() - t0
    log(f"  done in {wall:.1f} s (dt {res[0].timing['dt_s']:.3e} s)")
    fills = list(range(args.fill_offset, args.fill_offset + args.fills))
    records = {}
    for k, r in enumerate(rpms):
        chunk = res[k * args.fills:(k + 1) * args.fills]
        vals = [x.angle_deg for x in chunk if x.ok]
        dens = [x.bulk_density for x in chunk if x.ok and x.bulk_density is not None]
        mean, sem = mean_sem(vals)
        records[r] = {"case": case, "law": law.describe(), "experiment": exp_name, "rpm": r, "dt_rayleigh_fraction": frac,
                      "dt_s": res[0].timing["dt_s"], "fills": len(vals), "fill_indices": fills,
                      "angle_mean_deg": _r(mean), "angle_sem_deg": _r(sem),
                      "bulk_density": None if not dens else round(float(np.mean(dens)), 1),
                      **per_fill(chunk),
                      "failed": [x.error for x in chunk if not x.ok], "wall_s": round(wall, 1),
                      "device": res[0].timing["device"]}
    return records


def change_record(rec: dict, ref: dict) -> dict | None:
    """Change of one step against the smallest: difference of means, paired and unpaired with SEs."""
    if rec["angle_mean_deg"] is None or ref["angle_mean_deg"] is None:
        return None
    pairs = [(a, b) for a, b in zip(rec["angles_deg"], ref["angles_deg"]) if a is not None and b is not None]
    d_mean, d_sem = mean_sem([a - b for a, b in pairs])
    sa, sb = rec["angle_sem_deg"], ref["angle_sem_deg"]
    return {"case": rec["case"], "law": rec["law"], "experiment": rec["experiment"], "rpm": rec["rpm"],
            "dt_rayleigh_fraction": rec["dt_rayleigh_fraction"],
            "reference_fraction": ref["dt_rayleigh_fraction"], "fill_indices": rec["fill_indices"],
            "change_vs_smallest_deg": _r(rec["angle_mean_deg"] - ref["angle_mean_deg"]),
            "paired_fills": len(pairs), "paired_diff_mean_deg": _r(d_mean), "paired_diff_sem_deg": _r(d_sem),
            "unpaired_diff_deg": _r(rec["angle_mean_deg"] - ref["angle_mean_deg"]),
            "unpaired_diff_sem_deg": None if sa is None or sb is None else _r(np.hypot(sa, sb))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None)
    ap.add_argument("--scale", default="paper", choices=["paper", "quick"])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--experiments", nargs="+", default=["baffle", "drum", "cylinder"])
    ap.add_argument("--fractions", nargs="+", type=float, default=[0.2, 0.1, 0.05])
    ap.add_argument("--rpms", nargs="+", type=float, default=[15.0, 30.0, 45.0], help="drum speeds [rpm]")
    ap.add_argument("--fills", type=int, default=3)
    ap.add_argument("--fill-offset", type=int, default=0, help="index of the first fill")
    ap.add_argument("--processes", default="auto")
    ap.add_argument("--tangential", default="history",
                    help="tangential sub-model (history: LIGGGHTS, the default; mindlin: the default before 2026-11-27)")
    args = ap.parse_args(argv)
    quiet_warp()
    f_min = min(args.fractions)
    for case in args.cases:
        for exp_name in args.experiments:
            rpms = list(args.rpms) if exp_name == "drum" else [None]
            records = {}  # (frac, rpm) -> record
            for frac in sorted(args.fractions, reverse=True):
                for r, rec in run_step(case, exp_name, frac, rpms, args).items():
                    records[(frac, r)] = rec
                    emit(rec)
            for r in rpms:
                for frac in sorted(args.fractions, reverse=True):
                    ref = records.get((f_min, r))
                    if frac != f_min and ref is not None:
                        line = change_record(records[(frac, r)], ref)
                        if line is not None:
                            emit(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
