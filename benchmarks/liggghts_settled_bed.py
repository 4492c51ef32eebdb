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
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from warpdem.bench_settled_bed import D, R, loose_fill, morton_order
from warpdem.config_io import positive_float_arg, positive_int_arg

STEPS, WARMUP = 2000, 200
DT = 5.0e-5
SKIN = 0.3 * R


def data_file(pos: np.ndarray, width: float, top: float) -> str:
    """A LIGGGHTS ``read_data`` file of the spheres (atom_style granular: id type diameter density x y z)."""
    lines = ["LIGGGHTS data file: settled-bed loose fill", "", f"{len(pos)} atoms", "2 atom types", "",
             f"0 {width:.10g} xlo xhi", f"0 {width:.10g} ylo yhi", f"0 {top:.10g} zlo zhi", "", "Atoms", ""]
    lines += [f"{i + 1} 1 {D:.10g} 2661 {x:.10g} {y:.10g} {z:.10g}" for i, (x, y, z) in enumerate(pos)]
    return "\n".join(lines) + "\n"


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
    from validation.reference.liggghts import _require_executable, liggghts_version

    exe = _require_executable()
    width = 0.6 * max(1.0, math.sqrt(args.spheres / 20000.0))
    pos = loose_fill(args.spheres, width, np.random.default_rng(0))
    pos = pos[morton_order(pos, D)]
    top = float(pos[:, 2].max() + D)
    folder = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="liggghts_bed_"))
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "bed.data").write_text(data_file(pos, width, top))
    (folder / "in.bed").write_text(deck(width, top, args.rolling, args.settle_time))
    cmd = [exe, "-in", "in.bed", "-log", "log.liggghts", "-screen", "none", "-nocite"]
    if args.procs > 1:
        cmd = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-np", str(args.procs), *cmd]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=folder, capture_output=True, text=True, env={"OMP_NUM_THREADS": "1",
                                                                                 "PATH": "/usr/bin:/bin"})
    wall = time.perf_counter() - t0
    log = (folder / "log.liggghts").read_text(errors="replace") if (folder / "log.liggghts").exists() else ""
    if proc.returncode != 0 or "ERROR" in log:
        tail = "\n".join((log or proc.stdout + proc.stderr).splitlines()[-15:])
        raise SystemExit(f"LIGGGHTS failed in {folder} (rc {proc.returncode}):\n{tail}")
    r = parse(log)
    result = dict(case="settled-bed", code=liggghts_version(exe), host=platform.node(), spheres=args.spheres,
                  procs=r["procs"], rolling=args.rolling, walls="primitive planes", skin_m=SKIN, dt=DT,
                  steps=r["steps"], seconds=round(r["seconds"], 3),
                  sphere_steps_per_s=float(f"{args.spheres * r['steps'] / r['seconds']:.4g}"),
                  contacts_per_sphere=r["contacts_per_sphere"], settle_sim_time_s=(r["settle_steps"] or 0) * DT,
                  ke_per_particle_J=r["ke_per_particle_J"], wall_s=round(wall, 1), date=time.strftime("%Y-%m-%d"),
                  folder=str(folder) if args.keep else None)
    print(json.dumps(result), flush=True)
    return result


if __name__ == "__main__":
    main()
