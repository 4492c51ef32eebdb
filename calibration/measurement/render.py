"""Camera-like renderings of particle data, and synthetic test piles/images.

:func:`render_side_view` draws what a camera looking along y (or x) sees:
an orthographic silhouette of the spheres, material dark on a light
background, so that the image pipeline of :mod:`.images` measures simulation
and lab pictures alike (spec, section "Images").

Image convention shared with :mod:`.images`: the pixel (col, row) centre maps
to ``h_mm = (col - origin_col) / scale`` and ``v_mm = (origin_row - row) / scale``
with ``scale`` in px/mm, h to the right and v (z) up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

__all__ = [
    "RenderedView",
    "render_side_view",
    "lattice_fill",
    "synthetic_pile",
    "synthetic_slope_image",
]

_SHIFT = 4  # cv2 fixed-point bits for sub-pixel circle centres


@dataclass(frozen=True)
class RenderedView:
    """A rendered side view.

    image: uint8 grayscale (H, W). scale_px_per_mm: px/mm. origin_px: (col,
    row) of world point h = v = 0 (see module docstring). extent_m:
    (h_min, h_max, v_min, v_max) in m. plane: "xz" or "yz".
    """

    image: np.ndarray
    scale_px_per_mm: float
    origin_px: tuple[float, float]
    extent_m: tuple[float, float, float, float]
    plane: str

    def to_px(self, h_m: np.ndarray, v_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World (m) -> pixel (col, row) coordinates."""
        s = self.scale_px_per_mm * 1000.0
        return self.origin_px[0] + np.asarray(h_m) * s, self.origin_px[1] - np.asarray(v_m) * s


def render_side_view(
    positions: np.ndarray,
    radii: np.ndarray | float,
    *,
    plane: str = "xz",
    scale_px_per_mm: float = 2.0,
    extent_m: tuple[float, float, float, float] | None = None,
    slab: tuple[float, float] | None = None,
    background: float = 220.0,
    material: float = 50.0,
    noise_std: float = 0.0,
    antialias: bool = True,
    rng: np.random.Generator | int | None = None,
) -> RenderedView:
    """Orthographic side view of spheres as discs (silhouette).

    positions (N, 3) m, radii (N,) m. ``plane`` "xz" looks along y, "yz" along
    x. ``slab`` (m) keeps only particles whose depth coordinate (y for "xz", x
    for "yz") lies in it, like the spec's y in [30, 170] mm band. ``extent_m``
    (h_min, h_max, v_min, v_max) defaults to the particles' bounding box plus
    10 %. Grey levels: ``background`` and ``material`` (0-255); Gaussian noise
    of ``noise_std`` grey levels is added if > 0.
    """
    pos = np.asarray(positions, dtype=float)
    r = np.broadcast_to(np.asarray(radii, dtype=float), (pos.shape[0],))
    if plane not in ("xz", "yz"):
        raise ValueError(f"plane must be 'xz' or 'yz', got {plane!r}")
    hi_, di_ = (0, 1) if plane == "xz" else (1, 0)
    if slab is not None:
        keep = (pos[:, di_] >= slab[0]) & (pos[:, di_] <= slab[1])
        pos, r = pos[keep], r[keep]
    h, v = pos[:, hi_], pos[:, 2]
    if extent_m is None:
        if h.size == 0:
            raise ValueError("render_side_view: no particles and no extent given")
        h0, h1 = float((h - r).min()), float((h + r).max())
        v0, v1 = float((v - r).min()), float((v + r).max())
        ph, pv = 0.1 * (h1 - h0), 0.1 * (v1 - v0)
        extent_m = (h0 - ph, h1 + ph, v0 - pv, v1 + pv)
    h0, h1, v0, v1 = extent_m
    s = scale_px_per_mm * 1000.0  # px per m
    width, height = int(math.ceil((h1 - h0) * s)), int(math.ceil((v1 - v0) * s))
    origin = (-h0 * s - 0.5, v1 * s - 0.5)
    img = np.full((height, width), float(background), dtype=np.float32)
    f = 1 << _SHIFT
    cols = np.round((origin[0] + h * s) * f).astype(np.int64)
    rows = np.round((origin[1] - v * s) * f).astype(np.int64)
    rads = np.maximum(np.round(r * s * f).astype(np.int64), 1)
    line = cv2.LINE_AA if antialias else cv2.LINE_8
    for c, rw, rad in zip(cols.tolist(), rows.tolist(), rads.tolist()):
        cv2.circle(img, (c, rw), rad, float(material), -1, line, _SHIFT)
    if noise_std > 0:
        gen = np.random.default_rng(rng)
        img += gen.normal(0.0, noise_std, img.shape).astype(np.float32)
    out = np.clip(np.round(img), 0, 255).astype(np.uint8)
    return RenderedView(out, float(scale_px_per_mm), origin, tuple(map(float, extent_m)), plane)


# --------------------------------------------------------------------------- #
# synthetic piles (numpy only) for tests
# --------------------------------------------------------------------------- #
def lattice_fill(
    inside: Callable[[np.ndarray, np.ndarray], np.ndarray],
    bounds_m: tuple[tuple[float, float], tuple[float, float], tuple[float, float]],
    radius_range_m: tuple[float, float],
    *,
    rng: np.random.Generator | int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Non-overlapping spheres on a jittered cubic lattice, kept where
    ``inside(centres, radii)`` is True.

    Cell size = 2 * max radius; each sphere (radius uniform in
    ``radius_range_m``) is jittered inside its own cell, so no two overlap;
    each vertical column of cells is shifted by a random fraction of a cell so
    that layers do not line up. Spheres stay within the z bounds.
    Returns positions (N, 3) m and radii (N,) m.
    """
    gen = np.random.default_rng(rng)
    rmin, rmax = radius_range_m
    cell = 2.0 * rmax
    (x0, x1), (y0, y1), (z0, z1) = bounds_m
    xs = np.arange(x0 + 0.5 * cell, x1 - 0.5 * cell + 1e-12, cell)
    ys = np.arange(y0 + 0.5 * cell, y1 - 0.5 * cell + 1e-12, cell)
    zs = np.arange(z0 - 0.5 * cell, z1 + 0.5 * cell + 1e-12, cell)
    gx, gy, gz = np.meshgrid(xs, ys, zs, indexing="ij")
    # each x-y column of cells gets its own random z offset: spheres stay in
    # their column (no overlap) but the layers do not line up across columns
    gz = gz + gen.uniform(0.0, cell, gx.shape[:2])[:, :, None]
    grid = np.stack([gx, gy, gz], axis=-1).reshape(-1, 3)
    rad = gen.uniform(rmin, rmax, grid.shape[0])
    jitter = (0.5 * cell - rad)[:, None] * gen.uniform(-1.0, 1.0, grid.shape)
    pos = grid + jitter
    keep = (pos[:, 2] - rad >= z0) & (pos[:, 2] + rad <= z1) & np.asarray(inside(pos, rad), dtype=bool)
    return pos[keep], rad[keep]


def synthetic_pile(
    angle_deg: float,
    *,
    shape: str = "wedge",
    x_range: tuple[float, float] = (0.0, 0.300),
    y_range: tuple[float, float] = (0.0, 0.200),
    height: float = 0.150,
    crest_x: float = 0.060,
    radius_range: tuple[float, float] = (0.004, 0.005),
    floor_z: float = 0.0,
    rng: np.random.Generator | int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Synthetic heap of spheres lying wholly below a known sloped surface.

    ``shape="wedge"``: plateau z = ``height`` for x < ``crest_x``, then a plane
    descending in +x at ``angle_deg`` to the floor (a baffle-test pile).
    ``shape="cone"``: a cone of apex height ``height`` at the centre of the
    x-y ranges, flank at ``angle_deg`` (a hollow-cylinder pile).
    ``shape="plane"``: the plane rising in +x at ``angle_deg`` through
    (mean x, ``floor_z + height/2``), no plateau (a drum surface; clipped to
    the box). Every sphere is at least its radius below the surface
    (perpendicular distance). Lengths in m; returns (positions, radii).
    """
    t = math.tan(math.radians(angle_deg))
    cos_a = math.cos(math.radians(angle_deg))
    xc = 0.5 * (x_range[0] + x_range[1])
    yc = 0.5 * (y_range[0] + y_range[1])
    top = floor_z + height

    if shape == "wedge":
        def inside(p: np.ndarray, r: np.ndarray) -> np.ndarray:
            below_plane = (floor_z + height - t * (p[:, 0] - crest_x) - p[:, 2]) * cos_a >= r
            return below_plane & (p[:, 2] + r <= top)
    elif shape == "cone":
        def inside(p: np.ndarray, r: np.ndarray) -> np.ndarray:
            rho = np.hypot(p[:, 0] - xc, p[:, 1] - yc)
            return (top - t * rho - p[:, 2]) * cos_a >= r
    elif shape == "plane":
        def inside(p: np.ndarray, r: np.ndarray) -> np.ndarray:
            return (floor_z + 0.5 * height + t * (p[:, 0] - xc) - p[:, 2]) * cos_a >= r
    else:
        raise ValueError(f"shape must be 'wedge', 'cone' or 'plane', got {shape!r}")
    z_hi = top if shape != "plane" else floor_z + 0.5 * height + t * 0.5 * (x_range[1] - x_range[0])
    return lattice_fill(inside, (x_range, y_range, (floor_z, max(z_hi, floor_z + 2 * radius_range[1]))),
                        radius_range, rng=rng)


def synthetic_slope_image(
    angle_deg: float,
    *,
    size_px: tuple[int, int] = (480, 640),
    crest_col: float = 120.0,
    top_row: float = 120.0,
    floor_row: float = 420.0,
    background: float = 190.0,
    material: float = 60.0,
    noise_std: float = 0.0,
    gradient: float = 0.0,
    texture: float = 0.0,
    specks: float = 0.0,
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """Synthetic photograph of a pile with a known slope (uint8, H x W).

    Material (grey ``material``, dark) fills below a profile: a plateau at
    ``top_row`` for col < ``crest_col``, then a line falling at ``angle_deg``
    to the right down to ``floor_row``. ``gradient``: multiplicative lighting
    that falls linearly from 1 (left/top) to ``1 - gradient`` (right/bottom).
    ``texture``: amplitude (grey levels) of a structured background (stripes
    and blotches) and of the material's grain. ``specks``: dark dots (radius
    1-2 px, material grey) per 1000 background pixels, like dust or stray
    grains. ``noise_std``: Gaussian noise.
    """
    gen = np.random.default_rng(rng)
    hgt, wid = size_px
    rows, cols = np.mgrid[0:hgt, 0:wid].astype(np.float32)
    t = math.tan(math.radians(angle_deg))
    surface = np.clip(top_row + t * (cols - crest_col), top_row, floor_row)
    frac = np.clip(rows - surface + 0.5, 0.0, 1.0)  # partial-pixel coverage of the edge
    img = background * (1.0 - frac) + material * frac
    if texture > 0:
        stripes = np.sin(cols / 9.0 + 0.6 * np.sin(rows / 23.0)) * np.cos(rows / 31.0)
        blot = cv2.GaussianBlur(gen.normal(0, 1, (hgt, wid)).astype(np.float32), (0, 0), 6)
        blot /= blot.std() + 1e-9
        bg_tex = texture * (0.6 * stripes + 0.6 * blot)
        grain = cv2.GaussianBlur(gen.normal(0, 1, (hgt, wid)).astype(np.float32), (0, 0), 2)
        grain = texture * grain / (grain.std() + 1e-9)
        img = img + (1.0 - frac) * bg_tex + frac * 0.5 * grain
    if specks > 0:
        n = gen.poisson(specks * hgt * wid / 1000.0)
        dots = np.zeros((hgt, wid), np.float32)
        for c, r, rad in zip(gen.integers(0, wid, n), gen.integers(0, hgt, n), gen.integers(1, 3, n)):
            cv2.circle(dots, (int(c), int(r)), int(rad), 1.0, -1)
        img = img * (1.0 - dots) + material * dots
    if gradient:
        ramp = 0.5 * (cols / max(wid - 1, 1) + rows / max(hgt - 1, 1))
        img = img * (1.0 - gradient * ramp)
    if noise_std > 0:
        img = img + gen.normal(0, noise_std, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)
