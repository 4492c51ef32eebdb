"""Registers, spilled bytes and resident warps per SM of the force kernels of several contact laws,
with the compiler's own register choice and with register caps (``DEMSolver(force_registers=...)``).

    python benchmarks/force_kernel_registers.py --caps 80            # CUDA only; one JSON line per law and cap

Each law runs a tiny two-world drum scene (tests/test_contact_stages.py's) for a few steps on CUDA so
that its kernels are compiled and loaded, then :func:`warpdem.bench_settled_bed.kernel_resources`
reads the CUDA driver's figures. A cap that makes a kernel spill (``local_bytes`` > 0) costs time:
the settled bed at a cap of 64 spilled 80 B per thread and ran 5 % slower (docs/notes/engine_speed.md).
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

import warpdem as wd  # noqa: E402
from warpdem import geometry  # noqa: E402
from warpdem.bench_settled_bed import force_kernel_resources, quiet_warp  # noqa: E402

# the laws the engine's experiments and the diagnosis use (plus the plain Hertz-Mindlin default)
LAWS = {
    "hertz_mindlin": {},
    "epsd": dict(rolling="epsd"),
    "epsd2": dict(rolling="epsd2"),
    "epsd2_sjkr": dict(rolling="epsd2", cohesion="sjkr"),
    "cdt": dict(rolling="cdt"),
}


def drum_scene(law: dict, cap: int | None, device: str) -> wd.Simulation:
    rng = np.random.default_rng(1)
    b = wd.ModelBuilder(num_worlds=2, contact_law=wd.ContactLaw(**law))
    b.add_material(wd.GRAVEL)
    r = 0.004
    for w in range(2):
        ijk = np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), -1).reshape(-1, 3)
        pos = (-0.012, -0.012, -0.0425) + ijk * 2.05 * r + rng.uniform(-1e-4, 1e-4, (27, 3))
        b.add_spheres(pos, r, "gravel", world=w)
    drum = geometry.cylinder_shell(0.05, 0.04, axis=(0.0, 1.0, 0.0), sections=48)
    for w in range(2):
        b.add_wall(drum, wd.PLEXIGLAS, world=w, motion=wd.WallMotion.rotation((0, 1, 0), 30.0), name=f"drum {w}")
    sim = wd.Simulation(b.finalize(device, overlap_tolerance=0.2), dt=2e-5, force_registers=cap)
    sim.run(4)
    return sim


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--caps", type=int, nargs="*", default=[80], help="register caps besides the compiler's choice")
    ap.add_argument("--device", default="cuda")
    args = ap.parse_args(argv)
    quiet_warp()
    if not wp.get_device(args.device).is_cuda:
        raise SystemExit("force_kernel_registers.py: CUDA only (the CPU has no register cap)")
    out = []
    for name, law in LAWS.items():
        for cap in [None, *args.caps]:
            sim = drum_scene(law, cap, args.device)
            res = dict(case="force-kernel-registers", device=wp.get_device(args.device).name, law=name, cap=cap,
                       kernels=force_kernel_resources(sim.solver), date=time.strftime("%Y-%m-%d"))
            print(json.dumps(res), flush=True)
            out.append(res)
    return out


if __name__ == "__main__":
    main()
