"""Where does a small model's step go? The experiments' regime: few spheres, many steps.

    python benchmarks/step_cost.py --device cuda [--spheres 2000 20000 200000] [--worlds 1]
        [--neighbour-search cell_list|hash_grid] [--wall-stage split|fused]
        [--neighbour-layout sphere_major|slot_major] [--history-layout sphere_major|slot_major]
        [--fused-placement] [--wall-candidates 32|0] [--conditional-rebuild]

A drum-like case per size: spheres d = 16-20 mm in drums of 0.3 m (one drum per world, each
rotating at its own speed, as the diagnosis' drum designs are), about 950 spheres per drum,
dt = 8.26e-5 s. For each total size: milliseconds per step with the graph (as the experiments
run: a CUDA graph on a GPU, Warp's CPU graph on the CPU), without it, and a per-kernel breakdown
of 50 ungraphed steps (CUDA only; Warp's
CUDA activity timing). One JSON line per size.
"""
from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
import warp as wp

import warpdem as wd
from warpdem.bench_settled_bed import add_solver_options, quiet_warp, solver_options, time_steps, used_solver_options

PER_DRUM = 950  # a loose lattice holds ~950 in the drum's lower part (the paper fill settles to 1,648)
DT = 8.2599588e-05


def drum_model(total: int, device: str):
    from calibration.experiments.drum import drum_mesh

    worlds = max(1, round(total / PER_DRUM))
    b = wd.ModelBuilder(num_worlds=worlds, contact_law=wd.ContactLaw(rolling="epsd2"), max_contacts=16)
    b.add_material(wd.GRAVEL)
    rng = np.random.default_rng(0)
    # a loose lattice in the lower part of the drum (radius 0.15 m, length 0.15 m)
    s = 0.0205
    g = np.arange(-0.13, 0.13, s)
    y = np.arange(0.012, 0.14, s)
    pts = np.stack(np.meshgrid(g, y, g, indexing="ij"), -1).reshape(-1, 3)
    pts = pts[np.hypot(pts[:, 0], pts[:, 2]) < 0.135]
    pts = pts[np.argsort(pts[:, 2])][:PER_DRUM]
    mesh = drum_mesh(0.15, 0.15, 72)
    for w in range(worlds):
        r = rng.uniform(0.008, 0.010, len(pts))
        b.add_spheres(pts, r, "gravel", world=w)
        b.add_wall(mesh, "gravel", world=w, motion=wd.WallMotion.rotation((0, 1, 0), 15.0 + 30.0 * (w % 3) / 2))
    b.set_contact_parameters(mu_s_pp=0.5, mu_s_pw=0.5, mu_r_pp=0.1, mu_r_pw=0.1)
    return b.finalize(device, check_overlaps=False), worlds


def per_step_ms(sim: wd.Simulation, steps: int, device: str) -> float:
    """Milliseconds per step over ``steps`` steps after as many warm-up steps."""
    return time_steps(sim, device, steps, steps) / steps * 1e3


def kernel_breakdown(sim: wd.Simulation, steps: int) -> dict[str, float]:
    """Milliseconds per step of each kernel (and memcpy/memset) over ``steps`` ungraphed steps
    (Warp's CUDA activity timing, summed per name; largest first). On the CPU, where launches run
    synchronously on the calling thread, each ``wp.launch`` is timed on the host clock instead."""
    if not wp.get_device(sim.model.device).is_cuda:
        return cpu_kernel_breakdown(sim, steps)
    wp.timing_begin(cuda_filter=wp.TIMING_ALL)
    for _ in range(steps):
        sim.solver.step(sim.state, sim._next)
        sim.state, sim._next = sim._next, sim.state
    res = wp.timing_end()
    out: dict[str, float] = {}
    for r in res:
        out[r.name] = out.get(r.name, 0.0) + r.elapsed / steps
    return {k: round(v, 4) for k, v in sorted(out.items(), key=lambda kv: -kv[1])}


def cpu_kernel_breakdown(sim: wd.Simulation, steps: int) -> dict[str, float]:
    """:func:`kernel_breakdown` on the CPU: every ``wp.launch`` of ``steps`` ungraphed steps timed
    with ``time.perf_counter`` (a CPU launch returns when the kernel has run), summed per kernel key."""
    import time

    out: dict[str, float] = {}
    launch = wp.launch

    def timed_launch(kernel, *args, **kwargs):
        t0 = time.perf_counter()
        result = launch(kernel, *args, **kwargs)
        name = getattr(kernel, "key", str(kernel))
        out[name] = out.get(name, 0.0) + (time.perf_counter() - t0) * 1e3 / steps
        return result

    wp.launch = timed_launch
    try:
        for _ in range(steps):
            sim.solver.step(sim.state, sim._next)
            sim.state, sim._next = sim._next, sim.state
    finally:
        wp.launch = launch
    return {k: round(v, 4) for k, v in sorted(out.items(), key=lambda kv: -kv[1])}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None)
    ap.add_argument("--spheres", type=int, nargs="+", default=[2000, 20000, 200000])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--conditional-rebuild", action="store_true",
                    help="the list build behind a conditional graph node (CUDA; its early-exit launches skipped)")
    add_solver_options(ap)
    args = ap.parse_args(argv)
    quiet_warp()
    device = args.device or ("cuda" if wp.is_cuda_available() else "cpu")
    for n in args.spheres:
        model, worlds = drum_model(n, device)
        sim = wd.Simulation(model, DT, force=True, conditional_rebuild=args.conditional_rebuild,
                            **solver_options(args))
        sim.run(2000, check_every=2000)  # let the lattice collapse first
        graph_ms = per_step_ms(sim, args.steps, device)
        sim.use_graph = False
        plain_ms = per_step_ms(sim, max(50, args.steps // 10), device)
        kernels = kernel_breakdown(sim, 50) if wp.get_device(device).is_cuda else {}
        print(json.dumps(dict(case="drum-step-cost", device=wp.get_device(device).name, spheres=model.num_spheres,
                              worlds=worlds, **used_solver_options(sim.solver),
                              conditional_rebuild=sim.solver.conditional_rebuild,
                              graph_ms_per_step=round(graph_ms, 4), plain_ms_per_step=round(plain_ms, 4),
                              sphere_steps_per_s=float(f"{model.num_spheres / (graph_ms * 1e-3):.3g}"),
                              list_builds=int(sim.solver.list_builds.numpy()[0]), kernels_ms_per_step=kernels,
                              date=time.strftime("%Y-%m-%d"))), flush=True)


if __name__ == "__main__":
    main()
