"""clump-bed benchmark: the settled-bed case (benchmarks/settled_bed.py) with the seed paper's
gravel mix of multi-sphere clumps instead of spheres.

N rigid clumps of the five gravel shape classes (``warpdem.shapes.gravel_templates``, fill
level "medium" by default: 22-25 spheres per clump), drawn with the Table 3 number fractions
(``gravel_shape_mix``), random orientations; rho = 2661, E = 1e7 Pa, nu = 0.3, e = 0.6,
mu_s = 0.5, mu_r = 0.1 (EPSD). Box 0.6 x 0.6 m (widened in x, y at the same depth above
20000 bodies, or W worlds of N each), loose jittered lattice (settled_bed.loose_fill, scaled
to the clumps' bounding spheres), Morton order of the bodies. The step is the engine's
recommended one (Hertz contact of the smallest member at 2 m/s: 3.3e-5 s for "medium"),
capped at 5e-5 s. Settle until KE per body < 1e-6 J, then time ``--steps`` steps after
``--warmup`` steps. One JSON line per run.

    python benchmarks/clump_bed.py --bodies 300 --width 0.2 --device cpu
    python benchmarks/clump_bed.py --bodies 20000 --device cuda
    python benchmarks/clump_bed.py --bodies 20000 --worlds 10 --device cuda
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time

import numpy as np
import warp as wp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from settled_bed import D, loose_fill, morton_order, settle_and_time  # noqa: E402  (reuse the settled-bed set-up)

import warpdem as wd  # noqa: E402
from warpdem import geometry  # noqa: E402
from warpdem.shapes import gravel_shape_mix, gravel_templates  # noqa: E402
from warpdem.bench_settled_bed import quiet_warp  # noqa: E402


def clump_fill(n: int, width: float, bound: float, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """n clump centres in a width x width column, no two bounding spheres (radius ``bound``)
    overlapping: settled_bed.loose_fill laid out for spheres of diameter D, scaled by 2 bound / D
    (its jitter keeps centres >= 1.006 D apart, i.e. >= 2.01 bound after scaling), lifted off
    the floor and walls. Returns the centres and the box width that holds them."""
    k = 2.0 * bound / D
    pos = loose_fill(n, width / k, rng) * k + 0.06 * bound
    return pos, max(width, float(pos[:, :2].max()) + bound)


def build(n: int, worlds: int, rolling: str, device: str, max_contacts: int, fill_level: str = "medium",
          width: float | None = None, order: str = "morton", seed: int = 0):
    templates = gravel_templates(fill_level)
    names = list(templates)
    mix = gravel_shape_mix()
    law = wd.ContactLaw(rolling=rolling)
    b = wd.ModelBuilder(num_worlds=worlds, contact_law=law, max_contacts=max_contacts)
    b.add_material(wd.Material("bed", 1.0e7, 0.3, 2661.0))
    rng = np.random.default_rng(seed)
    # number fractions of Table 3: floor, then the largest remainders
    exact = np.array([mix[k] for k in names]) * n
    counts = np.floor(exact).astype(int)
    counts[np.argsort(counts - exact)[: n - counts.sum()]] += 1
    kinds = np.repeat(np.arange(len(names)), counts)
    rng.shuffle(kinds)
    bound = max(t.bounding_radius for t in templates.values())
    width = 0.6 * max(1.0, math.sqrt(n / 20000.0)) if width is None else float(width)
    pos, box = clump_fill(n, width, bound, rng)
    rot = wd.random_quaternions(n, rng)
    if order == "morton":  # memory order follows space (member spheres of a body are contiguous)
        perm = morton_order(pos, 2.0 * bound)
        pos, rot, kinds = pos[perm], rot[perm], kinds[perm]
        # one add_clumps call per run of equal templates keeps the Morton order of the bodies
        cut = np.flatnonzero(np.diff(kinds)) + 1
        runs = np.split(np.arange(n), cut)
    else:  # grouped by template
        runs = [np.flatnonzero(kinds == i) for i in range(len(names))]
    for w in range(worlds):
        for idx in runs:
            if len(idx):
                b.add_clumps(templates[names[kinds[idx[0]]]], pos[idx], "bed", world=w, rotations=rot[idx])
    b.add_wall(geometry.open_box((0, 0, 0), (box, box, pos[:, 2].max() + 2 * bound)), "bed")
    params = dict(restitution_pp=0.6, restitution_pw=0.6, mu_s_pp=0.5, mu_s_pw=0.5)
    if rolling != "none":
        params.update(mu_r_pp=0.1, mu_r_pw=0.1)
    b.set_contact_parameters(**params)
    model = b.finalize(device, check_overlaps=b.num_spheres <= 400_000)
    return model, box, {k: int(c) for k, c in zip(names, counts)}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bodies", type=int, default=20000, help="clumps per world")
    ap.add_argument("--worlds", type=int, default=1)
    ap.add_argument("--device", default=None, help="cpu or cuda (default: cuda if present)")
    ap.add_argument("--fill", default="medium", choices=["low", "medium", "high"], help="spheres per clump (Table 2)")
    ap.add_argument("--rolling", default="epsd", choices=["none", "cdt", "epsd"])
    ap.add_argument("--width", type=float, default=None, help="box width [m] (default: settled-bed rule)")
    ap.add_argument("--dt", type=float, default=None, help="time step [s] (default: recommended, <= 5e-5)")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--settle-time", type=float, default=3.0, help="max simulated settling time [s]")
    ap.add_argument("--max-contacts", type=int, default=12)
    ap.add_argument("--max-neighbours", type=int, default=None,
                    help="neighbour-list slots per sphere (small members of clumps see many foreign members)")
    ap.add_argument("--no-graph", action="store_true")
    ap.add_argument("--order", default="morton", choices=["morton", "grouped"], help="memory order of the bodies")
    args = ap.parse_args(argv)
    quiet_warp()
    device = args.device or ("cuda" if wp.is_cuda_available() else "cpu")
    t0 = time.perf_counter()
    model, width, counts = build(args.bodies, args.worlds, args.rolling, device, args.max_contacts, args.fill,
                                 args.width, args.order)
    limits = wd.time_step_limits(model)
    dt = args.dt or min(5.0e-5, limits.recommended)
    sim = wd.Simulation(model, dt, use_graph=None if not args.no_graph else False, steps_per_graph=50,
                        max_neighbours=args.max_neighbours)
    t_build = time.perf_counter() - t0
    settle_sim_time, t_settle, seconds = settle_and_time(sim, device, args.settle_time, args.warmup, args.steps)
    ke = sim.kinetic_energy() / args.bodies
    counts_c = sim.solver.contact_counts(sim.state)
    spheres = model.num_spheres // args.worlds
    n_bodies = args.bodies * args.worlds
    result = dict(
        case="clump-bed", device=str(wp.get_device(device)), device_name=wp.get_device(device).name,
        host=platform.node(), bodies=args.bodies, spheres=spheres, worlds=args.worlds, total_bodies=n_bodies,
        total_spheres=model.num_spheres, steps=args.steps, seconds=round(seconds, 4),
        sphere_steps_per_s=float(f"{model.num_spheres * args.steps / seconds:.4g}"),
        body_steps_per_s=float(f"{n_bodies * args.steps / seconds:.4g}"),
        contacts_per_sphere=round(float(counts_c.mean()), 3), spheres_per_body=round(spheres / args.bodies, 2),
        fill=args.fill, shape_counts=counts, rolling=args.rolling, dt=dt, dt_limit=float(f"{limits.limit:.4g}"),
        box_width_m=round(width, 4), settle_sim_time_s=round(settle_sim_time, 3), settle_wall_s=round(t_settle, 1),
        ke_per_body_J=float(f"{ke.max():.3g}"), build_s=round(t_build, 1), warp=wp.config.version,
        graph=sim.use_graph, order=args.order, date=time.strftime("%Y-%m-%d"))
    print(json.dumps(result), flush=True)
    return result


if __name__ == "__main__":
    main()
