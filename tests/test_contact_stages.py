"""The staged contact computation (warpdem.stages) reproduces the single contact kernel it
replaced: five short CPU scenes (and one contact launch with ``walls_on=False``) are run and their body positions, velocities, contact
counts and wall wear compared with values saved from the single-kernel code
(tests/data/contact_stages_reference.npz, written by ``python tests/test_contact_stages.py --write``
with the engine of commit 3cede01, before the split). The scenes run with
``pair_evaluation="full"``, the evaluation the reference was taken with (the CPU's ``"half"`` is
checked against it in tests/test_pair_evaluation.py).

Tolerance: the stages evaluate every contact with the same float32 operations in the same
order (wall contacts first, then the neighbour list; the particle stage continues the wall
stage's per-sphere sums), so the results agree to the last bit on the same platform; the
comparison allows rtol 1e-5 / atol 1e-9 (the float32 rounding of a few operations that a
compiler may contract differently, e.g. into fused multiply-adds, amplified over 200 steps of
contacts) so that it does not depend on the compiler's choices. Any physics change (a lost
contact, a different force) moves positions by far more than that within 200 steps.
"""
from __future__ import annotations

import math
import pathlib
import sys

import numpy as np
import pytest

import warpdem as wd
from warpdem import geometry

REFERENCE = pathlib.Path(__file__).parent / "data" / "contact_stages_reference.npz"
R = 0.005  # sphere radius [m]
RTOL, ATOL = 1e-5, 1e-9


# the saved values were computed with the tangential sub-model that was the default then
REFERENCE_TANGENTIAL = "mindlin"


def _lattice(n: int, spacing: float, origin, rng: np.random.Generator, jitter: float) -> np.ndarray:
    """n points of a cubic lattice (``spacing`` [m]) from ``origin``, jittered by up to ``jitter`` [m]."""
    side = math.ceil(n ** (1.0 / 3.0))
    ijk = np.array([(i, j, k) for k in range(side) for j in range(side) for i in range(side)][:n], dtype=float)
    return np.asarray(origin) + ijk * spacing + rng.uniform(-jitter, jitter, (n, 3))


def scene_drum() -> wd.Simulation:
    """Two worlds of spheres tumbling in a rotating drum (one BVH, each world's own speed and
    friction); world 1 is paused for a while (history carried over unchanged)."""
    rng = np.random.default_rng(1)
    b = wd.ModelBuilder(num_worlds=2, contact_law=wd.ContactLaw(tangential=REFERENCE_TANGENTIAL))
    b.add_material(wd.GRAVEL)
    for w in range(2):
        pos = _lattice(27, 2.05 * R, (-0.012, -0.012, -0.0425), rng, 1e-4)
        b.add_spheres(pos, R, "gravel", world=w, velocities=rng.normal(0.0, 0.3, (27, 3)) + (0.0, 0.0, -0.8))
    drum = geometry.cylinder_shell(0.05, 0.04, axis=(0.0, 1.0, 0.0), sections=48)
    b.add_wall(drum, wd.PLEXIGLAS, world=0, motion=wd.WallMotion.rotation((0, 1, 0), 30.0), name="drum 0")
    b.add_wall(drum, wd.PLEXIGLAS, world=1, motion=wd.WallMotion.rotation((0, 1, 0), -60.0), name="drum 1")
    b.set_contact_parameters(mu_s_pp=[0.3, 0.6], mu_s_pw=[0.5, 0.2], restitution_pp=0.5)
    return wd.Simulation(b.finalize("cpu", overlap_tolerance=0.2), dt=2e-5, use_graph=False,
                         pair_evaluation="full")


def scene_clumps() -> wd.Simulation:
    """Three-sphere clumps (asymmetric inertia) falling into an open box onto each other."""
    rng = np.random.default_rng(2)
    b = wd.ModelBuilder(contact_law=wd.ContactLaw(rolling="cdt", tangential=REFERENCE_TANGENTIAL))
    b.add_material(wd.GRAVEL)
    offsets = np.array([[-0.6 * R, 0.0, 0.0], [0.0, 0.2 * R, 0.0], [0.7 * R, 0.0, 0.1 * R]])
    radii = np.array([0.8 * R, R, 0.7 * R])
    mass = wd.GRAVEL.density * 4.0 / 3.0 * math.pi * float(np.sum(radii**3))
    inertia = (0.3 * mass * R**2, 0.5 * mass * R**2, 0.6 * mass * R**2)
    for p in _lattice(16, 2.7 * R, (0.012, 0.012, 0.007), rng, 2e-4):
        q = rng.normal(size=4)
        b.add_body(p, mass, inertia, offsets, radii, "gravel", rotation=q / np.linalg.norm(q),
                   velocity=rng.normal(0.0, 0.5, 3) + (0.0, 0.0, -1.0), angular_velocity=rng.normal(0.0, 50.0, 3))
    b.add_wall(geometry.open_box((0.0, 0.0, 0.0), (0.05, 0.05, 0.06)), wd.PLEXIGLAS)
    b.set_contact_parameters(mu_r_pp=0.1, mu_r_pw=0.05)
    return wd.Simulation(b.finalize("cpu", overlap_tolerance=0.2), dt=1e-5, use_graph=False,
                         pair_evaluation="full")


def scene_cohesion_epsd2() -> wd.Simulation:
    """Cohesive spheres with epsd2 rolling resistance heaped on a tilted plate. The reference was
    recorded when ``sjkr`` let the friction limits see the cohesion; that law is ``sjkr_reduced``
    since 2026-11-27 (``sjkr`` now follows LIGGGHTS' default, warpdem.contact.cohesion)."""
    rng = np.random.default_rng(3)
    b = wd.ModelBuilder(contact_law=wd.ContactLaw(rolling="epsd2", cohesion="sjkr_reduced", tangential=REFERENCE_TANGENTIAL))
    b.add_material(wd.GRAVEL)
    pos = _lattice(27, 1.98 * R, (-0.0125, -0.0125, 0.0068), rng, 5e-5)
    b.add_spheres(pos, R * rng.uniform(0.9, 1.1, 27), "gravel", velocities=rng.normal(0.0, 0.1, (27, 3)) + (0.0, 0.0, -0.3),
                  angular_velocities=rng.normal(0.0, 10.0, (27, 3)))
    b.add_wall(geometry.plane((0.0, 0.0, 0.0), 0.2, 0.2, normal=(0.1, 0.0, 1.0), subdivisions=8), "gravel")
    b.set_contact_parameters(cohesion_energy_density_pp=2e5, cohesion_energy_density_pw=1e5, mu_r_pp=0.2,
                             mu_r_pw=0.1)
    return wd.Simulation(b.finalize("cpu", overlap_tolerance=0.2), dt=1e-5, use_graph=False,
                         pair_evaluation="full")


def scene_wear() -> wd.Simulation:
    """Spheres thrown onto a translating, finely subdivided plate: per-triangle wear."""
    rng = np.random.default_rng(4)
    b = wd.ModelBuilder(contact_law=wd.ContactLaw(tangential=REFERENCE_TANGENTIAL))
    b.add_material(wd.GRAVEL)
    pos = _lattice(12, 2.5 * R, (-0.01, -0.01, 1.2 * R), rng, 2e-4)
    b.add_spheres(pos, R, "gravel", velocities=np.column_stack([rng.uniform(0.2, 0.6, 12), np.zeros(12),
                                                                -rng.uniform(0.3, 1.0, 12)]))
    b.add_wall(geometry.plane((0.0, 0.0, 0.0), 0.1, 0.1, subdivisions=20), "gravel",
               motion=wd.WallMotion.translation((-0.3, 0.1, 0.0)), name="plate")
    b.set_contact_parameters(mu_s_pw=0.4, restitution_pw=0.5)
    return wd.Simulation(b.finalize("cpu"), dt=2e-5, use_graph=False,
                         pair_evaluation="full")


def scene_no_walls() -> wd.Simulation:
    """A model without walls (the wall stages are skipped): clumps and spheres of two worlds
    colliding in free space with epsd rolling resistance."""
    rng = np.random.default_rng(5)
    b = wd.ModelBuilder(num_worlds=2, contact_law=wd.ContactLaw(rolling="epsd", tangential=REFERENCE_TANGENTIAL), gravity=(0.0, 0.0, 0.0))
    b.add_material(wd.GRAVEL)
    offsets = np.array([[-0.5 * R, 0.0, 0.0], [0.5 * R, 0.0, 0.0]])
    mass = 2.0 * wd.GRAVEL.density * 4.0 / 3.0 * math.pi * (0.8 * R) ** 3
    for w in range(2):
        pos = _lattice(27, 2.8 * R, (0.0, 0.0, 0.0), rng, 1e-4)
        for p in pos[:8]:
            q = rng.normal(size=4)
            b.add_body(p, mass, (0.1 * mass * R**2, 0.3 * mass * R**2, 0.3 * mass * R**2), offsets, [0.8 * R] * 2,
                       "gravel", world=w, rotation=q / np.linalg.norm(q), velocity=rng.normal(0.0, 0.5, 3))
        centre = pos.mean(axis=0)
        b.add_spheres(pos[8:], R, "gravel", world=w, velocities=(centre - pos[8:]) * 150.0)
    b.set_contact_parameters(mu_r_pp=[0.05, 0.2])
    return wd.Simulation(b.finalize("cpu", overlap_tolerance=0.2), dt=1e-5, use_graph=False,
                         pair_evaluation="full")


SCENES = {"drum": scene_drum, "clumps": scene_clumps, "cohesion_epsd2": scene_cohesion_epsd2, "wear": scene_wear,
          "no_walls": scene_no_walls, "drum_walls_off": scene_drum}
STEPS = 200


def run_scene(name: str) -> dict[str, np.ndarray]:
    sim = SCENES[name]()
    if name == "drum_walls_off":  # the profiling path: one contact launch without the walls
        sim.run(50)
        sim.solver.launch_contacts(sim.state, sim._next, sim.dt, walls_on=False)
        return {"contact_count": sim._next.contact_count.numpy(), "sphere_f": sim.solver.sphere_f.numpy(),
                "sphere_t": sim.solver.sphere_t.numpy()}
    if name == "drum":
        sim.run(100)
        sim.pause_worlds([1])
        sim.run(50)
        sim.resume_worlds()
        sim.run(STEPS - 150)
    else:
        sim.run(STEPS)
    s = sim.state
    out = {"body_q": s.body_q.numpy(), "body_rot": s.body_rot.numpy(), "body_v": s.body_v.numpy(),
           "body_w": s.body_w.numpy(), "contact_count": s.contact_count.numpy(),
           "sphere_f": sim.solver.sphere_f.numpy()}
    for f in sim.solver.wall_stats.FIELDS:
        ws = sim.solver.wall_stats  # world-major over every wall (the one zero entry without walls)
        out[f"wear_{f}"] = ws.per_triangle(f).ravel() if sim.model.walls else ws.summed(f).numpy()
    return out


def write_reference() -> None:
    data = {f"{name}/{k}": v for name in SCENES for k, v in run_scene(name).items()}
    REFERENCE.parent.mkdir(exist_ok=True)
    np.savez_compressed(REFERENCE, **data)


@pytest.mark.parametrize("name", list(SCENES))
def test_stages_reproduce_the_single_kernel(name):
    ref = np.load(REFERENCE)
    got = run_scene(name)
    assert int(ref[f"{name}/contact_count"].sum()) > 0  # the scene has contacts
    for k, v in got.items():
        want = ref[f"{name}/{k}"]
        if k == "contact_count":
            np.testing.assert_array_equal(v, want, err_msg=f"{name}/{k}")
        else:
            np.testing.assert_allclose(v, want, rtol=RTOL, atol=ATOL, err_msg=f"{name}/{k}")


if __name__ == "__main__":
    if "--write" in sys.argv:
        write_reference()
    else:  # print the largest differences from the reference
        ref = np.load(REFERENCE)
        for name in SCENES:
            for k, v in run_scene(name).items():
                want = ref[f"{name}/{k}"]
                d = np.abs(v.astype(np.float64) - want)
                print(f"{name:15s} {k:18s} max |diff| {d.max():.3e}  max |ref| {np.abs(want).max():.3e}")
