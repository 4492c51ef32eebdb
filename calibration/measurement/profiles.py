"""Angles of repose from particle data (definitions: docs/experiments.md).

Inputs are plain numpy arrays in SI units: particle centres ``positions`` (N, 3)
in metres (z up), radii (N,) in metres (or a scalar), masses (N,) in kg. Each
angle is ``atan(|slope|)`` in degrees of a least-squares line fitted by
:func:`fit_line` to a surface profile, the surface height of a bin being the
highest particle top ``z + r`` among particles whose centres lie in the bin
(spec A, B, C; seed paper Section 2.1.2 does the same on image edge points).

Defaults are the spec's values converted from mm to m; all are keyword
arguments and can be overridden.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .errors import MeasurementError

__all__ = [
    "LineFit",
    "SurfaceProfile",
    "ProfileFit",
    "DrumResult",
    "CylinderPileResult",
    "fit_line",
    "slope_to_angle_deg",
    "surface_profile",
    "mean_surface_height",
    "baffle_static_angle",
    "bulk_density",
    "drum_dynamic_angle",
    "revolution_snapshot_times",
    "cylinder_pile_angle",
]


# --------------------------------------------------------------------------- #
# shared helpers
# --------------------------------------------------------------------------- #
def slope_to_angle_deg(slope: float | np.ndarray) -> float | np.ndarray:
    """Angle of repose in degrees from a fitted slope: ``atan(|slope|)``.

    Seed paper Table 1 (angle from the linear-fit slope); spec A/B/C.
    """
    out = np.degrees(np.arctan(np.abs(slope)))
    return float(out) if np.ndim(out) == 0 else out


@dataclass(frozen=True)
class LineFit:
    """Least-squares line ``z = slope * x + intercept``.

    ``residual_rms`` is in the units of z; ``n`` is the number of points.
    """

    slope: float
    intercept: float
    residual_rms: float
    n: int

    @property
    def angle_deg(self) -> float:
        """``atan(|slope|)`` in degrees."""
        return slope_to_angle_deg(self.slope)


def fit_line(x: np.ndarray, z: np.ndarray) -> LineFit:
    """Ordinary least-squares line through points (x, z), any consistent units.

    Used by every angle definition here and by the image pipeline, so that the
    simulation and the lab share one fit. Raises :class:`MeasurementError` for
    fewer than 2 points, non-finite values or points that all share one x.
    """
    x = np.asarray(x, dtype=float).ravel()
    z = np.asarray(z, dtype=float).ravel()
    if x.shape != z.shape:
        raise MeasurementError(f"fit_line: x and z differ in length ({x.size} vs {z.size})")
    if x.size < 2:
        raise MeasurementError(f"fit_line: need at least 2 points, got {x.size}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(z))):
        raise MeasurementError("fit_line: non-finite coordinates")
    if np.ptp(x) == 0.0:
        raise MeasurementError("fit_line: all points share one x; no slope can be fitted")
    slope, intercept = np.polyfit(x, z, 1)
    resid = z - (slope * x + intercept)
    return LineFit(float(slope), float(intercept), float(np.sqrt(np.mean(resid**2))), int(x.size))


def _as_particles(positions: np.ndarray, radii: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise ValueError(f"positions must have shape (N, 3), got {pos.shape}")
    r = np.broadcast_to(np.asarray(radii, dtype=float), (pos.shape[0],))
    return pos, r


# --------------------------------------------------------------------------- #
# surface profile
# --------------------------------------------------------------------------- #
@dataclass(frozen=True)
class SurfaceProfile:
    """Binned surface: ``heights[i]`` is the highest particle top in bin i.

    Empty bins hold NaN in ``heights`` and 0 in ``counts`` (never interpolated).
    Lengths in the units of the inputs (m in this module).
    """

    centres: np.ndarray
    heights: np.ndarray
    counts: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """Boolean mask of non-empty bins."""
        return self.counts > 0


def surface_profile(
    x: np.ndarray,
    z_top: np.ndarray,
    bin_width: float,
    x_range: tuple[float, float],
) -> SurfaceProfile:
    """Highest ``z_top`` per bin of ``x`` over ``x_range`` (spec A/B/C binning).

    Bins are ``[lo + k*w, lo + (k+1)*w)``; the last bin is clipped at ``hi``
    and includes it. Points outside ``x_range`` are ignored.
    """
    lo, hi = float(x_range[0]), float(x_range[1])
    if not hi > lo or not bin_width > 0:
        raise ValueError(f"need x_range[1] > x_range[0] and bin_width > 0, got {x_range}, {bin_width}")
    n_bins = max(1, int(math.ceil((hi - lo) / bin_width - 1e-9)))
    edges = np.minimum(lo + bin_width * np.arange(n_bins + 1), hi)
    x = np.asarray(x, dtype=float).ravel()
    z_top = np.asarray(z_top, dtype=float).ravel()
    inside = (x >= lo) & (x <= hi)
    idx = np.clip(((x[inside] - lo) // bin_width).astype(np.int64), 0, n_bins - 1)
    heights = np.full(n_bins, -np.inf)
    np.maximum.at(heights, idx, z_top[inside])
    counts = np.bincount(idx, minlength=n_bins)
    heights[counts == 0] = np.nan
    return SurfaceProfile(0.5 * (edges[:-1] + edges[1:]), heights, counts)


def mean_surface_height(
    positions: np.ndarray,
    radii: np.ndarray | float,
    *,
    x_range: tuple[float, float] = (0.0, 0.300),
    y_range: tuple[float, float] = (0.0, 0.200),
    bin_width: float = 0.010,
    floor_z: float = 0.0,
) -> float:
    """Mean surface height (m above ``floor_z``) of a fill: the highest particle
    top in each ``bin_width`` x ``bin_width`` column of the x-y region, averaged
    over non-empty columns. Default region: the baffle box interior (spec A);
    this is the ``h_fill`` of spec A and the ``h`` of its bulk density.
    """
    pos, r = _as_particles(positions, radii)
    sel = (
        (pos[:, 0] >= x_range[0]) & (pos[:, 0] <= x_range[1])
        & (pos[:, 1] >= y_range[0]) & (pos[:, 1] <= y_range[1])
    )
    if not np.any(sel):
        raise MeasurementError("mean_surface_height: no particle in the region")
    nx = max(1, int(math.ceil((x_range[1] - x_range[0]) / bin_width - 1e-9)))
    ny = max(1, int(math.ceil((y_range[1] - y_range[0]) / bin_width - 1e-9)))
    ix = np.clip(((pos[sel, 0] - x_range[0]) // bin_width).astype(np.int64), 0, nx - 1)
    iy = np.clip(((pos[sel, 1] - y_range[0]) // bin_width).astype(np.int64), 0, ny - 1)
    top = np.full(nx * ny, -np.inf)
    np.maximum.at(top, ix * ny + iy, pos[sel, 2] + r[sel])
    return float(np.mean(top[np.isfinite(top)]) - floor_z)


@dataclass(frozen=True)
class ProfileFit:
    """A fitted surface profile (one angle).

    angle_deg: atan(|slope|) in degrees. slope: dz/dx (sign kept; for
    half-profiles x is the distance from the axis). intercept: m.
    x_fit, z_fit: centres (m) and heights (m) of the fitted bins.
    residual_rms: RMS of the fit residuals (m). n_bins: bins fitted.
    z_band: (low, high) heights (m) a bin had to lie between to be fitted,
    or None. profile: the full binned profile.
    """

    angle_deg: float
    slope: float
    intercept: float
    x_fit: np.ndarray
    z_fit: np.ndarray
    residual_rms: float
    n_bins: int
    z_band: tuple[float, float] | None
    profile: SurfaceProfile


def _fit_profile(
    profile: SurfaceProfile,
    *,
    z_band: tuple[float, float] | None,
    min_bins: int,
    what: str,
    exclude_above: float | None = None,
) -> ProfileFit:
    ok = profile.valid.copy()
    h = profile.heights
    if exclude_above is not None:
        ok &= ~(h >= exclude_above)
    if z_band is not None:
        ok &= (h >= z_band[0]) & (h <= z_band[1])
    n = int(np.count_nonzero(ok))
    if n < max(2, min_bins):
        band = "" if z_band is None else f" with height in [{z_band[0]:.4g}, {z_band[1]:.4g}] m"
        raise MeasurementError(
            f"{what}: only {n} bin(s){band} (need >= {max(2, min_bins)}); no angle can be measured"
        )
    fit = fit_line(profile.centres[ok], h[ok])
    return ProfileFit(
        angle_deg=fit.angle_deg,
        slope=fit.slope,
        intercept=fit.intercept,
        x_fit=profile.centres[ok].copy(),
        z_fit=h[ok].copy(),
        residual_rms=fit.residual_rms,
        n_bins=n,
        z_band=z_band,
        profile=profile,
    )


# --------------------------------------------------------------------------- #
# A. Baffle lifting box: static angle of repose
# --------------------------------------------------------------------------- #
def baffle_static_angle(
    positions: np.ndarray,
    radii: np.ndarray | float,
    h_fill: float,
    *,
    x_range: tuple[float, float] = (0.0, 0.300),
    y_range: tuple[float, float] = (0.030, 0.170),
    bin_width: float = 0.010,
    band: tuple[float, float] = (0.15, 0.85),
    floor_z: float = 0.0,
    min_bins: int = 3,
) -> ProfileFit:
    """Static angle of repose alpha_AoR_S of the baffle test (spec A).

    Particles with y in ``y_range`` and x in ``x_range`` (m); x binned in
    ``bin_width`` (m) bins, bin height = highest top ``z + r``. The line is
    fitted to the bins whose height above ``floor_z`` lies within
    ``band`` x ``h_fill`` (h_fill: mean fill surface height before the lift, m,
    see :func:`mean_surface_height`). Fewer than ``min_bins`` bins raises
    :class:`MeasurementError`.
    """
    if not h_fill > 0:
        raise ValueError(f"h_fill must be > 0 m, got {h_fill}")
    pos, r = _as_particles(positions, radii)
    sel = (pos[:, 1] >= y_range[0]) & (pos[:, 1] <= y_range[1])
    prof = surface_profile(pos[sel, 0], pos[sel, 2] + r[sel] - floor_z, bin_width, x_range)
    z_band = (band[0] * h_fill, band[1] * h_fill)
    fit = _fit_profile(prof, z_band=z_band, min_bins=min_bins, what="baffle_static_angle")
    # report the line in absolute z
    return _shift_z(fit, floor_z)


def _shift_z(fit: ProfileFit, dz: float) -> ProfileFit:
    if dz == 0.0:
        return fit
    p = fit.profile
    return ProfileFit(
        fit.angle_deg, fit.slope, fit.intercept + dz, fit.x_fit, fit.z_fit + dz, fit.residual_rms,
        fit.n_bins, None if fit.z_band is None else (fit.z_band[0] + dz, fit.z_band[1] + dz),
        SurfaceProfile(p.centres, p.heights + dz, p.counts),
    )


def bulk_density(
    positions: np.ndarray,
    radii: np.ndarray | float,
    masses: np.ndarray | float,
    box: tuple[tuple[float, float], tuple[float, float]] = ((0.020, 0.280), (0.020, 0.180)),
    h: float | None = None,
    *,
    z_min: float = 0.020,
    top_margin: float = 0.040,
) -> float:
    """Bulk density of the fill (kg/m^3), spec A.

    Mass of the particles whose centres lie in x in ``box[0]``, y in ``box[1]``,
    z in ``[z_min, h - top_margin]`` (m), divided by that volume. ``h`` is the
    mean surface height (m); if None it is computed with
    :func:`mean_surface_height` over the box interior (this is what ``radii`` is
    needed for).
    """
    pos, r = _as_particles(positions, radii)
    m = np.broadcast_to(np.asarray(masses, dtype=float), (pos.shape[0],))
    if h is None:
        h = mean_surface_height(pos, r)
    (x0, x1), (y0, y1) = box
    z1 = h - top_margin
    if not (x1 > x0 and y1 > y0 and z1 > z_min):
        raise MeasurementError(
            f"bulk_density: empty sampling volume (x {x0}-{x1}, y {y0}-{y1}, z {z_min}-{z1} m)"
        )
    sel = (
        (pos[:, 0] >= x0) & (pos[:, 0] <= x1)
        & (pos[:, 1] >= y0) & (pos[:, 1] <= y1)
        & (pos[:, 2] >= z_min) & (pos[:, 2] <= z1)
    )
    return float(m[sel].sum() / ((x1 - x0) * (y1 - y0) * (z1 - z_min)))


# --------------------------------------------------------------------------- #
# B. Rotating drum: dynamic angle of repose
# --------------------------------------------------------------------------- #
def revolution_snapshot_times(
    rpm: float, discard: int, record: int, *, t0: float = 0.0, frames: int = 3
) -> np.ndarray:
    """Snapshot times (s) for the drum: start, middle and end of each recorded
    revolution after ``discard`` revolutions (seed paper Section 2.1.2, spec B).

    Returns shape ``(record, frames)``; rotation starts at ``t0`` (s), one
    revolution lasts ``60 / rpm`` s. The end of revolution k coincides with the
    start of revolution k+1, as in the paper's start-middle-end protocol.
    ``frames`` > 3 spaces more frames evenly over each revolution, start and end
    included (fewer particles -> noisier frames -> more frames for the same spread).
    """
    if not rpm > 0 or discard < 0 or record < 1 or frames < 2:
        raise ValueError(f"need rpm > 0, discard >= 0, record >= 1, frames >= 2 "
                         f"(got {rpm}, {discard}, {record}, {frames})")
    period = 60.0 / rpm
    k = np.arange(discard, discard + record, dtype=float)[:, None]
    return t0 + period * (k + np.linspace(0.0, 1.0, int(frames))[None, :])


@dataclass(frozen=True)
class DrumResult:
    """Dynamic angle of repose from several drum snapshots (spec B).

    angle_deg: beta = atan(|mean slope|) in degrees. mean_slope: mean of the
    per-snapshot slopes. slopes, angles_deg: per snapshot. mean_deg, std_deg:
    mean and sample std (ddof=1; NaN for one snapshot) of per-snapshot angles.
    fits: per-snapshot :class:`ProfileFit` (x relative to the drum axis) of the measured
    snapshots. skipped: ``(index, reason)`` of snapshots that could not be measured (fewer
    than ``min_bins`` bins) and were left out, at most ``max_skipped`` of them.
    """

    angle_deg: float
    mean_slope: float
    slopes: np.ndarray
    angles_deg: np.ndarray
    mean_deg: float
    std_deg: float
    fits: list[ProfileFit] = field(repr=False)
    skipped: tuple[tuple[int, str], ...] = ()


def drum_dynamic_angle(
    snapshots: Sequence[np.ndarray | tuple[np.ndarray, np.ndarray]],
    radii: np.ndarray | float | None = None,
    *,
    axis_xz: tuple[float, float] = (0.0, 0.0),
    crop_side: float = 0.150,
    y_range: tuple[float, float] = (0.030, 0.120),
    bin_width: float = 0.010,
    min_bins: int = 3,
    max_skipped: int = 0,
) -> DrumResult:
    """Dynamic angle of repose beta_AoR_D of the rotating drum (spec B).

    ``snapshots``: positions arrays (N, 3) in m (then ``radii`` applies to all)
    or ``(positions, radii)`` pairs. In each snapshot, particles with centres in
    the x-z square of side ``crop_side`` (m) centred on ``axis_xz`` and y in
    ``y_range`` are binned in x (``bin_width``); bins whose surface reaches the
    crop's top edge (material above the crop, the surface is not seen there)
    are left out. One line per snapshot; beta = atan(|mean slope|). A snapshot with fewer than
    ``min_bins`` bins raises :class:`MeasurementError`, unless ``max_skipped`` > 0: then up to
    that many such snapshots are left out of the mean and listed in ``DrumResult.skipped``
    (with few large particles a steep frame can leave only 2 bins below the crop's top edge).
    """
    if len(snapshots) == 0:
        raise MeasurementError("drum_dynamic_angle: no snapshots")
    if max_skipped < 0:
        raise ValueError(f"max_skipped must be >= 0, got {max_skipped}")
    half = 0.5 * crop_side
    ax, az = axis_xz
    fits: list[ProfileFit] = []
    skipped: list[tuple[int, str]] = []
    for i, snap in enumerate(snapshots):
        if isinstance(snap, tuple):
            pos, r = _as_particles(*snap)
        else:
            if radii is None:
                raise ValueError("drum_dynamic_angle: give radii or (positions, radii) snapshots")
            pos, r = _as_particles(snap, radii)
        x = pos[:, 0] - ax
        z = pos[:, 2] - az
        sel = (
            (np.abs(x) <= half) & (np.abs(z) <= half)
            & (pos[:, 1] >= y_range[0]) & (pos[:, 1] <= y_range[1])
        )
        prof = surface_profile(x[sel], z[sel] + r[sel], bin_width, (-half, half))
        try:
            fits.append(_fit_profile(prof, z_band=None, min_bins=min_bins,
                                     what=f"drum_dynamic_angle (snapshot {i})", exclude_above=half))
        except MeasurementError as exc:
            skipped.append((i, str(exc)))
            if len(skipped) > max_skipped:
                more = f" ({len(skipped)} snapshots unmeasurable, at most {max_skipped} may be left out)" \
                    if max_skipped > 0 else ""
                raise MeasurementError(f"{exc}{more}") from None
    if not fits:
        raise MeasurementError("drum_dynamic_angle: no snapshot could be measured")
    slopes = np.array([f.slope for f in fits])
    angles = np.array([f.angle_deg for f in fits])
    mean_slope = float(slopes.mean())
    return DrumResult(
        angle_deg=slope_to_angle_deg(mean_slope),
        mean_slope=mean_slope,
        slopes=slopes,
        angles_deg=angles,
        mean_deg=float(angles.mean()),
        std_deg=float(angles.std(ddof=1)) if angles.size > 1 else float("nan"),
        fits=fits,
        skipped=tuple(skipped),
    )


# --------------------------------------------------------------------------- #
# C. Hollow cylinder lifting: validation pile angle
# --------------------------------------------------------------------------- #
@dataclass(frozen=True)
class CylinderPileResult:
    """Pile angle of the hollow-cylinder test (spec C, seed paper Table 10).

    thetas_deg: theta_1..4 for the half-profiles (+x, -x, +y, -y), degrees.
    gamma_s_deg: their mean. peak_height: pile peak height above the floor (m).
    fits: the four :class:`ProfileFit` (x = horizontal distance from the axis).
    """

    thetas_deg: np.ndarray
    gamma_s_deg: float
    peak_height: float
    fits: list[ProfileFit] = field(repr=False)

    HALVES = ("+x", "-x", "+y", "-y")


def cylinder_pile_angle(
    positions: np.ndarray,
    radii: np.ndarray | float,
    mean_diameter: float | None = None,
    *,
    axis_xy: tuple[float, float] = (0.0, 0.0),
    bin_width: float = 0.010,
    band: tuple[float, float] = (0.20, 0.80),
    r_max: float | None = None,
    floor_z: float = 0.0,
    min_bins: int = 3,
) -> CylinderPileResult:
    """Pile angle gamma_s after the hollow-cylinder lift (spec C).

    Four half-profiles as a camera sees them: x-z plane (particles with
    ``|y - y_axis| < mean_diameter``) split into +x and -x halves, and y-z plane
    (``|x - x_axis| < mean_diameter``) split into +y and -y. The horizontal
    distance from the axis is binned in ``bin_width`` (m) up to ``r_max``
    (default: the farthest selected particle); the line is fitted to bins whose
    height above ``floor_z`` is within ``band`` x the pile's peak height (the
    highest top among the selected particles). ``mean_diameter`` (m) defaults
    to ``2 * mean(radii)``.
    """
    pos, r = _as_particles(positions, radii)
    d = float(2.0 * np.mean(r)) if mean_diameter is None else float(mean_diameter)
    dx = pos[:, 0] - axis_xy[0]
    dy = pos[:, 1] - axis_xy[1]
    top = pos[:, 2] + r - floor_z
    in_xz = np.abs(dy) < d
    in_yz = np.abs(dx) < d
    halves = [
        (in_xz & (dx >= 0), dx),
        (in_xz & (dx < 0), -dx),
        (in_yz & (dy >= 0), dy),
        (in_yz & (dy < 0), -dy),
    ]
    any_sel = in_xz | in_yz
    if not np.any(any_sel):
        raise MeasurementError("cylinder_pile_angle: no particle within one mean diameter of the axis planes")
    peak = float(top[any_sel].max())
    if not peak > 0:
        raise MeasurementError(f"cylinder_pile_angle: pile peak height {peak} m is not above the floor")
    rmax = r_max if r_max is not None else float(max(np.abs(dx[in_xz]).max(initial=0.0),
                                                     np.abs(dy[in_yz]).max(initial=0.0))) + 1e-9
    z_band = (band[0] * peak, band[1] * peak)
    fits = []
    for name, (sel, dist) in zip(CylinderPileResult.HALVES, halves):
        prof = surface_profile(dist[sel], top[sel], bin_width, (0.0, rmax))
        fits.append(_shift_z(
            _fit_profile(prof, z_band=z_band, min_bins=min_bins, what=f"cylinder_pile_angle ({name} half)"),
            floor_z,
        ))
    thetas = np.array([f.angle_deg for f in fits])
    return CylinderPileResult(thetas, float(thetas.mean()), peak, fits)
