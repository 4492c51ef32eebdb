"""Pour spheres into a box, then lift its baffle and let the material run out.

    python examples/pour_box.py                  # ~3000 spheres, CPU by default (GPU if present)
    python examples/pour_box.py --spheres 20000 --device cuda --out out/pour

Writes VTK files (particles_*.vtp, wall_*.vtp) for ParaView and prints the angle of the
slope left behind, measured as the baffle test defines it (spec A) with
:mod:`calibration.measurement`; that is why the job lives here, not in the engine.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import warp as wp

import warpdem as wd
from warpdem import geometry
from warpdem.config_io import (check_output_folder, check_sphere_memory, device_arg, nonnegative_float_arg,
                               positive_int_arg)
from warpdem.io import write_vtk

from .measurement import baffle_static_angle, mean_surface_height


def loose_fill(n: int, lower, upper, d: float, rng) -> np.ndarray:
    """Jittered lattice of n sphere centres in the box [lower, upper], stacked upwards."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    s = 1.08 * d
    nx, ny = int((upper[0] - lower[0] - d) // s), int((upper[1] - lower[1] - d) // s)
    nz = math.ceil(n / (nx * ny))
    g = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), -1).reshape(-1, 3)
    g = g[np.argsort(g[:, 2], kind="stable")][:n]
    pos = lower + d / 2 + g * s + 0.02 * d
    return pos + rng.uniform(-0.03 * d, 0.03 * d, pos.shape)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="warpdem pour", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spheres", type=positive_int_arg, default=2000)
    ap.add_argument("--device", type=device_arg, default=None, help="cpu or cuda (default: cuda if present, else cpu)")
    ap.add_argument("--out", default="out/pour_box", help="output folder for VTK files")
    ap.add_argument("--frames", type=positive_int_arg, default=20, help="VTK frames to write")
    ap.add_argument("--mu", type=nonnegative_float_arg, default=0.5,
                    help="sliding friction (particle-particle and -wall)")
    ap.add_argument("--mu-r", type=nonnegative_float_arg, default=0.1, help="rolling friction (EPSD)")
    args = ap.parse_args(argv)
    check_sphere_memory(args.spheres, "--spheres", "pour fewer spheres")
    check_output_folder(args.out, "--out")
    from warpdem.warp_output import quiet_warp

    quiet_warp()
    device = args.device or ("cuda" if wp.is_cuda_available() else "cpu")
    d, rng = 0.018, np.random.default_rng(1)
    box_x, box_y = 0.30, 0.20
    b = wd.ModelBuilder(contact_law=wd.ContactLaw(rolling="epsd"))
    b.add_material(wd.GRAVEL)
    b.add_material(wd.PLEXIGLAS)
    pos = loose_fill(args.spheres, (0, 0, 0), (box_x, box_y, 1.0), d, rng)
    b.add_spheres(pos, rng.uniform(0.45 * d, 0.5 * d, len(pos)), "gravel")
    top = float(pos[:, 2].max() + d)
    # fixed walls x = 0, y = 0, y = box_y on a long floor; the baffle closes x = box_x
    b.add_wall(geometry.plane((0.35, box_y / 2, 0.0), 0.7, box_y, subdivisions=2), "plexiglas", name="floor")
    b.add_wall(geometry.plane((0.0, box_y / 2, top / 2), box_y, top, normal=(1, 0, 0)), "plexiglas", name="back")
    b.add_wall(geometry.plane((0.35, 0.0, top / 2), 0.7, top, normal=(0, 1, 0)), "plexiglas", name="side_y0")
    b.add_wall(geometry.plane((0.35, box_y, top / 2), 0.7, top, normal=(0, -1, 0)), "plexiglas", name="side_y1")
    t_lift = 1.0  # pour and settle, then lift the baffle at 0.1 m/s (spec A) until it clears the bed
    lift = 0.6 * top + 0.05
    b.add_wall(geometry.plane((box_x, box_y / 2, top / 2), box_y, top, normal=(-1, 0, 0)), "plexiglas", name="baffle",
               motion=wd.WallMotion.translation((0, 0, 0.1), start=t_lift, stop=t_lift + lift / 0.1))
    b.set_contact_parameters(mu_s_pp=args.mu, mu_s_pw=args.mu, mu_r_pp=args.mu_r, mu_r_pw=args.mu_r)
    model = b.finalize(device)
    dt = min(5e-5, wd.time_step_limits(model).recommended)
    sim = wd.Simulation(model, dt)
    t_end = t_lift + lift / 0.1 + 1.0
    steps = int(t_end / dt)
    out = Path(args.out)
    every = max(1, steps // args.frames)
    frame = [0]

    def dump(s):
        s.remove_outside((-0.05, -0.05, -0.05), (0.7, box_y + 0.05, 2.0))
        write_vtk(out, s, frame[0])
        frame[0] += 1

    print(f"warpdem pour_box: {model.num_spheres} spheres on {device}, dt = {dt:.2e} s, {steps} steps", flush=True)
    t0 = time.perf_counter()
    r = model.host["sphere_radius"]
    dump(sim)
    n_pour = int(t_lift / dt)
    sim.run(n_pour, callback=dump, callback_every=every, progress=True)
    h_fill = mean_surface_height(sim.sphere_positions(), r)  # settled fill height before the lift
    sim.run(steps - n_pour, callback=dump, callback_every=every, progress=True)
    wall = time.perf_counter() - t0
    x = sim.sphere_positions()
    active = sim.state.body_active.numpy().astype(bool)
    result = dict(spheres=model.num_spheres, device=device, steps=steps, wall_seconds=round(wall, 1),
                  sphere_steps_per_s=float(f"{model.num_spheres * steps / wall:.3g}"), vtk=str(out))
    try:
        fit = baffle_static_angle(x[active], r[active], h_fill)
        result.update(h_fill_m=round(h_fill, 4), angle_deg=round(fit.angle_deg, 2), bins=fit.n_bins)
    except ValueError as exc:  # MeasurementError: no slope to measure (e.g. all material ran out)
        result.update(angle_deg=None, measurement_error=str(exc))
    print(json.dumps(result))
    return result


def cli_main(argv: list[str] | None = None) -> int:
    """``warpdem pour``: run :func:`main`, exit code 0."""
    main(argv)
    return 0


if __name__ == "__main__":
    main()
