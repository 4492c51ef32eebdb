"""Where does a step's time go? Times each stage of DEMSolver.step on a settled bed.

    python benchmarks/profile_step.py --spheres 1000000 --device cuda [--order morton|lattice]
        [--neighbour-search cell_list|hash_grid] [--wall-stage split|fused]
        [--neighbour-layout sphere_major|slot_major] [--history-layout sphere_major|slot_major]
        [--fused-placement] [--load-state NPZ]

Prints one JSON line: milliseconds per stage (sphere placement, the neighbour search's build
(``hash_grid_build`` or ``cell_list_build``), a full list rebuild (search + list kernel), the
same launches on a step without a rebuild (``rebuild_skipped``), contact stages, full step)
averaged over --repeats steps, plus the bytes a step must at least move per sphere and the
effective bandwidth that implies. On CUDA also ``kernels_ms_per_step``: milliseconds per step
of each kernel over --repeats ungraphed steps (Warp's CUDA activity timing, summed per kernel
name, as in step_cost.py; on the CPU each launch timed on the host clock).
``--load-state``: start from a settled State saved by ``settled_bed.py --save-state`` (same
--spheres, --rolling and --order) instead of running --settle-time.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import warp as wp

import warpdem as wd
from warpdem.bench_settled_bed import add_solver_options, quiet_warp, solver_options, used_solver_options

from settled_bed import build, load_settled_state, min_bytes_per_sphere_step  # noqa: E402  (run from benchmarks/)
from step_cost import kernel_breakdown  # noqa: E402


@wp.kernel
def count_neighbours(grid: wp.uint64, x: wp.array(dtype=wp.vec3), r: wp.array(dtype=float),
                     world: wp.array(dtype=int), rmax: float, out: wp.array(dtype=int)):
    """Grid traversal cost alone: count touching neighbours."""
    i = wp.tid()
    xi = x[i]
    n = int(0)
    q = wp.hash_grid_query(grid, xi, r[i] + rmax, world[i])
    j = int(0)
    while wp.hash_grid_query_next(q, j):
        d = xi - x[j]
        rr = r[i] + r[j]
        if j != i and wp.dot(d, d) < rr * rr:
            n += 1
    out[i] = n


def timed(fn, device, repeats):
    fn()  # warm-up: compile and allocate outside the timing
    wp.synchronize_device(device)
    t0 = time.perf_counter()
    for _ in range(repeats):
        fn()
    wp.synchronize_device(device)
    return (time.perf_counter() - t0) / repeats * 1e3


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--spheres", type=int, default=200000)
    ap.add_argument("--device", default=None)
    ap.add_argument("--settle-time", type=float, default=0.6)
    ap.add_argument("--repeats", type=int, default=50)
    ap.add_argument("--rolling", default="epsd")
    ap.add_argument("--order", default="morton", choices=["morton", "lattice"])
    add_solver_options(ap)
    ap.add_argument("--load-state", default=None, metavar="NPZ", help="start from this settled State")
    args = ap.parse_args(argv)
    quiet_warp()
    device = args.device or ("cuda" if wp.is_cuda_available() else "cpu")
    model, _ = build(args.spheres, 1, args.rolling, device, 12, args.order)
    sim = wd.Simulation(model, 5e-5, steps_per_graph=50, **solver_options(args))
    if args.load_state:
        load_settled_state(args.load_state, sim)
        sim.run(200, check_every=200)
    else:
        sim.run(int(args.settle_time / 5e-5), check_every=5000)
    m, so = model, sim.solver
    # every closure reads sim.state when it runs: full_step swaps the States as a run does

    def place():
        so.place_spheres(sim.state)

    always = wp.ones(1, dtype=int, device=device)  # a rebuild flag that stays set

    def grid():
        """The neighbour search's own build (hash grid or cell list), as on a rebuild step."""
        s = sim.state
        if so.cell_list is not None:
            so.cell_list.build(s.sphere_x, m.sphere_world, m.sphere_body, s.body_active, always)
        else:
            so.grid.build(s.sphere_x, so.cell_size, groups=m.sphere_world)

    def full_rebuild():
        so.request_neighbour_rebuild()
        so._build_neighbour_list(sim.state)

    def rebuild_skipped():
        so._build_neighbour_list(sim.state)  # the flag is 0 after a build: what a step without a rebuild launches

    def full_step():
        so.step(sim.state, sim._next)
        sim.state, sim._next = sim._next, sim.state  # as a run does (fused_placement expects it)

    stages = {"place_spheres": timed(place, device, args.repeats),
              f"{args.neighbour_search}_build": timed(grid, device, args.repeats),
              "full_rebuild": timed(full_rebuild, device, args.repeats),
              "rebuild_skipped": timed(rebuild_skipped, device, args.repeats),
              "full_step": timed(full_step, device, args.repeats)}
    grid()
    stages["contact_stages"] = timed(lambda: so.launch_contacts(sim.state, sim._next, 5e-5), device, args.repeats)
    stages["contact_stages_no_walls"] = timed(lambda: so.launch_contacts(sim.state, sim._next, 5e-5, walls_on=False),
                                              device, args.repeats)
    if so.grid is not None:
        nb = wp.zeros(m.num_spheres, dtype=int, device=device)
        stages["grid_query_only"] = timed(lambda: wp.launch(count_neighbours, dim=m.num_spheres, inputs=[
            so.grid.id, sim.state.sphere_x, m.sphere_radius, m.sphere_world, m.max_radius, nb], device=device), device,
            args.repeats)
    # the contact kernel alone: re-run it through a step minus the others is awkward, so
    # time a step with the grid already built by patching build to a no-op
    search = so.cell_list if so.cell_list is not None else so.grid
    search.build = lambda *a, **k: None
    stages["step_without_grid_build"] = timed(full_step, device, args.repeats)
    del search.build  # the class's method again
    n = m.num_spheres
    k_avg = float(sim.solver.contact_counts(sim.state).mean())
    bytes_per_sphere = min_bytes_per_sphere_step(k_avg)
    ms = stages["full_step"]
    out = dict(device=str(wp.get_device(device)), spheres=n, order=args.order,
               **used_solver_options(so),
               state_from=args.load_state or f"{args.settle_time} s settled here", contacts_per_sphere=round(k_avg, 3),
               ms=stages, sphere_steps_per_s=float(f"{n / (ms * 1e-3):.4g}"),
               min_bytes_per_sphere_step=round(bytes_per_sphere), effective_GBps=round(n * bytes_per_sphere / (ms * 1e-3) / 1e9, 1))
    # CUDA activity timing, or each launch timed on the host on the CPU; advances the simulation (last)
    out["kernels_ms_per_step"] = kernel_breakdown(sim, args.repeats)
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
