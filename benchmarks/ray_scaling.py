"""One batch of DEM worlds on 1 and on N GPUs through Ray (issue 31, item 5): wall time, speed-up, same numbers.

    python benchmarks/ray_scaling.py --experiment baffle --worlds 192 --gpus 1 2 --out results/ray_scaling

Runs the same batch (one fill per world, ``fill_per_world``) three ways on one host:
``local`` (one launch on GPU 0, no Ray), ``ray x1`` (one Ray task holding one GPU: Ray's own
overhead) and ``ray xN`` (N tasks, one GPU each, the batch split in N). Each world's result
depends only on its own fill and parameters (the time step follows the material, not the batch),
so the split changes no number beyond float-reduction order; the script says how far they moved.
Writes ``ray_scaling.json`` (every timing, the device names, the command, the date) and prints one
line per run. The paper-scale baffle of 16-20 mm spheres (the hidden-effect labs' material, about
2,000 spheres a world) keeps each GPU busy at a few hundred worlds.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.executor import RayExecutor  # noqa: E402
from calibration.experiments import make_experiment  # noqa: E402
from calibration.materials import BulkMaterial  # noqa: E402
from warpdem.warp_output import quiet_warp  # noqa: E402


def parameter_sets(n: int, seed: int = 0) -> list[dict[str, float]]:
    """``n`` sliding-friction pairs spread over the calibration box."""
    rng = np.random.default_rng(seed)
    return [{"mu_s_pp": float(a), "mu_s_pw": float(b)} for a, b in rng.uniform([0.2, 0.2], [0.8, 0.7], (n, 2))]


def observables(results) -> np.ndarray:
    keys = sorted(results[0].observables)
    return np.array([[np.nan if r.observables.get(k) is None else float(r.observables[k]) for k in keys]
                     for r in results], float)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--experiment", default="baffle", choices=["baffle", "drum", "cylinder"])
    ap.add_argument("--scale", default="paper")
    ap.add_argument("--worlds", type=int, default=192)
    ap.add_argument("--gpus", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--skip-local", action="store_true")
    ap.add_argument("--settings", default="{}", help="experiment setting overrides as JSON (e.g. a small fill for a smoke test)")
    ap.add_argument("--out", default="results/ray_scaling")
    ap.add_argument("--device", default="cuda", help="cuda (default); cpu: a smoke test of the script, N tasks on N cores")
    args = ap.parse_args(argv)
    quiet_warp(always=True)
    import warp as wp

    on_gpu = args.device == "cuda"
    gpus = list(wp.get_cuda_devices()) if on_gpu else ["cpu"] * max(args.gpus)
    if not gpus:
        raise SystemExit("ray_scaling: no CUDA device")
    settings = {"fill_per_world": True, **json.loads(args.settings)}
    if args.scale == "paper":
        settings["material"] = BulkMaterial.spheres(0.016, 0.020, name="spheres d=16-20 mm")
    exp = make_experiment(args.experiment, args.scale, **settings)
    sets = parameter_sets(args.worlds)
    runs: list[dict] = []
    values: dict[str, np.ndarray] = {}
    keys: list[str] = []

    def record(name: str, gpus_used: int, t0: float, results) -> None:
        wall = time.perf_counter() - t0
        values[name] = observables(results)
        keys[:] = sorted(results[0].observables)
        ok = sum(r.status == "ok" for r in results)
        runs.append({"run": name, "gpus": gpus_used, "worlds": len(results), "ok": ok, "wall_s": round(wall, 2)})
        print(f"{name:>8}: {len(results)} worlds on {gpus_used} GPU(s) in {wall:.1f} s ({ok} ok)", flush=True)

    if not args.skip_local:
        exp.run(sets[:2], device=args.device)  # compile the kernels once, outside the timings
        t0 = time.perf_counter()
        record("local", 1, t0, exp.run(sets, device=args.device))
    for n in args.gpus:
        if n > len(gpus):
            print(f"ray x{n}: skipped, this host has {len(gpus)} GPU(s)")
            continue
        ex = RayExecutor(address="local", num_gpus=len(gpus) if on_gpu else None, num_cpus=max(2, 2 * len(gpus)),
                         gpus_per_task=1 if on_gpu else 0, tasks=n)
        ex.connect()
        if f"ray x{n}" == f"ray x{args.gpus[0]}":
            # compiles the kernels into Warp's on-disk cache; every GPU task then starts a worker of its own
            # (RayExecutor.remote_function), so each timed run includes its tasks' start-up
            exp.run(sets[: 2 * n], device=args.device, executor=ex)
        t0 = time.perf_counter()
        record(f"ray x{n}", n, t0, exp.run(sets, device=args.device, executor=ex))
    base = next((r for r in runs if r["run"] == f"ray x{args.gpus[0]}"), None)
    for r in runs:
        if base is not None:
            r["speedup_vs_" + base["run"].replace(" ", "")] = round(base["wall_s"] / r["wall_s"], 3)
    ref_name = "local" if "local" in values else runs[0]["run"]
    ref = values[ref_name]
    for r in runs:
        d = np.abs(values[r["run"]] - ref)
        r[f"max_abs_diff_vs_{ref_name}"] = float(np.nanmax(d)) if np.isfinite(d).any() else None
        r[f"worlds_bitwise_equal_to_{ref_name}"] = int(np.sum(np.all((values[r["run"]] == ref) |
                                                                      (np.isnan(ref) & np.isnan(values[r["run"]])), axis=1)))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    doc = {"command": "python " + " ".join([Path(sys.argv[0]).as_posix(), *(argv or sys.argv[1:])]),
           "date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "host": platform.node(),
           "devices": [wp.get_device(d).name for d in gpus] if on_gpu else ["cpu"], "experiment": args.experiment,
           "scale": args.scale, "worlds": args.worlds, "observable_keys": keys, "runs": runs}
    (out / "ray_scaling.json").write_text(json.dumps(doc, indent=1))
    print(json.dumps(runs, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
