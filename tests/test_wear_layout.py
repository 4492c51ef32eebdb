"""The wall wear accumulators (warpdem.solver.WallStats) hold one entry per triangle and world for a
wall of every world, one per triangle for a wall of one world: a batch of drums, one per world, needs
memory in proportion to its worlds, not to worlds x drums (a 234-world drum design held 95 million
entries per field, 1.5 GB, and a 2,105-world one could not be built at all)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import warpdem as wd
from warpdem import geometry
from warpdem.io import load_checkpoint, save_checkpoint

sys.path.insert(0, str(Path(__file__).parent))
from test_contact_stages import scene_drum  # noqa: E402

R = 0.005


def drums_per_world(worlds: int) -> wd.Model:
    """One turning drum per world and a floor plate shared by every world."""
    b = wd.ModelBuilder(num_worlds=worlds)
    b.add_material(wd.GRAVEL)
    drum = geometry.cylinder_shell(0.05, 0.04, axis=(0.0, 1.0, 0.0), sections=24)
    for w in range(worlds):
        b.add_sphere((0.0, 0.0, -0.03), R, "gravel", world=w)
        b.add_wall(drum, "gravel", world=w, motion=wd.WallMotion.rotation((0, 1, 0), 10.0 * (w + 1)))
    b.add_wall(geometry.plane((0.0, 0.0, -0.2), 0.1, 0.1, subdivisions=2), "gravel", name="floor")
    return b.finalize("cpu")


def test_entries_grow_with_worlds_not_with_worlds_times_walls():
    for worlds in (1, 4, 16):
        model = drums_per_world(worlds)
        stats = wd.WallStats(model, lanes=1)
        drum_t = model.walls[0].num_triangles
        floor_t = model.walls[-1].num_triangles
        assert stats.entries == worlds * drum_t + worlds * floor_t
        assert model.num_worlds * model.total_triangles == worlds * (worlds * drum_t + floor_t)  # the old layout
    # every entry belongs to exactly one (world, wall, triangle)
    model = drums_per_world(5)
    stats = wd.WallStats(model, lanes=1)
    taken = np.concatenate([stats.wall_entries(k)[stats.wall_entries(k) >= 0] for k in range(len(model.walls))])
    np.testing.assert_array_equal(np.sort(taken), np.arange(stats.entries))


def test_a_worlds_drum_wears_only_in_that_world():
    sim = scene_drum()  # two worlds, each with its own turning drum
    sim.run(300)
    ws = sim.solver.wall_stats
    assert ws.entries == sum(w.num_triangles for w in sim.model.walls)  # no world holds the other's drum
    for k in range(2):
        tri = ws.per_triangle("impulse_n", k)
        assert tri.shape == (2, sim.model.walls[k].num_triangles)
        assert tri[k].sum() > 0 and not tri[1 - k].any()
    np.testing.assert_allclose(ws.per_triangle("energy_n").sum(), ws.energy_n.numpy().sum(), rtol=1e-6)
    values = ws.impulse_n.numpy()  # one wall's triangles in a world or summed over worlds (the VTK cells)
    for k in range(2):
        full = ws.per_triangle("impulse_n", k)
        np.testing.assert_array_equal(ws.wall_triangles(values, k), full.sum(axis=0))
        for world in range(2):
            np.testing.assert_array_equal(ws.wall_triangles(values, k, world), full[world])


def test_a_shared_wall_reads_per_world_and_summed():
    model = drums_per_world(3)
    sim = wd.Simulation(model, 1e-5, use_graph=False)
    ws = sim.solver.wall_stats
    floor = len(model.walls) - 1
    values = np.arange(ws.entries, dtype=np.float32)  # every entry distinct
    idx = ws.wall_entries(floor)
    assert (idx >= 0).all()  # a wall of every world has an entry in each
    for world in range(3):
        np.testing.assert_array_equal(ws.wall_triangles(values, floor, world), values[idx[world]])
    np.testing.assert_array_equal(ws.wall_triangles(values, floor), values[idx].sum(axis=0))


def test_a_checkpoint_of_the_old_world_major_layout_still_loads(tmp_path):
    sim = scene_drum()
    sim.run(200)
    path = save_checkpoint(tmp_path / "new.npz", sim)
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    import json

    meta = json.loads(str(arrays["meta"]))
    del meta["wear_layout"]  # written before the compact layout: one entry per world and triangle of every wall
    arrays["meta"] = np.array(json.dumps(meta))
    for f in sim.solver.wall_stats.FIELDS:
        arrays[f"wear/{f}"] = sim.solver.wall_stats.per_triangle(f).ravel()
    np.savez_compressed(tmp_path / "old.npz", **arrays)
    old = load_checkpoint(tmp_path / "old.npz", "cpu")
    new = load_checkpoint(path, "cpu")
    for f in sim.solver.wall_stats.FIELDS:
        want = sim.solver.wall_stats.summed(f).numpy()
        assert want.any(), f
        np.testing.assert_array_equal(old.solver.wall_stats.summed(f).numpy(), want, err_msg=f)
        np.testing.assert_array_equal(new.solver.wall_stats.summed(f).numpy(), want, err_msg=f)
