"""Angle definitions from particle data (spec A, B, C)."""

import math

import numpy as np
import pytest

from calibration.measurement import (
    MeasurementError,
    baffle_static_angle,
    bulk_density,
    cylinder_pile_angle,
    drum_dynamic_angle,
    fit_line,
    mean_surface_height,
    revolution_snapshot_times,
    slope_to_angle_deg,
    surface_profile,
    synthetic_pile,
)


def test_fit_line_exact_and_errors():
    x = np.linspace(0, 0.3, 7)
    f = fit_line(x, 0.2 - 0.6515 * x)
    assert f.slope == pytest.approx(-0.6515, abs=1e-12)
    assert f.intercept == pytest.approx(0.2, abs=1e-12)
    assert f.residual_rms == pytest.approx(0.0, abs=1e-12)
    assert f.angle_deg == pytest.approx(math.degrees(math.atan(0.6515)))
    with pytest.raises(MeasurementError):
        fit_line([0.1], [0.2])
    with pytest.raises(MeasurementError):
        fit_line([0.1, 0.1, 0.1], [0.0, 0.1, 0.2])


def test_slope_to_angle():
    assert slope_to_angle_deg(1.0) == pytest.approx(45.0)
    assert slope_to_angle_deg(-1.0) == pytest.approx(45.0)
    np.testing.assert_allclose(slope_to_angle_deg(np.array([0.0, math.sqrt(3)])), [0.0, 60.0])


def test_surface_profile_max_and_empty_bins():
    x = np.array([0.001, 0.004, 0.025, 0.029, 0.0999, 0.2])  # last one outside range
    z = np.array([0.10, 0.30, 0.05, 0.02, 0.07, 9.0])
    p = surface_profile(x, z, 0.01, (0.0, 0.1))
    assert p.centres.shape == (10,)
    np.testing.assert_allclose(p.centres[:3], [0.005, 0.015, 0.025])
    assert p.heights[0] == pytest.approx(0.30)
    assert p.heights[2] == pytest.approx(0.05)
    assert p.heights[9] == pytest.approx(0.07)
    assert np.isnan(p.heights[1]) and p.counts[1] == 0  # empty: marked, not invented
    assert p.counts.tolist() == [2, 0, 2, 0, 0, 0, 0, 0, 0, 1]
    assert p.valid.sum() == 3


@pytest.mark.parametrize("angle", [25.0, 32.0, 40.0])
def test_baffle_static_angle_on_synthetic_pile(angle):
    pos, r = synthetic_pile(angle, height=0.15, crest_x=0.06, rng=int(angle))
    res = baffle_static_angle(pos, r, h_fill=0.15)
    assert res.angle_deg == pytest.approx(angle, abs=0.6)
    assert res.slope < 0  # descending towards the baffle
    assert res.n_bins >= 3 and res.n_bins == res.x_fit.size == res.z_fit.size
    lo, hi = res.z_band
    assert lo == pytest.approx(0.15 * 0.15) and hi == pytest.approx(0.85 * 0.15)
    assert np.all((res.z_fit >= lo) & (res.z_fit <= hi))
    assert res.residual_rms < 0.005


def test_baffle_static_angle_respects_y_band_and_floor():
    pos, r = synthetic_pile(30.0, rng=1)
    # junk near the side walls (y < 30 mm) must not count
    junk = np.array([[0.25, 0.01, 0.095], [0.27, 0.19, 0.095]])  # tops at 0.1 m: inside the band
    pos2 = np.vstack([pos, junk])
    r2 = np.concatenate([r, [0.005, 0.005]])
    a = baffle_static_angle(pos, r, 0.15).angle_deg
    assert baffle_static_angle(pos2, r2, 0.15).angle_deg == pytest.approx(a, abs=1e-12)
    # the same pile on a floor at z = 0.1 gives the same angle
    up = pos + np.array([0.0, 0.0, 0.1])
    res = baffle_static_angle(up, r, 0.15, floor_z=0.1)
    assert res.angle_deg == pytest.approx(a, abs=1e-9)
    assert res.intercept == pytest.approx(baffle_static_angle(pos, r, 0.15).intercept + 0.1)


def test_baffle_static_angle_too_few_bins_is_an_error():
    pos, r = synthetic_pile(30.0, rng=2)
    # a flat, undisturbed fill: no bin between 15 % and 85 % of h_fill
    flat = pos[pos[:, 0] < 0.05]
    with pytest.raises(MeasurementError, match="bin"):
        baffle_static_angle(flat, r[pos[:, 0] < 0.05], h_fill=0.15)
    # a very narrow band leaves fewer than 3 bins
    with pytest.raises(MeasurementError, match="need >= 3"):
        baffle_static_angle(pos, r, h_fill=0.15, band=(0.50, 0.52))


def test_mean_surface_height_and_bulk_density_on_lattice():
    # regular lattice: 10 mm cells, centres 5, 15, ... mm, 1 g each -> 1000 kg/m^3
    c = np.arange(0.005, 0.3, 0.01)
    gx, gy, gz = np.meshgrid(c, np.arange(0.005, 0.2, 0.01), np.arange(0.005, 0.2, 0.01), indexing="ij")
    pos = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    r = np.full(len(pos), 0.004)
    h = mean_surface_height(pos, r)
    assert h == pytest.approx(0.195 + 0.004)
    rho = bulk_density(pos, r, 0.001)
    assert rho == pytest.approx(1000.0, rel=0.02)
    assert bulk_density(pos, r, 0.001, h=h) == pytest.approx(rho)
    with pytest.raises(MeasurementError):
        bulk_density(pos, r, 0.001, h=0.05)  # z range [20, 10] mm is empty


def test_revolution_snapshot_times():
    t = revolution_snapshot_times(30.0, discard=5, record=10)
    assert t.shape == (10, 3)
    np.testing.assert_allclose(t[0], [10.0, 11.0, 12.0])  # 2 s per revolution
    np.testing.assert_allclose(t[-1], [28.0, 29.0, 30.0])  # ends at 15 revolutions = 30 s
    t2 = revolution_snapshot_times(15.0, discard=2, record=4, t0=0.5)
    np.testing.assert_allclose(t2[0], [8.5, 10.5, 12.5])
    t3 = revolution_snapshot_times(30.0, discard=1, record=2, frames=5)
    np.testing.assert_allclose(t3, [[2.0, 2.5, 3.0, 3.5, 4.0], [4.0, 4.5, 5.0, 5.5, 6.0]])
    with pytest.raises(ValueError, match="frames"):
        revolution_snapshot_times(30.0, 1, 2, frames=1)


def _drum_snapshot(angle, seed):
    # a plane surface rising in +x through roughly the drum axis (x = z = 0)
    return synthetic_pile(angle, shape="plane", x_range=(-0.1, 0.1), y_range=(0.0, 0.15),
                          height=0.12, floor_z=-0.12, rng=seed)


def test_drum_dynamic_angle():
    angles = [46.0, 49.0, 52.0]
    snaps = [_drum_snapshot(a, i) for i, a in enumerate(angles)]
    res = drum_dynamic_angle(snaps)
    assert res.slopes.shape == (3,) and np.all(res.slopes > 0)
    np.testing.assert_allclose(res.angles_deg, angles, atol=1.0)
    expected = math.degrees(math.atan(np.mean(np.tan(np.radians(angles)))))
    assert res.angle_deg == pytest.approx(expected, abs=0.7)
    assert res.angle_deg == pytest.approx(math.degrees(math.atan(res.mean_slope)))
    assert res.std_deg == pytest.approx(np.std(res.angles_deg, ddof=1))
    assert 1.5 < res.std_deg < 4.5
    # shared radii form
    pos0, r0 = snaps[0]
    assert drum_dynamic_angle([pos0], r0).angle_deg == pytest.approx(res.angles_deg[0])
    assert math.isnan(drum_dynamic_angle([pos0], r0).std_deg)


def test_drum_dynamic_angle_crop_and_errors():
    pos, r = _drum_snapshot(49.0, 7)
    res = drum_dynamic_angle([(pos, r)])
    f = res.fits[0]
    assert np.all(np.abs(f.x_fit) <= 0.075)
    assert np.all(f.z_fit < 0.075)  # bins reaching the crop top are left out
    # only particles y in [30, 120] mm count
    far = np.array([[-0.05, 0.14, 0.0]])  # well above the surface there, but y > 120 mm
    res2 = drum_dynamic_angle([(np.vstack([pos, far]), np.append(r, 0.005))])
    assert res2.angle_deg == pytest.approx(res.angle_deg)
    # a snapshot with the material outside the crop: an error naming it
    with pytest.raises(MeasurementError, match="snapshot 1"):
        drum_dynamic_angle([(pos, r), (pos + [0.0, 0.0, -0.3], r)])
    with pytest.raises(MeasurementError):
        drum_dynamic_angle([])


def test_drum_unmeasurable_snapshots_left_out_only_when_allowed_and_listed():
    good = [_drum_snapshot(a, i) for i, a in enumerate([46.0, 49.0, 52.0])]
    pos, r = good[1]
    empty = (pos + [0.0, 0.0, -0.3], r)  # the material has left the crop: no bin
    ref = drum_dynamic_angle(good)
    res = drum_dynamic_angle(good[:1] + [empty] + good[1:], max_skipped=1)
    assert [i for i, _ in res.skipped] == [1] and "snapshot 1" in res.skipped[0][1]
    assert res.angle_deg == pytest.approx(ref.angle_deg) and len(res.fits) == 3
    with pytest.raises(MeasurementError, match="2 snapshots unmeasurable, at most 1"):
        drum_dynamic_angle([empty, good[0], empty], max_skipped=1)
    with pytest.raises(MeasurementError, match="no snapshot could be measured"):
        drum_dynamic_angle([empty], max_skipped=3)
    with pytest.raises(ValueError, match="max_skipped"):
        drum_dynamic_angle(good, max_skipped=-1)


@pytest.mark.parametrize("angle", [28.0, 36.0])
def test_cylinder_pile_angle_on_cone(angle):
    pos, r = synthetic_pile(angle, shape="cone", x_range=(-0.25, 0.25), y_range=(-0.25, 0.25),
                            height=0.14, rng=int(angle))
    res = cylinder_pile_angle(pos, r)
    assert res.thetas_deg.shape == (4,)
    assert res.gamma_s_deg == pytest.approx(np.mean(res.thetas_deg))
    assert res.gamma_s_deg == pytest.approx(angle, abs=1.0)
    np.testing.assert_allclose(res.thetas_deg, angle, atol=2.0)
    assert res.peak_height == pytest.approx(0.14, abs=0.015)
    for f in res.fits:
        assert f.n_bins >= 3 and f.slope < 0
        assert np.all(f.z_fit >= 0.2 * res.peak_height) and np.all(f.z_fit <= 0.8 * res.peak_height)


def test_cylinder_pile_angle_off_axis_and_errors():
    pos, r = synthetic_pile(33.0, shape="cone", x_range=(-0.25, 0.25), y_range=(-0.25, 0.25),
                            height=0.14, rng=5)
    base = cylinder_pile_angle(pos, r, 0.009)
    moved = cylinder_pile_angle(pos + [0.5, -0.2, 0.0], r, 0.009, axis_xy=(0.5, -0.2))
    np.testing.assert_allclose(moved.thetas_deg, base.thetas_deg, atol=1e-9)
    with pytest.raises(MeasurementError):  # a single particle: no profile
        cylinder_pile_angle(np.array([[0.0, 0.0, 0.01]]), 0.005)
