"""The seed paper's five gravel shape classes as parametric meshes, and their clump templates.

Seed paper, Sec. 2.3.1: gravel is sorted into cone, prism, discoid, ellipsoid and sphere
classes (Table 3 number fractions), scanned, and filled with multi-sphere clumps at three
fill levels (Table 2 sphere counts). The scans are not published, so each class is
replaced by a parametric body whose volume V_R and sphericity Psi (eq. 14) reproduce
Table 4:

==========  ============================================================  ==========
class       body (one shape parameter solved for Psi, then scaled to V_R)  parameter
==========  ============================================================  ==========
cone        circular cone, apex and base rim blunted by a ball 0.05 R      H / R
prism       equilateral triangular prism, length = side, edges rounded     rho / side
discoid     flat disc with a fully rounded rim (disc ⊕ ball)               H / D
ellipsoid   triaxial ellipsoid, axes 1 : q : 0.75 q                        q
sphere      irregular sphere r(u) = 1 + eps g(u), g fixed smooth harmonics eps
==========  ============================================================  ==========

Table 4 is not self-consistent: its Psi column equals SA_es(V_m)/SA_rp, i.e. it uses the
*filled-model* volume V_m instead of the particle volume V_R (e.g. cone:
(36 pi 4540^2)^(1/3)/1709.8 = 0.775, whereas V_R = 4782 mm^3 gives 0.803). So V_R, SA_rp and
Psi cannot all be matched. ``basis="table"`` (default) matches V_R and the printed Psi
(the surface area then differs from SA_rp by 4-13 %); ``basis="scan"`` matches V_R and SA_rp,
i.e. Psi = (36 pi V_R^2)^(1/3) / SA_rp = 0.803, 0.820, 0.744, 0.892, 0.932.

The fills (:func:`gravel_fill`) bound every member radius below by
``warpdem.multisphere.DEFAULT_MIN_RADIUS_FRACTION`` (0.25) x the class's volume-equivalent
radius, i.e. >= 1.80 (discoid), 1.88 (sphere), 1.97 (ellipsoid), 2.61 (cone) and 2.87 mm
(prism): the smallest member sphere sets the DEM time step (Rayleigh time), and an
unbounded fill may leave a sub-millimetre member.

Meshes are in metres with the centroid at the origin. Rounded bodies are built exactly as
Minkowski sums: conv(union of balls at the vertices of a convex polytope) = polytope ⊕ ball.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import trimesh
from scipy.optimize import brentq

from .clump_geometry import ClumpTemplate
from .errors import ConfigError

__all__ = [
    "SHAPE_CLASSES",
    "TABLE4",
    "TABLE3_PERCENT",
    "FILL_LEVELS",
    "PAPER_MEDIUM_ERRORS",
    "ShapeSpec",
    "sphericity",
    "target_sphericity",
    "shape_mesh",
    "gravel_shape_mix",
    "gravel_templates",
    "gravel_fill",
]

SHAPE_CLASSES: tuple[str, ...] = ("cone", "prism", "discoid", "ellipsoid", "sphere")


@dataclass(frozen=True)
class ShapeSpec:
    """Seed-paper Table 4 row (SI units).

    Attributes: area_rp SA_rp [m^2], volume_r V_R [m^3], volume_m V_m [m^3] (paper's medium
    fill), psi Psi [-] as printed, volume_error_medium V_re [-] as printed (eq. 13).
    """

    area_rp: float
    volume_r: float
    volume_m: float
    psi: float
    volume_error_medium: float


#: Table 4 (mm^2 -> m^2, 10^3 mm^3 -> m^3, % -> fraction).
TABLE4: dict[str, ShapeSpec] = {
    "cone": ShapeSpec(1709.798e-6, 4.782e-6, 4.540e-6, 0.775, 0.0507),
    "prism": ShapeSpec(2027.787e-6, 6.373e-6, 6.839e-6, 0.859, 0.0730),
    "discoid": ShapeSpec(873.751e-6, 1.558e-6, 1.292e-6, 0.656, 0.1708),
    "ellipsoid": ShapeSpec(874.393e-6, 2.048e-6, 1.839e-6, 0.830, 0.1021),
    "sphere": ShapeSpec(758.346e-6, 1.767e-6, 1.844e-6, 0.959, 0.0436),
}
#: Table 3, number percentage of each class in a 1 L gravel sample.
TABLE3_PERCENT: dict[str, float] = {"cone": 18.61, "prism": 23.73, "discoid": 22.65,
                                    "ellipsoid": 18.11, "sphere": 16.90}
#: Table 2, spheres per clump at the low / medium / high fill levels.
FILL_LEVELS: dict[str, dict[str, int]] = {
    "low": {"cone": 5, "prism": 6, "discoid": 5, "ellipsoid": 8, "sphere": 5},
    "medium": {"cone": 24, "prism": 22, "discoid": 23, "ellipsoid": 22, "sphere": 25},
    "high": {"cone": 46, "prism": 42, "discoid": 44, "ellipsoid": 42, "sphere": 43},
}
#: Table 4, relative volume error of the paper's medium fill (eq. 13), fraction.
PAPER_MEDIUM_ERRORS: dict[str, float] = {k: v.volume_error_medium for k, v in TABLE4.items()}


def sphericity(mesh: trimesh.Trimesh) -> float:
    """Wadell sphericity, seed paper eq. 14: Psi = (36 pi V^2)^(1/3) / A  [-]."""
    return float((36.0 * math.pi * mesh.volume ** 2) ** (1.0 / 3.0) / mesh.area)


def target_sphericity(name: str, basis: str = "table") -> float:
    """Target Psi of class ``name``: Table 4 as printed ("table") or from V_R and SA_rp ("scan")."""
    spec = _spec(name)
    if basis == "table":
        return spec.psi
    if basis == "scan":
        return float((36.0 * math.pi * spec.volume_r ** 2) ** (1.0 / 3.0) / spec.area_rp)
    raise ConfigError(f"basis must be 'table' or 'scan', got {basis!r}")


def _spec(name: str) -> ShapeSpec:
    if name not in TABLE4:
        raise ConfigError(f"unknown shape class {name!r}; expected one of {SHAPE_CLASSES}")
    return TABLE4[name]


# ----------------------------------------------------------------------------------------
# parametric bodies (unit size; Psi depends on the single shape parameter only)
# ----------------------------------------------------------------------------------------
@lru_cache(maxsize=4)
def _ball_points(subdivisions: int) -> np.ndarray:
    return trimesh.creation.icosphere(subdivisions=subdivisions).vertices.copy()


def _rounded_hull(vertices: np.ndarray, rho: float, subdivisions: int = 2) -> trimesh.Trimesh:
    """Mesh of conv(vertices) ⊕ ball(rho) = convex hull of balls centred on the vertices."""
    pts = (vertices[:, None, :] + rho * _ball_points(subdivisions)[None]).reshape(-1, 3)
    return trimesh.convex.convex_hull(pts)


def _cone(h_over_r: float) -> trimesh.Trimesh:
    a = np.linspace(0.0, 2 * np.pi, 48, endpoint=False)
    rim = np.c_[np.cos(a), np.sin(a), np.zeros_like(a)]
    return _rounded_hull(np.vstack([rim, [[0.0, 0.0, h_over_r]]]), 0.05)


def _prism(rho_over_side: float) -> trimesh.Trimesh:
    tri = np.array([[1.0, 0.0], [-0.5, math.sqrt(3) / 2], [-0.5, -math.sqrt(3) / 2]]) / math.sqrt(3)
    v = np.vstack([np.c_[tri, np.zeros(3)], np.c_[tri, np.ones(3)]])   # side 1, length 1
    return _rounded_hull(v, rho_over_side, subdivisions=3)


def _discoid(h_over_d: float) -> trimesh.Trimesh:
    a = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
    h = 2.0 * h_over_d                                                  # D = 2
    rim = np.c_[np.cos(a), np.sin(a), np.zeros_like(a)] * (1.0 - h / 2)
    return _rounded_hull(rim, h / 2)


def _ellipsoid(q: float) -> trimesh.Trimesh:
    m = trimesh.creation.icosphere(subdivisions=3)
    m.apply_scale([1.0, q, 0.75 * q])
    return m


@lru_cache(maxsize=1)
def _bumps() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(20240611)
    dirs = rng.normal(size=(7, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    amps = rng.uniform(0.5, 1.0, 7) * rng.choice([-1.0, 1.0], 7)
    return dirs, amps


def _sphere(eps: float) -> trimesh.Trimesh:
    m = trimesh.creation.icosphere(subdivisions=3)
    u = m.vertices / np.linalg.norm(m.vertices, axis=1, keepdims=True)
    dirs, amps = _bumps()
    # smooth low-order relief: sum of P2/P3-like lobes, zero mean over the sphere
    cos = u @ dirs.T
    g = (amps * (1.5 * cos ** 2 - 0.5 + 0.6 * (2.5 * cos ** 3 - 1.5 * cos))).sum(axis=1)
    g /= np.abs(g).max()
    return trimesh.Trimesh(u * (1.0 + eps * g)[:, None], m.faces, process=False)


_BUILDERS = {
    "cone": (_cone, (0.6, 2.4)),       # lower (squat) branch of Psi(H/R), max Psi ~0.81 at H/R ~2.5
    "prism": (_prism, (0.0, 0.8)),
    "discoid": (_discoid, (0.05, 0.5)),
    "ellipsoid": (_ellipsoid, (0.2, 1.0)),
    "sphere": (_sphere, (0.0, 0.6)),
}


@lru_cache(maxsize=32)
def _solved(name: str, basis: str) -> tuple[float, trimesh.Trimesh]:
    build, (lo, hi) = _BUILDERS[name]
    psi_t = target_sphericity(name, basis)
    f = lambda x: sphericity(build(x)) - psi_t  # noqa: E731
    flo, fhi = f(lo), f(hi)
    if flo * fhi > 0:
        raise ConfigError(f"shape class {name!r}: target Psi={psi_t:.3f} outside the range "
                          f"[{min(flo, fhi) + psi_t:.3f}, {max(flo, fhi) + psi_t:.3f}] of its family")
    x = brentq(f, lo, hi, xtol=1e-6)
    m = build(x)
    m.apply_translation(-m.center_mass)
    m.apply_scale((_spec(name).volume_r / m.volume) ** (1.0 / 3.0))
    return x, m


def shape_mesh(name: str, basis: str = "table") -> trimesh.Trimesh:
    """Watertight mesh [m] of shape class ``name`` with volume V_R and sphericity from Table 4.

    ``basis``: "table" matches the printed Psi, "scan" matches the printed SA_rp (module doc).
    Returns a copy; the solved parameter is in ``mesh.metadata["shape_parameter"]``.
    """
    _spec(name)
    x, m = _solved(name, basis)
    out = m.copy()
    out.metadata["shape_class"] = name
    out.metadata["shape_parameter"] = x
    return out


def gravel_shape_mix() -> dict[str, float]:
    """Number fractions of the five classes (seed paper Table 3), summing to 1."""
    tot = sum(TABLE3_PERCENT.values())
    return {k: TABLE3_PERCENT[k] / tot for k in SHAPE_CLASSES}


def _fill_level_count(name: str, fill_level: str | int) -> int:
    if isinstance(fill_level, (int, np.integer)) and not isinstance(fill_level, bool):
        if fill_level < 1:
            raise ConfigError(f"fill level as a sphere count must be >= 1, got {fill_level}")
        return int(fill_level)
    if fill_level not in FILL_LEVELS:
        raise ConfigError(f"fill_level must be one of {tuple(FILL_LEVELS)} or a sphere count, got {fill_level!r}")
    return FILL_LEVELS[fill_level][name]


def gravel_fill(name: str, fill_level: str | int = "medium", basis: str = "table",
                min_radius_fraction: float | None = None):
    """Multi-sphere fill of one class: ``(ClumpTemplate at density 1 kg/m^3, FillReport)``. Cached.

    min_radius_fraction: lower bound on the member radii as a fraction of the class's
    volume-equivalent radius (None: ``fill_mesh``'s default, 0.25; 0: unbounded).
    ``FillReport.min_radius`` and ``FillReport.rayleigh_time_step()`` give the smallest
    member and the Rayleigh time step it implies.
    """
    from .multisphere import DEFAULT_MIN_RADIUS_FRACTION  # local import: multisphere imports nothing from here

    _spec(name)
    n = _fill_level_count(name, fill_level)
    frac = DEFAULT_MIN_RADIUS_FRACTION if min_radius_fraction is None else float(min_radius_fraction)
    return _gravel_fill(name, n, basis, frac)        # one cache entry however the arguments are spelt


@lru_cache(maxsize=64)
def _gravel_fill(name: str, n: int, basis: str, min_radius_fraction: float):
    from .multisphere import fill_mesh

    return fill_mesh(shape_mesh(name, basis), n, density=1.0, name=name, min_radius_fraction=min_radius_fraction)


def gravel_templates(fill_level: str | int = "medium", density: float = 2661.0,
                     basis: str = "table", min_radius_fraction: float | None = None) -> dict[str, ClumpTemplate]:
    """Clump templates of the five classes, keyed like :func:`gravel_shape_mix`.

    fill_level: "low" | "medium" | "high" (Table 2 counts per class) or a sphere count.
    density: particle density [kg/m^3] (seed paper Sec. 2.3.2: 2661).
    min_radius_fraction: see :func:`gravel_fill` (None: default bound, 0.25 r_eq).
    The fills are cached per (class, level, basis, bound) for the life of the process.
    """
    if not (density > 0 and math.isfinite(density)):
        raise ConfigError(f"gravel_templates: density must be > 0 kg/m^3, got {density}")
    return {k: gravel_fill(k, fill_level, basis, min_radius_fraction)[0].with_density(density)
            for k in SHAPE_CLASSES}
