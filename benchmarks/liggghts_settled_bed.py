"""The settled-bed case (docs/benchmarks.md) run by LIGGGHTS-PUBLIC 3.8 on this machine, so that
warpdem's CPU figure has a peer measured on the same cores the same day (issue 33, item 3).

Same case as ``benchmarks/settled_bed.py``: the same jittered lattice of N spheres d = 18 mm
(``loose_fill``, seed 0, in the same memory order), rho 2661, E 1e7 Pa, nu 0.3, e 0.6,
mu_s 0.5, mu_r 0.1 (LIGGGHTS ``rolling_friction epsd`` with no viscous part, as warpdem's
``epsd``; ``--rolling epsd2`` for the sub-model the spec's peer figure names), Hertz with
tangential history, dt 5e-5 s, gravity -z, the box as LIGGGHTS primitive planes (floor and four
sides), Verlet skin 0.3 R (warpdem's default) with ``neigh_modify delay 0``. Settle in chunks of
0.05 s until KE per particle < 1e-6 J (at least 0.3 s, at most --settle-time), then 200 warm-up
steps, then time 2000 steps: LIGGGHTS' own "Loop time" of that run. One JSON line.

    python benchmarks/liggghts_settled_bed.py --spheres 20000            # one core
    python benchmarks/liggghts_settled_bed.py --spheres 20000 --procs 2  # mpirun -np 2
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import re
import tempfile
import time
from pathlib import Path

import numpy as np

from warpdem.bench_settled_bed import D, R, loose_fill, morton_order
from warpdem.config_io import positive_float_arg, positive_int_arg

STEPS, WARMUP = 2000, 200
DT = 5.0e-5
SKIN = 0.3 * R


def deck(width: float, top: float, rolling: str, settle_time: float) -> str:
    """The input deck: setup, KE-criterion settling loop, warm-up, timed run."""
    chunk = int(round(0.05 / DT))
    max_chunks = int(math.ceil(settle_time / 0.05))
    min_chunks = int(math.ceil(0.3 / 0.05))
    viscous = ["fix m6 all property/global coefficientRollingViscousDamping peratomtypepair 2 0 0 0 0"] \
        if rolling == "epsd" else []
    model = f"model hertz tangential history rolling_friction {rolling}"
    return "\n".join([
        "atom_style granular", "atom_modify map array", "boundary f f f", "newton off",
        "communicate single vel yes", "units si",
        "read_data bed.data",
        f"neighbor {SKIN:.6g} bin", "neigh_modify delay 0", "hard_particles yes",
        "fix m1 all property/global youngsModulus peratomtype 1e7 1e7",
        "fix m2 all property/global poissonsRatio peratomtype 0.3 0.3",
        "fix m3 all property/global coefficientRestitution peratomtypepair 2 0.6 0.6 0.6 0.6",
        "fix m4 all property/global coefficientFriction peratomtypepair 2 0.5 0.5 0.5 0.5",
        "fix m5 all property/global coefficientRollingFriction peratomtypepair 2 0.1 0.1 0.1 0.1",
        *viscous,
        f"pair_style gran {model}", "pair_coeff * *",
        f"timestep {DT:g}",
        "fix gravity all gravity 9.81 vector 0.0 0.0 -1.0",
        f"fix floor all wall/gran {model} primitive type 2 zplane 0.0",
        f"fix side_x0 all wall/gran {model} primitive type 2 xplane 0.0",
        f"fix side_x1 all wall/gran {model} primitive type 2 xplane {width:.10g}",
        f"fix side_y0 all wall/gran {model} primitive type 2 yplane 0.0",
        f"fix side_y1 all wall/gran {model} primitive type 2 yplane {width:.10g}",
        "fix integrate all nve/sphere",
        "compute ke_translation all ke", "compute ke_rotation all erotate/sphere",
        "variable ke_per_particle equal (c_ke_translation+c_ke_rotation)/atoms",
        "thermo_style custom step atoms v_ke_per_particle", "thermo 1000", "thermo_modify lost ignore norm no",
        "variable step_now equal step",
        f"variable settle_i loop {max_chunks}",
        "label settle_loop",
        f"run {chunk} post no",
        f'if "${{ke_per_particle}} < 1e-6 && ${{settle_i}} >= {min_chunks}" then "jump SELF settled"',
        "next settle_i",
        "jump SELF settle_loop",
        "label settled",
        'print "SETTLED step ${step_now} ke_per_particle ${ke_per_particle}"',
        f"run {WARMUP} post no",
        'print "TIMED_START"',
        f"run {STEPS}",
        "compute contacts all contact/atom",
        "compute mean_contacts all reduce ave c_contacts",
        "thermo_style custom step atoms c_mean_contacts",
        "run 0",
    ]) + "\n"


def parse(log: str) -> dict:
    """Loop time of the timed run, the settling step and the mean contacts per sphere."""
    timed = log.split("TIMED_START", 1)[1]
    m = re.search(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms", timed)
    if not m:
        raise SystemExit("no 'Loop time' line after the timed run in the LIGGGHTS log")
    settled = re.search(r"SETTLED step (\d+) ke_per_particle ([0-9.eE+-]+)", log)
    # the last thermo line of the 'run 0': step atoms mean_contacts
    rows = re.findall(r"^\s*(\d+)\s+(\d+)\s+([0-9.eE+-]+)\s*$", timed.split("run 0", 1)[-1], re.M)
    return dict(seconds=float(m.group(1)), procs=int(m.group(2)), steps=int(m.group(3)), atoms=int(m.group(4)),
                settle_steps=int(settled.group(1)) if settled else None,
                ke_per_particle_J=float(settled.group(2)) if settled else None,
                contacts_per_sphere=float(rows[-1][2]) if rows else None)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spheres", type=positive_int_arg, default=20000)
    ap.add_argument("--procs", type=positive_int_arg, default=1, help="MPI processes (mpirun -np)")
    ap.add_argument("--rolling", default="epsd", choices=["epsd", "epsd2"])
    ap.add_argument("--settle-time", type=positive_float_arg, default=3.0, help="max simulated settling time [s]")
    ap.add_argument("--keep", default=None, help="run in this folder and keep it (default: a temporary one)")
    args = ap.parse_args(argv)
    from validation.reference.liggghts import LiggghtsFailed, run_deck
    from validation.reference.liggghts_experiments import sphere_data_file

    width = 0.6 * max(1.0, math.sqrt(args.spheres / 20000.0))
    pos = loose_fill(args.spheres, width, np.random.default_rng(0))
    pos = pos[morton_order(pos, D)]
    top = float(pos[:, 2].max() + D)
    data = sphere_data_file(pos, np.full(len(pos), R), 2661.0, np.zeros(3), np.array([width, width, top]))
    with tempfile.TemporaryDirectory(prefix="liggghts_bed_") as scratch:
        try:
            run = run_deck(deck(width, top, args.rolling, args.settle_time), Path(args.keep or scratch),
                           {"bed.data": data}, processes=args.procs)
        except LiggghtsFailed as e:
            raise SystemExit(str(e)) from None
    r = parse(run.log)
    result = dict(case="settled-bed", code=run.version, host=platform.node(), spheres=args.spheres,
                  procs=r["procs"], rolling=args.rolling, walls="primitive planes", skin_m=SKIN, dt=DT,
                  steps=r["steps"], seconds=round(r["seconds"], 3),
                  sphere_steps_per_s=float(f"{args.spheres * r['steps'] / r['seconds']:.4g}"),
                  contacts_per_sphere=r["contacts_per_sphere"], settle_sim_time_s=(r["settle_steps"] or 0) * DT,
                  ke_per_particle_J=r["ke_per_particle_J"], wall_s=round(run.wall_s, 1), date=time.strftime("%Y-%m-%d"),
                  folder=args.keep)
    print(json.dumps(result), flush=True)
    return result


if __name__ == "__main__":
    main()
