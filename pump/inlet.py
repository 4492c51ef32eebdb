"""Particles in and out of the pump without reallocating: an inlet that activates pre-allocated
bodies on a schedule, an outlet that deactivates the bodies leaving the discharge, and counts
per region.

The model is built once with every particle the run will ever inject ("reserve" bodies), parked
far below the pump and inactive (``body_active = 0``: no contacts, not integrated, out of the
neighbour list). Injection flips a body to active and gives it its inlet pose and velocity in a
kernel; removal flips it back. Arrays never change, so a captured CUDA graph stays valid; the
two kernels run between graph replays (every ``update`` call, e.g. every 0.5 ms of simulated
time), and a body scheduled at t_i but activated at t >= t_i is placed where it would be had it
entered at t_i (x_i + v_i (t - t_i)), so the stream stays evenly spaced.

Rate: the solids volume flux is phi Q, so n_dot = phi Q / V_mean particles per second (phi the
delivered volume fraction, V_mean the mean particle volume). Positions: a hexagonal lattice of
slots in the suction pipe's cross-section, ``slot_clearance`` apart, at a plane one particle
below the pipe's open end; a slot is reused only after the previous particle has moved one slot
spacing down the pipe at the fluid speed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpdem.builder import random_quaternions
from warpdem.errors import ConfigError

from .coupling import StructCache
from .geometry import REGIONS, PumpGeometry

PARK_DEPTH = 2.0  # parked bodies sit this far [m] below the pump


@wp.struct
class InjectionSchedule:
    """The scheduled particles, in time order per world."""

    time: wp.array(dtype=float)  # scheduled entry time [s]
    body: wp.array(dtype=int)  # reserve body injected
    position: wp.array(dtype=wp.vec3)  # entry position at that time [m]
    velocity: wp.array(dtype=wp.vec3)  # entry velocity [m/s]
    injected: wp.array(dtype=int)  # 1 once activated


@wp.struct
class BodyMotion:
    """One State's body arrays the inlet and outlet write, and each body's world."""

    active: wp.array(dtype=int)  # (State.body_active)
    position: wp.array(dtype=wp.vec3)  # centre of mass [m] (State.body_q)
    velocity: wp.array(dtype=wp.vec3)  # [m/s] (State.body_v)
    angular_velocity: wp.array(dtype=wp.vec3)  # [rad/s] (State.body_w)
    world: wp.array(dtype=int)  # (Model.body_world)


@wp.struct
class ExitRegions:
    """Where bodies leave: the discharge's open end and the pump's bounding box."""

    outlet_y: float  # plane of the discharge's open end [m]
    outlet_x0: float  # x range of the discharge opening [m]
    outlet_x1: float
    lower: wp.vec3  # bounding box of the pump, with a margin [m]
    upper: wp.vec3


@wp.kernel
def activate_scheduled(schedule: InjectionSchedule, bodies: BodyMotion, time: wp.array(dtype=wp.float64),
                       rebuild: wp.array(dtype=int), count: wp.array(dtype=int)):
    """Activate every scheduled body whose time has come, at the pose it would have reached;
    set ``rebuild`` (neighbour list) and add to ``count`` (injected so far)."""
    i = wp.tid()
    if schedule.injected[i] != 0:
        return
    t = float(time[0])
    if t < schedule.time[i]:
        return
    b = schedule.body[i]
    schedule.injected[i] = 1
    bodies.active[b] = 1
    bodies.position[b] = schedule.position[i] + schedule.velocity[i] * (t - schedule.time[i])
    bodies.velocity[b] = schedule.velocity[i]
    bodies.angular_velocity[b] = wp.vec3(0.0)
    rebuild[0] = 1
    wp.atomic_add(count, 0, 1)


@wp.kernel
def remove_leaving(bodies: BodyMotion, exits: ExitRegions, removed_outlet: wp.array(dtype=int),
                   removed_lost: wp.array(dtype=int)):
    """Deactivate bodies past the discharge's open end (counted per world as 'outlet') and
    bodies outside the pump's bounding box elsewhere (counted as 'lost': back out of the
    suction pipe, or through a gap in user meshes)."""
    b = wp.tid()
    if bodies.active[b] == 0:
        return
    x = bodies.position[b]
    if x[1] > exits.outlet_y and x[0] > exits.outlet_x0 and x[0] < exits.outlet_x1:
        bodies.active[b] = 0
        wp.atomic_add(removed_outlet, bodies.world[b], 1)
        return
    lo = exits.lower
    hi = exits.upper
    if x[0] < lo[0] or x[1] < lo[1] or x[2] < lo[2] or x[0] > hi[0] or x[1] > hi[1] or x[2] > hi[2]:
        bodies.active[b] = 0
        wp.atomic_add(removed_lost, bodies.world[b], 1)


def injection_rate(volume_fraction: float, flow_rate: float, mean_volume: float) -> float:
    """Particles per second delivering the solids volume fraction phi: phi Q / V_mean [1/s]."""
    if not 0.0 < volume_fraction < 0.6:
        raise ConfigError(f"volume_fraction must lie in (0, 0.6), got {volume_fraction}")
    return volume_fraction * flow_rate / mean_volume


def inlet_slots(geometry: PumpGeometry, bounding_radius: float, clearance: float = 0.002) -> np.ndarray:
    """(k, 2) x, y positions [m] of a hexagonal slot lattice in the suction pipe's section."""
    r_pipe = geometry.design.r_inlet
    s = 2.0 * bounding_radius + clearance
    r_max = r_pipe - bounding_radius - 0.5 * clearance
    if r_max < 0:
        raise ConfigError(f"particles of bounding radius {bounding_radius * 1e3:.1f} mm do not fit the suction pipe "
                          f"(radius {r_pipe * 1e3:.1f} mm)")
    n = int(math.ceil(r_max / s)) + 1
    pts = []
    for i in range(-n, n + 1):
        for j in range(-n, n + 1):
            x = s * (i + 0.5 * j)
            y = s * math.sqrt(3.0) / 2.0 * j
            if math.hypot(x, y) <= r_max + 1e-12:
                pts.append((x, y))
    return np.asarray(pts, dtype=float)


@dataclass
class InjectionPlan:
    """Per scheduled particle: world, time [s], position (3,) [m], velocity (3,) [m/s], and the
    sample index of the particle (into the ParticleSample of its world)."""

    world: np.ndarray
    time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    sample_index: np.ndarray
    rate: float
    slots: int

    @property
    def count(self) -> int:
        return int(len(self.time))


def plan_injection(geometry: PumpGeometry, rate: float, t_end: float, bounding_radius: float, worlds: int = 1,
                   t_start: float = 0.0, seed: int = 0, clearance: float = 0.002) -> InjectionPlan:
    """Schedule injections at ``rate`` [1/s] from ``t_start`` to ``t_end`` [s] in each world:
    evenly spaced times with a random phase per world, each on a free slot of the inlet lattice."""
    if not (rate > 0 and math.isfinite(rate)):
        raise ConfigError(f"injection rate must be > 0 particles/s, got {rate}")
    if not t_end > t_start >= 0:
        raise ConfigError(f"injection needs 0 <= t_start < t_end, got {t_start}, {t_end}")
    d = geometry.design
    rng = np.random.default_rng(seed)
    slots = inlet_slots(geometry, bounding_radius, clearance)
    u = d.inlet_velocity
    spacing = 2.0 * bounding_radius + clearance
    t_free = spacing / u  # a slot is free again once its particle has moved one spacing down
    z_inj = geometry.inlet_top - bounding_radius - 0.5 * clearance
    worlds_out, times, pos, sample = [], [], [], []
    for w in range(worlds):
        phase = rng.random()
        n = int(math.floor((t_end - t_start) * rate - phase)) + 1
        t = t_start + (np.arange(n) + phase) / rate
        t = t[t < t_end]
        last_use = np.full(len(slots), -np.inf)
        for k, ti in enumerate(t):
            free = np.flatnonzero(ti - last_use >= t_free - 1e-12)
            if len(free) == 0:
                raise ConfigError(f"injection rate {rate:.1f} /s is too high for the inlet: {len(slots)} slot(s) "
                                  f"of {spacing * 1e3:.1f} mm in the {2 * d.r_inlet * 1e3:.0f} mm pipe take at most "
                                  f"{len(slots) / t_free:.1f} particles/s at {u:.2f} m/s")
            s = int(rng.choice(free))
            last_use[s] = ti
            worlds_out.append(w)
            times.append(ti)
            pos.append((slots[s, 0], slots[s, 1], z_inj))
            sample.append(k)
    n_all = len(times)
    vel = np.tile([0.0, 0.0, -u], (n_all, 1))
    return InjectionPlan(np.asarray(worlds_out, dtype=np.int64), np.asarray(times, dtype=np.float64),
                         np.asarray(pos, dtype=np.float64).reshape(-1, 3), vel, np.asarray(sample, dtype=np.int64),
                         float(rate), int(len(slots)))


class ParticleInlet:
    """Reserve bodies for an :class:`InjectionPlan`, inject them on time, remove them at the
    outlet, and count them per region.

    Usage: ``inlet = ParticleInlet(geo, plan, samples)``; ``inlet.add_to_builder(builder, mat)``
    before ``finalize``; ``inlet.attach(sim)`` after the Simulation exists; then call
    ``inlet.update(sim)`` between ``sim.run`` chunks.

    Args:
        samples: one ``calibration.materials.ParticleSample`` per world (at least as many
            particles as the plan schedules in that world).
    """

    def __init__(self, geometry: PumpGeometry, plan: InjectionPlan, samples: list) -> None:
        self.geometry = geometry
        self.plan = plan
        self.samples = samples
        for w in np.unique(plan.world):
            need = int((plan.world == w).sum())
            if w >= len(samples) or samples[w].n < need:
                raise ConfigError(f"world {w}: the plan injects {need} particles but its sample has "
                                  f"{0 if w >= len(samples) else samples[w].n}")
        self.body_ids = np.zeros(plan.count, dtype=np.int64)
        self.sim = None

    def add_to_builder(self, builder, material) -> np.ndarray:
        """Add every scheduled particle as a parked body; returns their body indices."""
        plan = self.plan
        rng = np.random.default_rng(12345)
        r_b = max(float(np.max(s.bounding_radius)) for s in self.samples)
        pitch = 2.5 * r_b
        side = max(1, int(math.ceil(math.sqrt(plan.count))))
        for i in range(plan.count):
            w = int(plan.world[i])
            s = self.samples[w]
            k = int(plan.sample_index[i])
            park = (pitch * (i % side), pitch * (i // side), -PARK_DEPTH)
            if s.template[k] < 0:
                self.body_ids[i] = builder.add_sphere(park, float(s.radius[k]), material, world=w)
            else:
                t = s.material.clumps[int(s.template[k])][0]
                q = random_quaternions(1, rng)[0]
                self.body_ids[i] = builder.add_body(park, t.mass, t.inertia_principal, t.centers, t.radii, material,
                                                    world=w, rotation=q)
        return self.body_ids

    def attach(self, sim) -> None:
        """Park every reserve body inactive and upload the schedule (call once, before running)."""
        self.sim = sim
        m = sim.model
        d = m.device
        for st in (sim.state, sim._next):
            act = st.body_active.numpy()
            act[self.body_ids] = 0
            st.body_active.assign(act)
        p = self.plan
        self._schedule = InjectionSchedule()
        self._schedule.time = wp.array(p.time.astype(np.float32), dtype=float, device=d)
        self._schedule.body = wp.array(self.body_ids.astype(np.int32), dtype=int, device=d)
        self._schedule.position = wp.array(p.position.astype(np.float32), dtype=wp.vec3, device=d)
        self._schedule.velocity = wp.array(p.velocity.astype(np.float32), dtype=wp.vec3, device=d)
        self._schedule.injected = wp.zeros(max(p.count, 1), dtype=int, device=d)
        self._count = wp.zeros(1, dtype=int, device=d)
        nw = m.num_worlds
        self._out = wp.zeros(nw, dtype=int, device=d)
        self._lost = wp.zeros(nw, dtype=int, device=d)
        g = self.geometry
        lo, hi = g.bounds()
        margin = 0.05
        self._exits = ExitRegions()
        self._exits.outlet_y = float(g.outlet_y)
        self._exits.outlet_x0 = float(g.design.r3 - 0.01)
        self._exits.outlet_x1 = float(g.design.r_throat + 0.01)
        self._exits.lower = wp.vec3(*(lo - margin))
        self._exits.upper = wp.vec3(*(hi + margin))

        def motion(active: wp.array, position: wp.array, velocity: wp.array, angular_velocity: wp.array,
                   world: wp.array) -> BodyMotion:
            v = BodyMotion()
            v.active, v.position, v.velocity, v.angular_velocity = active, position, velocity, angular_velocity
            v.world = world
            return v

        self._motions = StructCache(motion)
        sim.solver.request_neighbour_rebuild()

    def update(self, sim=None) -> None:
        """Inject what is due and remove what left (two kernel launches, no allocation)."""
        sim = sim or self.sim
        if self.sim is None:
            raise ConfigError("ParticleInlet.update: call attach(sim) first")
        m = sim.model
        st = sim.state
        bodies = self._motions(st.body_active, st.body_q, st.body_v, st.body_w, m.body_world)
        if self.plan.count:
            wp.launch(activate_scheduled, dim=self.plan.count,
                      inputs=[self._schedule, bodies, st.time, sim.solver.rebuild, self._count], device=m.device)
        wp.launch(remove_leaving, dim=m.num_bodies, inputs=[bodies, self._exits, self._out, self._lost],
                  device=m.device)
        sim.solver.invalidate_views()  # bodies left play (a no-op unless the solver fuses the placement)

    # ---------------------------------------------------------------- read-back
    @property
    def injected(self) -> int:
        return int(self._count.numpy()[0])

    def removed_per_world(self) -> tuple[np.ndarray, np.ndarray]:
        """(left through the outlet, lost elsewhere) per world."""
        return self._out.numpy().copy(), self._lost.numpy().copy()

    def region_counts(self, sim=None) -> np.ndarray:
        """(num_worlds, len(REGIONS)) number of active reserve bodies per region now."""
        sim = sim or self.sim
        m = sim.model
        act = sim.state.body_active.numpy()[self.body_ids] != 0
        x = sim.state.body_q.numpy()[self.body_ids].astype(np.float64)
        reg = self.geometry.region_of(x)
        out = np.zeros((m.num_worlds, len(REGIONS)), dtype=np.int64)
        np.add.at(out, (self.plan.world[act], reg[act]), 1)
        return out
