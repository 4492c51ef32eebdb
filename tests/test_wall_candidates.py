"""The moving walls' kept candidate triangles (``DEMSolver(wall_candidates=...)``) give the same
results as querying the walls' BVHs every step (``wall_candidates=0``), bit for bit.

The scene is built so that a wrong validity rule shows: gravity is off and the spheres rest, so
they never move enough to gather their candidates again; only the walls' motion can make them
stale. A paddle turning at 300 rpm sweeps through resting spheres (world 0), and a plate
that starts to translate at t = 2 ms runs into a row of them (world 1). Spheres gathered their
(empty) candidates while the walls were far; unless the wall-drift bound
(:func:`warpdem.stages.wall_contacts.wall_drift`) makes them gather again, they are never hit
and their states differ from the BVH query's. Checked: with the drift test removed from
``moving_wall_candidates`` this file fails (the spheres stay at rest).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

import warpdem as wd
from warpdem import geometry

R = 0.005
DT = 2e-5
STEPS = 1500


def sweep_scene(wall_candidates: int, device: str = "cpu") -> wd.Simulation:
    """World 0: 6 resting spheres at 0.045 m from the z axis, 0.2-0.8 rad ahead of either blade of
    a paddle (a 0.12 x 0.02 m plate through the axis) turning at 300 rpm (0.94 rad in the run).
    World 1: a row of 5 resting spheres, and a plate 0.01 m away that moves towards them at
    2 m/s from t = 2 ms. No gravity."""
    b = wd.ModelBuilder(num_worlds=2, gravity=(0.0, 0.0, 0.0))
    b.add_material(wd.GRAVEL)
    ahead = np.linspace(0.2, 0.8, 3)
    angles = np.concatenate([ahead, ahead + math.pi])
    ring = np.column_stack([0.045 * np.cos(angles), 0.045 * np.sin(angles), np.zeros(6)])
    b.add_spheres(ring, R, "gravel", world=0)
    paddle = geometry.plane((0.0, 0.0, 0.0), 0.12, 0.02, normal=(0.0, 1.0, 0.0), subdivisions=4)
    b.add_wall(paddle, wd.GRAVEL, world=0, motion=wd.WallMotion.rotation((0, 0, 1), 300.0), name="paddle")
    row = np.column_stack([np.zeros(5), np.linspace(-0.024, 0.024, 5), np.zeros(5)])
    b.add_spheres(row, R, "gravel", world=1)
    plate = geometry.plane((0.01 + R, 0.0, 0.0), 0.06, 0.03, normal=(-1.0, 0.0, 0.0), subdivisions=6)
    b.add_wall(plate, wd.GRAVEL, world=1, motion=wd.WallMotion.translation((-2.0, 0.0, 0.0), start=0.002),
               name="plate")
    b.set_contact_parameters(mu_s_pw=0.4, restitution_pw=0.5)
    return wd.Simulation(b.finalize(device), dt=DT, v_ref=5.0, use_graph=False, wall_candidates=wall_candidates)


def run(wall_candidates: int, device: str = "cpu") -> tuple[dict[str, np.ndarray], int]:
    """The final State's arrays, and how many times (every 50 steps) a sphere's candidates had
    overflowed their slots."""
    sim = sweep_scene(wall_candidates, device)
    overflowed = 0
    for _ in range(STEPS // 50):
        sim.run(50)
        overflowed += int(np.sum(sim.solver.candidate_count.numpy() == -1))
    return sim.solver.export_state(sim.state), overflowed


DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no CUDA device"))]


@pytest.mark.parametrize("device", DEVICES)
def test_kept_candidates_match_the_bvh_query_bit_for_bit(device):
    queried, _ = run(0, device)
    kept, _ = run(32, device)
    # the walls hit every resting sphere: the paddle the whole ring, the plate the whole row
    speed = np.linalg.norm(queried["body_v"], axis=1)
    assert np.all(speed > 0.1), speed
    for key, want in queried.items():
        assert np.array_equal(kept[key], want), f"{key}: kept candidates differ from the BVH query"


def test_too_many_candidates_fall_back_to_the_bvh_query():
    queried, _ = run(0)
    few, overflowed = run(1)  # one slot: the plate's subdivided triangles overflow it
    assert overflowed > 0
    for key, want in queried.items():
        assert np.array_equal(few[key], want), f"{key}: overflowing candidates differ from the BVH query"


def test_a_model_without_moving_walls_keeps_no_candidates():
    b = wd.ModelBuilder()
    b.add_material(wd.GRAVEL)
    b.add_spheres(np.array([[0.0, 0.0, R]]), R, "gravel")
    b.add_wall(geometry.plane((0.0, 0.0, 0.0), 0.1, 0.1), "gravel")
    sim = wd.Simulation(b.finalize("cpu"), dt=DT, use_graph=False)
    assert sim.solver.wall_candidates == 0
    assert sim.solver.candidate_wall.shape == (1,)


@pytest.mark.parametrize("bad", [-1, 2.5, True, "32"])
def test_wall_candidates_must_be_a_non_negative_integer(bad):
    with pytest.raises(wd.ConfigError, match="wall_candidates must be an integer >= 0"):
        sweep_scene(bad)
