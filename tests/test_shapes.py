"""The seed paper's five gravel shape classes (Tables 2-4) and their clump templates."""
import math
import time

import numpy as np
import pytest

from warpdem.clump_geometry import union_mass_properties
from warpdem.errors import ConfigError
from warpdem.multisphere import DEFAULT_MIN_RADIUS_FRACTION, rayleigh_time_step
from warpdem.shapes import (FILL_LEVELS, SHAPE_CLASSES, TABLE3_PERCENT, TABLE4, gravel_fill,
                            gravel_shape_mix, gravel_templates, shape_mesh, sphericity,
                            target_sphericity)

# Table 4, as printed: V_R [1e3 mm^3], Psi [-]
PAPER = {"cone": (4.782, 0.775), "prism": (6.373, 0.859), "discoid": (1.558, 0.656),
         "ellipsoid": (2.048, 0.830), "sphere": (1.767, 0.959)}


@pytest.mark.parametrize("name", SHAPE_CLASSES)
def test_class_meshes_match_table4(name):
    mesh = shape_mesh(name)
    v_r, psi = PAPER[name]
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(v_r * 1e-6, rel=0.01)      # 10^3 mm^3 -> m^3
    assert abs(sphericity(mesh) - psi) < 0.01
    np.testing.assert_allclose(mesh.center_mass, 0.0, atol=1e-9)
    assert 0.003 < mesh.extents.min() and mesh.extents.max() < 0.04     # gravel-sized, metres


@pytest.mark.parametrize("name", SHAPE_CLASSES)
def test_scan_basis_matches_surface_area(name):
    mesh = shape_mesh(name, basis="scan")
    assert mesh.volume == pytest.approx(TABLE4[name].volume_r, rel=0.01)
    assert mesh.area == pytest.approx(TABLE4[name].area_rp, rel=0.01)


def test_table4_psi_column_uses_the_filled_volume():
    # documents the inconsistency handled by ``basis``: Psi = SA_es(V_m) / SA_rp
    for name, spec in TABLE4.items():
        psi_vm = (36 * math.pi * spec.volume_m ** 2) ** (1 / 3) / spec.area_rp
        assert psi_vm == pytest.approx(spec.psi, abs=1.5e-3)
        assert abs(target_sphericity(name, "scan") - spec.psi) > 0.02


def test_shape_mix_fractions():
    mix = gravel_shape_mix()
    assert list(mix) == list(SHAPE_CLASSES)
    assert sum(mix.values()) == pytest.approx(1.0, abs=1e-12)
    for k, pct in TABLE3_PERCENT.items():
        assert mix[k] == pytest.approx(pct / 100.0, abs=1e-4)
    assert mix["prism"] == max(mix.values())


def test_fill_level_counts_table2():
    assert FILL_LEVELS["low"] == {"cone": 5, "prism": 6, "discoid": 5, "ellipsoid": 8, "sphere": 5}
    assert FILL_LEVELS["medium"] == {"cone": 24, "prism": 22, "discoid": 23, "ellipsoid": 22, "sphere": 25}
    assert FILL_LEVELS["high"] == {"cone": 46, "prism": 42, "discoid": 44, "ellipsoid": 42, "sphere": 43}


def test_gravel_templates_low_fill_and_cache():
    t0 = time.perf_counter()
    tpls = gravel_templates("low", density=2661.0)
    first = time.perf_counter() - t0
    assert list(tpls) == list(SHAPE_CLASSES)
    for name, tpl in tpls.items():
        assert tpl.name == name
        assert tpl.n_spheres == FILL_LEVELS["low"][name]
        assert tpl.density == 2661.0
        assert tpl.mass == pytest.approx(2661.0 * TABLE4[name].volume_r, rel=2e-3)   # volume matched
        mp = union_mass_properties(tpl.centers, tpl.radii, 2661.0)
        np.testing.assert_allclose(mp.com, 0.0, atol=2e-3 * tpl.equivalent_radius)
        np.testing.assert_allclose(np.diag(mp.inertia), tpl.inertia_principal, rtol=5e-3)
    # cached: a second call (other density) does not refill
    t0 = time.perf_counter()
    again = gravel_templates("low", density=1000.0)
    assert time.perf_counter() - t0 < 0.2 * first + 0.05
    np.testing.assert_array_equal(again["cone"].radii, tpls["cone"].radii)
    assert again["cone"].mass == pytest.approx(tpls["cone"].mass * 1000.0 / 2661.0)
    rep = gravel_fill("cone", "low")[1]
    assert rep.n_spheres == 5 and rep.volume_error < 2e-3


def test_gravel_medium_templates_respect_the_radius_bound():
    # the smallest member sphere sets the DEM time step: every medium-fill member is
    # >= 0.25 r_eq (1.8-2.9 mm), so T_R >= 1.6e-4 s and the paper's dt 4.2e-5 s is ~0.25 T_R
    tpls = gravel_templates("medium", density=2661.0)
    for name, tpl in tpls.items():
        rep = gravel_fill(name, "medium")[1]
        r_eq = (3 * TABLE4[name].volume_r / (4 * math.pi)) ** (1 / 3)
        bound = DEFAULT_MIN_RADIUS_FRACTION * r_eq
        assert rep.radius_bound == pytest.approx(bound, rel=1e-3)
        assert tpl.n_spheres == rep.n_spheres == FILL_LEVELS["medium"][name]
        assert tpl.radii.min() >= bound >= 1.75e-3, name
        assert rep.min_radius == pytest.approx(tpl.radii.min())
        assert rep.volume_error < 2e-3
        assert rep.rayleigh_time_step(2661.0, 1e7, 0.3) >= rayleigh_time_step(1.75e-3) > 4.2e-5 / 0.3


def test_bad_names():
    with pytest.raises(ConfigError, match="unknown shape class"):
        shape_mesh("cube")
    with pytest.raises(ConfigError, match="basis"):
        shape_mesh("cone", basis="nope")
    with pytest.raises(ConfigError, match="fill_level"):
        gravel_templates("extreme")
    with pytest.raises(ConfigError, match="density"):
        gravel_templates("low", density=0.0)
