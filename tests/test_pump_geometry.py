"""Pump sizing and procedural geometry: duty, head, slip, passages, component tags, user meshes."""
import math

import numpy as np
import pytest
import trimesh

from pump.design import G, PumpDesign
from pump.geometry import (BLADE_ZONES, COMPONENTS, REGIONS, blade_camber, build_pump, passage_clearances)
from warpdem.errors import ConfigError


@pytest.fixture(scope="module")
def geo():
    return build_pump()


def test_default_design_matches_paper_duty_and_gulich_head():
    d = PumpDesign()
    q = 25.0 / 3600.0
    assert d.flow_rate == pytest.approx(q)
    # 65 mm inlet at 25 m^3/h: the paper's 2.1 m/s
    assert q / (math.pi * 0.0325**2) == pytest.approx(d.inlet_velocity)
    assert d.inlet_velocity == pytest.approx(2.1, abs=0.02)
    # Gulich: psi = 2 g H / u2^2 = 1.21 exp(-0.77 n_q / 100), n_q = n sqrt(Q) / H^0.75
    n_q = 1450.0 * math.sqrt(q) / 20.0**0.75
    psi = 1.21 * math.exp(-0.77 * n_q / 100.0)
    assert 2 * G * 20.0 / d.u2**2 == pytest.approx(psi, rel=1e-9)
    assert d.u2 == pytest.approx(math.pi * d.d2 * 1450.0 / 60.0)
    assert 17.0 < d.u2 < 21.0  # "blade tips at about 20 m/s"


def test_outlet_angle_gives_the_design_euler_head():
    d = PumpDesign()
    b2 = math.radians(d.beta2_blade_deg)
    gamma = 0.98 * (1 - math.sqrt(math.sin(b2)) / d.blades**0.7)  # d1/d2 below Wiesner's limit here
    assert d.slip_factor == pytest.approx(gamma, rel=1e-9)
    c_m2 = d.flow_rate / (math.pi * d.d2 * d.b2)
    c_u2 = gamma * d.u2 - c_m2 / math.tan(b2)
    assert d.u2 * c_u2 / G == pytest.approx(d.head / d.hydraulic_efficiency, rel=1e-6)
    fixed = PumpDesign(beta2_deg=30.0)
    assert fixed.beta2_blade_deg == 30.0 and fixed.euler_head < d.euler_head


def test_bad_design_input_is_named():
    with pytest.raises(ConfigError, match="head"):
        PumpDesign(head=-5)
    with pytest.raises(ConfigError, match="blades"):
        PumpDesign(blades=1)
    with pytest.raises(ConfigError, match="unknown key.*'speed'"):
        PumpDesign.from_config({"speed": 1450})
    with pytest.raises(ConfigError, match="leading_edge_radius"):
        PumpDesign(leading_edge_radius=0.02)


def test_every_triangle_is_tagged(geo):
    comps = set()
    for mesh, allowed in ((geo.impeller, {"shroud", "blade", "hub"}),
                          (geo.casing, {"volute", "tongue", "inlet", "outlet"})):
        names = set(mesh.component_names())
        assert names == allowed
        comps |= names
        assert mesh.faces.max() < len(mesh.vertices)
        assert np.all(mesh.areas() > 0)
    assert comps == set(COMPONENTS)
    zones = set(np.asarray(BLADE_ZONES)[geo.impeller.zone[geo.impeller.component == COMPONENTS.index("blade")]])
    assert zones == {"leading_edge", "pressure_side", "suction_side", "trailing_edge"}


def test_passages_take_25_mm_gravel(geo):
    c = passage_clearances(geo)
    for name, width in c.items():
        assert width >= 0.025 - 1e-9, f"{name} is only {width * 1e3:.1f} mm"


def test_pressure_side_faces_the_rotation(geo):
    """Rotation about +z: the pressure side lies at larger theta than the camber line."""
    d = geo.design
    imp = geo.impeller
    cen = imp.centroids()
    r = np.hypot(cen[:, 0], cen[:, 1])
    th = np.arctan2(cen[:, 1], cen[:, 0])
    rc, thc = blade_camber(d, 400, 0.0)
    for zone, sign in (("pressure_side", 1), ("suction_side", -1)):
        sel = imp.zone == BLADE_ZONES.index(zone)
        rel = th[sel] - np.interp(r[sel], rc, thc)
        rel = np.mod(rel + np.pi / d.blades, 2 * np.pi / d.blades) - np.pi / d.blades  # offset to own blade
        assert np.all(sign * rel > 0)
    # backswept: the camber angle falls with radius
    assert np.all(np.diff(thc) < 0)


def test_spiral_volute_area_schedule(geo):
    """Free-vortex volute: the section at theta carries Q theta / 2 pi (K_v b3 ln(r_o / r3))."""
    d = geo.design
    for frac in (0.25, 0.5, 1.0):
        ro = geo.spiral_radius(2 * np.pi * frac - 1e-9)
        assert d.k_volute * d.b3 * math.log(ro / d.r3) == pytest.approx(frac * d.flow_rate, rel=1e-6)
    cas = geo.casing
    spiral = cas.vertices[np.unique(cas.faces[cas.component == COMPONENTS.index("volute")])]
    r = np.hypot(spiral[:, 0], spiral[:, 1])
    assert r.max() == pytest.approx(d.r_throat, rel=1e-3)


def test_regions(geo):
    d = geo.design
    pts = [(0, 0, geo.inlet_top - 0.01), (0.08, 0, 0.015), (0, -(d.r2 + 0.01), 0.015), (d.r3 + 0.01, 0.05, 0.015),
           (0.3, 0.3, 0.0), (d.r3 - 0.0005, 0.03, 0.015)]
    names = [REGIONS[k] for k in geo.region_of(np.array(pts))]
    assert names == ["inlet", "impeller", "volute", "discharge", "outside", "outside"]


def test_user_mesh_replaces_a_component(tmp_path):
    box = trimesh.creation.box(extents=(100.0, 100.0, 10.0))  # millimetres
    path = tmp_path / "volute.stl"
    box.export(path)
    geo = build_pump(user_meshes={"volute": str(path)}, mesh_scale=0.001)
    sel = geo.casing.component == COMPONENTS.index("volute")
    assert sel.sum() == 12
    assert np.ptp(geo.casing.vertices[np.unique(geo.casing.faces[sel])][:, 0]) == pytest.approx(0.1)
    assert (geo.casing.component == COMPONENTS.index("inlet")).sum() > 0
    with pytest.raises(ConfigError, match="unknown pump component 'casing'"):
        build_pump(user_meshes={"casing": str(path)})
    with pytest.raises(ConfigError, match="not found"):
        build_pump(user_meshes={"blade": str(tmp_path / "missing.stl")})
