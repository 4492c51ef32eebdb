"""Mass properties of multi-sphere clumps (union of overlapping spheres) and clump templates.

A clump template is what the DEM engine needs to build a rigid multi-sphere particle:
member sphere centres in the *principal body frame* (centre of mass at the origin, axes
along the principal axes of inertia), radii, total mass and principal moments of inertia.

Mass properties are those of the UNION of the spheres (overlaps counted once), not the
naive sum of the member spheres.

Method (``union_mass_properties``)
----------------------------------
The union of balls B_i is split exactly into the disjoint convex cells B_i ∩ P_i, where P_i
is the power (Laguerre) cell of sphere i, bounded by the radical planes with the spheres
that overlap it (Edelsbrunner 1995, "The union of balls and its dual shape", Discrete
Comput. Geom. 13:415-440). Each cell is convex, so it is star-shaped about an interior
point p (its centre c_i when well inside, otherwise a Chebyshev centre from a small LP),
with radial extent rho(u) = min(ball exit, plane exits) along direction u. The radial
integrals int_0^rho t^k dt are done analytically and only the 2-D angular integral is
numerical: Gauss-Legendre in cos(theta) x trapezoid in phi (``resolution`` = number of
polar nodes; 2*resolution azimuthal nodes). Consequences:

* a single sphere (or spheres that do not overlap) is integrated exactly (to round-off);
* overlapping spheres: the angular integrand is continuous with kinks along the cell
  edges, so the error falls roughly as resolution^-2. Measured for two spheres against
  the analytic lens formula and a 1-D reference integral of the axisymmetric union:
  relative volume / inertia errors 4e-7 ... 2e-4 at the default resolution 48
  (the worst case being two nearly concentric equal spheres), 1e-3 at resolution 16.
  ``MassProperties.volume_error`` reports |V(resolution) - V(resolution/2)|, a
  conservative estimate of the error of the returned volume.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy.optimize import linprog

from .errors import ConfigError

__all__ = [
    "ClumpTemplate",
    "MassProperties",
    "union_mass_properties",
    "principal_frame",
    "make_template",
    "lens_volume",
]


# ----------------------------------------------------------------------------------------
# input checks
# ----------------------------------------------------------------------------------------
def _check_spheres(centers, radii, what: str = "clump") -> tuple[np.ndarray, np.ndarray]:
    c = np.asarray(centers, dtype=np.float64)
    r = np.asarray(radii, dtype=np.float64)
    if c.ndim == 1 and c.size == 3:
        c = c.reshape(1, 3)
    r = np.atleast_1d(r)
    if c.ndim != 2 or c.shape[1] != 3:
        raise ConfigError(f"{what}: centers must have shape (n, 3), got {c.shape}")
    if r.ndim != 1:
        raise ConfigError(f"{what}: radii must have shape (n,), got {r.shape}")
    if c.shape[0] == 0:
        raise ConfigError(f"{what}: empty sphere list (need at least one sphere)")
    if r.shape[0] != c.shape[0]:
        raise ConfigError(f"{what}: {c.shape[0]} centers but {r.shape[0]} radii")
    if not np.all(np.isfinite(c)):
        raise ConfigError(f"{what}: centers contain NaN/inf (rows {np.where(~np.isfinite(c).all(1))[0].tolist()})")
    if not np.all(np.isfinite(r)):
        raise ConfigError(f"{what}: radii contain NaN/inf (indices {np.where(~np.isfinite(r))[0].tolist()})")
    if np.any(r <= 0):
        raise ConfigError(f"{what}: radii must be > 0 m, got {r[r <= 0].tolist()} at indices "
                          f"{np.where(r <= 0)[0].tolist()}")
    return c, r


def _check_density(density: float, what: str = "clump") -> float:
    d = float(density)
    if not (d > 0 and math.isfinite(d)):
        raise ConfigError(f"{what}: density must be > 0 kg/m^3, got {density}")
    return d


# ----------------------------------------------------------------------------------------
# analytic references
# ----------------------------------------------------------------------------------------
def lens_volume(r1: float, r2: float, d: float) -> float:
    """Volume [m^3] of the intersection (lens) of two balls of radii r1, r2 at distance d.

    V = pi (r1 + r2 - d)^2 (d^2 + 2 d (r1 + r2) - 3 (r1 - r2)^2) / (12 d)
    (Weisstein, "Sphere-Sphere Intersection", MathWorld, eq. 16). Handles the disjoint
    (0) and contained (smaller ball) cases.
    """
    if d >= r1 + r2:
        return 0.0
    if d <= abs(r1 - r2):
        return 4.0 / 3.0 * math.pi * min(r1, r2) ** 3
    return math.pi * (r1 + r2 - d) ** 2 * (d * d + 2 * d * (r1 + r2) - 3 * (r1 - r2) ** 2) / (12 * d)


# ----------------------------------------------------------------------------------------
# angular quadrature
# ----------------------------------------------------------------------------------------
@lru_cache(maxsize=16)
def _sphere_rule(n_theta: int) -> tuple[np.ndarray, np.ndarray]:
    """Directions (m,3) and weights (m,) summing to 4 pi: Gauss-Legendre(cos theta) x trapezoid(phi)."""
    mu, wmu = np.polynomial.legendre.leggauss(n_theta)
    n_phi = 2 * n_theta
    phi = (np.arange(n_phi) + 0.5) * (2 * np.pi / n_phi)
    s = np.sqrt(1.0 - mu * mu)
    u = np.stack([
        (s[:, None] * np.cos(phi)[None, :]).ravel(),
        (s[:, None] * np.sin(phi)[None, :]).ravel(),
        np.repeat(mu, n_phi),
    ], axis=1)
    w = np.repeat(wmu, n_phi) * (2 * np.pi / n_phi)
    # a fixed irrational tilt avoids aligning the rule's poles with the (often axis-aligned)
    # cell faces; it does not change exactness for polynomials of degree < n_theta.
    a, b = 0.4317, 0.2791
    ca, sa, cb, sb = math.cos(a), math.sin(a), math.cos(b), math.sin(b)
    rot = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]]) @ np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    u = u @ rot.T
    u.setflags(write=False)
    w.setflags(write=False)
    return u, w


def _interior_point(r: float, n: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, float]:
    """Interior point of {|y| <= r} ∩ {n_k . y <= h_k} (unit n_k) and its clearance [m].

    Returns the origin if it is well inside, else the Chebyshev centre of the half-spaces
    intersected with a polytope inscribed in the ball (LP).
    """
    if n.shape[0] == 0:
        return np.zeros(3), r
    clear0 = min(r, float(h.min()))
    if clear0 >= 0.25 * r:
        return np.zeros(3), clear0
    g, _ = _sphere_rule(4)  # 32 directions; inscribed polytope of the ball
    cos_half = 0.80  # conservative: facets at distance 0.8 r stay inside the ball
    A = np.vstack([np.hstack([n, np.ones((n.shape[0], 1))]),
                   np.hstack([g, np.ones((g.shape[0], 1))])])
    b = np.concatenate([h, np.full(g.shape[0], cos_half * r)])
    res = linprog(c=[0, 0, 0, -1.0], A_ub=A, b_ub=b,
                  bounds=[(-r, r)] * 3 + [(0, r)], method="highs")
    if res.status != 0 or res.x[3] <= 1e-12 * r:
        return np.zeros(3), 0.0
    return res.x[:3], float(res.x[3])


def _cell_moments(c: np.ndarray, r: float, n: np.ndarray, h: np.ndarray,
                  n_theta: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume, first moment (about c) and second moment (about c) of B(c,r) ∩ {n.y <= h}."""
    p, clearance = _interior_point(r, n, h)
    if clearance <= 0.0:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    u, w = _sphere_rule(n_theta)
    # exit distance from p through the ball |p + t u| = r
    b = u @ p
    t = -b + np.sqrt(np.maximum(b * b + r * r - p @ p, 0.0))
    if n.shape[0]:
        nu = u @ n.T                           # (m, k)
        gap = h - n @ p                        # (k,) > 0
        with np.errstate(divide="ignore"):
            tp = np.where(nu > 1e-300, gap[None, :] / nu, np.inf)
        t = np.minimum(t, tp.min(axis=1))
    t3, t4, t5 = w * t ** 3 / 3.0, w * t ** 4 / 4.0, w * t ** 5 / 5.0
    vol = t3.sum()
    s1 = u.T @ t4                              # int u t^3 dt dOmega
    s2 = (u * t5[:, None]).T @ u               # int u u^T t^4 dt dOmega
    first = p * vol + s1
    second = np.outer(p, p) * vol + np.outer(p, s1) + np.outer(s1, p) + s2
    return float(vol), first, second


def _drop_contained(c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Indices of spheres not contained in another sphere (duplicates keep the first)."""
    d = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=2)
    tol = 1e-12 * r.max()
    keep = np.ones(len(r), dtype=bool)
    for i in range(len(r)):
        inside = (d[i] + r[i] <= r + tol)
        inside[i] = False
        # identical spheres: keep the lower index only
        same = inside & (np.abs(r - r[i]) <= tol) & (d[i] <= tol)
        inside &= ~(same & (np.arange(len(r)) > i))
        if np.any(inside):
            keep[i] = False
    return np.where(keep)[0]


def _union_moments(c: np.ndarray, r: np.ndarray, n_theta: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume, first and second moment (about the origin of the input frame) of the union."""
    idx = _drop_contained(c, r)
    c, r = c[idx], r[idx]
    vol, first, second = 0.0, np.zeros(3), np.zeros((3, 3))
    for i in range(len(r)):
        d = c - c[i]
        dist = np.linalg.norm(d, axis=1)
        nb = np.where((dist < r + r[i]) & (np.arange(len(r)) != i))[0]
        if nb.size:
            dn = dist[nb]
            n = d[nb] / dn[:, None]
            # radical plane of spheres i, k in coordinates y = x - c_i:
            # |y|^2 - r_i^2 <= |y - d|^2 - r_k^2  <=>  n.y <= (|d|^2 + r_i^2 - r_k^2) / (2|d|)
            h = (dn ** 2 + r[i] ** 2 - r[nb] ** 2) / (2 * dn)
        else:
            n, h = np.zeros((0, 3)), np.zeros(0)
        v, f, s = _cell_moments(c[i], r[i], n, h, n_theta)
        # shift moments from the cell frame (origin c_i) to the input frame
        vol += v
        first += f + c[i] * v
        second += s + np.outer(c[i], f) + np.outer(f, c[i]) + np.outer(c[i], c[i]) * v
    return vol, first, second


# ----------------------------------------------------------------------------------------
# public API
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MassProperties:
    """Mass properties of a homogeneous body, in the frame of the input coordinates.

    Attributes:
        volume: V [m^3].
        mass: m = density V [kg].
        com: centre of mass (3,) [m].
        inertia: inertia tensor about the centre of mass (3,3) [kg m^2].
        volume_error: estimated absolute quadrature error of ``volume`` [m^3] (0 when exact).
    """

    volume: float
    mass: float
    com: np.ndarray
    inertia: np.ndarray
    volume_error: float


def union_mass_properties(centers, radii, density: float = 1.0, resolution: int = 48) -> MassProperties:
    """Volume [m^3], centre of mass [m] and inertia tensor [kg m^2] of a UNION of spheres.

    Args:
        centers: (n,3) sphere centres [m].
        radii: (n,) radii [m] (> 0).
        density: [kg/m^3].
        resolution: polar Gauss-Legendre nodes of the angular rule (>= 8). Exact for
            non-overlapping spheres; for overlaps the relative error is <~1e-3 at 24 and
            <~2e-4 at 48 (see module docstring); ``volume_error`` gives an estimate.

    Cost: O(n * k * resolution^2) with k the mean number of overlapping neighbours
    (25 random overlapping spheres, resolution 48: ~50 ms, both passes).
    """
    c, r = _check_spheres(centers, radii, "union_mass_properties")
    rho = _check_density(density, "union_mass_properties")
    if int(resolution) < 8:
        raise ConfigError(f"union_mass_properties: resolution must be >= 8, got {resolution}")
    n_theta = int(resolution)
    # centre the coordinates for round-off (moments about a nearby point)
    shift = c.mean(axis=0)
    cs = c - shift
    vol, first, second = _union_moments(cs, r, n_theta)
    vol_coarse, _, _ = _union_moments(cs, r, max(4, n_theta // 2))
    com_local = first / vol
    # second moment about the COM, S = int (x-com)(x-com)^T dV;  I = tr(S) E - S
    S = second - vol * np.outer(com_local, com_local)
    S = 0.5 * (S + S.T)
    inertia = rho * (np.trace(S) * np.eye(3) - S)
    return MassProperties(volume=float(vol), mass=float(rho * vol), com=com_local + shift,
                          inertia=inertia, volume_error=float(abs(vol - vol_coarse)))


def principal_frame(inertia) -> tuple[np.ndarray, np.ndarray]:
    """Principal moments (3,) [kg m^2], ascending, and rotation R (3,3), det R = +1.

    Columns of R are the principal axes expressed in the input frame, so that
    inertia = R diag(moments) R^T and body coordinates are x_body = R^T (x - com).
    Axis signs are made deterministic: the largest component of axes 1 and 2 is positive,
    axis 3 = axis 1 x axis 2.
    """
    I = np.asarray(inertia, dtype=np.float64)
    if I.shape != (3, 3) or not np.all(np.isfinite(I)):
        raise ConfigError(f"principal_frame: inertia must be a finite (3,3) array, got shape {I.shape}")
    I = 0.5 * (I + I.T)
    moments, R = np.linalg.eigh(I)
    for k in range(2):
        j = np.argmax(np.abs(R[:, k]))
        if R[j, k] < 0:
            R[:, k] = -R[:, k]
    R[:, 2] = np.cross(R[:, 0], R[:, 1])
    return moments, R


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class ClumpTemplate:
    """Rigid multi-sphere particle in its principal body frame (SI units).

    Attributes:
        name: label (e.g. shape class).
        centers: (n,3) member sphere centres [m] in the body frame (COM at origin,
            axes = principal axes of inertia).
        radii: (n,) member radii [m].
        density: [kg/m^3].
        volume: volume of the union of the spheres [m^3].
        mass: density * volume [kg].
        inertia_principal: (3,) principal moments about the COM [kg m^2], ascending.
        rotation: (3,3) proper rotation whose columns are the body axes in the input frame.
        offset: (3,) the COM in the input frame [m]. Input -> body:
            x_body = rotation^T (x_in - offset);  body -> input: x_in = rotation x_body + offset.
        volume_error: estimated quadrature error of ``volume`` [m^3].
    """

    name: str
    centers: np.ndarray
    radii: np.ndarray
    density: float
    volume: float
    mass: float
    inertia_principal: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: _readonly(np.eye(3)))
    offset: np.ndarray = field(default_factory=lambda: _readonly(np.zeros(3)))
    volume_error: float = 0.0

    def __post_init__(self) -> None:
        c, r = _check_spheres(self.centers, self.radii, f"ClumpTemplate '{self.name}'")
        _check_density(self.density, f"ClumpTemplate '{self.name}'")
        for nm in ("volume", "mass"):
            v = getattr(self, nm)
            if not (v > 0 and math.isfinite(v)):
                raise ConfigError(f"ClumpTemplate '{self.name}': {nm} must be > 0, got {v}")
        ip = np.asarray(self.inertia_principal, dtype=np.float64)
        if ip.shape != (3,) or not np.all(np.isfinite(ip)) or np.any(ip <= 0):
            raise ConfigError(f"ClumpTemplate '{self.name}': inertia_principal must be 3 positive "
                              f"finite values [kg m^2], got {self.inertia_principal}")
        if ip.sum() - 2 * ip.max() < -1e-9 * ip.max():
            raise ConfigError(f"ClumpTemplate '{self.name}': principal moments {ip.tolist()} violate the "
                              f"triangle inequality I1 + I2 >= I3")
        R = np.asarray(self.rotation, dtype=np.float64)
        if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
            raise ConfigError(f"ClumpTemplate '{self.name}': rotation must be a proper rotation matrix")
        object.__setattr__(self, "centers", _readonly(c))
        object.__setattr__(self, "radii", _readonly(r))
        object.__setattr__(self, "inertia_principal", _readonly(ip))
        object.__setattr__(self, "rotation", _readonly(R))
        object.__setattr__(self, "offset", _readonly(np.asarray(self.offset, dtype=np.float64).reshape(3)))
        object.__setattr__(self, "density", float(self.density))
        object.__setattr__(self, "volume", float(self.volume))
        object.__setattr__(self, "mass", float(self.mass))

    @property
    def n_spheres(self) -> int:
        """Number of member spheres."""
        return int(self.radii.shape[0])

    @property
    def equivalent_radius(self) -> float:
        """Radius of the sphere of equal volume, (3V/4pi)^(1/3) [m]."""
        return (3.0 * self.volume / (4.0 * math.pi)) ** (1.0 / 3.0)

    @property
    def bounding_radius(self) -> float:
        """max |c_i| + r_i [m]: radius of the body-frame sphere enclosing the clump."""
        return float(np.max(np.linalg.norm(self.centers, axis=1) + self.radii))

    def with_density(self, density: float) -> "ClumpTemplate":
        """Same geometry at another density: mass and inertia scale linearly."""
        rho = _check_density(density, f"ClumpTemplate '{self.name}'")
        f = rho / self.density
        return ClumpTemplate(self.name, self.centers, self.radii, rho, self.volume, self.mass * f,
                             self.inertia_principal * f, self.rotation, self.offset, self.volume_error)


def make_template(centers, radii, density: float, name: str = "clump",
                  resolution: int = 48) -> ClumpTemplate:
    """Build a :class:`ClumpTemplate` from spheres given in any frame [m], density [kg/m^3].

    Computes the union mass properties, then moves the spheres into the principal frame:
    x_body = R^T (x - com).
    """
    c, r = _check_spheres(centers, radii, f"make_template '{name}'")
    mp = union_mass_properties(c, r, density, resolution)
    moments, R = principal_frame(mp.inertia)
    body = (c - mp.com) @ R
    return ClumpTemplate(name=name, centers=body, radii=r, density=float(density), volume=mp.volume,
                         mass=mp.mass, inertia_principal=moments, rotation=R, offset=mp.com,
                         volume_error=mp.volume_error)
