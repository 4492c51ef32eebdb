"""Multi-sphere fill of meshes (seed paper Sec. 2.3.1, eqs. 13-14)."""
import math

import numpy as np
import pytest
import trimesh

from warpdem.clump_geometry import union_mass_properties
from warpdem.errors import ConfigError
from warpdem.multisphere import clump_from_file, fill_mesh, relative_volume_error, sphericity

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
