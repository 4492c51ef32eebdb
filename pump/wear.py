"""Wear of the pump walls from the DEM contacts.

Definitions (per triangle and world; the engine accumulates the first four in every wall
contact, :class:`warpdem.solver.WallStats`; v is the velocity of the particle's contact point
relative to the wall, split into normal v_n and tangential v_t parts):

* Relative wear (EDEM's "relative wear" model, used by the seed paper's Fig. 17):
  cumulative normal contact energy E_n = sum |F_n v_n| dt [J] and cumulative tangential
  contact energy E_t = sum |F_t . v_t| dt [J]; no material constant.
* Cumulative contact force (seed paper Fig. 18, EDEM's "cumulative force"): the sum over the
  time steps of |F_n| and |F_t| [N] = contact impulse / dt; a component's *average cumulative
  contact force* is its total divided by its number of elements (as EDEM averages per element;
  it therefore depends on the meshing -- compare components of similar triangle size).
* Archard (1953) sliding wear volume V = (K / H) F_n s [m^3] (K dimensionless wear coefficient,
  H hardness of the wall [Pa], s sliding distance). While a contact slides, |F_t| = mu F_n and
  E_t = mu sum F_n |v_t| dt, so sum F_n s = E_t / mu_pw; sticking contacts (v_t ~ 0) add
  almost nothing. Depth = V / triangle area.
* Finnie (1960) ductile erosion per impact V = k m v^2 f(alpha), f = sin 2 alpha - 3 sin^2 alpha
  for tan alpha <= 1/3, cos^2 alpha / 3 above (alpha the impact angle from the wall), k [m^3/J]
  a material constant (1 / (2 p) with p the wall's flow pressure in Finnie's form; the default
  5e-10 m^3/J is an order of magnitude for steel, so absolute numbers are indicative only).
  Impacts are found by :class:`ImpactRecorder` (a registered body-force model that adds no
  force): a wall contact slot with no match in the previous step (same wall, normal within
  acos 0.7 -- the engine's history rule) is a new impact, with m the body mass and v the contact
  point's velocity relative to the wall at that step.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from warpdem import kernels as wk
from warpdem.body_forces import BodyForceContext, BodyForceModel, ParameterSpec, register_body_force
from warpdem.errors import ConfigError
from warpdem.layouts import DEFAULT_SLOT_LAYOUT, entry_function

from .coupling import StructCache
from .geometry import BLADE_ZONES, COMPONENTS


# Finnie (1960) Wear 3:87: the two branches of f(alpha) meet where tan(alpha) = 1/3.
FINNIE_SWITCH_ANGLE = math.atan(1.0 / 3.0)  # [rad], 18.43 deg


def finnie_f(alpha: np.ndarray) -> np.ndarray:
    """Finnie's angle function f(alpha) (alpha [rad] from the wall, 0 to pi/2):
    sin 2a - 3 sin^2 a for a <= atan(1/3), cos^2 a / 3 above (0 at a head-on impact)."""
    a = np.asarray(alpha, dtype=float)
    return np.where(a <= FINNIE_SWITCH_ANGLE, np.sin(2 * a) - 3 * np.sin(a) ** 2, np.cos(a) ** 2 / 3.0)


@wp.func
def finnie_angle_function(alpha: float):
    """Finnie's f(alpha), device side (see :func:`finnie_f`). The branch is chosen on the angle, not
    on tan(alpha): a head-on impact's float32 angle lands just above pi/2, where tan is a huge
    negative number and would pick the low-angle branch (f = -3 instead of 0)."""
    if alpha <= wp.static(FINNIE_SWITCH_ANGLE):
        return wp.sin(2.0 * alpha) - 3.0 * wp.sin(alpha) * wp.sin(alpha)
    return wp.cos(alpha) * wp.cos(alpha) / 3.0


@wp.struct
class ImpactBodies:
    """Per sphere its body, and the bodies' state and mass, as the impact kernel reads them."""

    sphere_body: wp.array(dtype=int)  # (Model.sphere_body)
    sphere_world: wp.array(dtype=int)  # (Model.sphere_world)
    position: wp.array(dtype=wp.vec3)  # body centre of mass [m] (State.body_q)
    velocity: wp.array(dtype=wp.vec3)  # [m/s] (State.body_v)
    angular_velocity: wp.array(dtype=wp.vec3)  # [rad/s] (State.body_w)
    active: wp.array(dtype=int)  # (State.body_active)
    mass: wp.array(dtype=float)  # [kg] (Model.body_mass)


@wp.struct
class ContactSlots:
    """One State's contact slots: slot s of sphere i at i * per_sphere + s, or at
    s * num_spheres + i with the solver's ``history_layout="slot_major"``."""

    per_sphere: int  # slots per sphere (Model.max_contacts)
    count: wp.array(dtype=int)  # slots in use per sphere
    partner: wp.array(dtype=int)  # partner sphere, or -(wall + 1) for a wall
    wall_normal: wp.array(dtype=wp.vec3)  # unit normal of a wall contact


@wp.struct
class SlotContactPoints:
    """Where this step's contact slots touch (DEMSolver.slot_point, slot_tri)."""

    point: wp.array(dtype=wp.vec3)  # contact point [m]
    triangle: wp.array(dtype=int)  # triangle within its wall


@wp.struct
class WallMotions:
    """Per wall its triangle numbering and prescribed motion (Model.wall_*)."""

    triangle_offset: wp.array(dtype=int)  # first triangle of each wall in a world's numbering
    total_triangles: int  # triangles per world
    linear_velocity: wp.array(dtype=wp.vec3)  # [m/s]
    angular_velocity: wp.array(dtype=wp.vec3)  # [rad/s] about origin
    origin: wp.array(dtype=wp.vec3)  # [m]
    t_start: wp.array(dtype=float)  # motion starts [s]
    t_stop: wp.array(dtype=float)  # motion stops [s]


@wp.struct
class ImpactTallies:
    """Per triangle (index world * total_triangles + triangle) and overall, what the impacts add up to."""

    erosion: wp.array(dtype=float)  # Finnie volume [m^3]
    impacts: wp.array(dtype=float)  # count [-]
    impact_energy: wp.array(dtype=float)  # 1/2 m v_n^2 [J]
    max_normal_speed: wp.array(dtype=float)  # (1,): largest v_n of any impact [m/s]


@functools.lru_cache(maxsize=None)
def record_wall_impacts_kernel(history_layout: str = DEFAULT_SLOT_LAYOUT) -> "wp.Kernel":
    """:func:`record_wall_impacts` for the solver's contact-slot layout (``DEMSolver.history_layout``,
    :mod:`warpdem.layouts`), built once per layout."""
    entry = entry_function(history_layout)  # compiled in: where slot s of sphere i lies

    @wp.kernel
    def record_wall_impacts(bodies: ImpactBodies, before: ContactSlots, after: ContactSlots, points: SlotContactPoints,
                            walls: WallMotions, time: wp.array(dtype=wp.float64), finnie_k: float,
                            tallies: ImpactTallies):
        """New wall contacts of this step (in ``after``, not matched in ``before``) -> Finnie
        erosion V = k m v^2 f(alpha) [m^3], impact count and normal impact energy 1/2 m v_n^2 [J]
        per triangle; ``finnie_k`` [m^3/J], ``time`` [s] of the step's start."""
        i = wp.tid()
        b = bodies.sphere_body[i]
        if bodies.active[b] == 0:
            return
        rows = after.count.shape[0]
        slots = after.per_sphere
        t_now = time[0]
        for s in range(after.count[i]):
            e = entry(i, s, rows, slots)
            tag = after.partner[e]
            if tag >= 0:
                continue
            nrm = after.wall_normal[e]
            new = int(1)
            for o in range(before.count[i]):
                e_old = entry(i, o, rows, slots)
                if before.partner[e_old] == tag and wp.dot(before.wall_normal[e_old], nrm) > wk.WALL_MATCH_COS:
                    new = 0
            if new == 0:
                continue
            kw = -tag - 1
            cp = points.point[e]
            v_wall = wk.wall_point_velocity(t_now, walls.t_start[kw], walls.t_stop[kw], walls.origin[kw],
                                            walls.linear_velocity[kw], walls.angular_velocity[kw], cp)
            v_rel = bodies.velocity[b] + wp.cross(bodies.angular_velocity[b], cp - bodies.position[b]) - v_wall
            v_n = -wp.dot(v_rel, nrm)
            if v_n <= 0.0:
                continue
            v_t = wp.length(v_rel + v_n * nrm)
            alpha = wp.atan2(v_n, v_t)
            m = bodies.mass[b]
            idx = bodies.sphere_world[i] * walls.total_triangles + walls.triangle_offset[kw] + points.triangle[e]
            wp.atomic_add(tallies.erosion, idx, finnie_k * m * wp.dot(v_rel, v_rel) * finnie_angle_function(alpha))
            wp.atomic_add(tallies.impacts, idx, 1.0)
            wp.atomic_add(tallies.impact_energy, idx, 0.5 * m * v_n * v_n)
            wp.atomic_max(tallies.max_normal_speed, 0, v_n)

    return record_wall_impacts


@register_body_force
class ImpactRecorder(BodyForceModel):
    """Records wall impacts (Finnie erosion, count, normal impact energy) per triangle; adds no
    force. Arrays ``erosion`` [m^3], ``impacts`` [-], ``impact_energy`` [J] of shape
    (num_worlds * total_triangles,)."""

    name = "wall_impacts"
    parameters = (ParameterSpec("finnie_k", "m^3/J", 5.0e-10, (0.0, 1.0),
                                "Finnie erosion constant k in V = k m v^2 f"),)
    reference = "Finnie (1960) Wear 3:87"

    def bind(self, ctx: BodyForceContext) -> None:
        """Allocate the tallies; the kernel's other structs are built on first use per set of
        engine arrays (:class:`pump.coupling.StructCache`)."""
        m = ctx.model
        n = max(m.num_worlds * m.total_triangles, 1)
        self.erosion = wp.zeros(n, dtype=float, device=ctx.device)
        self.impacts = wp.zeros(n, dtype=float, device=ctx.device)
        self.impact_energy = wp.zeros(n, dtype=float, device=ctx.device)
        self.max_normal_speed = wp.zeros(1, dtype=float, device=ctx.device)  # largest v_n of any impact [m/s]
        self._tallies = ImpactTallies()
        self._tallies.erosion, self._tallies.impacts = self.erosion, self.impacts
        self._tallies.impact_energy, self._tallies.max_normal_speed = self.impact_energy, self.max_normal_speed

        def bodies(position, velocity, angular_velocity, active) -> ImpactBodies:
            v = ImpactBodies()
            v.sphere_body, v.sphere_world, v.mass = m.sphere_body, m.sphere_world, m.body_mass
            v.position, v.velocity, v.angular_velocity, v.active = position, velocity, angular_velocity, active
            return v

        def slots(count, partner, wall_normal) -> ContactSlots:
            v = ContactSlots()
            v.per_sphere, v.count, v.partner, v.wall_normal = m.max_contacts, count, partner, wall_normal
            return v

        def points(point, triangle) -> SlotContactPoints:
            v = SlotContactPoints()
            v.point, v.triangle = point, triangle
            return v

        def walls(triangle_offset, linear_velocity, angular_velocity, origin, t_start, t_stop) -> WallMotions:
            v = WallMotions()
            v.triangle_offset, v.total_triangles = triangle_offset, m.total_triangles
            v.linear_velocity, v.angular_velocity, v.origin = linear_velocity, angular_velocity, origin
            v.t_start, v.t_stop = t_start, t_stop
            return v

        self._bodies, self._slots = StructCache(bodies), StructCache(slots)
        self._points, self._walls = StructCache(points), StructCache(walls)

    def zero(self) -> None:
        for a in (self.erosion, self.impacts, self.impact_energy, self.max_normal_speed):
            a.zero_()

    def launch(self, ctx: BodyForceContext, state_in, state_out, dt: float) -> None:
        """Tally the wall contacts that are new in ``state_out`` (kernels only)."""
        m = ctx.model
        s = ctx.solver
        if not m.walls:
            return
        bodies = self._bodies(state_in.body_q, state_in.body_v, state_in.body_w, state_in.body_active)
        before = self._slots(state_in.contact_count, state_in.contact_partner, state_in.contact_wnormal)
        after = self._slots(state_out.contact_count, state_out.contact_partner, state_out.contact_wnormal)
        points = self._points(s.slot_point, s.slot_tri)
        walls = self._walls(m.wall_tri_offset, m.wall_lin_vel, m.wall_ang_vel, m.wall_origin, m.wall_t_start,
                            m.wall_t_stop)
        wp.launch(record_wall_impacts_kernel(s.history_layout), dim=m.num_spheres, inputs=[
            bodies, before, after, points, walls, state_in.time, self.values["finnie_k"], self._tallies],
            device=m.device)


# ----------------------------------------------------------------------------- read-out
FIELDS = ("energy_n", "energy_t", "impulse_n", "impulse_t")


@dataclass
class WearSeries:
    """Per-component totals over time (world-summed unless noted): ``time`` (k,) [s] and, per
    field of :data:`FIELDS` and per component, (k,) arrays."""

    time: list = field(default_factory=list)
    totals: dict = field(default_factory=dict)

    def as_arrays(self) -> tuple[np.ndarray, dict[str, dict[str, np.ndarray]]]:
        return np.asarray(self.time), {f: {c: np.asarray(v) for c, v in d.items()} for f, d in self.totals.items()}


class WearRecorder:
    """Reads the wall accumulators of a pump simulation: per-triangle fields, per-component
    totals and their time series, Archard and Finnie wear.

    Args:
        sim: the Simulation; walls: indices of the pump walls in ``sim.model.walls`` whose
            triangles carry component labels (indices into :data:`pump.geometry.COMPONENTS`).
        impacts: the model's :class:`ImpactRecorder`, if any (for Finnie erosion).
        zones: optional {wall index: (T,) blade zone per triangle} (:data:`BLADE_ZONES`).
    """

    def __init__(self, sim, walls: list[int], impacts: ImpactRecorder | None = None,
                 zones: dict[int, np.ndarray] | None = None) -> None:
        self.sim = sim
        self.walls = list(walls)
        self.impacts = impacts
        self.zones = {int(k): np.asarray(v) for k, v in (zones or {}).items()}
        m = sim.model
        for w in self.walls:
            wall = m.walls[w]
            if wall.triangle_labels is None:
                raise ConfigError(f"wall '{wall.name}' has no triangle labels; the pump walls need component labels")
        self.series = WearSeries()
        self.count_series: list[np.ndarray] = []

    # ---------------------------------------------------------------- per triangle
    def per_triangle(self, field: str, world: int | None = None) -> dict[int, np.ndarray]:
        """{wall index: (T,) values} of one accumulator ('energy_n', 'energy_t', 'impulse_n',
        'impulse_t', or 'erosion'/'impacts'/'impact_energy' from the impact recorder), summed over
        the worlds (``world=None``) or of one world."""
        m = self.sim.model
        if field in FIELDS:
            full = getattr(self.sim.solver.wall_stats, field).numpy()
        elif self.impacts is not None and field in ("erosion", "impacts", "impact_energy"):
            full = getattr(self.impacts, field).numpy()
        else:
            raise ConfigError(f"unknown wear field '{field}'; valid: {list(FIELDS)} + erosion, impacts, impact_energy "
                              f"(with an ImpactRecorder)")
        a = full[: m.num_worlds * m.total_triangles].reshape(m.num_worlds, m.total_triangles).astype(np.float64)
        a = a.sum(axis=0) if world is None else a[world]
        return {w: a[m.walls[w].tri_offset: m.walls[w].tri_offset + m.walls[w].num_triangles] for w in self.walls}

    def labels(self) -> dict[int, np.ndarray]:
        return {w: np.asarray(self.sim.model.walls[w].triangle_labels) for w in self.walls}

    def areas(self) -> dict[int, np.ndarray]:
        out = {}
        for w in self.walls:
            wall = self.sim.model.walls[w]
            v, f = wall.vertices, wall.faces
            out[w] = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
        return out

    def per_component(self, field: str, world: int | None = None) -> dict[str, float]:
        """Total of one field per component (all pump walls together)."""
        vals = self.per_triangle(field, world)
        labs = self.labels()
        out = {c: 0.0 for c in COMPONENTS}
        for w, v in vals.items():
            for k, c in enumerate(COMPONENTS):
                out[c] += float(v[labs[w] == k].sum())
        return {c: v for c, v in out.items() if any((labs[w] == COMPONENTS.index(c)).any() for w in labs)}

    def triangles_per_component(self) -> dict[str, int]:
        labs = self.labels()
        out = {c: int(sum((l == k).sum() for l in labs.values())) for k, c in enumerate(COMPONENTS)}
        return {c: n for c, n in out.items() if n > 0}

    def cumulative_force(self, world: int | None = None, average: bool = True) -> dict[str, dict[str, float]]:
        """Cumulative contact force sum_steps |F| [N] per component, normal and tangential;
        ``average``: divided by the component's number of triangles (the paper's Fig. 18)."""
        dt = self.sim.dt
        n_tri = self.triangles_per_component()
        out = {}
        for kind, fld in (("normal", "impulse_n"), ("tangential", "impulse_t")):
            tot = self.per_component(fld, world)
            out[kind] = {c: v / dt / (n_tri[c] if average else 1) for c, v in tot.items()}
        return out

    def archard_volume(self, wear_coefficient: float, hardness: float,
                       world: int | None = None) -> dict[int, np.ndarray]:
        """Archard volume per triangle V = (K / H) E_t / mu_pw [m^3] (see module doc)."""
        if not (wear_coefficient > 0 and hardness > 0):
            raise ConfigError(f"Archard needs wear_coefficient > 0 and hardness > 0 Pa, "
                              f"got {wear_coefficient}, {hardness}")
        mu = self.sim.model.get_contact_parameter("mu_s_pw")
        m = self.sim.model
        e_t = getattr(self.sim.solver.wall_stats, "energy_t").numpy()[: m.num_worlds * m.total_triangles]
        e_t = e_t.reshape(m.num_worlds, m.total_triangles).astype(np.float64)
        if np.any(mu <= 0):
            raise ConfigError("Archard wear from the tangential energy needs mu_s_pw > 0 in every world")
        s = e_t / mu[:, None]  # sum F_n * sliding distance per world [N m]
        s = s.sum(axis=0) if world is None else s[world]
        k = wear_coefficient / hardness
        return {w: k * s[m.walls[w].tri_offset: m.walls[w].tri_offset + m.walls[w].num_triangles] for w in self.walls}

    # ---------------------------------------------------------------- time series
    def sample(self) -> None:
        """Append the current per-component totals (all worlds) to the time series."""
        self.series.time.append(self.sim.time)
        for f in FIELDS:
            tot = self.per_component(f)
            d = self.series.totals.setdefault(f, {})
            for c, v in tot.items():
                d.setdefault(c, []).append(v)

    def blade_zone_totals(self, field: str) -> dict[str, float]:
        """Totals of one field over the blade zones (leading edge, pressure/suction side,
        trailing edge) and their areas [m^2] (key '<zone>_area')."""
        out = {}
        vals = self.per_triangle(field)
        areas = self.areas()
        for w in self.walls:
            zone = self.zones.get(w)
            if zone is None:
                continue
            for k, z in enumerate(BLADE_ZONES[1:], start=1):
                sel = zone == k
                out[z] = out.get(z, 0.0) + float(vals[w][sel].sum())
                out[z + "_area"] = out.get(z + "_area", 0.0) + float(areas[w][sel].sum())
        return out
