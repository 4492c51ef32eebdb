"""Fast multi-sphere fill of a closed triangle mesh (seed paper Sec. 2.3.1, eqs. 13-14).

Algorithm (``fill_mesh``)
-------------------------
1. Sample a stratified (jittered-grid) point set in the padded bounding box. Points lie on
   vertical columns; each column is classified inside/outside exactly by the parity of its
   crossings with the mesh (one ray per column), so 10^5 points cost ~0.1 s.
2. Medial-axis seeds: interior sample points with their inscribed radius = distance to the
   surface (k-d tree on a dense surface sample).
3. Greedy: repeatedly take the seed ball that most reduces the symmetric difference
   (newly covered interior volume minus newly covered outside volume, on the sample
   points), until ``n_spheres`` are placed. Seeds whose inscribed radius is below the
   radius bound r_b (see below) are offered inflated to r_b (they then protrude and pay
   for the outside volume), so no ball below the bound is ever chosen.
4. Refinement: centres and radii are optimised together (L-BFGS) to minimise the symmetric
   difference |U Δ M| = |U \\ M| + |M \\ U| between the sphere union U and the mesh solid M,
   estimated on the sample points with a sigmoid indicator of width h then h/2 (h: point
   spacing), plus (``match_volume``) a penalty on the volume mismatch. Spheres may
   therefore protrude out of the mesh where that trades missing volume for less outside
   volume; the report gives the outside and missing fractions and the largest protrusion.
5. ``match_volume`` (default): all radii are scaled by one factor k (brentq, typically
   |k - 1| < 2 %) so that the clump volume equals the mesh volume, i.e. the clump has the
   particle's mass. The relative volume error of eq. 13 is then ~0 by construction and the
   shape fidelity is measured by the symmetric difference, which the report always gives.
   With ``match_volume=False`` eq. 13 measures the unconstrained best fit.

Smallest sphere
---------------
The DEM time step scales with the smallest member radius (Rayleigh time
T_R = pi R sqrt(rho/G) / (0.1631 nu + 0.8766), :func:`rayleigh_time_step`), so one tiny
member makes a whole simulation of such clumps 10-30x more expensive. As in commercial
fillers, every radius is bounded below: r_i >= r_b in the greedy step (above), in the
joint optimisation (a bound of the L-BFGS) and in the volume match (radii at the bound
stay there; the others are scaled). By default r_b = ``DEFAULT_MIN_RADIUS_FRACTION`` (0.25)
x the mesh's volume-equivalent radius r_eq = (3 V_R / 4 pi)^(1/3), i.e. 1.8-2.9 mm for the
seed paper's gravel (Table 4); ``min_radius`` [m] sets an absolute bound instead (both:
the larger). Without a bound the only floor is the optimiser's half sample spacing
(~0.27 mm for the paper's discoid), which a redundant member can collapse onto. Where the
bound forces the balls to protrude (parts thinner than 2 r_b) and their union at the bound
still exceeds V_R, the optimiser is re-run with a lowered volume target and a stronger
volume weight (its soft volume runs below the exact union volume). The requested sphere
count is always honoured: members that the optimiser parks inside the others (they add no
shape) are counted in ``n_redundant`` and named in ``notes``, as is a volume that cannot
be matched under the bound.

The reported clump volume V_m is that of the union of spheres (``union_mass_properties``,
error ~1e-4) and V_R is the exact mesh volume, so eq. 13 is not a sampling estimate. The
outside / missing fractions are estimated on a second, independent point sample (the
optimiser's own sample would flatter the fit), to about ±0.5 % of V_R.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from scipy.optimize import brentq, line_search
from scipy.spatial import cKDTree

from .clump_geometry import ClumpTemplate, make_template, union_mass_properties
from .errors import ConfigError
from .timestep import rayleigh_time

try:  # not re-exported by scipy.optimize
    from scipy.optimize._linesearch import LineSearchWarning
except ImportError:  # pragma: no cover
    LineSearchWarning = RuntimeWarning

__all__ = ["FillReport", "fill_mesh", "clump_from_file", "check_mesh", "relative_volume_error",
           "sphericity", "rayleigh_time_step", "DEFAULT_MIN_RADIUS_FRACTION"]

#: Default lower bound on member radii, as a fraction of the volume-equivalent radius.
DEFAULT_MIN_RADIUS_FRACTION = 0.25


def rayleigh_time_step(radius: float, density: float = 2661.0, youngs_modulus: float = 1.0e7,
                       poisson: float = 0.3) -> float:
    """Rayleigh time step T_R = pi R sqrt(rho / G) / (0.1631 nu + 0.8766) [s], G = E / (2 (1 + nu)).

    EDEM's "Rayleigh time step" of a sphere of ``radius`` [m]; the DEM step is a fraction of
    it (warpdem's ``time_step_limits`` recommends 0.2 T_R of the smallest sphere). Defaults:
    the seed paper's gravel (rho 2661 kg/m^3, E 1e7 Pa, nu 0.3).
    """
    if not (radius > 0 and density > 0 and youngs_modulus > 0 and -1.0 < poisson < 0.5):
        raise ConfigError(f"rayleigh_time_step: need radius, density, youngs_modulus > 0 and -1 < poisson < 0.5; "
                          f"got {radius}, {density}, {youngs_modulus}, {poisson}")
    return rayleigh_time(radius, density, youngs_modulus / (2.0 * (1.0 + poisson)), poisson)


@dataclass(frozen=True)
class FillReport:
    """Quality of a multi-sphere fill (SI units).

    Attributes:
        n_spheres: spheres in the clump.
        mesh_volume: V_R, volume of the mesh [m^3].
        mesh_area: SA_rp, area of the mesh [m^2].
        sphericity: Psi of the mesh, eq. 14 with V = V_R [-].
        clump_volume: V_m, volume of the union of spheres [m^3].
        volume_error: relative volume error |V_m - V_R| / V_R, eq. 13 [-] (fraction, not %).
        outside_fraction: |U \\ M| / V_R, clump volume outside the mesh [-] (sampled).
        missing_fraction: |M \\ U| / V_R, mesh volume not covered [-] (sampled).
        max_protrusion: largest distance a sphere reaches outside the mesh surface [m].
        radius_scale: factor applied to the radii to match V_m = V_R (1.0 if not matched;
            radii held at the bound are not scaled below it).
        time_s: wall-clock time of the fill [s].
        min_radius: smallest member radius [m] (>= radius_bound).
        max_radius: largest member radius [m].
        radius_bound: lower bound r_b imposed on the radii [m] (0: none).
        n_redundant: members lying (almost) entirely inside the others (exclusive volume
            < 0.5 % of their own): kept to honour ``n_spheres``, but they add no shape.
        notes: human-readable warnings (redundant members, volume not matchable, ...).
    """

    n_spheres: int
    mesh_volume: float
    mesh_area: float
    sphericity: float
    clump_volume: float
    volume_error: float
    outside_fraction: float
    missing_fraction: float
    max_protrusion: float
    radius_scale: float
    time_s: float
    min_radius: float = math.nan
    max_radius: float = math.nan
    radius_bound: float = 0.0
    n_redundant: int = 0
    notes: tuple[str, ...] = ()

    @property
    def symmetric_difference(self) -> float:
        """|U Δ M| / V_R [-] (>= volume_error)."""
        return self.outside_fraction + self.missing_fraction

    def rayleigh_time_step(self, density: float = 2661.0, youngs_modulus: float = 1.0e7,
                           poisson: float = 0.3) -> float:
        """Rayleigh time step [s] of the smallest member for a material (default: the paper's gravel)."""
        return rayleigh_time_step(self.min_radius, density, youngs_modulus, poisson)


def relative_volume_error(v_model: float, v_real: float) -> float:
    """Seed paper eq. 13: |V_m - V_R| / V_R [-] (fraction)."""
    return abs(v_model - v_real) / v_real


def sphericity(volume: float, area: float) -> float:
    """Seed paper eq. 14: Psi = SA_es / SA_rp = (36 pi V^2)^(1/3) / A [-]."""
    return (36.0 * math.pi * volume ** 2) ** (1.0 / 3.0) / area


def check_mesh(mesh: trimesh.Trimesh, what: str = "mesh") -> None:
    """Raise ConfigError unless ``mesh`` is a closed, consistently wound solid of positive volume."""
    if not isinstance(mesh, trimesh.Trimesh):
        raise ConfigError(f"{what}: expected a trimesh.Trimesh, got {type(mesh).__name__}")
    if len(mesh.faces) < 4:
        raise ConfigError(f"{what}: has {len(mesh.faces)} faces; a closed solid needs at least 4")
    if not np.all(np.isfinite(mesh.vertices)):
        raise ConfigError(f"{what}: vertices contain NaN/inf")
    if not mesh.is_watertight:
        from trimesh.grouping import group_rows
        n_open = len(group_rows(mesh.edges_sorted, require_count=1))
        raise ConfigError(f"{what}: mesh is not watertight ({n_open} boundary edges, i.e. holes); "
                          f"repair it first (e.g. trimesh.repair.fill_holes) -- its volume is undefined")
    if not mesh.is_winding_consistent:
        raise ConfigError(f"{what}: face winding is inconsistent (trimesh.repair.fix_winding)")
    if not mesh.volume > 0:
        raise ConfigError(f"{what}: volume {mesh.volume:g} <= 0 (inverted normals? trimesh.repair.fix_inversion)")


# ----------------------------------------------------------------------------------------
# sampling
# ----------------------------------------------------------------------------------------
def _column_crossings(tri: np.ndarray, xy: np.ndarray) -> list[np.ndarray]:
    """Sorted z of the crossings of vertical lines through ``xy`` (m,2) with triangles (f,3,3)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = b[:, :2] - a[:, :2], c[:, :2] - a[:, :2]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok = np.abs(det) > 1e-300
    a, b, c, e1, e2, det = a[ok], b[ok], c[ok], e1[ok], e2[ok], det[ok]
    lo = np.minimum(np.minimum(a[:, :2], b[:, :2]), c[:, :2])
    hi = np.maximum(np.maximum(a[:, :2], b[:, :2]), c[:, :2])
    out: list[np.ndarray] = [None] * len(xy)  # type: ignore[list-item]
    chunk = max(1, 2_000_000 // max(1, len(a)))
    for s in range(0, len(xy), chunk):
        p = xy[s:s + chunk]
        inbox = np.all((p[:, None, :] >= lo[None]) & (p[:, None, :] <= hi[None]), axis=2)
        ci, fi = np.nonzero(inbox)
        d = p[ci] - a[fi, :2]
        u = (d[:, 0] * e2[fi, 1] - d[:, 1] * e2[fi, 0]) / det[fi]
        v = (e1[fi, 0] * d[:, 1] - e1[fi, 1] * d[:, 0]) / det[fi]
        hit = (u >= 0) & (v >= 0) & (u + v <= 1)
        ci, fi, u, v = ci[hit], fi[hit], u[hit], v[hit]
        z = a[fi, 2] + u * (b[fi, 2] - a[fi, 2]) + v * (c[fi, 2] - a[fi, 2])
        order = np.lexsort((z, ci))
        ci, z = ci[order], z[order]
        split = np.searchsorted(ci, np.arange(len(p) + 1))
        for k in range(len(p)):
            out[s + k] = z[split[k]:split[k + 1]]
    return out


@dataclass
class _Samples:
    points: np.ndarray    # (N,3) normalised coordinates
    inside: np.ndarray    # (N,) bool
    weight: float         # volume per point (normalised units)
    spacing: float


def _inside(mesh: trimesh.Trimesh, pts: np.ndarray) -> np.ndarray:
    """Exact inside test by ray parity along +z (one column per point)."""
    out = np.zeros(len(pts), dtype=bool)
    for k, z in enumerate(_column_crossings(mesh.triangles, pts[:, :2])):
        out[k] = (np.searchsorted(z, pts[k, 2]) % 2) == 1
    return out


def _sample(mesh: trimesh.Trimesh, n_points: int, rng: np.random.Generator, lo: np.ndarray,
            hi: np.ndarray) -> _Samples:
    """Jittered grid of ~n_points in the box [lo, hi], classified inside/outside ``mesh``."""
    ext = hi - lo
    h = (np.prod(ext) / n_points) ** (1.0 / 3.0)
    nx, ny, nz = (max(2, int(round(e / h))) for e in ext)
    hx, hy, hz = ext[0] / nx, ext[1] / ny, ext[2] / nz
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    xy = np.c_[lo[0] + (ix.ravel() + rng.random(ix.size)) * hx, lo[1] + (iy.ravel() + rng.random(iy.size)) * hy]
    cross = _column_crossings(mesh.triangles, xy)
    zc = lo[2] + (np.arange(nz)[None, :] + rng.random((len(xy), nz))) * hz      # (m, nz)
    inside = np.zeros((len(xy), nz), dtype=bool)
    valid = np.ones(len(xy), dtype=bool)
    for k, z in enumerate(cross):
        if len(z) % 2:            # ray grazed an edge/vertex: drop the column
            valid[k] = False
        elif len(z):
            inside[k] = (np.searchsorted(z, zc[k]) % 2) == 1
    pts = np.stack([np.repeat(xy[valid, 0], nz), np.repeat(xy[valid, 1], nz), zc[valid].ravel()], axis=1)
    return _Samples(pts, inside[valid].ravel(), hx * hy * hz, float(h))


# ----------------------------------------------------------------------------------------
# greedy medial-axis seeding
# ----------------------------------------------------------------------------------------
def _sqdist(p: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(len(p), len(c)) squared distances, float32, elementwise (no BLAS threads)."""
    p32, c32 = p.astype(np.float32), c.astype(np.float32)
    out = np.zeros((len(p), len(c)), dtype=np.float32)
    for k in range(3):
        d = p32[:, k, None] - c32[None, :, k]
        out += d * d
    return out


def _greedy(cand: np.ndarray, crad: np.ndarray, pin: np.ndarray, n: int, pout: np.ndarray | None = None,
            r_bound: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Pick ``n`` candidate balls, each reducing the sampled symmetric difference the most.

    Candidate radii are max(inscribed radius, r_bound). Inscribed balls cover no outside
    volume; an inflated ball (inscribed radius < r_bound) also counts the not-yet-covered
    points of ``pout`` (outside points near the surface, sampled at the density of ``pin``)
    against it, and is only taken when no inscribed ball of radius >= r_bound still covers
    new interior (thin parts, or every inscribed ball used). Without inflated candidates
    this is "cover the most uncovered interior".
    """
    rad = np.maximum(crad, r_bound)
    cover = _sqdist(pin, cand) <= (rad * rad)[None, :]        # (N_in, n_cand) bool
    covered = np.zeros(len(pin), dtype=bool)
    gain = cover.sum(0).astype(np.float64)
    infl = np.nonzero(crad < r_bound)[0]
    use_out = len(infl) > 0 and pout is not None and len(pout) > 0
    if use_out:
        cover_out = _sqdist(pout, cand[infl]) <= (rad[infl] ** 2)[None, :]    # (N_out, n_infl)
        covered_out = np.zeros(len(pout), dtype=bool)
        gain[infl] -= cover_out.sum(0)
        col = np.full(len(cand), -1)
        col[infl] = np.arange(len(infl))
    chosen: list[int] = []
    fit = crad >= r_bound
    for _ in range(n):
        score = gain + 1e-9 * rad                              # ties: larger ball
        if chosen:
            score[chosen] = -np.inf
        if len(infl) and np.any(score[fit] > 0.5):             # an inscribed ball still helps
            score[infl] = -np.inf
        j = int(np.argmax(score))
        chosen.append(j)
        new = cover[:, j] & ~covered
        if new.any():
            gain -= cover[new].sum(0)
            covered |= new
        if use_out and col[j] >= 0:
            new_o = cover_out[:, col[j]] & ~covered_out
            if new_o.any():
                gain[infl] += cover_out[new_o].sum(0)            # already paid for
                covered_out |= new_o
    idx = np.array(chosen)
    return cand[idx].copy(), rad[idx].copy()


# ----------------------------------------------------------------------------------------
# refinement: minimise the sampled symmetric difference
# ----------------------------------------------------------------------------------------
def _objective(x: np.ndarray, pts: np.ndarray, nbr: np.ndarray, sgn: np.ndarray, w: float, eps: float,
               n: int, mu: float, v_target: float, box_lo: np.ndarray, box_hi: np.ndarray):
    """Soft symmetric difference (+ optional volume penalty) and its gradient.

    J = sum_k w [in_k (1 - s_k) + out_k s_k] + mu (V_s - V_R)^2 / V_R + B,
    s_k = sigmoid(u_k / eps), u_k = max_i (r_i - |p_k - c_i|), V_s = sum_k w s_k.
    The max runs over the K candidate spheres ``nbr[k]`` of each point (see ``_refine``).
    B = 10 sum_i pi r_i |overhang_i|^2 penalises balls reaching beyond the sampled box
    (there are no sample points there to count the outside volume).
    """
    cx, cy, cz, r = x[0:3 * n:3], x[1:3 * n:3], x[2:3 * n:3], x[3 * n:]
    px, py, pz = pts                                           # (3, N) coordinate rows
    dx, dy, dz = px[:, None] - cx[nbr], py[:, None] - cy[nbr], pz[:, None] - cz[nbr]   # (N,K)
    dist = np.sqrt(dx * dx + dy * dy + dz * dz) + 1e-12
    u_all = r[nbr] - dist
    j = np.argmax(u_all, axis=1)
    rows = np.arange(len(px))
    a = nbr[rows, j]
    # curvature correction: a soft ball of radius r holds the volume of a hard ball of
    # radius r + (pi^2/3) eps^2 / r (Sommerfeld expansion of int sigmoid((r - rho)/eps) 4 pi rho^2
    # d rho); shifting u by that amount makes the optimum unbiased for the hard union
    shift = _BETA * eps * eps / r[a]
    u = u_all[rows, j] - shift
    s = 0.5 * (1.0 + np.tanh(0.5 * u / eps))                  # sigmoid, overflow-free
    ds = s * (1.0 - s) / eps
    J = w * float((sgn * s).sum())                             # sgn: +1 outside, -1 inside
    g_u = w * sgn * ds
    if mu > 0.0:
        dv = w * float(s.sum()) - v_target
        J += mu * dv * dv / v_target
        g_u = g_u + (2.0 * mu * dv / v_target) * w * ds
    gr = np.bincount(a, weights=g_u * (1.0 + shift / r[a]), minlength=n)   # d(shift)/dr = -shift/r
    coef = g_u / dist[rows, j]                                 # d u / d c_a = (p - c_a) / |p - c_a|
    gc = np.stack([np.bincount(a, weights=coef * dd[rows, j], minlength=n) for dd in (dx, dy, dz)], axis=1)
    c = x[:3 * n].reshape(n, 3)
    over_hi = np.maximum(c + r[:, None] - box_hi, 0.0)
    over_lo = np.maximum(box_lo - (c - r[:, None]), 0.0)
    if over_hi.any() or over_lo.any():
        kb = 10.0 * math.pi * r[:, None]
        J += float((kb * (over_hi ** 2 + over_lo ** 2)).sum())
        gc += 2.0 * kb * (over_hi - over_lo)
        gr += (2.0 * kb * (over_hi + over_lo)).sum(1) + 10.0 * math.pi * (over_hi ** 2 + over_lo ** 2).sum(1)
    return J, np.concatenate([gc.ravel(), gr])


def _lbfgs(fg, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, maxiter: int, step0: float,
           m: int = 10, ftol: float = 1e-9) -> np.ndarray:
    """L-BFGS (two-loop recursion, strong-Wolfe ``scipy.optimize.line_search``), box by clipping.

    Plain numpy on purpose: scipy's L-BFGS-B calls BLAS in every iteration, and with OpenBLAS
    threads on a busy machine that costs ~10 ms per iteration (100x the objective here).
    Bounds: variables at a bound whose gradient points out of the box are held fixed for
    the step (their components of the gradient and of the direction are zeroed), so a
    radius resting on the lower radius bound does not clip -- and reset -- every step; when
    a step is clipped nevertheless, the curvature history is reset.
    """
    cache: dict[bytes, tuple[float, np.ndarray]] = {}

    def ev(z: np.ndarray) -> tuple[float, np.ndarray]:
        key = z.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = fg(z)
        return cache[key]

    x = np.clip(x0, lo, hi)
    f, g = ev(x)
    f_old = f + 0.5 * step0 * float(np.linalg.norm(g))     # sets the first trial step ~ step0
    S: list[np.ndarray] = []
    Y: list[np.ndarray] = []
    for _ in range(maxiter):
        held = ((x <= lo) & (g > 0.0)) | ((x >= hi) & (g < 0.0))
        gf = np.where(held, 0.0, g)
        gnorm = float(np.linalg.norm(gf))
        if gnorm == 0.0:
            break
        q, hist = gf.copy(), []
        for s_, y_ in zip(reversed(S), reversed(Y)):
            rho = 1.0 / float(np.dot(y_, s_))
            a = rho * float(np.dot(s_, q))
            q -= a * y_
            hist.append((a, rho, s_, y_))
        d = q * (float(np.dot(S[-1], Y[-1]) / np.dot(Y[-1], Y[-1])) if S else step0 / gnorm)
        for a, rho, s_, y_ in reversed(hist):
            d += s_ * (a - rho * float(np.dot(y_, d)))
        d = -d
        d[held] = 0.0
        if float(np.dot(d, g)) >= 0.0:                      # lost descent: steepest descent
            S.clear(), Y.clear()
            d = -gf * (step0 / gnorm)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LineSearchWarning)
            alpha, _, _, fn, _, gn = line_search(lambda z: ev(z)[0], lambda z: ev(z)[1], x, d, g, f, f_old,
                                                 c2=0.9, maxiter=20)
        if alpha is None:                                    # line search failed
            if S:
                S.clear(), Y.clear()
                continue
            break
        xn = x + alpha * d
        xc = np.clip(xn, lo, hi)
        if not np.array_equal(xc, xn):
            xn = xc
            fn, gn = ev(xn)
            S.clear(), Y.clear()
        else:
            if gn is None:
                gn = ev(xn)[1]
            s_, y_ = xn - x, gn - g
            if float(np.dot(s_, y_)) > 1e-12 * float(np.dot(y_, y_)):
                S.append(s_), Y.append(y_)
                if len(S) > m:
                    S.pop(0), Y.pop(0)
        done = (f - fn) <= ftol * max(abs(f), 1e-30)
        f_old, x, f, g = f, xn, fn, gn
        if done:
            break
    return x


_BETA = math.pi ** 2 / 3.0
_EPS_SCHEDULE = (1.0, 0.5)   # sigmoid widths in units of the point spacing (wider ones spoil the fit)


def _refine(c: np.ndarray, r: np.ndarray, smp: _Samples, lo: np.ndarray, hi: np.ndarray,
            r_min: float, r_max: float, iters: int, mu: float, v_target: float,
            k_nbr: int = 6, restart: int = 15) -> tuple[np.ndarray, np.ndarray]:
    """L-BFGS on centres and radii; sigmoid width annealed over ``_EPS_SCHEDULE`` x point spacing.

    Each point only sees its ``k_nbr`` spheres of largest u, re-selected every ``restart``
    iterations (exact unless a sphere overtakes k_nbr others within a restart).
    """
    n = len(r)
    sgn = np.where(smp.inside, -1.0, 1.0)
    pts = smp.points
    pts_t = np.ascontiguousarray(pts.T)
    x = np.concatenate([c.ravel(), r])
    lo_b = np.concatenate([np.tile(lo, n), np.full(n, r_min)])
    hi_b = np.concatenate([np.tile(hi, n), np.full(n, r_max)])
    k_nbr = min(k_nbr, n)
    n_rounds = max(1, int(math.ceil(iters / restart)))
    for eps_f in _EPS_SCHEDULE:
        for _ in range(n_rounds):
            u_all = x[3 * n:][None, :] - np.sqrt(_sqdist(pts, x[:3 * n].reshape(n, 3)))
            nbr = np.ascontiguousarray(np.argpartition(-u_all, k_nbr - 1, axis=1)[:, :k_nbr]) if k_nbr < n \
                else np.ascontiguousarray(np.broadcast_to(np.arange(n), (len(pts), n)))
            args = (pts_t, nbr, sgn, smp.weight, eps_f * smp.spacing, n, mu, v_target, lo, hi)
            x = _lbfgs(lambda z: _objective(z, *args), x, lo_b, hi_b, restart,
                       step0=0.25 * smp.spacing)
    return x[:3 * n].reshape(n, 3), x[3 * n:]


def _sampled_fractions(c: np.ndarray, r: np.ndarray, smp: _Samples, v_real: float) -> tuple[float, float]:
    covered = np.zeros(len(smp.points), dtype=bool)
    for ci, ri in zip(c, r):
        covered |= ((smp.points - ci) ** 2).sum(1) <= ri * ri
    outside = np.count_nonzero(covered & ~smp.inside) * smp.weight / v_real
    missing = np.count_nonzero(~covered & smp.inside) * smp.weight / v_real
    return float(outside), float(missing)


# ----------------------------------------------------------------------------------------
# public API
# ----------------------------------------------------------------------------------------
def fill_mesh(mesh: trimesh.Trimesh, n_spheres: int, density: float = 2661.0, *, name: str = "clump",
              n_points: int = 30_000, n_seeds: int = 1500, refine: bool = True, match_volume: bool = True,
              volume_weight: float = 10.0, max_iter: int = 30, seed: int = 0, min_radius: float | None = None,
              min_radius_fraction: float | None = None) -> tuple[ClumpTemplate, FillReport]:
    """Fill a closed mesh [m] with ``n_spheres`` overlapping spheres ("fast multi-sphere" method).

    Args:
        mesh: watertight, consistently wound triangle mesh; coordinates in metres.
        n_spheres: number of member spheres (seed paper Table 2: 5-8, 20-25, 40+).
        density: [kg/m^3] of the clump template.
        name: template name.
        n_points: sample points for the volume estimates (more: slower, finer).
        n_seeds: interior candidate centres for the greedy medial-axis step.
        refine: run the symmetric-difference optimisation (step 4 of the module doc);
            False keeps the greedy inscribed spheres.
        match_volume: scale the radii so that V_m = V_R (step 5); applies with refine=False too.
        volume_weight: weight of the volume-mismatch penalty during refinement (match_volume).
        max_iter: L-BFGS iterations per annealing stage.
        seed: RNG seed; the fill is deterministic for a given seed.
        min_radius: absolute lower bound on every member radius [m] (None: not set).
        min_radius_fraction: lower bound as a fraction of the volume-equivalent radius
            r_eq = (3 V_R / 4 pi)^(1/3). None: ``DEFAULT_MIN_RADIUS_FRACTION`` (0.25) unless
            ``min_radius`` is given; 0 with no ``min_radius``: no bound (only the optimiser's
            floor of half a sample spacing, ~0.04 r_eq). With both, the larger bound holds.

    Returns:
        (template in the principal body frame, :class:`FillReport`). The template has
        exactly ``n_spheres`` members, all of radius >= the bound (``FillReport.radius_bound``).

    Raises:
        ConfigError: non-watertight / inconsistently wound / empty mesh, n_spheres < 1, density <= 0,
            negative bound, or a bound above r_eq (one such sphere alone would exceed the particle volume).
    """
    t0 = time.perf_counter()
    check_mesh(mesh, f"fill_mesh '{name}'")
    if int(n_spheres) != n_spheres or n_spheres < 1:
        raise ConfigError(f"fill_mesh '{name}': n_spheres must be an integer >= 1, got {n_spheres}")
    if not (density > 0 and math.isfinite(density)):
        raise ConfigError(f"fill_mesh '{name}': density must be > 0 kg/m^3, got {density}")
    n = int(n_spheres)
    rng = np.random.default_rng(seed)
    v_real, area = float(mesh.volume), float(mesh.area)
    scale = (3.0 * v_real / (4.0 * math.pi)) ** (1.0 / 3.0)          # r_eq [m]
    r_bound = _radius_bound(name, scale, min_radius, min_radius_fraction)
    rb = r_bound / scale                                                # normalised
    notes: list[str] = []

    # normalised copy: centroid at 0, equivalent-sphere radius 1
    origin = mesh.center_mass
    m = mesh.copy()
    m.apply_translation(-origin)
    m.apply_scale(1.0 / scale)
    v_norm = float(m.volume)

    lo_m, hi_m = m.bounds
    pad = 0.06 * float((hi_m - lo_m).max())
    smp = _sample(m, n_points, rng, lo_m - pad, hi_m + pad)
    inside_pts = smp.points[smp.inside]
    if len(inside_pts) < 10 * n:
        raise ConfigError(f"fill_mesh '{name}': only {len(inside_pts)} sample points inside the mesh; "
                          f"raise n_points")
    # seeds: interior points with their inscribed-ball radius = distance to the surface,
    # from a dense surface sample (over-estimates by ~ spacing^2 / (2 r); refined later)
    surf = trimesh.sample.sample_surface(m, 20_000, seed=seed)[0]
    pick = rng.choice(len(inside_pts), size=min(n_seeds, len(inside_pts)), replace=False)
    cand = inside_pts[pick]
    crad = cKDTree(surf).query(cand)[0]
    n_pin = min(6000, len(inside_pts))
    pin = inside_pts[rng.choice(len(inside_pts), size=n_pin, replace=False)]
    pout = None
    if rb > 0 and np.any(crad < rb):
        # outside points that an inflated candidate (centre inside, radius rb) can reach,
        # subsampled at the density of ``pin`` so that counts compare as volumes
        out_pts = smp.points[~smp.inside]
        near = out_pts[cKDTree(surf).query(out_pts, distance_upper_bound=rb)[0] < rb]
        k_out = int(round(len(near) * n_pin / len(inside_pts)))
        pout = near[rng.choice(len(near), size=k_out, replace=False)] if k_out > 0 else None
    c, r = _greedy(cand, crad, pin, n, pout, rb)

    refine_args = {}
    if refine:
        lo, hi = smp.points.min(0), smp.points.max(0)
        refine_args = dict(smp=smp, lo=lo, hi=hi, r_min=max(0.5 * smp.spacing, rb),
                           r_max=max(2.0 * float(crad.max()), 2.0 * rb), iters=max_iter, v_target=v_norm)
        c, r = _refine(c, r, mu=(volume_weight if match_volume else 0.0), **refine_args)
    r = np.maximum(r, rb)

    volume_scale = 1.0
    if match_volume:
        volume_scale, excess = _match_volume(c, r, rb, v_norm)
        v_soft = v_norm
        for _ in range(3 if refine else 0):
            if excess <= 0.0:
                break
            # even with every radius at the bound the union exceeds V_R. The optimiser's soft
            # volume runs below the exact union volume (creases between overlapping balls), so
            # it believes the volume matched: lower its target by the excess, weight the volume
            # more, and let it pull the centres together
            v_soft -= excess * v_norm
            c, r = _refine(c, r, mu=10.0 * volume_weight, **{**refine_args, "v_target": v_soft})
            r = np.maximum(r, rb)
            volume_scale, excess = _match_volume(c, r, rb, v_norm)
        if excess > 0.0:
            notes.append(f"volume not matched: {n} spheres of radius >= {r_bound:.3g} m exceed V_R by "
                         f"{excess:.1%} (all at the bound); lower the bound or n_spheres")
        r = np.maximum(r * volume_scale, rb)

    # unbiased quality estimate on an independent sample (the optimiser has seen ``smp``)
    lo_t = np.minimum(lo_m, (c - r[:, None]).min(0)) - 0.01
    hi_t = np.maximum(hi_m, (c + r[:, None]).max(0)) + 0.01
    smp_test = _sample(m, n_points, np.random.default_rng(seed + 7919), lo_t, hi_t)
    outside, missing = _sampled_fractions(c, r, smp_test, v_norm)
    # largest protrusion out of the mesh surface (normalised units)
    _, dc, _ = trimesh.proximity.closest_point(m, c)
    inside_c = _inside(m, c)
    protr = float(np.max(np.where(inside_c, r - dc, r + dc)))

    n_redundant = _count_redundant(c, r, seed)
    if n_redundant:
        notes.append(f"{n_redundant} of {n} spheres lie (almost) entirely inside the others (exclusive volume "
                     f"< 0.5 %): kept to honour n_spheres, but they add no shape; n_spheres={n - n_redundant} "
                     f"would give about the same clump at a lower DEM cost")

    centers = c * scale + origin
    radii = np.maximum(r * scale, r_bound)          # round-off must not undercut the bound
    tpl = make_template(centers, radii, density, name=name)
    rep = FillReport(n_spheres=n, mesh_volume=v_real, mesh_area=area, sphericity=sphericity(v_real, area),
                     clump_volume=tpl.volume, volume_error=relative_volume_error(tpl.volume, v_real),
                     outside_fraction=outside, missing_fraction=missing,
                     max_protrusion=max(0.0, protr * scale), radius_scale=volume_scale,
                     time_s=time.perf_counter() - t0, min_radius=float(radii.min()),
                     max_radius=float(radii.max()), radius_bound=r_bound, n_redundant=n_redundant,
                     notes=tuple(notes))
    return tpl, rep


def _match_volume(c: np.ndarray, r: np.ndarray, rb: float, v_target: float) -> tuple[float, float]:
    """Factor k with V(union of balls max(k r_i, rb)) = v_target, and the relative excess volume
    left when even k -> rb / max(r) (every ball at the bound) is too large (0 when matched).

    brentq on the quadrature volume of clump_geometry; |k - 1| is typically < 1 %.
    """
    vol = lambda k: union_mass_properties(c, np.maximum(k * r, rb), 1.0, resolution=24).volume - v_target  # noqa: E731
    k_floor = rb / float(r.max()) if rb > 0 else 0.0      # at or below it every radius sits at rb
    k_lo, k_hi = 0.9, 1.1
    while (v_lo := vol(k_lo)) > 0:
        if k_lo <= k_floor:
            return k_lo, v_lo / v_target
        k_lo = max(k_lo * 0.9, k_floor)
    while vol(k_hi) < 0:
        k_hi *= 1.1
    return float(brentq(vol, k_lo, k_hi, xtol=1e-5)), 0.0


def _radius_bound(name: str, r_eq: float, min_radius: float | None, fraction: float | None) -> float:
    """Lower bound on member radii [m] from the absolute and relative options (see fill_mesh)."""
    if fraction is None:
        fraction = DEFAULT_MIN_RADIUS_FRACTION if min_radius is None else 0.0
    if not (math.isfinite(fraction) and fraction >= 0.0):
        raise ConfigError(f"fill_mesh '{name}': min_radius_fraction must be >= 0, got {fraction}")
    absolute = 0.0 if min_radius is None else float(min_radius)
    if not (math.isfinite(absolute) and absolute >= 0.0):
        raise ConfigError(f"fill_mesh '{name}': min_radius must be >= 0 m, got {min_radius}")
    bound = max(absolute, fraction * r_eq)
    if bound >= r_eq:
        raise ConfigError(f"fill_mesh '{name}': radius bound {bound:.4g} m >= the volume-equivalent radius "
                          f"{r_eq:.4g} m: a single such sphere exceeds the particle volume")
    return bound


def _count_redundant(c: np.ndarray, r: np.ndarray, seed: int) -> int:
    return int(_redundant(c, r, seed).sum())


def _redundant(c: np.ndarray, r: np.ndarray, seed: int, m: int = 800, tol: float = 0.005) -> np.ndarray:
    """Members whose exclusive volume (not covered by the others) is < ``tol`` of their own (sampled)."""
    n = len(r)
    out = np.zeros(n, dtype=bool)
    if n < 2:
        return out
    rng = np.random.default_rng(seed + 104729)
    u = rng.normal(size=(m, 3))
    u *= (rng.random(m) ** (1.0 / 3.0) / np.linalg.norm(u, axis=1))[:, None]    # uniform in the unit ball
    for i in range(n):
        p = c[i] + r[i] * u
        d2 = _sqdist(p, c)
        d2[:, i] = np.inf
        out[i] = np.count_nonzero(~(d2 <= (r * r)[None, :]).any(1)) < tol * m
    return out


def clump_from_file(path: str | Path, n_spheres: int, density: float = 2661.0, scale: float = 1.0,
                    **kwargs) -> tuple[ClumpTemplate, FillReport]:
    """Load an STL/OBJ/PLY mesh (via trimesh), scale it by ``scale`` to metres, and fill it.

    E.g. ``scale=1e-3`` for a scan in millimetres. Keyword arguments go to :func:`fill_mesh`.
    """
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"clump_from_file: no such file {str(p)!r}")
    if not (scale > 0 and math.isfinite(scale)):
        raise ConfigError(f"clump_from_file: scale must be > 0, got {scale}")
    loaded = trimesh.load(str(p), force="mesh")
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ConfigError(f"clump_from_file: {str(p)!r} holds no triangle mesh")
    loaded.apply_scale(scale)
    kwargs.setdefault("name", p.stem)
    return fill_mesh(loaded, n_spheres, density, **kwargs)
