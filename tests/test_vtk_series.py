"""VTK time series (warpdem.io.VtkSeries): .pvd collections of particles and walls that ParaView
and pyvista read back with every field."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

import warpdem as wd
from warpdem import geometry
from warpdem.io import VtkSeries, write_pvd

pv = pytest.importorskip("pyvista")

R = 0.009


def two_world_model() -> wd.Model:
    """27 spheres per world falling into an open box, a lifting plate shared by both worlds."""
    b = wd.ModelBuilder(num_worlds=2)
    b.add_material(wd.GRAVEL)
    rng = np.random.default_rng(1)
    g = np.arange(3) * 0.021 + 0.012
    pos = np.stack(np.meshgrid(g, g, g + 0.01, indexing="ij"), -1).reshape(-1, 3)
    for w in range(2):
        b.add_spheres(pos + rng.uniform(-1e-3, 1e-3, pos.shape), R, "gravel", world=w,
                      velocities=rng.normal(0, 0.2, pos.shape))
    b.add_wall(geometry.open_box((0, 0, 0), (0.07, 0.07, 0.2)), "gravel", name="open box")
    b.add_wall(geometry.plane((0.035, 0.035, 0.0), 0.07, 0.07), "gravel",
               motion=wd.WallMotion.translation((0, 0, 0.05), start=0.0, stop=0.02), name="lift")
    return b.finalize("cpu")


def test_series_reads_back_with_every_field_and_time(tmp_path):
    sim = wd.Simulation(two_world_model(), 5e-5)
    series = VtkSeries(tmp_path, world=1)
    for _ in range(3):
        sim.run(100)
        series.write(sim)
    names = sorted(p.name for p in tmp_path.glob("*.pvd"))
    assert names == ["particles.pvd", "wall_lift.pvd", "wall_open_box.pvd"]

    reader = pv.PVDReader(str(tmp_path / "particles.pvd"))
    assert reader.time_values == pytest.approx([0.005, 0.010, 0.015])
    reader.set_active_time_value(reader.time_values[-1])
    cloud = reader.read()[0]
    assert cloud.n_points == 27  # world 1 only
    for name in ("radius", "velocity", "angular_velocity", "contact_force", "id", "world", "contacts"):
        assert name in cloud.point_data, name
    assert np.all(cloud["world"] == 1)
    np.testing.assert_allclose(cloud["radius"], R)
    # the last frame holds the simulation's state: positions and angular velocities of world 1
    m = sim.model
    sel = m.host["sphere_world"] == 1
    np.testing.assert_allclose(cloud.points, sim.sphere_positions()[sel], atol=1e-6)
    np.testing.assert_allclose(cloud["angular_velocity"], sim.state.body_w.numpy()[m.host["sphere_body"][sel]],
                               atol=1e-6)
    # the spheres rest on the floor after 0.015 s: some carry contact forces
    assert np.abs(cloud["contact_force"]).max() > 0

    walls = pv.PVDReader(str(tmp_path / "wall_lift.pvd"))
    assert len(walls.time_values) == 3
    walls.set_active_time_value(walls.time_values[0])
    first = walls.read()[0]
    walls.set_active_time_value(walls.time_values[-1])
    last = walls.read()[0]
    for name in ("energy_n", "energy_t", "impulse_n", "impulse_t"):
        assert name in last.cell_data and last.n_cells == m.walls[1].num_triangles
    # the plate rises at 0.05 m/s: 0.5 mm between frames 0 and 2 (placed one step behind)
    assert last.points[:, 2].mean() - first.points[:, 2].mean() == pytest.approx(0.0005, abs=1e-5)


def test_pvd_is_valid_collection_xml(tmp_path):
    path = write_pvd(tmp_path / "a.pvd", [(0.0, "a_000000.vtp"), (0.5, "a_000001.vtp")])
    root = ET.parse(path).getroot()
    assert root.get("type") == "Collection"
    sets = root.find("Collection").findall("DataSet")
    assert [(float(d.get("timestep")), d.get("file")) for d in sets] == [(0.0, "a_000000.vtp"), (0.5, "a_000001.vtp")]


def test_times_must_increase_and_world_must_exist(tmp_path):
    with pytest.raises(ValueError, match="non-decreasing"):
        write_pvd(tmp_path / "a.pvd", [(1.0, "a"), (0.5, "b")])
    sim = wd.Simulation(two_world_model(), 5e-5)
    with pytest.raises(wd.ConfigError, match="world 5 does not exist"):
        VtkSeries(tmp_path, world=5).write(sim)
