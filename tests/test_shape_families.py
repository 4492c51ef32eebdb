"""Shape families (warpdem.shape_families) and shaped bulk materials (calibration.materials).

Checks: volume equivalence against the analytic union volume of collinear equal spheres
(lens formula, Weisstein "Sphere-Sphere Intersection"); aspect ratio measured from the
clump's bounding extent; inertia against the quadrature of warpdem.clump_geometry and a
1-D integral of the solid of revolution; continuity in the parameter; bounds errors; the
material round trip; a two-world DEM drop (spheres and rods of equal volume, one launch).
"""
import json
import math

import numpy as np
import pytest
from scipy.integrate import quad

import warpdem as wd
from calibration.filling import Box, add_fill, member_positions, random_fill, settle
from calibration.materials import BulkMaterial, ParticleShape, equal_number_size_classes, sample_particles
from warpdem import geometry
from warpdem.clump_geometry import lens_volume, make_template, union_mass_properties
from warpdem.shape_families import SHAPE_FAMILIES, ElongatedClumps, ShapeFamily, register_shape_family

RHO = wd.GRAVEL.density
ASPECTS = (1.0, 1.05, 1.2, 1.5, 2.0, 2.5, 3.0, 3.5)


@pytest.fixture(scope="module")
def elongated():
    return wd.shape_family("elongated")


def sphere_volume(d):
    return math.pi / 6.0 * d**3


def collinear_union_volume(tpl) -> float:
    """Union of equal balls on one axis: V_ball + (n-1)(V_ball - lens(s)) (each ball meets the
    union of the previous ones only in its neighbour's lens)."""
    r = float(tpl.radii[0])
    x = np.sort(tpl.centers[:, 0])
    v = 4.0 / 3.0 * math.pi * r**3
    return v + sum(v - lens_volume(r, r, float(s)) for s in np.diff(x))


def profile(tpl, x):
    """Radius of the solid of revolution at axial position x [m] (0 outside)."""
    r = float(tpl.radii[0])
    return np.sqrt(np.max(np.maximum(r * r - (x - tpl.centers[:, 0]) ** 2, 0.0)))


def extents(tpl) -> np.ndarray:
    """Bounding-box size of the clump along its body axes [m]."""
    lo = (tpl.centers - tpl.radii[:, None]).min(axis=0)
    hi = (tpl.centers + tpl.radii[:, None]).max(axis=0)
    return hi - lo


# ------------------------------------------------------------------------------ registry
def test_registry_lists_the_family_with_declared_parameters(elongated):
    assert "elongated" in wd.available_shape_families()
    assert isinstance(elongated, ShapeFamily) and isinstance(elongated, ElongatedClumps)
    spec = elongated.parameter_specs["aspect_ratio"]
    assert isinstance(spec, wd.ParameterSpec)  # the contact sub-models' declaration class
    assert (spec.default, spec.bounds) == (1.0, (1.0, 3.5)) and spec.unit and spec.description
    assert "Favier" in elongated.reference
    with pytest.raises(wd.ConfigError, match="unknown shape family 'rods'.*elongated"):
        wd.shape_family("rods")


def test_a_new_family_is_one_class_and_flows_into_materials():
    """A family defined outside the package (default quadrature mass properties) is usable
    from a material config with no other edit."""

    class Dumbbell(ShapeFamily):
        name = "test_dumbbell"
        spheres_per_particle = 2
        parameters = (wd.ParameterSpec("separation", "centre distance / radius", 1.0, (0.0, 1.8), "gap"),)
        reference = "test"

        def unit_geometry(self, separation=1.0):
            return np.array([[0.0, 0.0, 0.0], [separation, 0.0, 0.0]]), np.array([1.0, 1.0])

    register_shape_family(Dumbbell)
    try:
        assert "test_dumbbell" in wd.available_shape_families()
        t = Dumbbell().template(0.01, RHO, separation=1.2)
        assert t.volume == pytest.approx(sphere_volume(0.01), rel=1e-12)
        # the geometry was rescaled exactly: the analytic union volume agrees to quadrature accuracy
        r, s = float(t.radii[0]), float(np.ptp(t.centers[:, 0]))
        assert 2 * 4 / 3 * math.pi * r**3 - lens_volume(r, r, s) == pytest.approx(t.volume, rel=1e-3)
        m = BulkMaterial.from_config({"shape": "test_dumbbell", "separation": 0.5, "diameter": 0.01})
        assert m.shape_parameter_values == {"separation": 0.5}
        assert set(m.shape_parameters) == {"separation"}
        with pytest.raises(ValueError, match="already registered"):
            register_shape_family(type("Other", (Dumbbell,), {}))
    finally:
        SHAPE_FAMILIES.pop("test_dumbbell", None)


# ------------------------------------------------------------------------------ geometry
@pytest.mark.parametrize("a", ASPECTS)
@pytest.mark.parametrize("d", [0.005, 0.018])
def test_volume_equivalent_and_aspect_ratio_from_extent(elongated, a, d):
    t = elongated.template(d, RHO, aspect_ratio=a)
    assert collinear_union_volume(t) == pytest.approx(sphere_volume(d), rel=1e-3)
    assert t.volume == pytest.approx(sphere_volume(d), rel=1e-12)
    assert t.mass == pytest.approx(RHO * sphere_volume(d), rel=1e-12)
    assert t.equivalent_radius == pytest.approx(d / 2, rel=1e-12)
    ext = extents(t)
    assert ext[0] / ext[1] == pytest.approx(a, rel=1e-9)  # long axis = body x (smallest moment)
    assert ext[1] == pytest.approx(ext[2], rel=1e-12)
    assert t.n_spheres == (1 if a == 1.0 else 5)
    assert np.allclose(t.centers.mean(axis=0), 0.0, atol=1e-15)


@pytest.mark.parametrize("a", [1.5, 2.0, 2.5, 3.0, 3.5])
def test_inertia_matches_clump_geometry(elongated, a):
    """clump_geometry's quadrature agrees to 3e-4 here; nearer a = 1 (five strongly
    overlapping members) its error grows to ~1e-2 (a = 1.1), hence the closed form."""
    d = 0.018
    t = elongated.template(d, RHO, aspect_ratio=a)
    mp = union_mass_properties(t.centers, t.radii, RHO)
    np.testing.assert_allclose(mp.inertia, np.diag(t.inertia_principal), rtol=1e-3, atol=1e-3 * t.inertia_principal[0])
    np.testing.assert_allclose(mp.com, 0.0, atol=1e-5 * d)  # quadrature
    assert mp.volume == pytest.approx(t.volume, rel=1e-3)
    assert make_template(t.centers, t.radii, RHO).inertia_principal == pytest.approx(t.inertia_principal, rel=1e-3)


@pytest.mark.parametrize("a", [1.05, 1.2, 1.5, 2.5, 3.5])
def test_inertia_is_that_of_the_solid_of_revolution(elongated, a):
    """Independent 1-D integrals of the union's profile about its centre (tight)."""
    t = elongated.template(0.018, RHO, aspect_ratio=a)
    r = float(t.radii[0])
    lo, hi = t.centers[0, 0] - r, t.centers[-1, 0] + r
    brk = list(0.5 * (t.centers[1:, 0] + t.centers[:-1, 0]))
    vol = quad(lambda x: math.pi * profile(t, x) ** 2, lo, hi, points=brk, limit=200)[0]
    i_axial = quad(lambda x: RHO * math.pi / 2 * profile(t, x) ** 4, lo, hi, points=brk, limit=200)[0]
    i_trans = quad(lambda x: RHO * math.pi * profile(t, x) ** 2 * (profile(t, x) ** 2 / 4 + x * x), lo, hi,
                   points=brk, limit=200)[0]
    assert vol == pytest.approx(t.volume, rel=1e-9)
    assert t.inertia_principal == pytest.approx([i_axial, i_trans, i_trans], rel=1e-8)


def test_sphere_at_aspect_one_and_limit(elongated):
    d = 0.012
    t = elongated.template(d, RHO)  # default aspect_ratio = 1
    i_sphere = 0.1 * RHO * sphere_volume(d) * d**2
    assert t.n_spheres == 1 and t.radii[0] == pytest.approx(d / 2)
    assert t.inertia_principal == pytest.approx([i_sphere] * 3, rel=1e-12)
    near = elongated.template(d, RHO, aspect_ratio=1.0 + 1e-6)
    assert near.inertia_principal == pytest.approx(t.inertia_principal, rel=1e-5)
    assert near.bounding_radius == pytest.approx(t.bounding_radius, rel=1e-5)


def test_continuous_in_aspect_ratio(elongated):
    d = 0.018
    t150 = elongated.template(d, RHO, aspect_ratio=1.50)
    t151 = elongated.template(d, RHO, aspect_ratio=1.51)
    rel = np.abs(t151.inertia_principal / t150.inertia_principal - 1.0)
    assert np.all(rel < 0.01) and np.all(rel > 0)
    # no jumps anywhere on a fine grid: consecutive templates 0.01 apart differ by < 1 %
    grid = np.round(np.arange(1.01, 3.5001, 0.01), 6)
    moments = np.array([elongated.template(d, RHO, aspect_ratio=a).inertia_principal for a in grid])
    radii = np.array([elongated.template(d, RHO, aspect_ratio=a).radii[0] for a in grid])
    assert np.abs(np.diff(moments, axis=0) / moments[:-1]).max() < 0.01
    assert np.abs(np.diff(radii) / radii[:-1]).max() < 0.01
    assert np.all(np.diff(moments[:, 0]) < 0) and np.all(np.diff(moments[:, 2]) > 0)  # monotonic


def test_surface_bumpiness_matches_the_measured_profile(elongated):
    for a, expected in [(1.0, 0.0), (2.0, 0.0159), (3.0, 0.0670), (3.5, 0.1097)]:
        b = elongated.surface_bumpiness(aspect_ratio=a)
        assert b == pytest.approx(expected, abs=1e-4)
        t = elongated.template(0.01, RHO, aspect_ratio=a)
        width = extents(t)[1]
        x = np.linspace(t.centers[0, 0], t.centers[-1, 0], 4001)
        dip = (0.5 * width - np.array([profile(t, xi) for xi in x])).max() / width
        assert dip == pytest.approx(b, abs=1e-6)


@pytest.mark.parametrize("bad, match", [
    ({"aspect_ratio": 0.9}, r"'aspect_ratio' of family 'elongated' = 0.9 outside its admissible range \[1.0, 3.5\]"),
    ({"aspect_ratio": 3.6}, r"'aspect_ratio'.*\[1.0, 3.5\]"),
    ({"aspect_ratio": float("nan")}, r"'aspect_ratio'.*\[1.0, 3.5\]"),
    ({"aspect_ratio": "long"}, r"'aspect_ratio' of family 'elongated' must be a number"),
    ({"aspect": 2.0}, r"unknown shape parameter\(s\) \['aspect'\]; valid: \['aspect_ratio'\]"),
])
def test_bounds_errors_name_the_parameter_and_range(elongated, bad, match):
    with pytest.raises(wd.ConfigError, match=match):
        elongated.template(0.01, RHO, **bad)
    with pytest.raises(wd.ConfigError, match=match):
        BulkMaterial.shaped("elongated", 0.016, 0.02, **bad)


def test_template_rejects_bad_size_and_density(elongated):
    with pytest.raises(wd.ConfigError, match="diameter must be > 0"):
        elongated.template(0.0, RHO)
    with pytest.raises(wd.ConfigError, match="density"):
        elongated.template(0.01, -1.0)


# ------------------------------------------------------------------------------ materials
def test_shaped_material_size_classes_keep_the_sphere_mass():
    m = BulkMaterial.shaped("elongated", 0.016, 0.020, aspect_ratio=1.5, size_classes=5)
    spheres = BulkMaterial.spheres(0.016, 0.020)
    assert len(m.clumps) == 5 and all(f == pytest.approx(0.2) for _, f in m.clumps)
    assert m.mean_particle_mass == pytest.approx(spheres.mean_particle_mass, rel=1e-12)
    deq = [(6 * t.volume / math.pi) ** (1 / 3) for t, _ in m.clumps]
    assert deq == pytest.approx(list(equal_number_size_classes(0.016, 0.020, 5)), rel=1e-12)
    assert 0.016 < deq[0] < deq[-1] < 0.020
    assert all(t.density == m.particle.density for t, _ in m.clumps)
    one = BulkMaterial.shaped("elongated", 0.018, aspect_ratio=2.0)
    assert len(one.clumps) == 1 and one.clumps[0][0].volume == pytest.approx(sphere_volume(0.018))
    s = sample_particles(m, n=50, rng=0)
    assert s.n == 50 and np.all(s.template >= 0) and np.bincount(s.template).tolist() == [10] * 5
    assert s.equivalent_diameter == pytest.approx(np.array(deq)[s.template])


def test_shape_parameters_and_round_trip():
    base = BulkMaterial.shaped("elongated", 0.016, 0.020, aspect_ratio=1.5, solids_fraction=0.55)
    assert set(base.shape_parameters) == {"aspect_ratio"}
    assert base.shape_parameters["aspect_ratio"].bounds == (1.0, 3.5)
    assert base.shape_parameter_values == {"aspect_ratio": 1.5}
    rods = base.with_shape_parameters(aspect_ratio=2.5)
    assert rods.shape_parameter_values == {"aspect_ratio": 2.5} and base.shape_parameter_values == {"aspect_ratio": 1.5}
    assert rods.shape.diameter == base.shape.diameter and rods.shape.size_classes == base.shape.size_classes
    assert rods.solids_fraction == 0.55 and rods.particle == base.particle
    assert rods.mean_particle_mass == pytest.approx(base.mean_particle_mass, rel=1e-12)
    assert "aspect_ratio=2.5" in rods.name and rods.source["aspect_ratio"] == 2.5
    assert extents(rods.clumps[0][0])[0] / extents(rods.clumps[0][0])[1] == pytest.approx(2.5)
    back = rods.with_shape_parameters(aspect_ratio=1.5)
    assert back.shape == base.shape and back.name == base.name
    for (t0, f0), (t1, f1) in zip(base.clumps, back.clumps):
        assert f0 == f1 and np.array_equal(t0.centers, t1.centers) and np.array_equal(t0.inertia_principal,
                                                                                     t1.inertia_principal)
    assert base.with_shape_parameters() is base
    named = BulkMaterial.shaped("elongated", 0.016, 0.02, name="my rods").with_shape_parameters(aspect_ratio=2)
    assert named.name == "my rods"
    with pytest.raises(wd.ConfigError, match=r"unknown shape parameter\(s\) \['mu_s'\]"):
        base.with_shape_parameters(mu_s=0.5)
    with pytest.raises(wd.ConfigError, match=r"'aspect_ratio'.*\[1.0, 3.5\]"):
        base.with_shape_parameters(aspect_ratio=4.0)
    plain = BulkMaterial.spheres(0.016, 0.02)
    assert plain.shape_parameters == {} and plain.shape_parameter_values == {}
    assert plain.with_shape_parameters() is plain
    with pytest.raises(wd.ConfigError, match="has no shape parameters.*shaped"):
        plain.with_shape_parameters(aspect_ratio=2.0)
    mix = BulkMaterial.clump_mix([(base.clumps[0][0], 1.0)])
    assert mix.shape_parameters == {}


def test_describe_and_config_name_the_full_material():
    m = BulkMaterial.from_config({"shape": "elongated", "aspect_ratio": 1.5, "diameter": [0.016, 0.020],
                                  "size_classes": 3, "density": 2500})
    assert m.shape == ParticleShape("elongated", (("aspect_ratio", 1.5),), (0.016, 0.02), 3)
    assert m.particle.density == 2500 and len(m.clumps) == 3
    rec = m.describe()
    json.dumps(rec)
    assert rec["type"] == "shaped" and rec["shape"] == "elongated"
    assert rec["shape_parameters"] == {"aspect_ratio": 1.5} and rec["diameter"] == [0.016, 0.02]
    assert rec["spheres_per_clump"] == 5 and rec["surface_bumpiness"] > 0 and "Favier" in rec["shape_reference"]
    again = BulkMaterial.from_config(m.source)  # the source is a config of the same material
    assert again.shape == ParticleShape("elongated", (("aspect_ratio", 1.5),), (0.016, 0.02), 3)
    default = BulkMaterial.from_config({"type": "shaped", "shape": "elongated", "diameter": 0.018})
    assert default.shape_parameter_values == {"aspect_ratio": 1.0} and default.clumps[0][0].n_spheres == 1
    # the forms accepted before still work
    assert BulkMaterial.from_config({"diameter": 0.018}).diameter == (0.018, 0.018)
    assert BulkMaterial.from_config({"type": "spheres", "diameter": [0.016, 0.02], "name": "s"}).name == "s"
    bad = [
        ({"type": "spheres", "diameter": 0.02, "aspect_ratio": 2}, "unknown key.*add 'shape: elongated'"),
        ({"shape": "elongated", "diameter": 0.02, "aspect_ratio": 5}, r"'aspect_ratio'.*\[1.0, 3.5\]"),
        ({"shape": "rods", "diameter": 0.02}, "unknown shape family 'rods'"),
        ({"shape": "elongated", "aspect_ratio": 2}, "needs 'diameter'"),
        ({"type": "shaped", "diameter": 0.02}, "needs 'shape'"),
        ({"shape": "elongated", "diameter": 0.02, "fill_level": "low"}, "'fill_level' applies to type 'gravel'"),
        ({"type": "spheres", "shape": "elongated", "diameter": 0.02}, "'shape' does not apply to type 'spheres'"),
        ({"shape": "elongated", "diameter": 0.02, "size_classes": 0}, "size_classes must be a positive integer"),
        ({"shape": "elongated", "diameter": 18}, "millimetres"),
    ]
    for cfg, match in bad:
        with pytest.raises(wd.ConfigError, match=match):
            BulkMaterial.from_config(cfg)


# ------------------------------------------------------------------------------ DEM
def test_spheres_and_rods_of_equal_volume_settle_in_one_launch():
    """One model, two worlds: world 0 spheres, world 1 rods (aspect 2.5) of the same
    volume-equivalent diameter, dropped into the same box; they settle, stay rigid and finite."""
    d, n = 0.012, 30
    base = BulkMaterial.shaped("elongated", d)
    materials = [BulkMaterial.spheres(d), base.with_shape_parameters(aspect_ratio=2.5)]
    region = Box((0.0, 0.0, 0.0), (0.05, 0.05, 0.05))
    b = wd.ModelBuilder(num_worlds=2)
    b.add_material(wd.GRAVEL)
    b.add_wall(geometry.open_box((0.0, 0.0, 0.0), (0.05, 0.05, 0.3)), "gravel")
    fills = []
    for w, mat in enumerate(materials):
        fill = random_fill(region, sample_particles(mat, n=n, rng=w), rng=w)
        add_fill(b, fill, "gravel", w)
        fills.append(fill)
    model = b.finalize("cpu")
    h = model.host
    mass = np.bincount(h["body_world"], weights=h["body_mass"])
    assert mass[1] == pytest.approx(mass[0], rel=1e-6)  # equal solid volume per world
    sim = wd.Simulation(model, wd.time_step_limits(model).recommended)
    rod_gaps = np.diff(member_positions(fills[1])[0][:5], axis=0)
    report = settle(sim, 1e-6, 1.0, min_time=0.2)
    assert np.all(report.settled)
    q = sim.state.body_q.numpy()
    x = sim.sphere_positions()
    assert np.all(np.isfinite(q)) and np.all(np.isfinite(x))
    r = h["sphere_radius"]
    assert np.all(x[:, 2] - r > -0.05 * r) and np.all(x[:, :2] - r[:, None] > -0.05 * r[:, None])
    assert np.all(x[:, :2] + r[:, None] < 0.05 + 0.05 * r[:, None])
    assert np.all(q[:, 2] < 0.05)  # every particle came down into the box
    rod0 = np.nonzero(h["sphere_body"] == np.nonzero(h["body_world"] == 1)[0][0])[0]
    assert len(rod0) == 5
    np.testing.assert_allclose(np.linalg.norm(np.diff(x[rod0], axis=0), axis=1),
                               np.linalg.norm(rod_gaps, axis=1), rtol=1e-4)  # rigid
    assert np.all(sim.kinetic_energy() < 1e-6 * n)
