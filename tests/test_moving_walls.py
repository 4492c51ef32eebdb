"""Moving walls are looked up in their rest frame (no mesh is moved or refitted per step): the
contact force on a sphere must equal the force from a static copy of the wall placed where the
motion has taken it, with the sphere given the opposite of the wall's velocity (same relative
motion), and per-world walls of one geometry must each act only in their own world."""
import math

import numpy as np
import pytest

import warpdem as wd
from calibration.experiments.drum import drum_mesh

T_NOW = 0.37  # s, time of the compared step


def _force_on_sphere(mesh_vertices, faces, motion, x, v, time, device="cpu"):
    b = wd.ModelBuilder()
    b.add_material(wd.GRAVEL)
    b.add_sphere(x, 0.01, "gravel", velocity=v)
    import trimesh

    b.add_wall(trimesh.Trimesh(mesh_vertices, faces, process=False), "gravel", motion=motion)
    sim = wd.Simulation(b.finalize(device, overlap_tolerance=1.0), 1e-6, use_graph=False)
    sim.state.time.assign(np.array([time]))
    sim.run(1)
    return sim.solver.sphere_f.numpy()[0].astype(np.float64)


@pytest.mark.parametrize("motion", [
    wd.WallMotion.rotation((0.0, 1.0, 0.0), 45.0, start=0.1),
    wd.WallMotion(velocity=(0.02, 0.0, 0.05), angular_velocity=(0.0, 2.0, 0.3), origin=(0.01, 0.02, 0.0), start=0.05,
                  stop=0.3),
])
def test_rest_frame_lookup_matches_a_placed_static_wall(motion):
    drum = drum_mesh(0.15, 0.15, 72)
    wall = wd.model.Wall("w", np.asarray(drum.vertices), np.asarray(drum.faces), 0, -1, motion, 0)
    placed = wall.points_at(T_NOW)
    # a sphere pressed 0.5 mm into the lowest shell facet near mid-length, where the wall now is
    tri_centres = placed[drum.faces].mean(axis=1)
    k = int(np.argmin(tri_centres[:, 2] + 10.0 * np.abs(tri_centres[:, 1] - tri_centres[:, 1].mean())))
    n = np.cross(placed[drum.faces[k, 1]] - placed[drum.faces[k, 0]], placed[drum.faces[k, 2]] - placed[drum.faces[k, 0]])
    n /= np.linalg.norm(n)
    if np.dot(n, placed.mean(axis=0) - tri_centres[k]) < 0:
        n = -n  # pointing into the drum
    x = tri_centres[k] + n * (0.01 - 5e-4)
    # the wall material's velocity at the contact point, from the motion's definition
    tau = min(max(T_NOW, motion.start), motion.stop) - motion.start
    moving_now = motion.start <= T_NOW < motion.stop
    centre = np.asarray(motion.origin) + np.asarray(motion.velocity) * tau
    v_wall = (np.asarray(motion.velocity) + np.cross(motion.angular_velocity, tri_centres[k] - centre)) if moving_now else 0 * n
    f_moving = _force_on_sphere(drum.vertices, drum.faces, motion, x, (0, 0, 0), T_NOW)
    f_placed = _force_on_sphere(placed, drum.faces, wd.WallMotion(), x, -v_wall, T_NOW)
    assert np.dot(f_moving, n) > 1.0  # a real contact, pushing the sphere into the drum
    np.testing.assert_allclose(f_moving, f_placed, rtol=2e-4, atol=1e-4 * np.linalg.norm(f_placed))


def test_wall_points_at_follows_the_motion():
    sq = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    m = wd.WallMotion(velocity=(0.0, 0.0, 1.0), angular_velocity=(0.0, 0.0, math.pi), start=1.0, stop=1.5)
    w = wd.model.Wall("w", sq, np.array([[0, 1, 2]]), 0, -1, m, 0)
    np.testing.assert_allclose(w.points_at(0.5), sq)  # before the start: at rest
    at = w.points_at(2.0)  # stopped after half a second: turned 90 deg about z, lifted 0.5 m
    np.testing.assert_allclose(at, [[0.0, 1.0, 0.5], [-1.0, 0.0, 0.5], [0.0, 0.0, 1.5]], atol=1e-12)


def test_per_world_walls_act_in_their_own_world_only():
    """Two worlds, each with its own copy of one floor geometry (one shared BVH); world 1's
    floor is lifted away at t = 0, so only world 0's sphere is held."""
    from warpdem import geometry

    b = wd.ModelBuilder(num_worlds=2)
    b.add_material(wd.GRAVEL)
    for w in range(2):
        b.add_sphere((0.0, 0.0, 0.01), 0.01, "gravel", world=w)  # touching
    floor = geometry.plane((0.0, 0.0, 0.0), 0.2, 0.2)
    b.add_wall(floor, "gravel", world=0, name="floor 0")
    b.add_wall(floor, "gravel", world=1, motion=wd.WallMotion.translation((0.0, 0.0, -5.0)), name="floor 1")
    model = b.finalize("cpu")
    assert model.walls[0].mesh is model.walls[1].mesh  # one BVH for equal geometry
    sim = wd.Simulation(model, 1e-5)
    sim.run(2000)  # 0.02 s
    z = sim.state.body_q.numpy()[:, 2]
    assert z[0] > 0.0099  # world 0 rests on its floor
    np.testing.assert_allclose(z[1], 0.01 - 0.5 * 9.81 * 0.02 ** 2, rtol=1e-3)  # world 1 falls freely
