"""Union-of-spheres mass properties, principal frames and clump templates."""
import math
import time

import numpy as np
import pytest
from scipy.integrate import quad

from warpdem.clump_geometry import (ClumpTemplate, lens_volume, make_template, principal_frame,
                                    union_mass_properties)
from warpdem.errors import ConfigError


def _axisymmetric_reference(r1: float, r2: float, d: float):
    """Volume, COM z, axial and transverse moment (about the COM, density 1) of the union of
    balls (0,0,0; r1) and (0,0,d; r2), by 1-D adaptive quadrature over discs."""
    def rho2(z):
        return max(r1 * r1 - z * z, r2 * r2 - (z - d) ** 2, 0.0)

    lo, hi = min(-r1, d - r2), max(r1, d + r2)
    zc = (r1 * r1 - r2 * r2 + d * d) / (2 * d)          # radical plane
    kw = dict(points=[zc], epsabs=0, epsrel=1e-12, limit=200)
    V = quad(lambda z: math.pi * rho2(z), lo, hi, **kw)[0]
    zg = quad(lambda z: math.pi * rho2(z) * z, lo, hi, **kw)[0] / V
    i_ax = quad(lambda z: 0.5 * math.pi * rho2(z) ** 2, lo, hi, **kw)[0]
    i_tr = quad(lambda z: 0.25 * math.pi * rho2(z) ** 2 + math.pi * rho2(z) * (z - zg) ** 2, lo, hi, **kw)[0]
    return V, zg, i_ax, i_tr


def test_single_sphere_exact():
    r, rho, c = 0.013, 2661.0, np.array([0.1, -0.2, 0.05])
    mp = union_mass_properties([c], [r], rho)
    v = 4.0 / 3.0 * math.pi * r ** 3
    assert mp.volume == pytest.approx(v, rel=1e-12)
    assert mp.mass == pytest.approx(rho * v, rel=1e-12)
    np.testing.assert_allclose(mp.com, c, atol=1e-15)
    i0 = 0.4 * rho * v * r * r                           # 2/5 m r^2
    np.testing.assert_allclose(mp.inertia, i0 * np.eye(3), rtol=1e-11, atol=1e-12 * i0)
    assert mp.volume_error < 1e-12 * v


def test_disjoint_spheres_are_exact_sum():
    c = np.array([[0, 0, 0], [3.0, 0, 0]])
    r = np.array([1.0, 0.5])
    mp = union_mass_properties(c, r, 1.0)
    vols = 4 / 3 * math.pi * r ** 3
    assert mp.volume == pytest.approx(vols.sum(), rel=1e-12)
    assert mp.com[0] == pytest.approx(3.0 * vols[1] / vols.sum(), rel=1e-12)


@pytest.mark.parametrize("r1,r2,d", [(1.0, 1.0, 1.0), (1.0, 0.6, 1.2), (1.0, 0.5, 0.7), (1.0, 1.0, 0.1)])
def test_two_spheres_volume_lens_formula(r1, r2, d):
    v_ref = 4 / 3 * math.pi * (r1 ** 3 + r2 ** 3) - lens_volume(r1, r2, d)
    mp = union_mass_properties([[0, 0, 0], [0, 0, d]], [r1, r2], 1.0)
    assert mp.volume == pytest.approx(v_ref, rel=1e-3)      # brief: 0.5 %; method gives ~1e-4
    assert mp.volume < 4 / 3 * math.pi * (r1 ** 3 + r2 ** 3)  # not the naive sum
    # the error estimate is conservative
    assert abs(mp.volume - v_ref) <= mp.volume_error + 1e-12


def test_lens_formula_limits():
    assert lens_volume(1.0, 1.0, 2.5) == 0.0
    assert lens_volume(1.0, 0.3, 0.2) == pytest.approx(4 / 3 * math.pi * 0.027)
    # equal spheres at distance d: 2 caps of height r - d/2, V_cap = pi h^2 (3r - h)/3
    h = 1.0 - 0.5
    assert lens_volume(1.0, 1.0, 1.0) == pytest.approx(2 * math.pi * h * h * (3 - h) / 3)


@pytest.mark.parametrize("r1,r2,d", [(1.0, 0.6, 1.2), (1.0, 1.0, 1.0)])
def test_two_spheres_inertia_vs_reference(r1, r2, d):
    # put the pair on a tilted axis so that all tensor components are exercised
    axis = np.array([1.0, 2.0, -0.5])
    axis /= np.linalg.norm(axis)
    base = np.array([0.3, -0.1, 0.2])
    mp = union_mass_properties([base, base + d * axis], [r1, r2], 1.0)
    V, zg, i_ax, i_tr = _axisymmetric_reference(r1, r2, d)
    assert mp.volume == pytest.approx(V, rel=1e-3)
    np.testing.assert_allclose(mp.com, base + zg * axis, atol=1e-3 * r1)
    expected = i_tr * np.eye(3) + (i_ax - i_tr) * np.outer(axis, axis)
    np.testing.assert_allclose(mp.inertia, expected, atol=2e-3 * i_ax)


def test_contained_and_duplicate_spheres_ignored():
    big = union_mass_properties([[0, 0, 0]], [1.0], 1.0)
    mp = union_mass_properties([[0, 0, 0], [0.2, 0.1, 0], [0, 0, 0]], [1.0, 0.5, 1.0], 1.0)
    assert mp.volume == pytest.approx(big.volume, rel=1e-12)
    np.testing.assert_allclose(mp.inertia, big.inertia, rtol=1e-10, atol=1e-14)


def test_dumbbell_principal_axes():
    # symmetric dumbbell along (1,1,0)/sqrt2: smallest moment about that axis
    u = np.array([1.0, 1.0, 0.0]) / math.sqrt(2)
    c = np.array([-0.8 * u, 0.8 * u, np.zeros(3)])
    r = np.array([0.5, 0.5, 0.3])
    mp = union_mass_properties(c, r, 1.0)
    np.testing.assert_allclose(mp.com, 0.0, atol=1e-9)
    moments, R = principal_frame(mp.inertia)
    assert moments[0] < moments[1] == pytest.approx(moments[2], rel=1e-6)
    assert abs(abs(R[:, 0] @ u) - 1.0) < 1e-9
    np.testing.assert_allclose(R @ np.diag(moments) @ R.T, mp.inertia, atol=1e-12)


def test_principal_frame_is_proper_rotation():
    rng = np.random.default_rng(3)
    for _ in range(20):
        A = rng.normal(size=(3, 3))
        I = A @ A.T + 0.1 * np.eye(3)
        moments, R = principal_frame(I)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.all(np.diff(moments) >= 0)
        np.testing.assert_allclose(R @ np.diag(moments) @ R.T, I, atol=1e-10)


def test_make_template_principal_body_frame():
    rng = np.random.default_rng(0)
    c = rng.normal(size=(7, 3)) * 4e-3 + np.array([0.1, 0.2, 0.3])
    r = rng.uniform(2e-3, 4e-3, 7)
    tpl = make_template(c, r, 2661.0, name="rand")
    body = union_mass_properties(tpl.centers, tpl.radii, tpl.density)
    np.testing.assert_allclose(body.com, 0.0, atol=1e-4 * tpl.equivalent_radius)
    off = body.inertia - np.diag(np.diag(body.inertia))
    assert np.abs(off).max() < 1e-3 * tpl.inertia_principal.max()
    np.testing.assert_allclose(np.diag(body.inertia), tpl.inertia_principal, rtol=2e-3)
    # frame bookkeeping: x_in = R x_body + offset
    np.testing.assert_allclose(tpl.centers @ tpl.rotation.T + tpl.offset, c, atol=1e-12)
    assert np.linalg.det(tpl.rotation) == pytest.approx(1.0)
    assert tpl.mass == pytest.approx(2661.0 * tpl.volume)
    assert tpl.n_spheres == 7
    # with_density scales mass and inertia only
    t2 = tpl.with_density(1000.0)
    assert t2.mass == pytest.approx(1000.0 * tpl.volume)
    np.testing.assert_allclose(t2.inertia_principal, tpl.inertia_principal * 1000.0 / 2661.0)
    with pytest.raises(ValueError):
        tpl.centers[0, 0] = 1.0                          # read-only arrays


def test_speed_25_spheres():
    rng = np.random.default_rng(1)
    c = rng.normal(size=(25, 3)) * 0.8
    r = rng.uniform(0.3, 0.8, 25)
    union_mass_properties(c, r, 1.0)                     # warm the quadrature cache
    t = time.perf_counter()
    mp = union_mass_properties(c, r, 1.0)
    assert time.perf_counter() - t < 0.5
    assert mp.volume_error < 5e-3 * mp.volume            # 0.5 % accuracy target


@pytest.mark.parametrize("centers,radii,match", [
    (np.zeros((0, 3)), np.zeros(0), "empty"),
    ([[0, 0, 0]], [-1.0], "radii must be > 0"),
    ([[0, 0, 0]], [0.0], "radii must be > 0"),
    ([[0, 0, np.nan]], [1.0], "NaN"),
    ([[0, 0, 0]], [np.inf], "NaN/inf"),
    ([[0, 0, 0], [1, 0, 0]], [1.0], "2 centers but 1 radii"),
    ([[0, 0]], [1.0], "shape"),
])
def test_bad_input(centers, radii, match):
    with pytest.raises(ConfigError, match=match):
        union_mass_properties(centers, radii, 1.0)
    with pytest.raises(ConfigError):
        make_template(centers, radii, 1.0)


def test_bad_density_and_template_fields():
    with pytest.raises(ConfigError, match="density"):
        union_mass_properties([[0, 0, 0]], [1.0], -5.0)
    with pytest.raises(ConfigError, match="inertia_principal"):
        ClumpTemplate("x", [[0, 0, 0]], [1.0], 1.0, 1.0, 1.0, [1.0, 1.0, -1.0])
    with pytest.raises(ConfigError, match="rotation"):
        ClumpTemplate("x", [[0, 0, 0]], [1.0], 1.0, 1.0, 1.0, [1.0, 1.0, 1.0], rotation=-np.eye(3))
