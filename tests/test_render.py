"""Camera-like rendering and the synthetic pile generator; one image pipeline
for simulation and lab: rendered-image angle vs particle-profile angle."""

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from calibration.measurement import (
    baffle_static_angle,
    cylinder_pile_angle,
    measure_image,
    render_side_view,
    synthetic_pile,
)
from calibration.measurement.render import lattice_fill


def test_single_sphere_geometry():
    pos = np.array([[0.100, 0.050, 0.040]])
    r = np.array([0.010])
    v = render_side_view(pos, r, scale_px_per_mm=2.0, extent_m=(0.0, 0.2, 0.0, 0.1), antialias=False)
    img = v.image
    assert img.shape == (200, 400) and img.dtype == np.uint8
    dark = img < 128
    area_px = dark.sum()
    assert area_px == pytest.approx(math.pi * 20.0**2, rel=0.05)  # radius 10 mm = 20 px
    rows, cols = np.nonzero(dark)
    c_exp, r_exp = v.to_px(0.100, 0.040)
    assert cols.mean() == pytest.approx(c_exp, abs=0.5)
    assert rows.mean() == pytest.approx(r_exp, abs=0.5)
    assert r_exp == pytest.approx(199.5 - 80.0, abs=0.01)  # z up: 40 mm above the bottom edge


def test_plane_slab_background_and_noise():
    pos = np.array([[0.05, 0.02, 0.05], [0.15, 0.18, 0.05]])
    r = 0.01
    ext = (0.0, 0.2, 0.0, 0.1)
    both = render_side_view(pos, r, extent_m=ext, scale_px_per_mm=1.0)
    assert (both.image < 128).sum() == pytest.approx(2 * math.pi * 100, rel=0.08)
    one = render_side_view(pos, r, extent_m=ext, scale_px_per_mm=1.0, slab=(0.0, 0.1))
    assert (one.image < 128).sum() == pytest.approx(math.pi * 100, rel=0.08)
    assert (one.image[:, 100:] < 128).sum() == 0  # the particle at y = 0.18 is out of the slab
    side = render_side_view(pos, r, plane="yz", extent_m=ext, scale_px_per_mm=1.0)
    cols = np.nonzero(side.image < 128)[1]
    assert cols.min() < 40 and cols.max() > 160  # horizontal axis is y
    assert side.image.max() == 220 and side.image.min() == 50
    n1 = render_side_view(pos, r, extent_m=ext, noise_std=10.0, rng=3).image
    n2 = render_side_view(pos, r, extent_m=ext, noise_std=10.0, rng=3).image
    np.testing.assert_array_equal(n1, n2)
    assert 5 < np.std(n1[:10, :].astype(float)) < 15
    auto = render_side_view(pos, r)  # default extent: bounding box + 10 %
    assert auto.extent_m[0] < 0.04 and auto.extent_m[1] > 0.16
    with pytest.raises(ValueError):
        render_side_view(pos, r, plane="xy")


def test_synthetic_pile_non_overlapping_and_below_surface():
    angle = 33.0
    pos, r = synthetic_pile(angle, rng=0)
    assert len(r) > 1000
    tree = cKDTree(pos)
    pairs = np.array(sorted(tree.query_pairs(0.0101)))
    d = np.linalg.norm(pos[pairs[:, 0]] - pos[pairs[:, 1]], axis=1)
    assert np.all(d >= r[pairs[:, 0]] + r[pairs[:, 1]] - 1e-12)
    t = math.tan(math.radians(angle))
    surface = np.minimum(0.15, 0.15 - t * (pos[:, 0] - 0.06))
    assert np.all(pos[:, 2] + r <= surface + 1e-12)
    assert np.all(pos[:, 2] - r >= 0.0)
    # lattice_fill respects the predicate
    p2, r2 = lattice_fill(lambda p, rr: p[:, 0] < 0.05, ((0, 0.1), (0, 0.1), (0, 0.1)), (0.003, 0.004), rng=1)
    assert len(r2) > 0 and np.all(p2[:, 0] < 0.05)


@pytest.mark.parametrize("angle", [27.0, 38.0])
def test_rendered_image_agrees_with_profile_baffle(angle):
    """Spec A on a synthetic pile: particle profile vs the rendered camera view."""
    pos, r = synthetic_pile(angle, height=0.15, crest_x=0.06, rng=int(angle) + 100)
    h_fill = 0.15
    prof = baffle_static_angle(pos, r, h_fill)
    scale = 2.0
    view = render_side_view(pos, r, slab=(0.030, 0.170), scale_px_per_mm=scale,
                            extent_m=(-0.02, 0.32, -0.02, 0.20), noise_std=8.0, rng=1)
    img = measure_image(view.image, scale_px_per_mm=scale, origin_px=view.origin_px,
                        window=(0.0, 300.0, -5.0, 200.0), fit_band=(0.15, 0.85), h_ref=h_fill * 1000)
    assert abs(img.angle_deg - prof.angle_deg) < 1.0
    assert abs(img.angle_deg - angle) < 1.0
    assert abs(prof.angle_deg - angle) < 1.0


def test_rendered_image_agrees_with_profile_cylinder():
    """Spec C: +x half-profile of the cone vs the right half of the x-z view."""
    angle = 33.0
    pos, r = synthetic_pile(angle, shape="cone", x_range=(-0.25, 0.25), y_range=(-0.25, 0.25),
                            height=0.14, rng=21)
    d = 2 * float(np.mean(r))
    res = cylinder_pile_angle(pos, r, d)
    view = render_side_view(pos, r, slab=(-d, d), scale_px_per_mm=2.0,
                            extent_m=(-0.26, 0.26, -0.02, 0.17), noise_std=5.0, rng=2)
    right = measure_image(view.image, scale_px_per_mm=2.0, origin_px=view.origin_px,
                          window=(0.0, 250.0, -5.0, 170.0), fit_band=(0.2, 0.8))
    left = measure_image(view.image, scale_px_per_mm=2.0, origin_px=view.origin_px,
                         window=(-250.0, 0.0, -5.0, 170.0), fit_band=(0.2, 0.8))
    assert abs(right.angle_deg - res.thetas_deg[0]) < 1.0
    assert abs(left.angle_deg - res.thetas_deg[1]) < 1.0
    assert right.slope < 0 < left.slope
