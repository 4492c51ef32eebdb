"""How well a time step resolves single impacts (issue 10, "Time step and damping").

The standard experiments run at a fraction of the Rayleigh time T_R of the batch's smallest
sphere (0.2 by default). This benchmark isolates the integration error of that choice from
everything else (packing, chaos, frame sampling): binary impacts at the speeds a granular flow
reaches, integrated at several fractions of T_R and compared with a 50 x finer step.

Impacts (no gravity; the paper's gravel, E = 1e7 Pa, nu = 0.3, rho = 2661 kg/m^3, against
Plexiglas walls; restitution 0.6; sliding friction 0.45 particle-particle, 0.35 wall;
``epsd2`` rolling resistance mu_r 0.15 unless ``--rolling none``), one world per impact speed,
all in one model, for each tangential sub-model named (``--tangential history mindlin``):

* ``sphere_pair``: two spheres of d = 16 mm head on at relative speed v: normal restitution
  e_n = v_rel' / v_rel.
* ``sphere_wall_oblique``: one sphere at 45 deg onto a plane, v_n = v_t = v / sqrt(2): e_n,
  tangential ratio v_t' / v_t and spin w' R / v_t (Chung & Ooi 2011, test 6 style).
* ``rod_wall``: a rod of the ``elongated`` family (aspect ratio 2, d_eq = 16 mm; 5 members of
  smaller radius) tilted 30 deg, falling flat-ish onto a plane at v: the rebound speed of its
  centre of mass and the kinetic energy kept (an off-centre impact with rotation).

Speeds 0.25-4 m/s: a 0.3 m drum at 45 rpm moves its wall at 0.71 m/s, and particles falling
across the drum reach about sqrt(2 g 0.3) = 2.4 m/s. The Hertz contact lasts
t_c = 2.868 (m*^2 / (R* E*^2 v))^(1/5) (Johnson 1985, Sec. 11.4), so faster impacts get fewer steps.

One JSON line per (case, speed, fraction) on stdout, then a summary table on stderr:

    python benchmarks/impact_resolution.py --fractions 0.2 0.1 0.05 --reference 0.002 --tangential history mindlin
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np
import warp as wp

import warpdem as wd
from warpdem import geometry
from warpdem.shape_families import shape_family
from warpdem.bench_settled_bed import quiet_warp

SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0)  # impact speed [m/s]
D = 0.016  # sphere diameter / rod volume-equivalent diameter [m]
PARAMS = dict(restitution_pp=0.6, restitution_pw=0.6, mu_s_pp=0.45, mu_s_pw=0.35)
ROLLING_PARAMS = dict(mu_r_pp=0.15, mu_r_pw=0.15)
CASES = ("sphere_pair", "sphere_wall_oblique", "rod_wall")


def _builder(law: wd.ContactLaw) -> wd.ModelBuilder:
    b = wd.ModelBuilder(num_worlds=len(SPEEDS), gravity=(0.0, 0.0, 0.0), contact_law=law)
    b.add_material(wd.GRAVEL)
    b.add_material(wd.PLEXIGLAS)
    return b


def _rod_template():
    return shape_family("elongated").template(D, wd.GRAVEL.density, aspect_ratio=2.0)


def build(case: str, law: wd.ContactLaw, device: str | None) -> wd.Model:
    """One world per impact speed; bodies start 1e-6 m clear of their partner."""
    b = _builder(law)
    r = 0.5 * D
    gap = 1.0e-6
    for w, v in enumerate(SPEEDS):
        if case == "sphere_pair":
            b.add_sphere((0.0, 0.0, -r - gap), r, "gravel", world=w, velocity=(0.0, 0.0, 0.5 * v))
            b.add_sphere((0.0, 0.0, r + gap), r, "gravel", world=w, velocity=(0.0, 0.0, -0.5 * v))
        elif case == "sphere_wall_oblique":
            c = v / math.sqrt(2.0)
            b.add_sphere((0.0, 0.0, r + gap), r, "gravel", world=w, velocity=(c, 0.0, -c))
        elif case == "rod_wall":
            tpl = _rod_template()
            tilt = math.radians(30.0)
            # rod axis = principal x; rotate about y by the tilt: its low end touches first
            q = (0.0, math.sin(0.5 * tilt), 0.0, math.cos(0.5 * tilt))
            rot = _quat_matrix(q)
            members = np.asarray(tpl.centers) @ rot.T
            lowest = float(np.min(members[:, 2] - np.asarray(tpl.radii)))
            b.add_clumps(tpl, [(0.0, 0.0, -lowest + gap)], "gravel", world=w, rotations=[q],
                         velocities=[(0.0, 0.0, -v)])
        else:
            raise ValueError(case)
    if case != "sphere_pair":
        b.add_wall(geometry.plane((0.0, 0.0, 0.0), 0.4, 0.4), "plexiglas")
    b.set_contact_parameters(**PARAMS, **(ROLLING_PARAMS if law.rolling != "none" else {}))
    return b.finalize(device)


def _quat_matrix(q) -> np.ndarray:
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def outcome(case: str, model: wd.Model, sim: wd.Simulation) -> list[dict[str, float]]:
    """Post-impact quantities per world (speed), dimensionless."""
    v = sim.state.body_v.numpy().astype(np.float64)
    w = sim.state.body_w.numpy().astype(np.float64)
    out = []
    for k, s in enumerate(SPEEDS):
        if case == "sphere_pair":
            v0, v1 = v[2 * k], v[2 * k + 1]
            out.append({"e_n": float((v1[2] - v0[2]) / s)})
        elif case == "sphere_wall_oblique":
            c = s / math.sqrt(2.0)
            out.append({"e_n": float(v[k, 2] / c), "tangential_ratio": float(v[k, 0] / c),
                        "spin_ratio": float(w[k, 1] * 0.5 * D / c)})
        else:
            m = float(model.host["body_mass"][k])
            inertia = np.asarray(model.host["body_inertia"][k], dtype=np.float64)
            q = sim.state.body_rot.numpy()[k].astype(np.float64)
            rot = _quat_matrix(q)
            w_body = rot.T @ w[k]
            ke = 0.5 * m * float(v[k] @ v[k]) + 0.5 * float(np.sum(inertia * w_body**2))
            out.append({"rebound_ratio": float(v[k, 2] / s), "energy_kept": ke / (0.5 * m * s * s)})
    return out


def run_case(case: str, law: wd.ContactLaw, fraction: float, device: str | None) -> tuple[list[dict[str, float]], dict]:
    """Outcomes per speed at dt = ``fraction`` x the Rayleigh time, and the run's facts."""
    model = build(case, law, device)
    lim = wd.time_step_limits(model)
    t_r = lim.rayleigh
    dt = fraction * t_r
    sim = wd.Simulation(model, dt, force=True, v_ref=max(SPEEDS))
    # long enough for the slowest impact (and a rod's second contact) to end
    t_end = 8.0 * wd.hertz_contact_time(float(model.host["body_mass"].min()) / 2, 0.25 * D, 5.0e6, min(SPEEDS))
    steps = int(math.ceil(t_end / dt))
    t0 = time.perf_counter()
    sim.run(steps, check_every=max(1, steps))
    info = {"dt_s": dt, "rayleigh_s": t_r, "steps": steps, "wall_s": round(time.perf_counter() - t0, 2),
            "steps_per_contact_at": {f"{s:g}": _steps_per_contact(model, s, dt) for s in SPEEDS}}
    return outcome(case, model, sim), info


def _steps_per_contact(model: wd.Model, v: float, dt: float) -> float:
    """Hertz contact duration of the smallest sphere against its twin, in steps."""
    r = float(model.host["sphere_radius"].min())
    m = wd.GRAVEL.density * 4.0 / 3.0 * math.pi * r**3
    e_eff = wd.materials.effective_youngs_modulus(wd.GRAVEL, wd.GRAVEL)
    return round(wd.hertz_contact_time(0.5 * m, 0.5 * r, e_eff, v) / dt, 1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--fractions", nargs="+", type=float, default=[0.2, 0.1, 0.05],
                    help="time steps as fractions of the smallest sphere's Rayleigh time")
    ap.add_argument("--reference", type=float, default=0.002, help="fraction of the reference (fine) step")
    ap.add_argument("--tangential", nargs="+", default=["history", "mindlin"], help="tangential sub-models to compare")
    ap.add_argument("--rolling", default="epsd2", help="rolling sub-model (none: no rolling resistance)")
    args = ap.parse_args(argv)
    quiet_warp()
    rows = []
    for tangential in args.tangential:
        law = wd.ContactLaw(tangential=tangential, rolling=args.rolling)
        rows += compare_steps(law, args)
    sys.stderr.write(f"{'law':<38}{'case':<22}{'v [m/s]':>8}{'dt/T_R':>8}{'steps/t_c':>10}  relative deviation from "
                     f"dt/T_R = {args.reference:g}\n")
    for r in rows:
        dev = ", ".join(f"{q} {x:+.1%}" for q, x in r["relative_deviation"].items())
        sys.stderr.write(f"{r['law']:<38}{r['case']:<22}{r['speed_m_s']:>8g}{r['dt_rayleigh_fraction']:>8g}"
                         f"{r['steps_per_contact']:>10g}  {dev}\n")
    return 0


def compare_steps(law: wd.ContactLaw, args) -> list[dict]:
    """One JSON line per (case, speed, fraction) of one law, printed and returned."""
    rows = []
    for case in args.cases:
        ref, _ = run_case(case, law, args.reference, args.device)
        for frac in sorted(args.fractions, reverse=True):
            got, info = run_case(case, law, frac, args.device)
            for k, s in enumerate(SPEEDS):
                dev = {q: round(got[k][q] - ref[k][q], 4) for q in got[k]}
                rel = {q: round((got[k][q] - ref[k][q]) / abs(ref[k][q]), 4) for q in got[k]}
                line = {"law": law.describe(), "case": case, "speed_m_s": s, "dt_rayleigh_fraction": frac,
                        "dt_s": info["dt_s"],
                        "steps_per_contact": info["steps_per_contact_at"][f"{s:g}"],
                        "values": {q: round(x, 4) for q, x in got[k].items()},
                        "reference": {q: round(x, 4) for q, x in ref[k].items()},
                        "reference_fraction": args.reference, "deviation": dev, "relative_deviation": rel,
                        "device": args.device, "warp": wp.config.version}
                print(json.dumps(line), flush=True)
                rows.append(line)
    return rows


if __name__ == "__main__":
    raise SystemExit(main())
