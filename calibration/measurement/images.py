"""Angle of repose from a picture (spec section "Images"; seed paper Section
2.1.2 and Figure 3: grayscale, binarisation, denoising, edge points, least
squares line).

Pipeline of :func:`measure_image`:

1. grayscale (BGR/BGRA or gray input, any integer or float dtype);
2. illumination correction: a smooth gain (2-D polynomial of log intensity,
   fitted jointly with one offset per Otsu class, iterated) is divided out, so a
   lighting gradient or vignetting does not move the threshold; small Gaussian
   blur against pixel noise;
3. binarisation: Otsu inside the window, or a given threshold (0-255, applied
   to the raw grayscale: no illumination correction then); the material side
   is dark, bright, or decided automatically (the class that fills more of the
   window's bottom rows than of its top rows); a window that is not two-toned
   (Otsu separability or class contrast too low) has no material;
4. morphological opening (removes background specks/texture) then closing
   (fills gaps between particles), elliptical kernels;
5. inside the window, the largest connected material region (it must cover
   at least ``min_area_frac`` of the window, else: no material); its upper edge
   is the topmost material pixel of each column; columns where it touches the
   window's top edge (the surface is above the window) are left out;
6. least-squares line (:func:`.profiles.fit_line`) through the edge points,
   optionally only those whose height lies in a band of a reference height
   (spec A: 15-85 % of h_fill; spec C: 20-80 % of the peak).

Coordinates: pixel (col, row) centre -> ``x = (col - origin_col) / scale`` and
``z = (origin_row - row) / scale`` (mm with ``scale`` in px/mm, else px with
scale 1; z up). ``origin_px`` defaults to the bottom-left pixel centre.
Failures (no material, no contrast, too few edge points, a flat surface) raise
:class:`.errors.MeasurementError`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import cv2
import numpy as np

from .errors import MeasurementError
from .profiles import fit_line, revolution_snapshot_times, slope_to_angle_deg

__all__ = [
    "ImageMeasurement",
    "VideoMeasurement",
    "to_gray",
    "correct_illumination",
    "binarize",
    "upper_edge",
    "measure_image",
    "video_frame_indices",
    "video_frames_for_revolutions",
]


# --------------------------------------------------------------------------- #
# steps
# --------------------------------------------------------------------------- #
def to_gray(image: np.ndarray | str | os.PathLike) -> np.ndarray:
    """Load (path) or convert an image to float32 grayscale scaled to 0-255.

    Colour arrays are taken as BGR(A), OpenCV's order. Integer images are
    scaled by their dtype's range, float images by their own min/max if they
    exceed [0, 1] else by 255.
    """
    if isinstance(image, (str, os.PathLike)):
        arr = cv2.imread(os.fspath(image), cv2.IMREAD_UNCHANGED)
        if arr is None:
            raise MeasurementError(f"cannot read image {os.fspath(image)!r}")
    else:
        arr = np.asarray(image)
    if arr.ndim == 3:
        if arr.shape[2] == 1:
            arr = arr[:, :, 0]
        elif arr.shape[2] in (3, 4):
            code = cv2.COLOR_BGR2GRAY if arr.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
            if arr.dtype not in (np.uint8, np.uint16, np.float32):
                arr = arr.astype(np.float32)
            arr = cv2.cvtColor(arr, code)
        else:
            raise MeasurementError(f"unsupported image shape {arr.shape}")
    elif arr.ndim != 2:
        raise MeasurementError(f"unsupported image shape {arr.shape}")
    if np.issubdtype(arr.dtype, np.integer):
        g = arr.astype(np.float32) * (255.0 / np.iinfo(arr.dtype).max)
    else:
        g = arr.astype(np.float32)
        hi = float(np.nanmax(g)) if g.size else 0.0
        g = g * 255.0 if hi <= 1.0 else g
    return g


def _otsu(u8: np.ndarray) -> float:
    t, _ = cv2.threshold(u8, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    return float(t)


def _to_u8(g: np.ndarray) -> np.ndarray:
    lo, hi = np.percentile(g, [0.1, 99.9])
    if hi - lo < 1e-6:
        return np.zeros(g.shape, np.uint8)
    return np.clip((g - lo) * (255.0 / (hi - lo)), 0, 255).astype(np.uint8)


def correct_illumination(gray: np.ndarray, *, degree: int = 2, iterations: int = 3,
                         step: int | None = None) -> np.ndarray:
    """Divide out a smooth lighting gain; returns 0-255 float32.

    Model: ``log(I) = a_class + P(col, row)`` with P a 2-D polynomial of the
    given degree (no constant) shared by material and background, and
    ``a_class`` one offset per Otsu class; classes are re-estimated
    ``iterations`` times. Fitted on every ``step``-th pixel (default: about
    20 000 samples). ``degree=0`` returns the input.
    """
    if degree <= 0:
        return gray.astype(np.float32)
    hgt, wid = gray.shape
    if step is None:
        step = max(1, int(math.sqrt(hgt * wid / 20000.0)))
    logi = np.log1p(np.maximum(gray, 0)).astype(np.float32)
    rr, cc = np.mgrid[0:hgt:step, 0:wid:step]
    u = (cc.ravel() / max(wid - 1, 1) - 0.5).astype(np.float64)
    v = (rr.ravel() / max(hgt - 1, 1) - 0.5).astype(np.float64)
    terms = [u**i * v**j for i in range(degree + 1) for j in range(degree + 1 - i) if i + j > 0]
    basis = np.stack(terms, axis=1)
    sample = logi[::step, ::step].ravel().astype(np.float64)
    poly = np.zeros_like(sample)
    for _ in range(iterations):
        corr = sample - poly
        t = _otsu(_to_u8(corr)[None, :])
        lo, hi = np.percentile(corr, [0.1, 99.9])
        cls = (corr - lo) * (255.0 / max(hi - lo, 1e-9)) > t
        design = np.column_stack([cls, ~cls, basis]).astype(np.float64)
        coef = np.linalg.lstsq(design.T @ design, design.T @ sample, rcond=None)[0]  # normal equations
        poly = basis @ coef[2:]
    # evaluate the polynomial on the full grid
    ufull = (np.arange(wid) / max(wid - 1, 1) - 0.5)[None, :]
    vfull = (np.arange(hgt) / max(hgt - 1, 1) - 0.5)[:, None]
    full = np.zeros((hgt, wid), np.float64)
    k = 0
    for i in range(degree + 1):
        for j in range(degree + 1 - i):
            if i + j > 0:
                full += coef[2 + k] * (ufull**i * vfull**j)
                k += 1
    out = np.expm1(logi - full)
    return _scale_like(out, gray)


def _scale_like(g: np.ndarray, ref: np.ndarray) -> np.ndarray:
    lo, hi = np.percentile(g, [0.1, 99.9])
    rlo, rhi = np.percentile(ref, [0.1, 99.9])
    if hi - lo < 1e-9:
        return g.astype(np.float32)
    return ((g - lo) * ((rhi - rlo) / (hi - lo)) + rlo).astype(np.float32)


def binarize(
    gray: np.ndarray,
    *,
    threshold: float | None = None,
    material: str = "auto",
    window: tuple[int, int, int, int] | None = None,
    min_separability: float = 0.70,
    min_contrast: float = 25.0,
) -> tuple[np.ndarray, float, str, float]:
    """Binary material mask (uint8 0/255) of a 0-255 grayscale image.

    ``threshold``: grey level, Otsu's if None. ``material``: "dark", "bright"
    or "auto". ``window`` (c0, c1, r0, r1) px, used for the automatic side
    decision and the checks. Unless a threshold is given, raises
    :class:`MeasurementError` when the two classes are not distinct (Otsu
    separability sigma_B^2/sigma_T^2 below ``min_separability`` or class
    medians closer than ``min_contrast`` grey levels): no material.
    Returns (mask, threshold, material side, separability).
    """
    if material not in ("auto", "dark", "bright"):
        raise ValueError(f"material must be 'auto', 'dark' or 'bright', got {material!r}")
    c0, c1, r0, r1 = window if window is not None else (0, gray.shape[1], 0, gray.shape[0])
    roi = gray[r0:r1, c0:c1]
    u8 = np.clip(np.round(gray), 0, 255).astype(np.uint8)
    roi8 = u8[r0:r1, c0:c1]
    if roi8.size == 0:
        raise MeasurementError("empty measurement window")
    if threshold is None:
        if float(roi.max() - roi.min()) < 1.0:
            raise MeasurementError("no material: the image window is uniform (no contrast)")
        t = _otsu(roi8)
    else:
        t = float(threshold)
    dark = roi8 <= t
    n_dark = int(dark.sum())
    if n_dark == 0 or n_dark == dark.size:
        raise MeasurementError(f"no material: threshold {t:.1f} leaves a single class in the window")
    a, b = roi[dark], roi[~dark]
    w0 = n_dark / dark.size
    sep = float(w0 * (1 - w0) * (a.mean() - b.mean()) ** 2 / max(roi.var(), 1e-12))
    contrast = float(np.median(b) - np.median(a))
    if threshold is None and sep < min_separability:
        raise MeasurementError(
            f"no material: the image window is not two-toned (Otsu separability {sep:.2f} < {min_separability})"
        )
    if threshold is None and contrast < min_contrast:
        raise MeasurementError(
            f"no material: the two grey-level classes differ by {contrast:.1f} < {min_contrast} grey levels"
        )
    if material == "auto":
        band = max(1, dark.shape[0] // 10)
        score = dark[-band:].mean() - dark[:band].mean()
        if abs(score) < 0.05:
            raise MeasurementError(
                "no material found, or cannot decide which side is material (the bottom and top "
                "of the window look alike); if there is material, pass material='dark' or 'bright'"
            )
        material = "dark" if score > 0 else "bright"
    mask = (u8 <= t) if material == "dark" else (u8 > t)
    return mask.astype(np.uint8) * 255, t, material, sep


def _ellipse(k: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))


def upper_edge(mask: np.ndarray, *, keep_largest: bool = True) -> np.ndarray:
    """Row of the topmost material pixel of each column (float, NaN where the
    column has none). With ``keep_largest`` only the largest 8-connected
    material region counts."""
    m = mask > 0
    if keep_largest:
        n, labels, stats, _ = cv2.connectedComponentsWithStats(m.astype(np.uint8), connectivity=8)
        if n <= 1:
            return np.full(mask.shape[1], np.nan)
        big = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        m = labels == big
    has = m.any(axis=0)
    first = np.argmax(m, axis=0).astype(float)
    first[~has] = np.nan
    return first


# --------------------------------------------------------------------------- #
# measurement
# --------------------------------------------------------------------------- #
@dataclass
class ImageMeasurement:
    """Result of :func:`measure_image`.

    angle_deg: atan(|slope|) in degrees. slope: dz/dx (z up, sign kept).
    intercept: z at x = 0 (``units``). points: (K, 2) fitted edge points (x, z)
    in ``units`` ("mm" or "px"). residual_rms: in ``units``. n_points: K.
    threshold: grey level used; material: "dark"/"bright"; separability: Otsu
    sigma_B^2/sigma_T^2 in the window. window_px: (c0, c1, r0, r1).
    scale: px per unit; origin_px: (col, row) of x = z = 0. gray: the input
    as 0-255 grayscale; mask: material mask (after denoising); edge_rows:
    upper-edge row per column of the window (NaN elsewhere).
    """

    angle_deg: float
    slope: float
    intercept: float
    points: np.ndarray
    residual_rms: float
    n_points: int
    units: str
    threshold: float
    material: str
    separability: float
    window_px: tuple[int, int, int, int]
    scale: float
    origin_px: tuple[float, float]
    gray: np.ndarray = field(repr=False)
    mask: np.ndarray = field(repr=False)
    edge_rows: np.ndarray = field(repr=False)

    def as_dict(self) -> dict:
        """JSON-ready summary (no arrays but the fitted points' count)."""
        return {
            "angle_deg": self.angle_deg, "slope": self.slope, "intercept": self.intercept,
            "units": self.units, "n_points": self.n_points, "residual_rms": self.residual_rms,
            "threshold": self.threshold, "material": self.material,
            "separability": self.separability, "window_px": list(self.window_px),
            "scale_px_per_unit": self.scale, "origin_px": list(self.origin_px),
        }

    def diagnostic_image(self) -> np.ndarray:
        """BGR picture: image, material tint (green), window (blue), fitted
        edge points (yellow), fitted line (red) and the angle."""
        base = cv2.cvtColor(np.clip(self.gray, 0, 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
        tint = base.copy()
        tint[self.mask > 0] = (0.6 * tint[self.mask > 0] + 0.4 * np.array([0, 200, 0])).astype(np.uint8)
        c0, c1, r0, r1 = self.window_px
        cv2.rectangle(tint, (c0, r0), (c1 - 1, r1 - 1), (255, 120, 0), 1)
        cols = self.origin_px[0] + self.points[:, 0] * self.scale
        rows = self.origin_px[1] - self.points[:, 1] * self.scale
        for c, r in zip(cols.astype(int), rows.astype(int)):
            cv2.circle(tint, (int(c), int(r)), 1, (0, 230, 255), -1)
        xa = np.array([(c0 - self.origin_px[0]) / self.scale, (c1 - 1 - self.origin_px[0]) / self.scale])
        za = self.slope * xa + self.intercept
        p = [(int(round(self.origin_px[0] + x * self.scale)), int(round(self.origin_px[1] - z * self.scale)))
             for x, z in zip(xa, za)]
        cv2.line(tint, p[0], p[1], (0, 0, 255), 1, cv2.LINE_AA)
        txt = f"angle {self.angle_deg:.2f} deg  slope {self.slope:.4f}  n={self.n_points}"
        (tw, th), base_ = cv2.getTextSize(txt, cv2.FONT_HERSHEY_SIMPLEX, 0.6, 1)
        cv2.rectangle(tint, (4, 4), (12 + tw, 12 + th + base_), (255, 255, 255), -1)
        cv2.putText(tint, txt, (8, 8 + th), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 255), 1, cv2.LINE_AA)
        return tint

    def save_diagnostic(self, path: str | os.PathLike) -> str:
        """Write :meth:`diagnostic_image` to ``path`` (format from extension)."""
        path = os.fspath(path)
        d = os.path.dirname(path)
        if d:
            os.makedirs(d, exist_ok=True)
        if not cv2.imwrite(path, self.diagnostic_image()):
            raise MeasurementError(f"cannot write diagnostic picture {path!r}")
        return path


def _window_px(
    shape: tuple[int, int],
    window: Sequence[float] | None,
    window_units: str,
    scale: float,
    origin: tuple[float, float],
) -> tuple[int, int, int, int]:
    hgt, wid = shape
    if window is None:
        return 0, wid, 0, hgt
    if len(window) != 4:
        raise ValueError(f"window must be (x_min, x_max, z_min, z_max) or (c0, c1, r0, r1), got {window}")
    if window_units == "px":
        c0, c1, r0, r1 = (int(round(v)) for v in window)
    elif window_units in ("mm", "units"):
        x0, x1, z0, z1 = window
        c0 = int(math.ceil(origin[0] + x0 * scale - 1e-9))
        c1 = int(math.floor(origin[0] + x1 * scale + 1e-9)) + 1
        r0 = int(math.ceil(origin[1] - z1 * scale - 1e-9))
        r1 = int(math.floor(origin[1] - z0 * scale + 1e-9)) + 1
    else:
        raise ValueError(f"window_units must be 'mm' or 'px', got {window_units!r}")
    if abs(c1 - c0) < 2 or abs(r1 - r0) < 2:  # too small wherever it lies: not "outside the image"
        raise MeasurementError(f"measurement window {list(window)} ({window_units}) is {abs(c1 - c0)} px wide and "
                               f"{abs(r1 - r0)} px high; a profile needs at least 2 px each way: give a larger window")
    c0, c1 = max(0, min(c0, c1)), min(wid, max(c0, c1))
    r0, r1 = max(0, min(r0, r1)), min(hgt, max(r0, r1))
    if c1 - c0 < 2 or r1 - r0 < 2:
        raise MeasurementError(f"measurement window {list(window)} ({window_units}) lies outside the image "
                               f"of {wid} x {hgt} px")
    return c0, c1, r0, r1


def measure_image(
    image: np.ndarray | str | os.PathLike,
    *,
    scale_px_per_mm: float | None = None,
    window: Sequence[float] | None = None,
    window_units: str | None = None,
    origin_px: tuple[float, float] | None = None,
    threshold: float | None = None,
    material: str = "auto",
    illumination_degree: int = 2,
    blur_sigma_px: float = 1.0,
    open_px: int = 5,
    close_px: int = 5,
    keep_largest: bool = True,
    fit_band: tuple[float, float] | None = None,
    h_ref: float | None = None,
    min_points: int = 10,
    min_area_frac: float = 0.01,
    min_angle_deg: float = 1.0,
    min_separability: float = 0.70,
    min_contrast: float = 25.0,
    diagnostic_path: str | os.PathLike | None = None,
) -> ImageMeasurement:
    """Angle of repose of the material's upper edge in a picture (px/mm scale
    optional). See the module docstring for the steps.

    ``window``: (x_min, x_max, z_min, z_max) in mm (needs ``scale_px_per_mm``)
    or, with ``window_units="px"``, (col_min, col_max, row_min, row_max).
    ``window_units`` defaults to "mm" when a scale is given, else "px".
    ``fit_band`` (lo, hi): fit only edge points with lo*h_ref <= z <= hi*h_ref;
    ``h_ref`` (same units as z) defaults to the highest edge point in the
    window (the pile peak, spec C). Kernel sizes and sigmas in px. Raises
    :class:`MeasurementError` for no material (no two-toned window, or the
    largest material region after denoising below ``min_area_frac`` of the
    window), fewer than ``min_points`` edge points, or a fitted angle below
    ``min_angle_deg`` (flat, no slope).
    ``diagnostic_path``: if given, the diagnostic picture is written there.
    """
    gray0 = to_gray(image)
    hgt, wid = gray0.shape
    scale = float(scale_px_per_mm) if scale_px_per_mm else 1.0
    units = "mm" if scale_px_per_mm else "px"
    origin = (0.0, float(hgt - 1)) if origin_px is None else (float(origin_px[0]), float(origin_px[1]))
    if window_units is None:
        window_units = "mm" if scale_px_per_mm else "px"
    win = _window_px((hgt, wid), window, window_units, scale, origin)
    c0, c1, r0, r1 = win

    gray = correct_illumination(gray0, degree=illumination_degree) if threshold is None else gray0
    if blur_sigma_px > 0:
        gray = cv2.GaussianBlur(gray, (0, 0), blur_sigma_px)
    mask, t, side, sep = binarize(gray, threshold=threshold, material=material, window=win,
                                  min_separability=min_separability, min_contrast=min_contrast)
    if open_px > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, _ellipse(open_px))
    if close_px > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, _ellipse(close_px))
    sub = mask[r0:r1, c0:c1] > 0
    n_lab, labels, stats, _ = cv2.connectedComponentsWithStats(sub.astype(np.uint8), connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    if n_lab <= 1 or areas.max() < min_area_frac * sub.size:
        raise MeasurementError(
            f"no material in the measurement window after denoising (largest region "
            f"{int(areas.max()) if n_lab > 1 else 0} px < {min_area_frac:.0%} of the window)"
        )
    if keep_largest:
        sub = labels == 1 + int(np.argmax(areas))
    edge = upper_edge(sub, keep_largest=False)
    ok = np.isfinite(edge) & (edge > 0)  # edge on the window's top row: surface above the window
    cols = np.arange(c0, c1, dtype=float)[ok]
    rows = edge[ok] + r0
    x = (cols - origin[0]) / scale
    z = (origin[1] - rows) / scale
    if fit_band is not None and x.size:
        ref = float(z.max()) if h_ref is None else float(h_ref)
        keep = (z >= fit_band[0] * ref) & (z <= fit_band[1] * ref)
        x, z = x[keep], z[keep]
    if x.size < min_points:
        raise MeasurementError(
            f"too few edge points in the window ({x.size} < {min_points}); no surface to fit"
        )
    fit = fit_line(x, z)
    full_edge = np.full(wid, np.nan)
    full_edge[c0:c1] = edge + r0
    res = ImageMeasurement(
        angle_deg=fit.angle_deg, slope=fit.slope, intercept=fit.intercept,
        points=np.column_stack([x, z]), residual_rms=fit.residual_rms, n_points=fit.n,
        units=units, threshold=t, material=side, separability=sep, window_px=win,
        scale=scale, origin_px=origin, gray=gray0, mask=mask, edge_rows=full_edge,
    )
    if diagnostic_path is not None:
        res.save_diagnostic(diagnostic_path)
    if fit.angle_deg < min_angle_deg:
        raise MeasurementError(
            f"no slope: the fitted surface is flat ({fit.angle_deg:.2f} deg < {min_angle_deg} deg)"
        )
    return res


# --------------------------------------------------------------------------- #
# video (drum, spec B)
# --------------------------------------------------------------------------- #
@dataclass
class VideoMeasurement:
    """Drum video result (spec B, seed paper Section 2.1.2).

    angle_deg: atan(|mean slope|) (the paper's beta). mean_slope; mean_deg and
    std_deg (ddof=1) of per-frame angles; frame_indices, times_s (n,);
    frames: per-frame :class:`ImageMeasurement`.
    """

    angle_deg: float
    mean_slope: float
    mean_deg: float
    std_deg: float
    frame_indices: np.ndarray
    times_s: np.ndarray
    frames: list[ImageMeasurement] = field(repr=False)

    def as_dict(self) -> dict:
        return {
            "angle_deg": self.angle_deg, "mean_slope": self.mean_slope,
            "mean_deg": self.mean_deg, "std_deg": self.std_deg,
            "frame_indices": self.frame_indices.tolist(), "times_s": self.times_s.tolist(),
            "slopes": [f.slope for f in self.frames], "angles_deg": [f.angle_deg for f in self.frames],
        }


def video_frame_indices(fps: float, rpm: float, discard: int, record: int, *,
                        t0: float = 0.0, n_frames: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Frame indices and times (s) of the start, middle and end of each recorded
    revolution (``3 * record`` frames). The end frame is the last frame of its
    revolution (one before the next revolution's start frame). Rotation starts
    at ``t0`` s. Raises :class:`MeasurementError` if ``n_frames`` is too few."""
    times = revolution_snapshot_times(rpm, discard, record, t0=t0)
    idx = np.round(times * fps).astype(np.int64)
    idx[:, 2] -= 1
    idx[:, 2] = np.maximum(idx[:, 2], idx[:, 1])
    idx = idx.ravel()
    if n_frames is not None and idx.max() >= n_frames:
        raise MeasurementError(
            f"video has {n_frames} frames but frame {int(idx.max())} is needed "
            f"({discard} discarded + {record} recorded revolutions at {rpm} rpm, {fps} fps)"
        )
    return idx, idx / float(fps)


def _read_frames(path: str, wanted: Iterable[int]) -> dict[int, np.ndarray]:
    cap = cv2.VideoCapture(path)
    if not cap.isOpened():
        raise MeasurementError(f"cannot open video {path!r}")
    wanted = sorted(set(int(i) for i in wanted))
    out: dict[int, np.ndarray] = {}
    i = 0
    try:
        for target in wanted:
            while i < target:
                if not cap.grab():
                    raise MeasurementError(f"video {path!r} ends at frame {i}, frame {target} needed")
                i += 1
            ok, frame = cap.read()
            if not ok:
                raise MeasurementError(f"video {path!r} ends at frame {i}, frame {target} needed")
            out[target] = frame
            i += 1
    finally:
        cap.release()
    return out


def video_frames_for_revolutions(
    path_or_frames: str | os.PathLike | Sequence[np.ndarray],
    fps: float | None,
    rpm: float,
    discard: int,
    record: int,
    *,
    t0: float = 0.0,
    diagnostic_dir: str | os.PathLike | None = None,
    **measure_kw,
) -> VideoMeasurement:
    """Measure a drum video (file path or a sequence of frames) at the start,
    middle and end of each of ``record`` revolutions after ``discard``
    (seed paper: 15 recorded, first 5 discarded; spec B). ``fps`` None reads it
    from the file. ``measure_kw`` go to :func:`measure_image` (scale, window =
    the crop square, ...). Returns beta = atan(|mean slope|), and the mean and
    std of the per-frame angles."""
    if isinstance(path_or_frames, (str, os.PathLike)):
        path = os.fspath(path_or_frames)
        cap = cv2.VideoCapture(path)
        if not cap.isOpened():
            raise MeasurementError(f"cannot open video {path!r}")
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) or None
        fps = fps or float(cap.get(cv2.CAP_PROP_FPS))
        cap.release()
        if not fps:
            raise MeasurementError(f"video {path!r} has no frame rate; pass fps")
        idx, times = video_frame_indices(fps, rpm, discard, record, t0=t0, n_frames=n)
        frames = _read_frames(path, idx)
        get = frames.__getitem__
    else:
        seq = path_or_frames
        if not fps:
            raise ValueError("fps is required with a sequence of frames")
        idx, times = video_frame_indices(fps, rpm, discard, record, t0=t0, n_frames=len(seq))
        get = seq.__getitem__
    results = []
    for k, i in enumerate(idx):
        diag = None if diagnostic_dir is None else os.path.join(os.fspath(diagnostic_dir), f"frame_{i:06d}.png")
        try:
            results.append(measure_image(get(int(i)), diagnostic_path=diag, **measure_kw))
        except MeasurementError as e:
            raise MeasurementError(f"frame {int(i)} (t = {times[k]:.3f} s): {e}") from e
    slopes = np.array([r.slope for r in results])
    angles = np.array([r.angle_deg for r in results])
    ms = float(slopes.mean())
    return VideoMeasurement(
        angle_deg=slope_to_angle_deg(ms), mean_slope=ms, mean_deg=float(angles.mean()),
        std_deg=float(angles.std(ddof=1)) if angles.size > 1 else float("nan"),
        frame_indices=idx, times_s=times, frames=results,
    )
