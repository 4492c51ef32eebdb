"""The cell-list neighbour search (warpdem.stages.cell_list) builds the same Verlet list as Warp's
hash grid, entry for entry, and the same trajectories to the last bit; its launches do nothing
while the device's rebuild flag is 0 (so they can sit unconditionally in a CUDA graph).

Cases: polydisperse spheres and clumps in several worlds that share space, with inactive
bodies and a wall; a wide size distribution (r ratio 4); tables so small that many cells share
one bucket (1 and 4 buckets) and one large enough for a two-level scan; short runs of a pile
in a box and of clumps with both searches.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

import warpdem as wd
from warpdem import geometry
from warpdem.stages.cell_list import CellList, bucket_count_for

R = 0.005  # sphere radius [m]


def mixed_model(seed: int = 0, worlds: int = 3, per_world: int = 120, r_min: float = 0.6 * R,
                r_max: float = 1.4 * R, clumps_per_world: int = 10) -> wd.Model:
    """Spheres of radii in [r_min, r_max] [m] and two-sphere clumps scattered in the same box in
    every world (so worlds overlap in space), an open box as a wall of all worlds."""
    rng = np.random.default_rng(seed)
    b = wd.ModelBuilder(num_worlds=worlds)
    b.add_material(wd.GRAVEL)
    half = 0.022
    offsets = np.array([[-0.6 * R, 0.0, 0.0], [0.6 * R, 0.0, 0.0]])
    mass = 2.0 * wd.GRAVEL.density * 4.0 / 3.0 * math.pi * R**3
    for w in range(worlds):
        pos = rng.uniform(-half, half, (per_world, 3))
        b.add_spheres(pos, rng.uniform(r_min, r_max, per_world), "gravel", world=w)
        for p in rng.uniform(-half, half, (clumps_per_world, 3)):
            q = rng.normal(size=4)
            b.add_body(p, mass, (0.1 * mass * R**2, 0.3 * mass * R**2, 0.3 * mass * R**2), offsets, [R, 0.8 * R],
                       "gravel", world=w, rotation=q / np.linalg.norm(q))
    b.add_wall(geometry.open_box((-0.026, -0.026, -0.026), (0.026, 0.026, 0.026)), wd.PLEXIGLAS)
    return b.finalize("cpu", check_overlaps=False)


def neighbour_lists(model: wd.Model, state: wd.State, search: str, num_buckets: int | None = None,
                    max_neighbours: int = 400) -> dict[str, np.ndarray]:
    """Build the list once with ``search`` (``num_buckets``: the cell list's table size) and return
    each row (count, indices), the near-wall flags and the overflow counters."""
    solver = wd.DEMSolver(model, 1e-6, force=True, neighbour_search=search, max_neighbours=max_neighbours)
    if num_buckets is not None:
        solver.cell_list = CellList(model.num_spheres, solver.cell_size, model.device, num_buckets=num_buckets)
    solver.place_spheres(state)
    solver._build_neighbour_list(state)
    return rows(solver)


def rows(solver: wd.DEMSolver) -> dict[str, np.ndarray]:
    count = solver.nb_count.numpy().copy()
    index = solver.nb_index.numpy().reshape(len(count), solver.max_neighbours)
    return dict(count=count, index=np.array([index[i, :c] for i, c in enumerate(count)], dtype=object),
                near_wall=solver.near_wall.numpy().copy(), overflow=solver.nb_overflow.numpy().copy(),
                x_at_build=solver.x_at_build.numpy().copy())


def assert_same_lists(a: dict, b: dict) -> None:
    np.testing.assert_array_equal(a["count"], b["count"])
    for i, (ra, rb) in enumerate(zip(a["index"], b["index"])):
        np.testing.assert_array_equal(ra, rb, err_msg=f"row of sphere {i}")
    np.testing.assert_array_equal(a["near_wall"], b["near_wall"])
    np.testing.assert_array_equal(a["overflow"], b["overflow"])
    np.testing.assert_array_equal(a["x_at_build"], b["x_at_build"])


def with_inactive_bodies(model: wd.Model, seed: int = 1, fraction: float = 0.15) -> wd.State:
    state = model.state()
    active = state.body_active.numpy()
    active[np.random.default_rng(seed).random(len(active)) < fraction] = 0
    state.body_active.assign(active)
    return state


def test_lists_equal_the_hash_grid_in_overlapping_worlds_with_clumps_and_inactive_bodies():
    model = mixed_model()
    state = with_inactive_bodies(model)
    grid = neighbour_lists(model, state, "hash_grid")
    cells = neighbour_lists(model, state, "cell_list")
    assert_same_lists(grid, cells)
    # the case is not empty: worlds overlap, rows are long, walls near, clump mates excluded
    assert grid["count"].sum() > 5 * model.num_spheres
    assert 0 < grid["near_wall"].sum() < model.num_spheres
    body = model.host["sphere_body"]
    world = model.host["sphere_world"]
    active = state.body_active.numpy()
    for i, row in enumerate(cells["index"]):
        row = row.astype(int)
        assert np.all(body[row] != body[i]) and np.all(world[row] == world[i]) and np.all(active[body[row]] == 1)
        if active[body[i]] == 0:
            assert len(row) == 0


@pytest.mark.parametrize("num_buckets", [1, 4, None, 1 << 17])
def test_wide_sizes_and_crowded_buckets_give_the_same_lists(num_buckets):
    """r ratio 4; 1 or 4 buckets for all cells and worlds (every query meets other cells' and
    worlds' entries in its buckets), the default table, and a large one (two scan levels)."""
    model = mixed_model(seed=2, worlds=2, per_world=150, r_min=0.4 * R, r_max=1.6 * R, clumps_per_world=5)
    state = with_inactive_bodies(model, seed=3, fraction=0.1)
    assert_same_lists(neighbour_lists(model, state, "hash_grid"),
                      neighbour_lists(model, state, "cell_list", num_buckets=num_buckets))


def test_a_clump_of_small_spheres_in_one_cell():
    """Many small spheres (r 4x smaller than the largest) crowd each cell of a dense cluster."""
    rng = np.random.default_rng(4)
    b = wd.ModelBuilder(num_worlds=2)
    b.add_material(wd.GRAVEL)
    for w in range(2):
        b.add_spheres(rng.uniform(-0.006, 0.006, (150, 3)), 0.25 * R, "gravel", world=w)
        b.add_spheres(rng.uniform(-0.02, 0.02, (4, 3)), R, "gravel", world=w)
    model = b.finalize("cpu", check_overlaps=False)
    state = model.state()
    assert_same_lists(neighbour_lists(model, state, "hash_grid", max_neighbours=600),
                      neighbour_lists(model, state, "cell_list", max_neighbours=600))


def test_overflow_counters_equal_the_hash_grid():
    """A full row drops different entries depending on the search order, but the counters the
    solver reports (entries dropped, longest row needed) are the same."""
    model = mixed_model(seed=5, worlds=1, per_world=200)
    state = model.state()
    a = neighbour_lists(model, state, "hash_grid", max_neighbours=4)
    b = neighbour_lists(model, state, "cell_list", max_neighbours=4)
    assert a["overflow"][0] > 0
    np.testing.assert_array_equal(a["overflow"], b["overflow"])
    np.testing.assert_array_equal(a["count"], b["count"])


def test_scan_gives_each_bucket_its_range():
    """The bucket ranges (bucket_start, bucket_count) tile the sorted entries without gap or
    overlap (an exclusive prefix sum, in the scan's strided bucket order), and every active
    sphere sits in its bucket's range (two-level scan)."""
    model = mixed_model(seed=6, worlds=2, per_world=100, clumps_per_world=0)
    state = with_inactive_bodies(model, seed=7)
    solver = wd.DEMSolver(model, 1e-6, force=True)
    solver.place_spheres(state)
    cl = CellList(model.num_spheres, solver.cell_size, "cpu", num_buckets=1 << 17)
    assert len(cl.scan_levels) == 2
    cl.build(state.sphere_x, model.sphere_world, model.sphere_body, state.body_active, wp.ones(1, dtype=int))
    start, count = cl.bucket_ranges()
    used = np.flatnonzero(count)
    used = used[np.argsort(start[used])]
    np.testing.assert_array_equal(start[used], np.concatenate([[0], np.cumsum(count[used])[:-1]]))
    active = state.body_active.numpy()[model.host["sphere_body"]] != 0
    assert count.sum() == active.sum()
    bucket = cl.sphere_bucket.numpy()
    sorted_sphere = cl.sorted_sphere.numpy()
    for i in np.flatnonzero(active):
        assert i in sorted_sphere[start[bucket[i]]: start[bucket[i]] + count[bucket[i]]]
    assert np.all(bucket[~active] == -1)
    assert bucket_count_for(model.num_spheres) == 512 and bucket_count_for(10**9) == 1 << 22


def test_nothing_happens_without_the_rebuild_flag():
    """With rebuild[0] = 0 every launch of the cell list and the list kernel returns at once:
    spheres moved by more than a cell leave the table and the list as they were."""
    model = mixed_model(seed=8, worlds=2, per_world=80)
    state = model.state()
    solver = wd.DEMSolver(model, 1e-6, force=True)
    solver.place_spheres(state)
    solver._build_neighbour_list(state)  # rebuild is 1 at construction, cleared by finish_build
    assert int(solver.rebuild.numpy()[0]) == 0 and int(solver.list_builds.numpy()[0]) == 1
    cl = solver.cell_list
    table_before = {k: getattr(cl, k).numpy().copy() for k in
                    ("bucket_count", "bucket_start", "sphere_cell", "sphere_bucket", "sphere_rank", "sorted_sphere",
                     "sorted_cell")}
    lists_before = rows(solver)
    q = state.body_q.numpy()
    state.body_q.assign(q + np.random.default_rng(9).uniform(-3, 3, q.shape) * solver.cell_size)
    solver.place_spheres(state)
    solver._build_neighbour_list(state)
    for k, v in table_before.items():
        np.testing.assert_array_equal(getattr(cl, k).numpy(), v, err_msg=k)
    assert_same_lists(lists_before, rows(solver))
    assert int(solver.list_builds.numpy()[0]) == 1
    # and with the flag set, the moved spheres are sorted and listed again
    solver.request_neighbour_rebuild()
    solver._build_neighbour_list(state)
    assert int(solver.list_builds.numpy()[0]) == 2
    assert not np.array_equal(cl.sorted_sphere.numpy(), table_before["sorted_sphere"])
    np.testing.assert_array_equal(solver.x_at_build.numpy(), state.sphere_x.numpy())


def pile(search: str) -> wd.Simulation:
    """Polydisperse spheres of two worlds poured into an open box (the same box in both)."""
    rng = np.random.default_rng(10)
    b = wd.ModelBuilder(num_worlds=2, contact_law=wd.ContactLaw(rolling="epsd"))
    b.add_material(wd.GRAVEL)
    g = (np.arange(4) - 1.5) * 2.3 * R
    pos = np.stack(np.meshgrid(g, g, np.arange(4) * 2.3 * R + 1.5 * R, indexing="ij"), -1).reshape(-1, 3)
    for w in range(2):
        b.add_spheres(pos + rng.uniform(-2e-4, 2e-4, pos.shape), R * rng.uniform(0.5, 1.0, len(pos)), "gravel",
                      world=w, velocities=rng.normal(0.0, 0.3, pos.shape))
    b.add_wall(geometry.open_box((-0.012, -0.012, 0.0), (0.012, 0.012, 0.05)), wd.PLEXIGLAS)
    b.set_contact_parameters(mu_r_pp=0.1, mu_r_pw=0.1)
    return wd.Simulation(b.finalize("cpu", overlap_tolerance=0.2), dt=2e-5, use_graph=False, neighbour_search=search)


def clumps(search: str) -> wd.Simulation:
    """Three-sphere clumps (asymmetric inertia) falling into an open box onto each other."""
    rng = np.random.default_rng(11)
    b = wd.ModelBuilder(contact_law=wd.ContactLaw(rolling="cdt"))
    b.add_material(wd.GRAVEL)
    offsets = np.array([[-0.6 * R, 0.0, 0.0], [0.0, 0.2 * R, 0.0], [0.7 * R, 0.0, 0.1 * R]])
    radii = np.array([0.8 * R, R, 0.4 * R])
    mass = wd.GRAVEL.density * 4.0 / 3.0 * math.pi * float(np.sum(radii**3))
    inertia = (0.3 * mass * R**2, 0.5 * mass * R**2, 0.6 * mass * R**2)
    g = np.arange(3) * 2.7 * R + 0.012
    for p in np.stack(np.meshgrid(g, g, [0.0075, 0.0215], indexing="ij"), -1).reshape(-1, 3):
        q = rng.normal(size=4)
        b.add_body(p, mass, inertia, offsets, radii, "gravel", rotation=q / np.linalg.norm(q),
                   velocity=rng.normal(0.0, 0.5, 3) + (0.0, 0.0, -1.0), angular_velocity=rng.normal(0.0, 50.0, 3))
    b.add_wall(geometry.open_box((0.0, 0.0, 0.0), (0.05, 0.05, 0.06)), wd.PLEXIGLAS)
    return wd.Simulation(b.finalize("cpu", overlap_tolerance=0.2), dt=1e-5, use_graph=False, neighbour_search=search)


@pytest.mark.parametrize("scene", [pile, clumps])
def test_trajectories_are_bitwise_identical(scene):
    runs = {}
    for search in ("hash_grid", "cell_list"):
        sim = scene(search)
        assert sim.solver.neighbour_search == search
        sim.run(300)
        runs[search] = (sim.state.body_q.numpy(), sim.state.body_rot.numpy(), sim.state.body_v.numpy(),
                        int(sim.solver.list_builds.numpy()[0]), int(sim.state.contact_count.numpy().sum()))
    for a, b in zip(runs["hash_grid"], runs["cell_list"]):
        np.testing.assert_array_equal(a, b)
    assert runs["cell_list"][3] > 1 and runs["cell_list"][4] > 0  # lists rebuilt on the way, bodies in contact


def test_unknown_search_is_a_config_error():
    model = mixed_model(worlds=1, per_world=5, clumps_per_world=0)
    with pytest.raises(wd.ConfigError, match="neighbour_search"):
        wd.DEMSolver(model, 1e-6, force=True, neighbour_search="octree")
