"""Multi-sphere fill of meshes (seed paper Sec. 2.3.1, eqs. 13-14)."""
import math

import numpy as np
import pytest
import trimesh

from warpdem.clump_geometry import union_mass_properties
from warpdem.errors import ConfigError
from warpdem.multisphere import (DEFAULT_MIN_RADIUS_FRACTION, clump_from_file, fill_mesh, rayleigh_time_step,
                                  relative_volume_error, sphericity)
from warpdem.timestep import rayleigh_time

FAST = dict(n_points=12_000, n_seeds=800, max_iter=30)


def test_equations_13_14():
    assert relative_volume_error(4.540, 4.782) == pytest.approx(0.0506, abs=1e-4)   # Table 4, cone
    r = 0.7
    assert sphericity(4 / 3 * math.pi * r ** 3, 4 * math.pi * r ** 2) == pytest.approx(1.0)
    # cube: Psi = pi^(1/3) 6^(2/3) / 6 = 0.806
    assert sphericity(1.0, 6.0) == pytest.approx(0.80600, abs=1e-5)


def test_unit_sphere_one_sphere_is_exact():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.01)
    r_eq = (3 * mesh.volume / (4 * math.pi)) ** (1 / 3)
    tpl, rep = fill_mesh(mesh, 1, density=2000.0, **FAST)
    assert tpl.n_spheres == 1
    assert rep.volume_error < 1e-3                               # eq. 13, volume matched
    assert tpl.radii[0] == pytest.approx(r_eq, rel=1e-3)
    assert rep.symmetric_difference < 0.02
    assert np.linalg.norm(tpl.offset) < 5e-5                     # centred (0.5 % of r)
    np.testing.assert_allclose(tpl.centers, 0.0, atol=1e-15)
    np.testing.assert_allclose(tpl.inertia_principal, 0.4 * tpl.mass * tpl.radii[0] ** 2, rtol=1e-9)
    assert rep.sphericity == pytest.approx(sphericity(mesh.volume, mesh.area))
    # the unconstrained best fit is nearly unbiased too
    tpl_u, rep_u = fill_mesh(mesh, 1, match_volume=False, **FAST)
    assert rep_u.volume_error < 0.02
    assert rep_u.radius_scale == 1.0
    assert tpl_u.radii[0] == pytest.approx(r_eq, rel=0.007)


def test_more_spheres_fit_an_ellipsoid_better():
    mesh = trimesh.creation.icosphere(subdivisions=3)
    mesh.apply_scale([0.012, 0.007, 0.005])
    sym, err = [], []
    for n in (2, 6, 18):
        _, rep = fill_mesh(mesh, n, match_volume=False, **FAST)
        sym.append(rep.symmetric_difference)
        err.append(rep.volume_error)
    assert sym[0] > sym[1] > sym[2]
    assert sym[2] < 0.12
    assert err[2] < 0.03


def test_box_fill_reports_consistent_quantities():
    mesh = trimesh.creation.box([0.02, 0.012, 0.008])
    tpl, rep = fill_mesh(mesh, 12, density=2661.0, **FAST)
    # volume matched (step 5): eq. 13 ~ 0, mass = rho V_R
    assert rep.volume_error < 2e-3
    assert tpl.mass == pytest.approx(2661.0 * mesh.volume, rel=2e-3)
    assert rep.clump_volume == pytest.approx(tpl.volume)
    assert rep.mesh_volume == pytest.approx(mesh.volume)
    assert rep.mesh_area == pytest.approx(mesh.area)
    # outside - missing = (V_m - V_R)/V_R up to sampling noise
    assert abs(rep.outside_fraction - rep.missing_fraction) < 0.02
    assert 0.0 < rep.symmetric_difference < 0.5
    assert 0.0 <= rep.max_protrusion < 0.004
    assert 0.8 < rep.radius_scale < 1.2
    # template is in the principal frame and consistent with the union of its spheres
    mp = union_mass_properties(tpl.centers, tpl.radii, tpl.density)
    np.testing.assert_allclose(mp.com, 0.0, atol=1e-3 * tpl.equivalent_radius)
    # box 20 x 12 x 8 mm: smallest moment about the long axis, which maps to body x
    assert abs(tpl.rotation[0, 0]) > 0.95
    assert rep.time_s > 0


def test_refinement_beats_greedy_and_is_deterministic():
    mesh = trimesh.creation.capsule(height=0.02, radius=0.006)
    _, greedy = fill_mesh(mesh, 6, refine=False, match_volume=False, **FAST)
    t1, refined = fill_mesh(mesh, 6, match_volume=False, **FAST)
    t2, _ = fill_mesh(mesh, 6, match_volume=False, **FAST)
    assert refined.symmetric_difference < greedy.symmetric_difference
    assert greedy.outside_fraction < 0.01                     # inscribed balls stay inside
    np.testing.assert_array_equal(t1.radii, t2.radii)


def test_non_watertight_mesh_raises():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    holed = trimesh.Trimesh(mesh.vertices, mesh.faces[:-3], process=False)
    with pytest.raises(ConfigError, match="not watertight"):
        fill_mesh(holed, 5)


@pytest.mark.parametrize("n,density,match", [(0, 1.0, "n_spheres"), (2.5, 1.0, "n_spheres"),
                                             (3, -1.0, "density")])
def test_bad_arguments(n, density, match):
    with pytest.raises(ConfigError, match=match):
        fill_mesh(trimesh.creation.icosphere(2), n, density=density)


def test_inverted_mesh_raises():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    inv = trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], process=False)
    with pytest.raises(ConfigError, match="volume"):
        fill_mesh(inv, 3)


def test_clump_from_file_mm_scan(tmp_path):
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=8.0)      # "scan" in millimetres
    mesh.apply_scale([1.3, 1.0, 0.8])
    path = tmp_path / "pebble.stl"
    mesh.export(path)
    tpl, rep = clump_from_file(path, 4, density=2661.0, scale=1e-3, **FAST)
    assert tpl.name == "pebble"
    assert rep.mesh_volume == pytest.approx(mesh.volume * 1e-9, rel=1e-6)
    assert tpl.volume == pytest.approx(rep.mesh_volume, rel=2e-3)
    assert tpl.radii.max() < 0.011
    with pytest.raises(ConfigError, match="no such file"):
        clump_from_file(tmp_path / "missing.stl", 4)
    with pytest.raises(ConfigError, match="scale"):
        clump_from_file(path, 4, scale=0.0)


def _r_eq(mesh):
    return (3 * mesh.volume / (4 * math.pi)) ** (1 / 3)


def test_rayleigh_time_step():
    # EDEM / Li et al. 2005: T_R = pi R sqrt(rho/G) / (0.1631 nu + 0.8766), G = E / (2 (1 + nu))
    g = 1e7 / 2.6
    assert rayleigh_time_step(0.002, 2661.0, 1e7, 0.3) == pytest.approx(rayleigh_time(0.002, 2661.0, g, 0.3))
    assert rayleigh_time_step(0.002) == pytest.approx(math.pi * 0.002 * math.sqrt(2661 / g) / (0.1631 * 0.3 + 0.8766))
    # the paper's dt 4.2e-5 s is ~0.2 T_R of a 2 mm sphere; a 0.27 mm member needs ~7x less
    assert 0.15 < 4.2e-5 / rayleigh_time_step(0.002) < 0.3
    assert rayleigh_time_step(0.00027) == pytest.approx(rayleigh_time_step(0.002) * 0.135)
    with pytest.raises(ConfigError):
        rayleigh_time_step(0.0)


def test_thin_disc_respects_radius_bound():
    # disc 20 mm across, 2 mm thick: r_eq = 5.31 mm; a bound of 0.4 r_eq = 2.12 mm is twice the
    # half-thickness, so no inscribed ball qualifies and every member protrudes
    mesh = trimesh.creation.cylinder(radius=0.010, height=0.002, sections=48)
    bound = 0.4 * _r_eq(mesh)
    assert bound > 2 * 0.001
    _, free = fill_mesh(mesh, 24, min_radius_fraction=0.0, **FAST)
    assert free.radius_bound == 0.0 and free.min_radius < bound     # unbounded: ~1.1 mm here
    tpl, rep = fill_mesh(mesh, 24, density=2661.0, min_radius_fraction=0.4, **FAST)
    assert tpl.n_spheres == rep.n_spheres == 24                  # count honoured
    assert rep.radius_bound == pytest.approx(bound)
    assert tpl.radii.min() >= bound
    assert rep.min_radius == tpl.radii.min() and rep.max_radius == tpl.radii.max()
    assert rep.volume_error < 2e-3 and not any("volume not matched" in t for t in rep.notes)
    assert rep.rayleigh_time_step() == pytest.approx(rayleigh_time_step(tpl.radii.min()))
    # absolute bound (metres), optimiser and volume match keep it too
    tpl_a, rep_a = fill_mesh(mesh, 10, min_radius=1.5e-3, match_volume=False, **FAST)
    assert rep_a.radius_bound == 1.5e-3 and tpl_a.radii.min() >= 1.5e-3
    # both given: the larger holds
    _, rep_b = fill_mesh(mesh, 4, min_radius=1.0e-3, min_radius_fraction=0.3, refine=False, **FAST)
    assert rep_b.radius_bound == pytest.approx(0.3 * _r_eq(mesh))


def test_radius_bound_volume_match():
    mesh = trimesh.creation.cylinder(radius=0.010, height=0.002, sections=48)
    # 16 balls of >= 0.45 r_eq = 2.4 mm over a 2 mm thick disc: the optimiser must pull them
    # together to hold only V_R -- it does, count and bound kept
    tpl, rep = fill_mesh(mesh, 16, min_radius_fraction=0.45, **FAST)
    assert tpl.n_spheres == 16 and tpl.radii.min() >= rep.radius_bound
    assert rep.volume_error < 2e-3
    # without the optimiser (greedy balls only) 24 such balls hold 1.4 V_R: the count and the
    # bound are kept and the report says that the volume is not matched
    tpl, rep = fill_mesh(mesh, 24, min_radius_fraction=0.45, refine=False, **FAST)
    assert tpl.n_spheres == 24 and tpl.radii.min() >= rep.radius_bound
    assert rep.volume_error > 0.05
    assert any(t.startswith("volume not matched") for t in rep.notes)


def test_default_radius_bound_and_unbounded_fill():
    mesh = trimesh.creation.icosphere(subdivisions=3)
    mesh.apply_scale([0.012, 0.007, 0.005])
    tpl, rep = fill_mesh(mesh, 12, **FAST)
    assert rep.radius_bound == pytest.approx(DEFAULT_MIN_RADIUS_FRACTION * _r_eq(mesh))
    assert tpl.radii.min() >= rep.radius_bound
    _, free = fill_mesh(mesh, 12, min_radius_fraction=0.0, **FAST)
    assert free.radius_bound == 0.0 and free.min_radius > 0.0
    assert (rep.n_redundant > 0) == any("inside the others" in t for t in rep.notes)


@pytest.mark.parametrize("kw,match", [(dict(min_radius=-1e-3), "min_radius"),
                                      (dict(min_radius_fraction=-0.1), "min_radius_fraction"),
                                      (dict(min_radius_fraction=1.2), "volume-equivalent"),
                                      (dict(min_radius=0.05), "volume-equivalent")])
def test_bad_radius_bound(kw, match):
    with pytest.raises(ConfigError, match=match):
        fill_mesh(trimesh.creation.icosphere(2, radius=0.01), 3, **kw)
