"""Interleaved A/B timing of the solver levers of issue 15 in one process (less noise than one
process per variant: the variants share the machine's state, and the order alternates per round).

    python benchmarks/levers_ab.py --spheres 1000000 --device cuda --load-state /tmp/bed.npz
    python benchmarks/levers_ab.py --spheres 20000 --device cpu --load-state /tmp/bed20k.npz --steps 100
    python benchmarks/levers_ab.py --spheres 1000000 --device cuda --load-state /tmp/bed.npz --compare force_registers none 64 80
    python benchmarks/levers_ab.py --spheres 1000000 --device cuda --load-state /tmp/bed.npz --compare wear_lanes 1 32

``--compare OPTION VALUE...`` compares values of one Simulation option instead of the layout levers
(``none`` is None; integers are integers). Every line also gives the registers, spilled bytes and
resident warps per SM of the two force kernels.

The settled bed of ``settled_bed.py --save-state`` is loaded into one Simulation per variant
(default, each lever alone, all levers); then ``--rounds`` rounds of ``--steps`` steps each,
every variant once per round (with the CUDA graph on CUDA). One JSON line per variant: the
least and the median milliseconds per step, and the kinetic energy at the end, which must be
the same for every variant (the levers change no result).
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import warp as wp

import warpdem as wd

from settled_bed import build, load_settled_state  # noqa: E402  (run from benchmarks/)
from warpdem.bench_settled_bed import (LEVER_VARIANTS, force_kernel_resources, option_value, quiet_warp,  # noqa: E402
                                      time_steps)

VARIANTS = {**LEVER_VARIANTS, "default": {}}  # "default" is "auto" (all on a GPU, none on the CPU)


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spheres", type=int, default=20000)
    ap.add_argument("--device", default=None)
    ap.add_argument("--load-state", required=True, metavar="NPZ", help="settled State of settled_bed.py --save-state")
    ap.add_argument("--rounds", type=int, default=10)
    ap.add_argument("--steps", type=int, default=200, help="steps per round and variant")
    ap.add_argument("--rolling", default="epsd")
    ap.add_argument("--max-contacts", type=int, default=12)
    ap.add_argument("--order", default="morton", choices=["morton", "lattice"])
    ap.add_argument("--compare", nargs="+", default=None, metavar="OPTION VALUE",
                    help="one Simulation option and its values to compare (instead of the layout levers)")
    args = ap.parse_args(argv)
    variants = VARIANTS
    if args.compare:
        if len(args.compare) < 2:
            ap.error("--compare needs an option and at least one value")
        option, values = args.compare[0], [option_value(v) for v in args.compare[1:]]
        variants = {f"{option}_{v}": {option: v} for v in values}
    quiet_warp()
    device = args.device or ("cuda" if wp.is_cuda_available() else "cpu")
    model, _ = build(args.spheres, 1, args.rolling, device, args.max_contacts, args.order)
    sims = {}
    for name, options in variants.items():
        sim = wd.Simulation(model, 5.0e-5, steps_per_graph=50, **options)
        load_settled_state(args.load_state, sim)
        sim.run(2 * args.steps, check_every=2 * args.steps)  # compile, capture, first list build
        sims[name] = sim
    times: dict[str, list[float]] = {name: [] for name in variants}
    for r in range(args.rounds):
        for name in (list(variants) if r % 2 == 0 else list(variants)[::-1]):
            times[name].append(time_steps(sims[name], device, 0, args.steps) / args.steps * 1e3)
    out = []
    for name, sim in sims.items():
        t = np.array(times[name])
        res = dict(case="levers-ab", device=wp.get_device(device).name, spheres=model.num_spheres, variant=name,
                   rounds=args.rounds, steps_per_round=args.steps, min_ms_per_step=round(float(t.min()), 4),
                   median_ms_per_step=round(float(np.median(t)), 4),
                   sphere_steps_per_s_best=float(f"{model.num_spheres / (t.min() * 1e-3):.4g}"),
                   ke_end_J=float(sim.kinetic_energy()[0]), list_builds=int(sim.solver.list_builds.numpy()[0]),
                   kernels=force_kernel_resources(sim.solver), date=time.strftime("%Y-%m-%d"))
        print(json.dumps(res), flush=True)
        out.append(res)
    return out


if __name__ == "__main__":
    main()
