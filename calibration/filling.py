"""Loose fills, settling and levelling for the standard experiments
(docs/experiments.md, A "Fill", B "Fill", C "Fill").

Fill: random sequential addition (RSA) in horizontal slabs rising from the region's
floor. Each particle (spheres, or clumps with a random orientation) tries batches of random
centres in the current slab; a try is accepted when every member sphere lies inside the
region and clears every placed member sphere by ``gap``. When a whole batch fails the slab
moves up. Regions that are open at the top (box, vertical cylinder) may be exceeded: the
column then stands above the walls' nominal height and pours down when settled (the walls
of the experiments are raised to contain it). The result is checked for overlaps with a
``scipy.spatial.cKDTree``. A closed region (the drum) that one loose pass cannot hold is
filled by :func:`pour_fill`: place what fits, settle it in a one-world model, add more in
the freed space, repeat.

Levelling removes particles whose top is above a height. A :class:`warpdem.Model` is
immutable, so removal is done by **deactivating bodies** in ``sim.state.body_active`` (the
engine then skips them in contacts, integration and kinetic energy); contact history of the
remaining particles is kept. Positions of deactivated bodies stay in the arrays: read
particles through :func:`active_spheres` / :func:`active_bodies`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from warpdem import ConfigError, SettleReport
from warpdem.builder import random_quaternions

from .materials import ParticleSample

__all__ = ["Box", "VerticalCylinder", "HorizontalCylinder", "FillResult", "FillError", "random_fill", "pour_fill",
           "check_no_overlap", "add_fill", "member_positions", "SettleReport", "settle", "level",
           "active_spheres", "active_bodies", "body_tops", "run_for", "insertion_region", "poured_fill",
           "fill_body_ids", "hold_batches", "release_batches"]


class FillError(ConfigError):
    """The particles do not fit into the fill region."""


# --------------------------------------------------------------------------- regions
@dataclass(frozen=True)
class Box:
    """Axis-aligned box [lower, upper] [m]; open at the top when ``open_top`` (the fill may
    then rise above ``upper[2]``)."""

    lower: tuple[float, float, float]
    upper: tuple[float, float, float]
    open_top: bool = True

    def __post_init__(self) -> None:
        if not all(u > l for l, u in zip(self.lower, self.upper)):
            raise ConfigError(f"Box: upper {self.upper} must exceed lower {self.lower} in x, y and z")

    def contains(self, x: np.ndarray, r: np.ndarray, gap: float) -> np.ndarray:
        lo = np.asarray(self.lower) + (r + gap)[:, None]
        hi = np.asarray(self.upper) - (r + gap)[:, None]
        ok = np.all(x[:, :2] >= lo[:, :2], axis=1) & np.all(x[:, :2] <= hi[:, :2], axis=1) & (x[:, 2] >= lo[:, 2])
        return ok if self.open_top else ok & (x[:, 2] <= hi[:, 2])

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.lower, float), np.asarray(self.upper, float)


@dataclass(frozen=True)
class VerticalCylinder:
    """Cylinder with a vertical axis through ``center`` (x, y) [m], radius [m], z in [z0, z1]."""

    center: tuple[float, float]
    radius: float
    z0: float
    z1: float
    open_top: bool = True

    def __post_init__(self) -> None:
        if not (self.radius > 0 and self.z1 > self.z0):
            raise ConfigError(f"VerticalCylinder: need radius > 0 and z1 > z0, got {self.radius}, {self.z0}, {self.z1}")

    def contains(self, x: np.ndarray, r: np.ndarray, gap: float) -> np.ndarray:
        rho = np.hypot(x[:, 0] - self.center[0], x[:, 1] - self.center[1])
        ok = (rho <= self.radius - r - gap) & (x[:, 2] >= self.z0 + r + gap)
        return ok if self.open_top else ok & (x[:, 2] <= self.z1 - r - gap)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        c, R = self.center, self.radius
        return np.array([c[0] - R, c[1] - R, self.z0]), np.array([c[0] + R, c[1] + R, self.z1])


@dataclass(frozen=True)
class HorizontalCylinder:
    """Closed cylinder with its axis along y through (x, z) = ``center`` [m] (a drum), y in [y0, y1]."""

    center: tuple[float, float]
    radius: float
    y0: float
    y1: float
    open_top = False

    def __post_init__(self) -> None:
        if not (self.radius > 0 and self.y1 > self.y0):
            raise ConfigError(f"HorizontalCylinder: need radius > 0 and y1 > y0, got {self.radius}, {self.y0}, {self.y1}")

    def contains(self, x: np.ndarray, r: np.ndarray, gap: float) -> np.ndarray:
        rho = np.hypot(x[:, 0] - self.center[0], x[:, 2] - self.center[1])
        return (rho <= self.radius - r - gap) & (x[:, 1] >= self.y0 + r + gap) & (x[:, 1] <= self.y1 - r - gap)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        c, R = self.center, self.radius
        return np.array([c[0] - R, self.y0, c[1] - R]), np.array([c[0] + R, self.y1, c[1] + R])


Region = Box | VerticalCylinder | HorizontalCylinder


# --------------------------------------------------------------------------- fill
@dataclass(frozen=True)
class FillResult:
    """Placed particles: body centres ``positions`` (n, 3) [m] and body-to-world quaternions
    ``rotations`` (n, 4) (x, y, z, w) for ``sample``; the first ``placed`` are placed (the
    rest, after a partial fill, hold NaN). ``top``: highest particle top [m];
    ``above_region``: the column rises above the region's nominal top; ``settled``: the
    positions come from a settled pour (contacts overlap slightly, see :func:`pour_fill`)."""

    sample: ParticleSample
    positions: np.ndarray
    rotations: np.ndarray
    top: float
    above_region: bool
    region: object
    placed: int = -1
    settled: bool = False
    pours: int = 0
    #: poured fill (:func:`poured_fill`): each particle's insertion batch (n,), and the height [m]
    #: batch k waits above its release position (k * ``batch_stride``) until it is released
    batch: np.ndarray | None = None
    batch_stride: float = 0.0

    def __post_init__(self) -> None:
        if self.placed < 0:
            object.__setattr__(self, "placed", int(self.sample.n))

    @property
    def complete(self) -> bool:
        return self.placed == self.sample.n

    @property
    def poured(self) -> bool:
        """The particles are inserted in batches (:func:`poured_fill`), not placed at once."""
        return self.batch is not None

    @property
    def loose_solids_fraction(self) -> float:
        """Solid volume / region volume up to ``top`` (a rough measure of looseness)."""
        lo, hi = self.region.bounds
        if isinstance(self.region, HorizontalCylinder):
            return float("nan")
        area = (hi[0] - lo[0]) * (hi[1] - lo[1]) if isinstance(self.region, Box) else math.pi * self.region.radius**2
        return self.sample.solid_volume / (area * (self.top - lo[2]))


def member_positions(fill: FillResult) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Member spheres of the placed particles: centres (m, 3) [m], radii (m,), owner (m,)."""
    xs, rs, owner = [], [], []
    rot = Rotation.from_quat(fill.rotations[: fill.placed])
    for i in range(fill.placed):
        off, r = fill.sample.members(i)
        xs.append(fill.positions[i] + rot[i].apply(off))
        rs.append(r)
        owner.append(np.full(len(r), i))
    return np.concatenate(xs), np.concatenate(rs), np.concatenate(owner)


def random_fill(region: Region, sample: ParticleSample, rng: np.random.Generator | int | None = None,
                gap: float | None = None, batch: int = 48, rise: float = 0.25, max_rise_factor: float = 20.0,
                fixed: tuple[np.ndarray, np.ndarray] | None = None, allow_partial: bool = False) -> FillResult:
    """Loose non-overlapping placement of ``sample`` in ``region`` (module docstring).

    Args:
        gap: clearance between member spheres and to the region [m] (default 2 % of the
            largest bounding radius).
        batch: random centres tried per particle before the slab rises.
        rise: slab rise after a failed batch, in largest bounding radii.
        max_rise_factor: an open-top column may reach this many region heights.
        fixed: (positions (k, 3), rotations (k, 4)) of the first k particles, already placed
            (e.g. settled by :func:`pour_fill`); only the others are placed, clear of them.
        allow_partial: in a closed region, return what fits instead of raising.
    Raises:
        FillError: the particles do not fit (closed region full, or the column grows absurdly).
    """
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    n = sample.n
    rb = sample.bounding_radius
    rb_max = float(rb.max())
    gap = 0.02 * rb_max if gap is None else float(gap)
    lo, hi = region.bounds
    height = hi[2] - lo[2]
    is_sphere = sample.template < 0
    k0 = 0 if fixed is None else int(len(fixed[0]))
    quats = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    free = ~is_sphere & (np.arange(n) >= k0)
    if np.any(free):
        quats[free] = random_quaternions(int(np.count_nonzero(free)), rng)
    pos = np.full((n, 3), np.nan)
    if k0:
        pos[:k0] = np.asarray(fixed[0], dtype=float)
        quats[:k0] = np.asarray(fixed[1], dtype=float)
    rots = Rotation.from_quat(quats)
    # member offsets in the world frame (orientation fixed per particle) and radii
    offs, mrad = [], []
    for i in range(n):
        o, r = sample.members(i)
        offs.append(rots[i].apply(o) if not is_sphere[i] else o)
        mrad.append(r)
    placed_members = [(pos[i] + offs[i], mrad[i]) for i in range(k0)]
    dz = 2.0 * rb_max
    level = lo[2]
    z_limit = lo[2] + max_rise_factor * height
    placed = n
    for i in range(k0, n):
        ri = rb[i]
        o_i, r_i = offs[i], mrad[i]
        while True:
            if not region.open_top and level + 2 * ri > hi[2] + 1e-12:
                if allow_partial:
                    placed = i
                    break
                raise FillError(f"fill: only {i} of {n} particles fit in the closed region "
                                f"{type(region).__name__} (bounds {lo.round(4).tolist()} - {hi.round(4).tolist()} m) "
                                f"in one loose pass; use pour_fill (settles and adds more), less material or a "
                                f"larger region")
            if level > z_limit:
                raise FillError(f"fill: the loose column exceeds {max_rise_factor:g} region heights after {i} of {n} "
                                f"particles; the cross-section is too small for this material")
            c = np.empty((batch, 3))
            c[:, 0] = rng.uniform(lo[0] + ri, hi[0] - ri, batch) if hi[0] - lo[0] > 2 * ri else 0.5 * (lo[0] + hi[0])
            c[:, 1] = rng.uniform(lo[1] + ri, hi[1] - ri, batch) if hi[1] - lo[1] > 2 * ri else 0.5 * (lo[1] + hi[1])
            c[:, 2] = rng.uniform(level + ri, level + ri + dz, batch)
            # inside the region (all members)
            k = len(r_i)
            mem = (c[:, None, :] + o_i[None, :, :]).reshape(-1, 3)
            inside = region.contains(mem, np.tile(r_i, batch), gap).reshape(batch, k).all(axis=1)
            cand = np.nonzero(inside)[0]
            accepted = -1
            if cand.size:
                # bounding-sphere conflicts with placed particles near the slab
                near = np.nonzero(pos[:i, 2] > level - 2.0 * rb_max - gap)[0]
                if near.size == 0:
                    accepted = int(cand[0])
                else:
                    d = np.linalg.norm(c[cand, None, :] - pos[None, near, :], axis=2)
                    conflict = d < (ri + rb[near] + gap)[None, :]
                    for a in range(cand.size):
                        js = near[conflict[a]]
                        if js.size == 0:
                            accepted = int(cand[a])
                            break
                        if is_sphere[i] and np.all(is_sphere[js]):
                            continue  # bounding spheres are the spheres: a real conflict
                        xm = c[cand[a]] + o_i
                        other = np.concatenate([placed_members[j][0] for j in js])
                        orad = np.concatenate([placed_members[j][1] for j in js])
                        dm = np.linalg.norm(xm[:, None, :] - other[None, :, :], axis=2)
                        if np.all(dm >= r_i[:, None] + orad[None, :] + gap):
                            accepted = int(cand[a])
                            break
            if accepted >= 0:
                pos[i] = c[accepted]
                placed_members.append((c[accepted] + o_i, r_i))
                break
            level += rise * rb_max
        if placed < n:
            break
    tops = np.array([np.max(m[0][:, 2] + m[1]) for m in placed_members]) if placed_members else np.array([lo[2]])
    top = float(tops.max())
    res = FillResult(sample, pos, quats, top, bool(top > hi[2] + 1e-12), region, placed=placed,
                     settled=fixed is not None)
    if fixed is None:
        check_no_overlap(res)
    return res


def check_no_overlap(fill: FillResult, tol: float = 0.0) -> float:
    """Largest overlap between member spheres of different placed particles [m]; raises
    FillError above ``tol``."""
    x, r, owner = member_positions(fill)
    tree = cKDTree(x)
    pairs = tree.query_pairs(2.0 * float(r.max()), output_type="ndarray")
    if len(pairs) == 0:
        return 0.0
    a, b = pairs[:, 0], pairs[:, 1]
    keep = owner[a] != owner[b]
    a, b = a[keep], b[keep]
    ov = r[a] + r[b] - np.linalg.norm(x[a] - x[b], axis=1) if len(a) else np.zeros(0)
    worst = float(ov.max()) if ov.size else 0.0
    if worst > tol:
        raise FillError(f"fill: particles {owner[a[np.argmax(ov)]]} and {owner[b[np.argmax(ov)]]} overlap by "
                        f"{worst:.3g} m")
    return max(worst, 0.0)


def pour_fill(region: Region, sample: ParticleSample, add_walls: Callable, rng: np.random.Generator | int | None = None,
              device: str | None = None, ke_per_particle: float = 1.0e-6, max_time: float = 1.5,
              max_pours: int = 30, contact_law=None) -> FillResult:
    """Fill a region that one loose pass cannot hold (a closed drum): place what fits
    (:func:`random_fill`), let it settle in a one-world model whose walls ``add_walls(builder)``
    adds (default contact parameters of the law, particle material = the sample's), then
    place more in the freed space above the bed, and repeat until every particle is in.
    ``contact_law``: the experiment's :class:`warpdem.ContactLaw` (None: Hertz-Mindlin + epsd).

    The result holds settled positions (``settled=True``): neighbours overlap by their
    weight's Hertz overlap, so models built from it need a lenient overlap check.
    """
    import warpdem as wd

    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    fill = random_fill(region, sample, rng, allow_partial=True)
    pours = 0
    while not fill.complete:
        pours += 1
        k = fill.placed
        if pours > max_pours or k == 0:
            raise FillError(f"pour_fill: {k} of {sample.n} particles placed after {pours - 1} pour(s); "
                            f"the region cannot hold this material")
        b = wd.ModelBuilder(1, contact_law=contact_law if contact_law is not None else wd.ContactLaw(rolling="epsd"))
        mat = sample.material.particle
        b.add_material(mat)
        add_walls(b)
        part = FillResult(_subset(sample, k), fill.positions[:k], fill.rotations[:k], fill.top, False, region,
                          settled=fill.settled)
        ids = add_fill(b, part, mat.name, 0)
        model = b.finalize(device, overlap_tolerance=1.0)
        sim = wd.Simulation(model, wd.time_step_limits(model).recommended)
        t_fall = math.sqrt(2.0 * max(fill.top - region.bounds[0][2], 0.0) / 9.81)
        settle(sim, ke_per_particle, max(max_time, t_fall), min_time=t_fall)
        q = sim.state.body_q.numpy().astype(float)[ids]
        rot = sim.state.body_rot.numpy().astype(float)[ids]
        fill = random_fill(region, sample, rng, fixed=(q, rot), allow_partial=True)
        if fill.placed == k:
            raise FillError(f"pour_fill: no room for more particles after settling ({k} of {sample.n} placed); "
                            f"the region cannot hold this material")
    x, r, _ = member_positions(fill)
    return FillResult(sample, fill.positions, fill.rotations, float(np.max(x[:, 2] + r)), fill.above_region, region,
                      settled=pours > 0, pours=pours)


def _subset(sample: ParticleSample, k: int) -> ParticleSample:
    return ParticleSample(sample.material, sample.template[:k], sample.radius[:k], sample.bounding_radius[:k],
                          sample.mass[:k], sample.equivalent_diameter[:k])


# --------------------------------------------------------------------------- poured fill
def insertion_region(region: Region, solid_volume: float, d_max: float, inset: float) -> Box | VerticalCylinder:
    """The insertion region of a poured fill, as the LIGGGHTS decks pour theirs
    (``_pour_region`` in validation/reference/liggghts_experiments.py): in the upper part of an
    open ``region`` (box or vertical cylinder), clear of its walls by ``inset`` [m]; from one
    largest diameter ``d_max`` above an estimate of the settled bed's top (``solid_volume`` [m^3]
    at a solids fraction of 0.6), max(4 d_max, a quarter of the bed height) high. Closed (the
    particles lie wholly inside it, LIGGGHTS' ``all_in yes``)."""
    if isinstance(region, Box):
        (x0, y0, z0), (x1, y1, _) = region.lower, region.upper
        bed = z0 + solid_volume / 0.6 / ((x1 - x0) * (y1 - y0))
        lo = bed + d_max
        hi = lo + max(4.0 * d_max, 0.25 * (bed - z0))
        return Box((x0 + inset, y0 + inset, lo), (x1 - inset, y1 - inset, hi), open_top=False)
    if isinstance(region, VerticalCylinder):
        R, z0 = region.radius, region.z0
        bed = z0 + solid_volume / 0.6 / (math.pi * R**2)
        lo = bed + d_max
        hi = lo + max(4.0 * d_max, 0.25 * (bed - z0))
        return VerticalCylinder(region.center, R - inset, lo, hi, open_top=False)
    raise FillError(f"poured fill: no insertion region for a {type(region).__name__} (a box or a vertical cylinder "
                    "open at the top)")


def region_volume(region: Box | VerticalCylinder) -> float:
    """Volume [m^3] of a box or a vertical cylinder."""
    lo, hi = region.bounds
    if isinstance(region, VerticalCylinder):
        return math.pi * region.radius**2 * (region.z1 - region.z0)
    return float(np.prod(hi - lo))


def poured_fill(region: Region, insert: Box | VerticalCylinder, sample: ParticleSample, batch_volume: float,
                rng: np.random.Generator | int | None = None, gap: float | None = None) -> FillResult:
    """A poured fill (LIGGGHTS' ``insert/rate/region``): ``sample`` split in order into insertion
    batches of at most ``batch_volume`` [m^3] of solid each (to one particle: particle i joins batch
    ceil(V_i / batch_volume) - 1 by the cumulative solid volume V_i), each batch placed by
    :func:`random_fill` inside the closed insertion region ``insert`` (no overlap within the batch).
    Batch k waits k x ``batch_stride`` above its release position (the region's height and one
    largest diameter: the waiting batches never overlap) until the protocol releases it
    (:func:`release_batches`); ``positions`` are the waiting positions, ``top`` the highest top at
    release. ``region``: the experiment's fill region (its floor is the fill's)."""
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    if not batch_volume > 0:
        raise FillError(f"poured fill: batch volume must be > 0 m^3, got {batch_volume}")
    vol = sample.mass / sample.material.particle.density
    batch = np.maximum(np.ceil(np.cumsum(vol) / batch_volume - 1e-9).astype(np.int64) - 1, 0)
    lo, hi = insert.bounds
    stride = float(hi[2] - lo[2]) + 2.0 * float(sample.bounding_radius.max())
    pos = np.empty((sample.n, 3))
    rot = np.empty((sample.n, 4))
    for k in np.unique(batch):
        idx = np.nonzero(batch == k)[0]
        part = random_fill(insert, _select(sample, idx), rng, gap=gap)
        pos[idx] = part.positions + np.array([0.0, 0.0, k * stride])
        rot[idx] = part.rotations
    res = FillResult(sample, pos, rot, 0.0, False, region, batch=batch, batch_stride=stride)
    x, r, owner = member_positions(res)
    top = float(np.max(x[:, 2] + r - batch[owner] * stride))
    res = FillResult(sample, pos, rot, top, bool(top > region.bounds[1][2] + 1e-12), region, batch=batch,
                     batch_stride=stride)
    check_no_overlap(res)
    return res


def _select(sample: ParticleSample, idx: np.ndarray) -> ParticleSample:
    return ParticleSample(sample.material, sample.template[idx], sample.radius[idx], sample.bounding_radius[idx],
                          sample.mass[idx], sample.equivalent_diameter[idx])


def fill_body_ids(model, world: int, sample: ParticleSample) -> np.ndarray:
    """Body ids of ``world``'s particles in the order of ``sample`` (a world built by
    :func:`add_fill` alone: spheres first, then clumps template by template)."""
    order = [np.nonzero(sample.template < 0)[0]]
    order += [np.nonzero(sample.template == k)[0] for k in np.unique(sample.template[sample.template >= 0])]
    order = np.concatenate(order)
    bodies = np.nonzero(model.host["body_world"] == world)[0]
    if len(bodies) != sample.n:
        raise FillError(f"world {world} holds {len(bodies)} bodies, its fill {sample.n} particles")
    ids = np.empty(sample.n, dtype=np.int64)
    ids[order] = bodies
    return ids


def hold_batches(sim, bodies: np.ndarray) -> None:
    """Take ``bodies`` (waiting insertion batches) out of play: inactive, frozen where they wait."""
    active = sim.state.body_active.numpy().copy()
    active[np.asarray(bodies, dtype=np.int64)] = 0
    sim.state.body_active.assign(active)
    sim.solver.invalidate_views()


def release_batches(sim, bodies: np.ndarray, drop: np.ndarray, gap: float = 0.0) -> np.ndarray:
    """Insert waiting bodies (LIGGGHTS' ``overlapcheck yes``, ``vel constant 0 0 0``): in the
    given order, each body is moved down by its ``drop`` [m] and made active at rest, unless one
    of its spheres would then overlap (closer than the radii and ``gap``) an active sphere of its
    world or one inserted before it in this call; such a body keeps waiting where it is. Host-side
    (between chunks of steps); returns the mask of the bodies inserted."""
    bodies = np.asarray(bodies, dtype=np.int64)
    drop = np.asarray(drop, dtype=float)
    h = sim.model.host
    x = sim.sphere_positions()
    q = sim.state.body_q.numpy().copy()
    active = sim.state.body_active.numpy().copy()
    sb, sr, sw = h["sphere_body"], h["sphere_radius"].astype(float), h["sphere_world"]
    first, count = h["body_first"], h["body_count"]
    done = np.zeros(len(bodies), dtype=bool)
    for w in np.unique(h["body_world"][bodies]):
        cand = np.nonzero(h["body_world"][bodies] == w)[0]  # positions in ``bodies``, in their order
        # the candidates' spheres where they would be inserted, and which candidate owns each
        owner = np.concatenate([np.full(int(count[bodies[j]]), k) for k, j in enumerate(cand)])
        idx = np.concatenate([np.arange(int(first[bodies[j]]), int(first[bodies[j]] + count[bodies[j]]))
                              for j in cand])
        xc = x[idx] - np.stack([np.zeros(len(idx)), np.zeros(len(idx)), drop[cand][owner]], axis=1)
        rc = sr[idx]
        tree_c = cKDTree(xc)
        blocked = np.zeros(len(cand), dtype=bool)  # overlaps an active sphere of the world
        on = (active[sb] != 0) & (sw == w)
        if on.any():
            xa, ra = x[on], sr[on]
            reach = float(ra.max() + rc.max() + gap)
            pairs = tree_c.sparse_distance_matrix(cKDTree(xa), reach, output_type="ndarray")
            hit = pairs["v"] < rc[pairs["i"]] + ra[pairs["j"]] + gap
            blocked[np.unique(owner[pairs["i"][hit]])] = True
        # candidates overlapping each other: the later one waits if the earlier one goes in
        pairs = tree_c.query_pairs(float(2.0 * rc.max() + gap), output_type="ndarray")
        if len(pairs):
            a, b = owner[pairs[:, 0]], owner[pairs[:, 1]]
            dist = np.linalg.norm(xc[pairs[:, 0]] - xc[pairs[:, 1]], axis=1)
            clash = (a != b) & (dist < rc[pairs[:, 0]] + rc[pairs[:, 1]] + gap)
            earlier: dict[int, set[int]] = {}
            for first_in, later in zip(np.minimum(a, b)[clash], np.maximum(a, b)[clash]):
                earlier.setdefault(int(later), set()).add(int(first_in))
        else:
            earlier = {}
        ok = ~blocked
        for k in sorted(earlier):  # in the candidates' order, as they go in one after another
            if ok[k] and any(ok[e] for e in earlier[k]):
                ok[k] = False
        done[cand] = ok
    moved = bodies[done]
    if moved.size:
        q[moved, 2] = (q[moved, 2].astype(float) - drop[done]).astype(np.float32)
        active[moved] = 1
        sim.state.body_q.assign(q)
        for arr in (sim.state.body_v, sim.state.body_w):
            v = arr.numpy().copy()
            v[moved] = 0.0
            arr.assign(v)
        sim.state.body_active.assign(active)
        sim.solver.invalidate_views()
        sim.solver.request_neighbour_rebuild()  # the inserted spheres enter the neighbour lists
    return done


def add_fill(builder, fill: FillResult, material, world: int) -> np.ndarray:
    """Add a fill's particles to a :class:`warpdem.ModelBuilder` in ``world``; returns body ids
    in the order of ``fill.sample``."""
    if not fill.complete:
        raise FillError(f"add_fill: only {fill.placed} of {fill.sample.n} particles are placed")
    s = fill.sample
    ids = np.empty(s.n, dtype=np.int64)
    sph = np.nonzero(s.template < 0)[0]
    if sph.size:
        ids[sph] = builder.add_spheres(fill.positions[sph], s.radius[sph], material, world=world)
    for k in np.unique(s.template[s.template >= 0]):
        sel = np.nonzero(s.template == k)[0]
        ids[sel] = builder.add_clumps(s.material.clumps[int(k)][0], fill.positions[sel], material, world=world,
                                      rotations=fill.rotations[sel])
    return ids


# --------------------------------------------------------------------------- state access
def active_spheres(sim, world: int | None = None, positions: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Centres (m, 3) [m] and radii (m,) of the spheres of active bodies (one world, or all).
    ``positions``: a previous ``sim.sphere_positions()`` read-back to reuse."""
    h = sim.model.host
    x = sim.sphere_positions() if positions is None else positions
    act = sim.state.body_active.numpy()[h["sphere_body"]] != 0
    if world is not None:
        act &= h["sphere_world"] == world
    return x[act], h["sphere_radius"][act].astype(np.float64)


def active_bodies(sim, world: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Centres of mass (m, 3) [m] and masses (m,) [kg] of active bodies (one world, or all)."""
    h = sim.model.host
    act = sim.state.body_active.numpy() != 0
    if world is not None:
        act &= h["body_world"] == world
    return sim.state.body_q.numpy()[act].astype(np.float64), h["body_mass"][act].astype(np.float64)


def body_tops(sim, positions: np.ndarray | None = None) -> np.ndarray:
    """Highest member-sphere top z + r of every body [m] (inactive bodies included)."""
    h = sim.model.host
    x = sim.sphere_positions() if positions is None else positions
    tops = np.full(sim.model.num_bodies, -np.inf)
    np.maximum.at(tops, h["sphere_body"], x[:, 2] + h["sphere_radius"])
    return tops


def level(sim, height: float, world: int | None = None) -> np.ndarray:
    """Levelling (spec A "Fill"): deactivate bodies whose top is above ``height`` [m] (one
    world or all); returns the number removed per world."""
    h = sim.model.host
    tops = body_tops(sim)
    active = sim.state.body_active.numpy().copy()
    remove = (active != 0) & (tops > height)
    if world is not None:
        remove &= h["body_world"] == world
    active[remove] = 0
    sim.state.body_active.assign(active)
    sim.solver.invalidate_views()  # a no-op unless the solver fuses the placement into integration
    return np.bincount(h["body_world"][remove], minlength=sim.model.num_worlds)


# --------------------------------------------------------------------------- settling


def settle(sim, ke_per_particle: float = 1.0e-6, max_time: float | np.ndarray = 1.5,
           min_time: float | np.ndarray = 0.0, check_interval: float = 0.02,
           remove_box: tuple | None = None) -> SettleReport:
    """Spec A/C "settled" criterion: mean kinetic energy per active particle of every world below
    ``ke_per_particle`` [J] after ``min_time``, or ``max_time`` [s] passed (per world possible);
    bodies leaving ``remove_box`` are removed. Each world is paused once settled, see
    :meth:`warpdem.Simulation.settle`."""
    return sim.settle(ke_per_particle, max_time, check_interval, min_time, remove_box)


def run_for(sim, duration: float, remove_box: tuple | None = None, remove_interval: float = 0.05) -> tuple[int, int]:
    """Advance ``duration`` [s], removing bodies outside ``remove_box`` every
    ``remove_interval`` [s]; returns (steps, bodies removed)."""
    steps = int(round(duration / sim.dt))
    if steps <= 0:
        return 0, 0
    if remove_box is None:
        sim.run(steps)
        return steps, 0
    every = max(1, int(round(remove_interval / sim.dt)))
    done, removed = 0, 0
    while done < steps:
        k = min(every, steps - done)
        sim.run(k, check_every=k)
        removed += sim.remove_outside(*remove_box)
        done += k
    return steps, removed


