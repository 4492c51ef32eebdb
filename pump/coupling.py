"""Fluid forces on the particles from a prescribed flow sampled on a grid (one-way coupling by
default; an optional two-way correction of the fluid velocity on the coarse grid).

:class:`GridFluidForces` is a registered body-force model (:mod:`warpdem.body_forces`), so it is
compiled into the DEM step like a contact sub-model and captured in the CUDA graph with it.
Per active body b (volume-equivalent diameter d = 2 a, solid volume V, velocity v), with the fluid
velocity u and acceleration Du/Dt trilinearly interpolated at the centre of mass (the drag's u as
``drag_velocity`` says, below):

* Drag, ``drag="di_felice"`` (default; Di Felice 1994, as CFDEMcoupling):
  Re = rho_f d eps |u - v| / mu, C_d = (0.63 + 4.8 / sqrt(Re))^2,
  chi = 3.7 - 0.65 exp(-(1.5 - log10 Re)^2 / 2), F_d = (1/8) C_d rho_f pi d^2 eps^(2 - chi) |u - v| (u - v),
  with the local voidage eps from a coarse grid: eps = 1 - (solid volume of the bodies whose
  centres lie in the cell) / (cell volume), per world, rebuilt every step, floored at
  ``min_voidage``. ``drag="schiller_naumann"`` (dilute limit, eps = 1): F_d = 3 pi mu d
  (1 + 0.15 Re^0.687) (u - v), C_d = 0.44 above Re = 1000 (Schiller & Naumann 1933).
* The fluid velocity the drag reads, ``drag_velocity`` (a finite-size option: the gravel is 10-25 mm,
  33-83 % of the 30 mm passage):

  - ``"centre"`` (default): u at the centre of mass, the point-particle rule of CFD-DEM codes;
  - ``"surface_average"``: the mean of u over the particle's sphere (Faxen's first law: the Stokes
    drag of a sphere in a non-uniform flow is F = 3 pi mu d (<u>_S - v) with
    <u>_S = u + (a^2 / 6) lap u + O(a^4); Faxen 1922, Ann. Phys. 68:89; Maxey & Riley 1983).
    At finite Re the average is a model: Calzavarini et al. 2009, J. Fluid Mech. 630:179, use it as
    the Faxen correction of finite-size point particles in turbulence;
  - ``"volume_average"``: the mean over the particle's volume, <u>_V = u + (a^2 / 10) lap u + O(a^4)
    (the average Calzavarini et al. 2009 apply to the fluid-acceleration terms).

  Both averages by a six-point rule on the axes, <u> = (1/6) sum_k [u(x + rho e_k) + u(x - rho e_k)]
  = u + (rho^2 / 6) lap u + O(rho^4), exact for fields up to cubic in x: rho = a (surface) or
  a sqrt(3/5) (volume). Each sample is the grid's trilinear interpolation, so the grid must resolve
  the particle (spacing below a). The undisturbed-flow and added-mass forces keep Du/Dt at the
  centre. The averages correct for the flow's variation over the particle, not for its confinement:
  a particle comparable to the passage forces the fluid it displaces past it, which raises its drag
  (a sphere moving along a tube: Haberman & Sayre 1958, David Taylor Model Basin rep. 1143; Di
  Felice 1996, Int. J. Multiphase Flow 22:527 at finite Re); that wall effect is not modelled.
* Undisturbed-flow (pressure-gradient) force F_p = rho_f V Du/Dt (Maxey & Riley 1983); it equals
  -V grad p* where no blade force acts (:mod:`pump.flow`); times ``pressure_gradient`` (1 or 0).
* Buoyancy F_b = -rho_f V g (times ``buoyancy``).
* Added mass F_a = C_a rho_f V (Du/Dt - dv/dt), C_a = ``added_mass`` (0.5 for a sphere; Auton,
  Hunt & Prud'homme 1988). dv/dt is the body's acceleration over the previous step (explicit
  lag; stable for C_a rho_f / rho_p < 1, 0.19 for gravel in water); it is left out in the step
  a body is (re)activated. It matters where the fluid accelerates strongly (the impeller:
  |Du/Dt| up to ~1000 m/s^2, so F_a is comparable to the drag there).

Two-way mode (``two_way=True``; off by default). Per world and coarse cell c (edge h_c, volume
V_c = h_c^3, fluid mass m_c = rho_f eps_c V_c) the model carries P_c [kg m/s], the change of the
cell's fluid momentum by the particles (relative to the prescribed flow); the fluid velocity in the cell is the prescribed one plus
du_c = P_c / m_c. The drag reaction -F_i of every particle whose centre lies in c is the cell's
momentum sink (the CFD-DEM particle-fluid interaction term, Kafui, Thornton & Adams 2002, Chem.
Eng. Sci. 57:2395, their model B; Zhu et al. 2007, Chem. Eng. Sci. 62:3378, Eq. 12), and the
disturbance leaves the cell with the through-flow over its flow-through time
tau_c = h_c / |u0(centre of c)| (first-order upwind: undisturbed fluid enters):

    dP_c/dt = -sum_i F_i - P_c / tau_c,   F_i = beta_i (u0(x_i) + P_c / m_c - v_i).

beta_i = |F_drag(u_rel)| / |u_rel| is the drag law's coefficient at the previous step's relative
velocity (the semi-implicit drag of CFDEMcoupling / Xiao & Sun 2011, J. Comput. Phys. 230:5216);
the step dt is integrated implicitly in P_c (S_c = sum_i beta_i (u0(x_i) - v_i), B_c = sum_i beta_i):

    P_c <- (P_c - dt S_c) / (1 + r dt / tau_c + dt B_c / m_c),      r = ``relaxation`` (1; 0: closed box)

and the particles then feel F_i with this P_c, so the fluid loses exactly the momentum the
particles gain from drag (to float32 round-off), the update is unconditionally stable, and du_c
is a weighted mean of 0 and the slips v_i - u0(x_i): the correction cannot reverse the flow past
the particles' velocity. In steady state du_c = -tau_c sum_i F_i / m_c (local momentum balance of
the fluid crossing the cell). The coupling interval is the DEM step; the correction is built
with kernels only (graph-safe), per world. It is a simplification: no pressure-velocity coupling
and no continuity (the slowed fluid is not diverted around a cloud), the disturbance is not
carried into the downstream cells, only drag is exchanged (the undisturbed-flow, buoyancy and
added-mass forces act on the prescribed field and have no reaction on it), and Du/Dt is the
prescribed one. The prescribed field (``grid``) is never changed.

Not modelled: lift (Saffman, Magnus), fluid torque, the particles' effect on the flow in the
default one-way mode (at 1 % solids eps^(2-chi) ~ 1.03, so the fluid's momentum sink is small),
turbulence.
"""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
import warp as wp

from warpdem.body_forces import (BodyForceContext, BodyForceModel, ParameterSpec, di_felice_drag,
                                 register_body_force, schiller_naumann_drag)
from warpdem.errors import ConfigError

from .flow import FlowGrid

DRAG_LAWS = ("di_felice", "schiller_naumann")
#: where the drag reads the fluid velocity (module docstring), and the radius of the six-point rule
#: as a fraction of the particle's radius: 1 for the surface mean, sqrt(3/5) for the volume mean
DRAG_VELOCITIES = ("centre", "surface_average", "volume_average")
DRAG_SAMPLE_RADIUS = {"centre": 0.0, "surface_average": 1.0, "volume_average": math.sqrt(3.0 / 5.0)}


# ----------------------------------------------------------------------------- kernel arguments
@wp.struct
class BodyView:
    """What the fluid kernels read of the bodies: one engine State's arrays plus fixed per-body data."""

    position: wp.array(dtype=wp.vec3)  # centre of mass [m] (State.body_q)
    velocity: wp.array(dtype=wp.vec3)  # [m/s] (State.body_v)
    active: wp.array(dtype=int)  # 0: parked or removed, no fluid force (State.body_active)
    world: wp.array(dtype=int)  # (Model.body_world)
    radius: wp.array(dtype=float)  # volume-equivalent radius [m] (BodyForceContext.body_radius)
    volume: wp.array(dtype=float)  # solid volume [m^3] (BodyForceContext.body_volume)


@wp.struct
class FluidField:
    """The prescribed flow on the fine grid, node (i, j, k) at origin + (i, j, k) / inv_spacing."""

    velocity: wp.array3d(dtype=wp.vec3)  # u [m/s]
    acceleration: wp.array3d(dtype=wp.vec3)  # Du/Dt [m/s^2]
    origin: wp.vec3  # [m]
    inv_spacing: float  # 1 / node spacing [1/m]


@wp.struct
class VoidageGrid:
    """The coarse grid, per world; flat cell index world * nx ny nz + (i ny + j) nz + k."""

    origin: wp.vec3  # corner of cell (0, 0, 0) [m]
    inv_cell: float  # 1 / cell edge [1/m]
    nx: int
    ny: int
    nz: int
    cell_volume: float  # V_c [m^3]
    min_voidage: float  # floor of eps [-]
    solid: wp.array(dtype=float)  # solid volume of the bodies centred in each cell [m^3], rebuilt every step


@wp.struct
class CellExchange:
    """Two-way momentum exchange (module docstring): per cell and per body (1-element
    placeholders in one-way mode, never read there)."""

    inv_tau: wp.array(dtype=float)  # 1 / flow-through time per cell of one world [1/s]
    momentum: wp.array(dtype=wp.vec3)  # P_c [kg m/s]
    velocity_change: wp.array(dtype=wp.vec3)  # du_c = P_c / m_c [m/s]
    drag_coefficient_sum: wp.array(dtype=float)  # B_c = sum beta_i [kg/s]
    drag_source: wp.array(dtype=wp.vec3)  # S_c = sum beta_i (u0_i - v_i) [N]
    body_drag_coefficient: wp.array(dtype=float)  # beta_i [kg/s]


@wp.struct
class FluidCoupling:
    """Fluid properties and coupling options."""

    density: float  # rho_f [kg/m^3]
    viscosity: float  # mu_f [Pa s]
    drag_law: int  # index into DRAG_LAWS (0: Di Felice, 1: Schiller-Naumann)
    drag_sample_radius: float  # rho / a of the drag velocity's six-point rule; 0: at the centre
    pressure_factor: float  # on rho_f V Du/Dt [-]
    buoyancy_factor: float  # on -rho_f V g [-]
    added_mass: float  # C_a [-]
    gravity: wp.vec3  # g [m/s^2]
    two_way: int  # 1: drag with the cell's du_c and beta_i (CellExchange)
    relaxation: float  # r on the two-way relaxation rate 1 / tau_c [-]


@wp.struct
class AddedMassMemory:
    """Per body, for the lagged particle acceleration dv/dt of the added-mass force."""

    previous_velocity: wp.array(dtype=wp.vec3)  # v at the previous step [m/s]
    seen: wp.array(dtype=int)  # 1: active at the previous step too


class StructCache:
    """Warp structs keyed by the arrays they are built from: built on first use, reused while
    the same array objects come back (the solver alternates two States, so a step finds its
    struct ready); a replaced array builds a new one. Holds at most ``size`` entries."""

    def __init__(self, build: Callable[..., Any], size: int = 4) -> None:
        self._build = build
        self._size = size
        self._entries: dict[tuple[int, ...], tuple[tuple, Any]] = {}

    def __call__(self, *arrays: Any) -> Any:
        key = tuple(map(id, arrays))
        entry = self._entries.get(key)
        if entry is None:  # the entry keeps its arrays alive, so their ids are not reused
            if len(self._entries) >= self._size:
                self._entries.clear()
            entry = self._entries[key] = (arrays, self._build(*arrays))
        return entry[1]


# ----------------------------------------------------------------------------- device functions
@wp.func
def sample_vec3(field: wp.array3d(dtype=wp.vec3), origin: wp.vec3, inv_h: float, x: wp.vec3):
    """Trilinear interpolation of a node-centred vec3 grid at x, clamped to the grid."""
    g = (x - origin) * inv_h
    gx = wp.clamp(g[0], 0.0, float(field.shape[0] - 1) - 1.0e-4)
    gy = wp.clamp(g[1], 0.0, float(field.shape[1] - 1) - 1.0e-4)
    gz = wp.clamp(g[2], 0.0, float(field.shape[2] - 1) - 1.0e-4)
    i = int(gx)
    j = int(gy)
    k = int(gz)
    fx = gx - float(i)
    fy = gy - float(j)
    fz = gz - float(k)
    c00 = field[i, j, k] * (1.0 - fx) + field[i + 1, j, k] * fx
    c10 = field[i, j + 1, k] * (1.0 - fx) + field[i + 1, j + 1, k] * fx
    c01 = field[i, j, k + 1] * (1.0 - fx) + field[i + 1, j, k + 1] * fx
    c11 = field[i, j + 1, k + 1] * (1.0 - fx) + field[i + 1, j + 1, k + 1] * fx
    c0 = c00 * (1.0 - fy) + c10 * fy
    c1 = c01 * (1.0 - fy) + c11 * fy
    return c0 * (1.0 - fz) + c1 * fz


@wp.func
def cell_of(cells: VoidageGrid, world: int, x: wp.vec3):
    """Flat index of the coarse cell of world ``world`` holding x (clamped to the grid)."""
    i = wp.clamp(int(wp.floor((x[0] - cells.origin[0]) * cells.inv_cell)), 0, cells.nx - 1)
    j = wp.clamp(int(wp.floor((x[1] - cells.origin[1]) * cells.inv_cell)), 0, cells.ny - 1)
    k = wp.clamp(int(wp.floor((x[2] - cells.origin[2]) * cells.inv_cell)), 0, cells.nz - 1)
    return world * cells.nx * cells.ny * cells.nz + (i * cells.ny + j) * cells.nz + k


@wp.func
def cell_voidage(cells: VoidageGrid, c: int):
    """eps_c = max(1 - solid_c / V_c, min_voidage) [-]."""
    return wp.max(1.0 - cells.solid[c] / cells.cell_volume, cells.min_voidage)


@wp.func
def cell_fluid_mass(cells: VoidageGrid, c: int, rho_f: float):
    """Fluid mass in a coarse cell m_c = rho_f eps_c V_c [kg]."""
    return rho_f * cell_voidage(cells, c) * cells.cell_volume


@wp.func
def drag_velocity(flow: FluidField, fluid: FluidCoupling, x: wp.vec3, radius: float):
    """The fluid velocity the drag reads [m/s] (module docstring): u(x) at the centre x [m], or the
    six-point mean (1/6) sum_k [u(x + rho e_k) + u(x - rho e_k)], rho = ``fluid.drag_sample_radius``
    times the body's ``radius`` [m]."""
    if fluid.drag_sample_radius == 0.0:
        return sample_vec3(flow.velocity, flow.origin, flow.inv_spacing, x)
    rho = fluid.drag_sample_radius * radius
    ex = wp.vec3(rho, 0.0, 0.0)
    ey = wp.vec3(0.0, rho, 0.0)
    ez = wp.vec3(0.0, 0.0, rho)
    s = sample_vec3(flow.velocity, flow.origin, flow.inv_spacing, x + ex)
    s = s + sample_vec3(flow.velocity, flow.origin, flow.inv_spacing, x - ex)
    s = s + sample_vec3(flow.velocity, flow.origin, flow.inv_spacing, x + ey)
    s = s + sample_vec3(flow.velocity, flow.origin, flow.inv_spacing, x - ey)
    s = s + sample_vec3(flow.velocity, flow.origin, flow.inv_spacing, x + ez)
    s = s + sample_vec3(flow.velocity, flow.origin, flow.inv_spacing, x - ez)
    return s / 6.0


@wp.func
def drag_force(u_rel: wp.vec3, d: float, eps: float, fluid: FluidCoupling):
    """The drag law chosen by ``fluid.drag_law`` (0: Di Felice, 1: Schiller-Naumann) [N]."""
    if fluid.drag_law == 0:
        return di_felice_drag(u_rel, d, eps, fluid.density, fluid.viscosity)
    return schiller_naumann_drag(u_rel, d, fluid.density, fluid.viscosity)


# ----------------------------------------------------------------------------- kernels
@wp.kernel
def scatter_solid_volume(bodies: BodyView, cells: VoidageGrid):
    """Add each active body's solid volume [m^3] to ``cells.solid`` at the cell of its centre."""
    b = wp.tid()
    if bodies.active[b] == 0:
        return
    wp.atomic_add(cells.solid, cell_of(cells, bodies.world[b], bodies.position[b]), bodies.volume[b])


@wp.kernel
def gather_drag_exchange(bodies: BodyView, flow: FluidField, cells: VoidageGrid, fluid: FluidCoupling,
                         exchange: CellExchange):
    """Two-way, pass 1: per body the linearised drag coefficient beta_i = |F_d(u_rel)| / |u_rel|
    [kg/s] at the previous step's cell velocity (semi-implicit drag, Xiao & Sun 2011); per cell
    B_c = sum beta_i [kg/s] and S_c = sum beta_i (u0_i - v_i) [N]."""
    b = wp.tid()
    if bodies.active[b] == 0:
        exchange.body_drag_coefficient[b] = 0.0
        return
    x = bodies.position[b]
    v = bodies.velocity[b]
    u0 = drag_velocity(flow, fluid, x, bodies.radius[b])
    c = cell_of(cells, bodies.world[b], x)
    m_c = cell_fluid_mass(cells, c, fluid.density)
    slip = wp.length(u0 + exchange.momentum[c] / m_c - v)
    probe = wp.max(slip, 1.0e-9)  # beta is the drag law's F / |u_rel|, finite as |u_rel| -> 0
    k = drag_force(wp.vec3(probe, 0.0, 0.0), 2.0 * bodies.radius[b], cell_voidage(cells, c), fluid)[0] / probe
    exchange.body_drag_coefficient[b] = k
    wp.atomic_add(exchange.drag_coefficient_sum, c, k)
    wp.atomic_add(exchange.drag_source, c, k * (u0 - v))


@wp.kernel
def relax_cell_momentum(cells: VoidageGrid, fluid: FluidCoupling, exchange: CellExchange, dt: float):
    """Two-way, pass 2 (per world and cell), dP_c/dt = -sum_i F_i - r P_c / tau_c implicit in P_c
    (sink: Kafui, Thornton & Adams 2002, model B): P_c <- (P_c - dt S_c) / (1 + r dt / tau_c + dt B_c / m_c)
    [kg m/s]; du_c = P_c / m_c [m/s]; ``dt`` [s]."""
    c = wp.tid()
    m_c = cell_fluid_mass(cells, c, fluid.density)
    inv_tau = exchange.inv_tau[c % (cells.nx * cells.ny * cells.nz)]
    p = (exchange.momentum[c] - dt * exchange.drag_source[c]) / (
        1.0 + fluid.relaxation * dt * inv_tau + dt * exchange.drag_coefficient_sum[c] / m_c)
    exchange.momentum[c] = p
    exchange.velocity_change[c] = p / m_c


@wp.kernel
def fluid_forces(bodies: BodyView, flow: FluidField, cells: VoidageGrid, fluid: FluidCoupling,
                 exchange: CellExchange, memory: AddedMassMemory, dt: float, force: wp.array(dtype=wp.vec3),
                 voidage: wp.array(dtype=float)):
    """Add F = F_d + p rho_f V Du/Dt - b rho_f V g + C_a rho_f V (p Du/Dt - dv/dt) to ``force`` [N]:
    drag (Di Felice 1994 or Schiller & Naumann 1933), undisturbed flow (Maxey & Riley 1983),
    buoyancy, added mass (Auton, Hunt & Prud'homme 1988; dv/dt lagged one step of ``dt`` [s]);
    p, b the pressure and buoyancy factors. Writes each body's local voidage eps [-] to ``voidage``."""
    b = wp.tid()
    if bodies.active[b] == 0:
        memory.seen[b] = 0
        return
    x = bodies.position[b]
    v = bodies.velocity[b]
    u = drag_velocity(flow, fluid, x, bodies.radius[b])  # the drag's fluid velocity (centre or mean)
    a_f = sample_vec3(flow.acceleration, flow.origin, flow.inv_spacing, x)
    c = cell_of(cells, bodies.world[b], x)
    eps = cell_voidage(cells, c)
    voidage[b] = eps
    f = wp.vec3(0.0)
    if fluid.two_way == 0:
        f = drag_force(u - v, 2.0 * bodies.radius[b], eps, fluid)
    else:  # the drag the cell's momentum sink was built with (see relax_cell_momentum)
        f = exchange.body_drag_coefficient[b] * (u + exchange.velocity_change[c] - v)
    m_f = fluid.density * bodies.volume[b]  # displaced fluid mass [kg]
    f = f + fluid.pressure_factor * m_f * a_f - fluid.buoyancy_factor * m_f * fluid.gravity
    if fluid.added_mass > 0.0:
        a_p = wp.vec3(0.0)
        if memory.seen[b] != 0:
            a_p = (v - memory.previous_velocity[b]) / dt
        f = f + fluid.added_mass * m_f * (fluid.pressure_factor * a_f - a_p)
    memory.previous_velocity[b] = v
    memory.seen[b] = 1
    force[b] = force[b] + f


@register_body_force
class GridFluidForces(BodyForceModel):
    """Drag, undisturbed-flow (pressure-gradient) force, buoyancy and added mass from a flow
    sampled on a :class:`pump.flow.FlowGrid` (see the module docstring for the equations).

    Args:
        grid: the sampled flow (velocity, Du/Dt; fluid density and viscosity).
        drag: 'di_felice' (local voidage, default) or 'schiller_naumann' (dilute).
        drag_velocity: where the drag reads the fluid velocity: 'centre' (default),
            'surface_average' (Faxen: the mean over the particle's sphere) or 'volume_average'
            (module docstring).
        two_way: correct the fluid velocity per coarse cell by the particles' drag reaction
            (module docstring); False (default): one-way, the prescribed flow only.
        relaxation: factor r [-] on the two-way relaxation rate |u0| / h_c towards the prescribed
            flow (1: flow-through time; 0: closed box, the disturbance never decays).
        Declared parameters (keyword): added_mass C_a [-], pressure_gradient and buoyancy
        switches [0/1], voidage_cell [m] (coarse cell edge), min_voidage [-].
    """

    name = "grid_fluid"
    parameters = (
        ParameterSpec("added_mass", "-", 0.5, (0.0, 2.0), "added-mass coefficient C_a (0.5: sphere)"),
        ParameterSpec("pressure_gradient", "-", 1.0, (0.0, 1.0), "factor on the undisturbed-flow force rho_f V Du/Dt"),
        ParameterSpec("buoyancy", "-", 1.0, (0.0, 1.0), "factor on the buoyancy -rho_f V g"),
        ParameterSpec("voidage_cell", "m", 0.05, (1.0e-4, 10.0), "edge of the coarse voidage cells"),
        ParameterSpec("min_voidage", "-", 0.35, (0.05, 1.0), "floor of the local voidage"),
    )
    reference = ("Di Felice (1994) Int. J. Multiphase Flow 20:153; Schiller & Naumann (1933); Maxey & Riley (1983) "
                 "Phys. Fluids 26:883; Auton, Hunt & Prud'homme (1988) J. Fluid Mech. 197:241")

    def __init__(self, grid: FlowGrid, drag: str = "di_felice", two_way: bool = False, relaxation: float = 1.0,
                 drag_velocity: str = "centre", **values: float) -> None:
        super().__init__(**values)
        if not isinstance(grid, FlowGrid):
            raise ConfigError(f"grid_fluid: grid must be a pump.flow.FlowGrid, got {type(grid).__name__}")
        if drag not in DRAG_LAWS:
            raise ConfigError(f"grid_fluid: unknown drag law '{drag}'; valid: {list(DRAG_LAWS)}")
        if not isinstance(drag_velocity, str) or drag_velocity not in DRAG_VELOCITIES:
            raise ConfigError(f"grid_fluid: drag_velocity must be one of {list(DRAG_VELOCITIES)} (where the drag "
                              f"reads the fluid velocity), got {drag_velocity!r}")
        if not isinstance(two_way, (bool, np.bool_)):
            raise ConfigError(f"grid_fluid: two_way must be true or false, got {two_way!r}")
        if isinstance(relaxation, bool) or not isinstance(relaxation, (int, float, np.floating, np.integer)) \
                or not (math.isfinite(relaxation) and 0.0 <= relaxation <= 100.0):
            raise ConfigError(f"grid_fluid: relaxation must be a number in [0, 100] (factor on |u0| / cell), "
                              f"got {relaxation!r}")
        self.grid = grid
        self.drag = drag
        self.drag_velocity = drag_velocity
        self.two_way = bool(two_way)
        self.relaxation = float(relaxation)
        self.cell_momentum = None  # two-way: (worlds * cells) vec3 [kg m/s], set by bind
        self.cell_velocity_change = None  # two-way: du_c (worlds * cells) vec3 [m/s]

    def describe(self) -> dict:
        return {**super().describe(), "drag": self.drag, "drag_velocity": self.drag_velocity,
                "grid_spacing": self.grid.spacing,
                "grid_shape": list(self.grid.shape), "fluid_density": self.grid.density,
                "fluid_viscosity": self.grid.viscosity, "coupling": "two-way" if self.two_way else "one-way",
                **({"two_way_relaxation": self.relaxation} if self.two_way else {})}

    @property
    def coarse_shape(self) -> tuple[int, int, int]:
        """Cells of the coarse (voidage and two-way) grid per axis; cell (i, j, k) spans
        origin + voidage_cell * [i, i + 1) x [j, j + 1) x [k, k + 1) [m]."""
        extent = np.asarray(self.grid.shape, dtype=float) * self.grid.spacing
        c = self.values["voidage_cell"]
        return tuple(max(1, int(math.ceil(e / c))) for e in extent)

    def fluid_velocity_change(self) -> np.ndarray:
        """Two-way correction du_c of the cell fluid velocity [m/s], shape (worlds, nx, ny, nz, 3)
        (zeros in one-way mode; a host read, not for the stepping loop)."""
        worlds = self._num_worlds
        if not self.two_way:
            return np.zeros((worlds, *self._cdims, 3), dtype=np.float32)
        return self.cell_velocity_change.numpy().reshape(worlds, *self._cdims, 3)

    def fluid_momentum_change(self) -> np.ndarray:
        """Two-way: change P_c of each cell's fluid momentum by the particles' drag [kg m/s],
        shape (worlds, nx, ny, nz, 3) (zeros in one-way mode)."""
        if not self.two_way:
            return np.zeros((self._num_worlds, *self._cdims, 3), dtype=np.float32)
        return self.cell_momentum.numpy().reshape(self._num_worlds, *self._cdims, 3)

    def bind(self, ctx: BodyForceContext) -> None:
        """Upload the flow, allocate the coarse-grid and per-body buffers, build the kernels'
        structs (the per-State BodyView is built on first use, :meth:`body_view`)."""
        m = ctx.model
        dev = ctx.device
        g = self.grid
        c = self.values["voidage_cell"]
        self._cdims = self.coarse_shape
        self._num_worlds = m.num_worlds
        n_cells = max(m.num_worlds * int(np.prod(self._cdims)), 1)
        self._velocity = wp.array(np.ascontiguousarray(g.velocity), dtype=wp.vec3, device=dev)

        self._flow = FluidField()
        self._flow.velocity = self._velocity
        self._flow.acceleration = wp.array(np.ascontiguousarray(g.acceleration), dtype=wp.vec3, device=dev)
        self._flow.origin = wp.vec3(*np.asarray(g.origin, dtype=float))
        self._flow.inv_spacing = 1.0 / g.spacing

        self._cells = VoidageGrid()
        self._cells.origin = self._flow.origin
        self._cells.inv_cell = 1.0 / c
        self._cells.nx, self._cells.ny, self._cells.nz = self._cdims
        self._cells.cell_volume = c**3
        self._cells.min_voidage = self.values["min_voidage"]
        self._cells.solid = wp.zeros(n_cells, dtype=float, device=dev)

        self._fluid = FluidCoupling()
        self._fluid.density = float(g.density)
        self._fluid.viscosity = float(g.viscosity)
        self._fluid.drag_law = DRAG_LAWS.index(self.drag)
        self._fluid.drag_sample_radius = DRAG_SAMPLE_RADIUS[self.drag_velocity]
        self._fluid.pressure_factor = self.values["pressure_gradient"]
        self._fluid.buoyancy_factor = self.values["buoyancy"]
        self._fluid.added_mass = self.values["added_mass"]
        self._fluid.gravity = ctx.gravity
        self._fluid.two_way = int(self.two_way)
        self._fluid.relaxation = self.relaxation

        self._memory = AddedMassMemory()
        self._memory.previous_velocity = wp.array(m.initial["body_v"], dtype=wp.vec3, device=dev)
        self._memory.seen = wp.zeros(m.num_bodies, dtype=int, device=dev)
        self.voidage = wp.ones(m.num_bodies, dtype=float, device=dev)

        self._exchange = CellExchange()
        if self.two_way:
            idx = np.stack(np.meshgrid(*[np.arange(k) for k in self._cdims], indexing="ij"), -1).reshape(-1, 3)
            centres = np.asarray(g.origin, dtype=float) + (idx + 0.5) * c
            speed = np.linalg.norm(g.interpolate(centres), axis=1)
            inv_tau = np.where(speed > 0.0, speed / c, 0.0)  # 1 / flow-through time [1/s]; 0 in still fluid
            self._exchange.inv_tau = wp.array(inv_tau.astype(np.float32), dtype=float, device=dev)
            self.cell_momentum = wp.zeros(n_cells, dtype=wp.vec3, device=dev)
            self.cell_velocity_change = wp.zeros(n_cells, dtype=wp.vec3, device=dev)
            self._exchange.drag_coefficient_sum = wp.zeros(n_cells, dtype=float, device=dev)
            self._exchange.drag_source = wp.zeros(n_cells, dtype=wp.vec3, device=dev)
            self._exchange.body_drag_coefficient = wp.zeros(m.num_bodies, dtype=float, device=dev)
            self._exchange.momentum = self.cell_momentum
            self._exchange.velocity_change = self.cell_velocity_change
        else:  # placeholders: fluid_forces takes the struct but reads it only in two-way mode
            self._exchange.inv_tau = wp.zeros(1, dtype=float, device=dev)
            self._exchange.momentum = wp.zeros(1, dtype=wp.vec3, device=dev)
            self._exchange.velocity_change = wp.zeros(1, dtype=wp.vec3, device=dev)
            self._exchange.drag_coefficient_sum = wp.zeros(1, dtype=float, device=dev)
            self._exchange.drag_source = wp.zeros(1, dtype=wp.vec3, device=dev)
            self._exchange.body_drag_coefficient = wp.zeros(1, dtype=float, device=dev)

        def view(position: wp.array, velocity: wp.array, active: wp.array) -> BodyView:
            v = BodyView()
            v.position, v.velocity, v.active = position, velocity, active
            v.world, v.radius, v.volume = m.body_world, ctx.body_radius, ctx.body_volume
            return v

        self._body_views = StructCache(view)

    def body_view(self, state) -> BodyView:
        """The :class:`BodyView` of one engine State (built once per State and reused)."""
        return self._body_views(state.body_q, state.body_v, state.body_active)

    def launch(self, ctx: BodyForceContext, state_in, state_out, dt: float) -> None:
        """Voidage, then (two-way) the cells' momentum exchange, then the force on each body."""
        n = ctx.model.num_bodies
        dev = ctx.device
        bodies = self.body_view(state_in)
        self._cells.solid.zero_()
        wp.launch(scatter_solid_volume, dim=n, inputs=[bodies, self._cells], device=dev)
        if self.two_way:
            self._exchange.drag_coefficient_sum.zero_()
            self._exchange.drag_source.zero_()
            wp.launch(gather_drag_exchange, dim=n, inputs=[bodies, self._flow, self._cells, self._fluid,
                                                           self._exchange], device=dev)
            wp.launch(relax_cell_momentum, dim=self.cell_momentum.shape[0],
                      inputs=[self._cells, self._fluid, self._exchange, float(dt)], device=dev)
        wp.launch(fluid_forces, dim=n, inputs=[bodies, self._flow, self._cells, self._fluid, self._exchange,
                                               self._memory, float(dt)], outputs=[ctx.force, self.voidage],
                  device=dev)
