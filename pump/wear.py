"""Wear of the pump walls from the DEM contacts: what is accumulated, and the metrics derived from it.

Accumulated per triangle and world (the engine adds the first four in every wall contact,
:class:`warpdem.solver.WallStats`; v is the velocity of the particle's contact point relative to
the wall, split into normal v_n and tangential v_t parts, F = F_n + F_t the contact force):

* normal / tangential contact impulse J_n = sum_steps |F_n| dt, J_t = sum_steps |F_t| dt [N s];
* normal / tangential contact energy E_n = sum |F_n v_n| dt, E_t = sum |F_t . v_t| dt [J] (EDEM's
  "relative wear" energies, the seed paper's Fig. 17);
* impacts (new wall contacts), DNV-RP-O501 erosion mass [kg] and normal impact energy 1/2 m v_n^2
  [J], by :class:`ImpactRecorder` (a registered body-force model that adds no force): a contact slot
  with no match in the previous step (same wall, normal within acos 0.7, the engine's history
  rule) is a new impact, with m the body mass and v the contact point's velocity relative to the
  wall at that step; erosion per impact m K U^n F(alpha) (:mod:`pump.erosion`).

Metrics (:data:`METRICS`, defined here once; :meth:`WearRecorder.metric`): every metric is
computed per world and then averaged over the worlds (independent replicates), so it does not
grow with the number of worlds; T is the simulated time elapsed since the accumulators started
(:attr:`WearRecorder.elapsed`); a group is one triangle, a component or a region
(:mod:`pump.regions`) with area A:

    force_n = J_n / T [N]              time-averaged normal contact force (tangential: force_t)
    pressure_n = J_n / (T A) [Pa]      its value per unit area (intensive: what a map shows)
    energy_n_per_area = E_n / A [J/m^2], power_n_per_area = E_n / (T A) [W/m^2]
    dnv_depth_rate = M_dnv / (rho_t A T) [mm/year], archard_depth_rate = (K_a/H)(E_t/mu_pw) / (A T)
    edem_cumulative_force_n = J_n / (dt n_elements) [N]

The last is what EDEM calls the "average cumulative contact force" and the seed paper plots in its
Fig. 18: the sum over time steps of |F| per element. It is kept under this name for comparison
only: it doubles when dt halves (it counts steps) and, per element, shrinks as the mesh is refined.
J, E and their per-area and per-time forms do neither (tests/test_pump_metrics.py).

Archard: while a contact slides |F_t| = mu F_n, so E_t = mu sum F_n |v_t| dt and sum F_n s = E_t /
mu_pw; sticking contacts (v_t ~ 0) add almost nothing. The work of the normal force per impact is
summed with the step's start velocity: +O(dt / t_c) (pump/README.md, "Time step").
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpdem import kernels as wk
from warpdem.body_forces import BodyForceContext, BodyForceModel, ParameterSpec, register_body_force
from warpdem.errors import ConfigError
from warpdem.layouts import DEFAULT_SLOT_LAYOUT, entry_function

from .coupling import StructCache
from .erosion import ArchardWear, DNVErosion, depth_rate_mm_per_year
from .geometry import COMPONENTS
from .regions import REGIONS, BlockSeries

#: name -> (unit, definition) of every wear metric (module docstring)
METRICS: dict[str, tuple[str, str]] = {
    "impulse_n": ("N s", "accumulated normal contact impulse J_n = sum over steps of |F_n| dt"),
    "impulse_t": ("N s", "accumulated tangential contact impulse J_t = sum over steps of |F_t| dt"),
    "force_n": ("N", "time-averaged normal contact force J_n / T (T: elapsed simulated time)"),
    "force_t": ("N", "time-averaged tangential contact force J_t / T"),
    "pressure_n": ("Pa", "time-averaged normal contact force per unit area J_n / (T A)"),
    "pressure_t": ("Pa", "time-averaged tangential contact force per unit area J_t / (T A)"),
    "energy_n": ("J", "accumulated normal contact energy E_n = sum |F_n v_n| dt (EDEM relative wear)"),
    "energy_t": ("J", "accumulated tangential contact energy E_t = sum |F_t . v_t| dt (EDEM relative wear)"),
    "energy_n_per_area": ("J/m^2", "E_n / A"),
    "energy_t_per_area": ("J/m^2", "E_t / A"),
    "power_n_per_area": ("W/m^2", "normal contact energy rate per unit area E_n / (T A)"),
    "power_t_per_area": ("W/m^2", "tangential contact energy rate per unit area E_t / (T A)"),
    "impacts": ("-", "new wall contacts (impacts)"),
    "impact_rate_per_area": ("1/(m^2 s)", "impacts / (T A)"),
    "dnv_erosion_mass": ("kg", "DNV-RP-O501 erosion: sum over impacts of m K U^n F(alpha)"),
    "dnv_depth_rate": ("mm/year", "DNV erosion depth rate M / (rho_t A T), continuous operation"),
    "archard_depth_rate": ("mm/year", "Archard sliding-wear depth rate (K_a / H)(E_t / mu_pw) / (A T)"),
    "edem_cumulative_force_n": ("N", "EDEM 'average cumulative contact force' (seed paper Fig. 18): "
                                     "sum over steps of |F_n| per element = J_n / (dt n_elements); dt- and "
                                     "mesh-dependent, for comparison only"),
    "edem_cumulative_force_t": ("N", "as edem_cumulative_force_n, tangential"),
}

#: accumulated base fields per group and world: engine (:class:`warpdem.solver.WallStats`) and impacts
ENGINE_FIELDS = ("energy_n", "energy_t", "impulse_n", "impulse_t")
IMPACT_FIELDS = ("impacts", "erosion", "impact_energy", "finnie")
BASE_FIELDS = ENGINE_FIELDS + ("impacts", "erosion", "sliding_work")  # sliding_work = E_t / mu_pw [N m]

#: DNV eq. 3.3 ductile constants, compiled into the impact kernel
_DNV = DNVErosion()

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

    erosion: wp.array(dtype=float)  # DNV-RP-O501 wall mass lost [kg]
    finnie: wp.array(dtype=float)  # Finnie (1960) volume [m^3] (only with finnie_k > 0; no published k)
    impacts: wp.array(dtype=float)  # count [-]
    impact_energy: wp.array(dtype=float)  # 1/2 m v_n^2 [J]
    max_normal_speed: wp.array(dtype=float)  # (1,): largest v_n of any impact [m/s]


# Finnie (1960) Wear 3:87: the two branches of f(alpha) meet where tan(alpha) = 1/3.
FINNIE_SWITCH_ANGLE = math.atan(1.0 / 3.0)  # [rad], 18.43 deg


def finnie_f(alpha: np.ndarray) -> np.ndarray:
    """Finnie's angle function f(alpha) (alpha [rad] from the wall, 0 to pi/2):
    sin 2a - 3 sin^2 a for a <= atan(1/3), cos^2 a / 3 above (0 at a head-on impact)."""
    a = np.asarray(alpha, dtype=float)
    return np.where(a <= FINNIE_SWITCH_ANGLE, np.sin(2 * a) - 3 * np.sin(a) ** 2, np.cos(a) ** 2 / 3.0)


@wp.func
def finnie_angle_function(alpha: float):
    """Finnie's f(alpha), device side (see :func:`finnie_f`); the branch is chosen on the angle (a
    head-on impact's float32 angle lands just above pi/2, where tan would pick the wrong branch)."""
    if alpha <= wp.static(FINNIE_SWITCH_ANGLE):
        return wp.sin(2.0 * alpha) - 3.0 * wp.sin(alpha) * wp.sin(alpha)
    return wp.cos(alpha) * wp.cos(alpha) / 3.0


@wp.func
def dnv_angle_function(alpha: float):
    """DNV-RP-O501 (2015) eq. 3.3, ductile: F = A (sin a + B (sin a - sin^2 a))^k (1 - exp(-C a)),
    A = 0.6, B = 7.2, C = 20, k = 0.6 (:class:`pump.erosion.DNVErosion`); alpha [rad] from the wall."""
    a = wp.clamp(alpha, 0.0, 1.5707963)
    s = wp.sin(a)
    base = wp.max(s + wp.static(_DNV.B) * (s - s * s), 0.0)
    return wp.static(_DNV.A) * wp.pow(base, wp.static(_DNV.k)) * (1.0 - wp.exp(-wp.static(_DNV.C) * a))


@functools.lru_cache(maxsize=None)
def record_wall_impacts_kernel(history_layout: str = DEFAULT_SLOT_LAYOUT) -> "wp.Kernel":
    """:func:`record_wall_impacts` for the solver's contact-slot layout (``DEMSolver.history_layout``,
    :mod:`warpdem.layouts`), built once per layout."""
    entry = entry_function(history_layout)  # compiled in: where slot s of sphere i lies

    @wp.kernel
    def record_wall_impacts(bodies: ImpactBodies, before: ContactSlots, after: ContactSlots, points: SlotContactPoints,
                            walls: WallMotions, time: wp.array(dtype=wp.float64), dnv_k: float, dnv_n: float,
                            finnie_k: float, tallies: ImpactTallies):
        """New wall contacts of this step (in ``after``, not matched in ``before``) -> DNV erosion
        mass m K U^n F(alpha) [kg], Finnie volume finnie_k m U^2 f(alpha) [m^3], impact count and
        normal impact energy 1/2 m v_n^2 [J] per triangle; ``time`` [s] of the step's start."""
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
            speed = wp.length(v_rel)
            idx = bodies.sphere_world[i] * walls.total_triangles + walls.triangle_offset[kw] + points.triangle[e]
            wp.atomic_add(tallies.erosion, idx, m * dnv_k * wp.pow(speed, dnv_n) * dnv_angle_function(alpha))
            wp.atomic_add(tallies.finnie, idx, finnie_k * m * speed * speed * finnie_angle_function(alpha))
            wp.atomic_add(tallies.impacts, idx, 1.0)
            wp.atomic_add(tallies.impact_energy, idx, 0.5 * m * v_n * v_n)
            wp.atomic_max(tallies.max_normal_speed, 0, v_n)

    return record_wall_impacts


@register_body_force
class ImpactRecorder(BodyForceModel):
    """Records wall impacts per triangle and world; adds no force. Arrays of shape
    (num_worlds * total_triangles,): ``erosion`` (DNV-RP-O501 wall mass [kg], :mod:`pump.erosion`),
    ``impacts`` [-], ``impact_energy`` [J], ``finnie`` (Finnie volume [m^3], zero unless a
    ``finnie_k`` is given: no published k exists for this wall, so it is off by default)."""

    name = "wall_impacts"
    parameters = (ParameterSpec("dnv_K", "(m/s)^-n", _DNV.K, (0.0, 1.0),
                                "DNV-RP-O501 material constant K in E_m = K U^n F(alpha) (steel grades: 2e-9)"),
                  ParameterSpec("dnv_n", "-", _DNV.n, (0.0, 6.0),
                                "DNV-RP-O501 velocity exponent n (steel grades: 2.6)"),
                  ParameterSpec("finnie_k", "m^3/J", 0.0, (0.0, 1.0),
                                "Finnie erosion constant k in V = k m v^2 f (0: off; no published value for this wall)"))
    reference = "DNVGL-RP-O501 (2015) Sec. 3; Finnie (1960) Wear 3:87"

    def bind(self, ctx: BodyForceContext) -> None:
        """Allocate the tallies; the kernel's other structs are built on first use per set of
        engine arrays (:class:`pump.coupling.StructCache`)."""
        m = ctx.model
        n = max(m.num_worlds * m.total_triangles, 1)
        self.erosion = wp.zeros(n, dtype=float, device=ctx.device)
        self.finnie = wp.zeros(n, dtype=float, device=ctx.device)
        self.impacts = wp.zeros(n, dtype=float, device=ctx.device)
        self.impact_energy = wp.zeros(n, dtype=float, device=ctx.device)
        self.max_normal_speed = wp.zeros(1, dtype=float, device=ctx.device)  # largest v_n of any impact [m/s]
        self._tallies = ImpactTallies()
        self._tallies.erosion, self._tallies.finnie, self._tallies.impacts = self.erosion, self.finnie, self.impacts
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
        for a in (self.erosion, self.finnie, self.impacts, self.impact_energy, self.max_normal_speed):
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
            bodies, before, after, points, walls, state_in.time, self.values["dnv_K"], self.values["dnv_n"],
            self.values["finnie_k"], self._tallies], device=m.device)


# ----------------------------------------------------------------------------- read-out
RATE_METRICS = ("force_n", "force_t", "pressure_n", "pressure_t", "power_n_per_area", "power_t_per_area",
                "impact_rate_per_area", "dnv_depth_rate", "archard_depth_rate")


def derive(name: str, totals: dict[str, np.ndarray], area: np.ndarray, triangles: np.ndarray, duration: float,
           dt: float, dnv: DNVErosion = _DNV, archard: ArchardWear = ArchardWear()) -> np.ndarray:
    """One metric of :data:`METRICS` from accumulated base fields (``totals``: field -> (..., G)
    arrays accumulated over ``duration`` [s]; ``area`` (G,) [m^2], ``triangles`` (G,) elements)."""
    if name not in METRICS:
        raise ConfigError(f"unknown wear metric '{name}'; valid: {sorted(METRICS)}")
    a = np.asarray(area, dtype=float)
    safe_a = np.where(a > 0, a, np.nan)
    per_t = 1.0 / duration if duration > 0 else math.nan
    kind = name[-1] if name[-2:] in ("_n", "_t") else ""
    if name in ("impulse_n", "impulse_t", "energy_n", "energy_t", "impacts"):
        return totals[name]
    if name.startswith("force_"):
        return totals["impulse_" + kind] * per_t
    if name.startswith("pressure_"):
        return totals["impulse_" + kind] * per_t / safe_a
    if name.endswith("_per_area") and name.startswith("energy_"):
        return totals[name[: len("energy_n")]] / safe_a
    if name.startswith("power_"):
        return totals["energy_" + name[len("power_")]] * per_t / safe_a
    if name == "impact_rate_per_area":
        return totals["impacts"] * per_t / safe_a
    if name == "dnv_erosion_mass":
        return totals["erosion"]
    if name == "dnv_depth_rate":
        return depth_rate_mm_per_year(totals["erosion"] / dnv.density, a, duration)
    if name == "archard_depth_rate":
        return depth_rate_mm_per_year(archard.volume(totals["sliding_work"]), a, duration)
    if name.startswith("edem_cumulative_force_"):
        return totals["impulse_" + kind] / dt / np.where(np.asarray(triangles) > 0, triangles, np.nan)
    raise AssertionError(name)  # every name of METRICS is handled above


@dataclass
class GroupTotals:
    """Base fields accumulated per world and group: ``totals`` field -> (worlds, G) over
    ``elapsed`` [s]; ``area`` (G,) [m^2], ``triangles`` (G,), group ``names``."""

    kind: str
    names: list
    area: np.ndarray
    triangles: np.ndarray
    totals: dict
    elapsed: float
    dt: float


class WearRecorder:
    """Reads the wall accumulators of a simulation: per-triangle fields, per-group (component,
    region, triangle) totals per world, the metrics of :data:`METRICS` as ensemble means over the
    worlds, and snapshots of the per-world region totals (for confidence intervals).

    Args:
        sim: the Simulation; walls: indices of the walls in ``sim.model.walls`` whose triangles
            carry component labels (indices into :data:`pump.geometry.COMPONENTS`).
        impacts: the model's :class:`ImpactRecorder`, if any (impacts, DNV erosion).
        regions: optional {wall index: (T,) region index into :data:`pump.regions.REGIONS`}.
        dnv, archard: erosion and sliding-wear constants (:mod:`pump.erosion`).
        t_start: simulated time [s] at which the accumulators started (0: with the simulation;
            :meth:`reset` zeroes them and restarts the clock).
    """

    def __init__(self, sim, walls: list[int], impacts: ImpactRecorder | None = None,
                 regions: dict[int, np.ndarray] | None = None,
                 dnv: DNVErosion = _DNV, archard: ArchardWear = ArchardWear(), t_start: float = 0.0) -> None:
        self.sim = sim
        self.walls = list(walls)
        self.impacts = impacts
        self.regions = {int(k): np.asarray(v, dtype=np.int64) for k, v in (regions or {}).items()}
        self.dnv, self.archard = dnv, archard
        m = sim.model
        for w in self.walls:
            wall = m.walls[w]
            if wall.triangle_labels is None:
                raise ConfigError(f"wall '{wall.name}' has no triangle labels; the pump walls need component labels")
            if w in self.regions and self.regions[w].shape != (wall.num_triangles,):
                raise ConfigError(f"wall '{wall.name}': regions need one entry per triangle ({wall.num_triangles})")
        if self.regions and set(self.regions) != set(self.walls):
            raise ConfigError("regions must be given for every recorded wall or for none")
        self.t_start = float(t_start)
        self.series = {"component": BlockSeries(), "region": BlockSeries()}

    # ---------------------------------------------------------------- time
    @property
    def elapsed(self) -> float:
        """Simulated time since the accumulators started [s]."""
        return float(self.sim.time) - self.t_start

    def reset(self) -> None:
        """Zero the wall accumulators (and the impact tallies) and restart the clock and the series."""
        self.sim.solver.wall_stats.zero()
        if self.impacts is not None:
            self.impacts.zero()
        self.t_start = float(self.sim.time)
        self.series = {"component": BlockSeries(), "region": BlockSeries()}

    # ---------------------------------------------------------------- per triangle
    def world_field(self, field: str) -> np.ndarray:
        """(worlds, T) one accumulated field over the recorded walls' triangles (in wall order):
        an engine field (:data:`ENGINE_FIELDS`), an impact tally (:data:`IMPACT_FIELDS`, needs an
        :class:`ImpactRecorder`) or ``sliding_work`` = E_t / mu_pw [N m] (Archard's sum F_n s)."""
        m = self.sim.model
        if field in ENGINE_FIELDS:
            stats = self.sim.solver.wall_stats
            entries = self.__dict__.setdefault("_entries", {})
            if not entries:  # (worlds, T) accumulator entry of every recorded triangle, -1 where absent
                entries["all"] = np.concatenate([stats.wall_entries(w) for w in self.walls], axis=1)
            idx = entries["all"]
            a = stats.summed(field).numpy().astype(np.float64)  # one read of the device array
            return np.where(idx >= 0, a[np.maximum(idx, 0)], 0.0)
        if field in IMPACT_FIELDS and self.impacts is not None:
            full = getattr(self.impacts, field).numpy()[: m.num_worlds * m.total_triangles].astype(np.float64)
            full = full.reshape(m.num_worlds, m.total_triangles)
            return np.concatenate([full[:, m.walls[w].tri_offset: m.walls[w].tri_offset + m.walls[w].num_triangles]
                                   for w in self.walls], axis=1)
        if field == "sliding_work":
            mu = np.asarray(m.get_contact_parameter("mu_s_pw"), dtype=float)
            if np.any(mu <= 0):
                raise ConfigError("Archard wear from the tangential energy needs mu_s_pw > 0 in every world")
            return self.world_field("energy_t") / mu[:, None]
        raise ConfigError(f"unknown wear field '{field}'; valid: {list(ENGINE_FIELDS)} + sliding_work"
                          + (f" + {list(IMPACT_FIELDS)}" if self.impacts is not None else
                             " (impacts, erosion, ... need an ImpactRecorder)"))

    def _split(self, a: np.ndarray) -> dict[int, np.ndarray]:
        out, k = {}, 0
        for w in self.walls:
            n = self.sim.model.walls[w].num_triangles
            out[w] = a[..., k: k + n]
            k += n
        return out

    def per_triangle(self, field: str, world: int | None = None) -> dict[int, np.ndarray]:
        """{wall index: (T,) values} of one accumulated field: the mean over the worlds
        (``world=None``) or one world's."""
        a = self.world_field(field)
        return self._split(a.mean(axis=0) if world is None else a[world])

    def labels(self) -> dict[int, np.ndarray]:
        return {w: np.asarray(self.sim.model.walls[w].triangle_labels) for w in self.walls}

    def areas(self) -> dict[int, np.ndarray]:
        out = {}
        for w in self.walls:
            wall = self.sim.model.walls[w]
            v, f = wall.vertices, wall.faces
            out[w] = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
        return out

    # ---------------------------------------------------------------- groups
    def groups(self, kind: str) -> tuple[list[str], np.ndarray]:
        """Group names (only those with triangles) and each triangle's group index (in wall order)
        for ``kind`` 'component', 'region' or 'triangle'."""
        if kind == "triangle":
            n = sum(self.sim.model.walls[w].num_triangles for w in self.walls)
            return [str(i) for i in range(n)], np.arange(n)
        if kind == "component":
            lab, names = np.concatenate([self.labels()[w] for w in self.walls]), COMPONENTS
        elif kind == "region":
            if not self.regions:
                raise ConfigError("no regions given to the WearRecorder (regions={wall: region index per triangle})")
            lab, names = np.concatenate([self.regions[w] for w in self.walls]), REGIONS
        else:
            raise ConfigError(f"unknown group kind '{kind}'; valid: component, region, triangle")
        used = np.unique(lab)
        remap = np.full(len(names), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        return [names[k] for k in used], remap[lab]

    def _base_fields(self) -> tuple[str, ...]:
        return BASE_FIELDS if self.impacts is not None else ENGINE_FIELDS + ("sliding_work",)

    def _indicator(self, kind: str):
        """Sparse (T, G) matrix: 1 where triangle t belongs to group g (cached per kind)."""
        cache = self.__dict__.setdefault("_indicators", {})
        if kind not in cache:
            from scipy.sparse import csr_matrix

            names, idx = self.groups(kind)
            cache[kind] = csr_matrix((np.ones(len(idx)), (np.arange(len(idx)), idx)), shape=(len(idx), len(names)))
        return cache[kind]

    def base_values(self) -> dict[str, np.ndarray]:
        """Every base field (:data:`BASE_FIELDS`) per world and triangle: field -> (worlds, T);
        each accumulator is read from the device once."""
        out = {f: self.world_field(f) for f in self._base_fields() if f != "sliding_work"}
        mu = np.asarray(self.sim.model.get_contact_parameter("mu_s_pw"), dtype=float)
        if np.any(mu <= 0):
            raise ConfigError("Archard wear from the tangential energy needs mu_s_pw > 0 in every world")
        out["sliding_work"] = out["energy_t"] / mu[:, None]
        return out

    def group_values(self, kind: str, values: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """Base fields summed per world and group: field -> (worlds, G) (``values``: from
        :meth:`base_values`, read now when None)."""
        values = self.base_values() if values is None else values
        m = self._indicator(kind)
        return {f: np.asarray(m.T @ a.T).T for f, a in values.items()}

    def totals(self, kind: str = "component") -> GroupTotals:
        """Everything accumulated so far per world and group (see :class:`GroupTotals`)."""
        names, idx = self.groups(kind)
        area = np.bincount(idx, weights=np.concatenate([self.areas()[w] for w in self.walls]), minlength=len(names))
        tri = np.bincount(idx, minlength=len(names)).astype(float)
        return GroupTotals(kind, names, area, tri, self.group_values(kind), self.elapsed, self.sim.dt)

    def metric_per_world(self, name: str, kind: str = "component") -> tuple[list[str], np.ndarray]:
        """Group names and (worlds, G) values of one metric of :data:`METRICS`."""
        g = self.totals(kind)
        return g.names, derive(name, g.totals, g.area, g.triangles, g.elapsed, g.dt, self.dnv, self.archard)

    def metric(self, name: str, kind: str = "component", world: int | None = None) -> dict[str, float]:
        """{group: value} of one metric of :data:`METRICS`: the mean over the worlds
        (``world=None``) or one world's."""
        names, v = self.metric_per_world(name, kind)
        v = v.mean(axis=0) if world is None else v[world]
        return {n: float(x) for n, x in zip(names, v)}

    # ---------------------------------------------------------------- compatibility helpers
    def per_component(self, field: str, world: int | None = None) -> dict[str, float]:
        """Accumulated total of one field per component: mean over the worlds (``world=None``)
        or one world's."""
        names, idx = self.groups("component")
        a = self.world_field(field)
        a = a.mean(axis=0) if world is None else a[world]
        return {n: float(v) for n, v in zip(names, np.bincount(idx, weights=a, minlength=len(names)))}

    def triangles_per_component(self) -> dict[str, int]:
        names, idx = self.groups("component")
        return {n: int(c) for n, c in zip(names, np.bincount(idx, minlength=len(names)))}

    def edem_cumulative_force(self, world: int | None = None) -> dict[str, dict[str, float]]:
        """EDEM's "average cumulative contact force" per component [N] (seed paper Fig. 18):
        sum over steps of |F| per element = J / (dt n_elements), normal and tangential. It counts
        time steps (doubles when dt halves) and depends on the element size: comparison only."""
        return {"normal": self.metric("edem_cumulative_force_n", world=world),
                "tangential": self.metric("edem_cumulative_force_t", world=world)}

    def archard_volume(self, wear_coefficient: float | None = None, hardness: float | None = None,
                       world: int | None = None) -> dict[int, np.ndarray]:
        """Archard volume per triangle V = (K_a / H) E_t / mu_pw [m^3] (module doc); defaults:
        :class:`pump.erosion.ArchardWear`."""
        k = self.archard.wear_coefficient if wear_coefficient is None else wear_coefficient
        h = self.archard.hardness if hardness is None else hardness
        if not (k > 0 and h > 0):
            raise ConfigError(f"Archard needs wear_coefficient > 0 and hardness > 0 Pa, got {k}, {h}")
        return {w: ArchardWear(k, h).volume(v) for w, v in self.per_triangle("sliding_work", world).items()}

    # ---------------------------------------------------------------- snapshots
    def sample(self) -> None:
        """Append the current per-world totals of every base field, per component and (with
        regions) per region, to :attr:`series` (time: simulated time [s])."""
        t = float(self.sim.time)
        values = self.base_values()
        self.series["component"].append(t, self.group_values("component", values))
        if self.regions:
            self.series["region"].append(t, self.group_values("region", values))
