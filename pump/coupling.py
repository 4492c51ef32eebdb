"""Fluid forces on the particles from a prescribed flow sampled on a grid (one-way coupling by
default; an optional two-way correction of the fluid velocity on the coarse grid).

:class:`GridFluidForces` is a registered body-force model (:mod:`warpdem.body_forces`), so it is
compiled into the DEM step like a contact sub-model and captured in the CUDA graph with it.
Per active body b (volume-equivalent diameter d, solid volume V, velocity v), with the fluid
velocity u and acceleration Du/Dt trilinearly interpolated at the centre of mass:

* Drag, ``drag="di_felice"`` (default; Di Felice 1994, as CFDEMcoupling):
  Re = rho_f d eps |u - v| / mu, C_d = (0.63 + 4.8 / sqrt(Re))^2,
  chi = 3.7 - 0.65 exp(-(1.5 - log10 Re)^2 / 2), F_d = (1/8) C_d rho_f pi d^2 eps^(2 - chi) |u - v| (u - v),
  with the local voidage eps from a coarse grid: eps = 1 - (solid volume of the bodies whose
  centres lie in the cell) / (cell volume), per world, rebuilt every step, floored at
  ``min_voidage``. ``drag="schiller_naumann"`` (dilute limit, eps = 1): F_d = 3 pi mu d
  (1 + 0.15 Re^0.687) (u - v), C_d = 0.44 above Re = 1000 (Schiller & Naumann 1933).
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

import numpy as np
import warp as wp

from warpdem.body_forces import (BodyForceContext, BodyForceModel, ParameterSpec, di_felice_drag,
                                 register_body_force, schiller_naumann_drag)
from warpdem.errors import ConfigError

from .flow import FlowGrid

DRAG_LAWS = ("di_felice", "schiller_naumann")


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
def coarse_cell(x: wp.vec3, origin: wp.vec3, inv_c: float, nx: int, ny: int, nz: int):
    i = wp.clamp(int(wp.floor((x[0] - origin[0]) * inv_c)), 0, nx - 1)
    j = wp.clamp(int(wp.floor((x[1] - origin[1]) * inv_c)), 0, ny - 1)
    k = wp.clamp(int(wp.floor((x[2] - origin[2]) * inv_c)), 0, nz - 1)
    return (i * ny + j) * nz + k


@wp.kernel
def scatter_solid_volume(
    body_q: wp.array(dtype=wp.vec3),
    body_active: wp.array(dtype=int),
    body_world: wp.array(dtype=int),
    body_volume: wp.array(dtype=float),
    origin: wp.vec3,
    inv_c: float,
    nx: int,
    ny: int,
    nz: int,
    solid: wp.array(dtype=float),
):
    """Sum the solid volume of active bodies per coarse cell and world (centre-in-cell)."""
    b = wp.tid()
    if body_active[b] == 0:
        return
    cell = coarse_cell(body_q[b], origin, inv_c, nx, ny, nz)
    wp.atomic_add(solid, body_world[b] * nx * ny * nz + cell, body_volume[b])


@wp.kernel
def fluid_forces(
    body_q: wp.array(dtype=wp.vec3),
    body_v: wp.array(dtype=wp.vec3),
    body_active: wp.array(dtype=int),
    body_world: wp.array(dtype=int),
    body_volume: wp.array(dtype=float),
    body_radius: wp.array(dtype=float),
    velocity: wp.array3d(dtype=wp.vec3),
    acceleration: wp.array3d(dtype=wp.vec3),
    origin: wp.vec3,
    inv_h: float,
    solid: wp.array(dtype=float),
    c_origin: wp.vec3,
    inv_c: float,
    cnx: int,
    cny: int,
    cnz: int,
    cell_volume: float,
    rho_f: float,
    mu_f: float,
    drag_law: int,
    min_voidage: float,
    pressure_factor: float,
    buoyancy_factor: float,
    added_mass: float,
    gravity: wp.vec3,
    dt: float,
    v_prev: wp.array(dtype=wp.vec3),
    seen: wp.array(dtype=int),
    two_way: int,
    beta: wp.array(dtype=float),
    cell_velocity_change: wp.array(dtype=wp.vec3),
    force: wp.array(dtype=wp.vec3),
    voidage_out: wp.array(dtype=float),
):
    b = wp.tid()
    if body_active[b] == 0:
        seen[b] = 0
        return
    x = body_q[b]
    v = body_v[b]
    vol = body_volume[b]
    d = 2.0 * body_radius[b]
    u = sample_vec3(velocity, origin, inv_h, x)
    a_f = sample_vec3(acceleration, origin, inv_h, x)
    cell = body_world[b] * cnx * cny * cnz + coarse_cell(x, c_origin, inv_c, cnx, cny, cnz)
    eps = wp.max(1.0 - solid[cell] / cell_volume, min_voidage)
    voidage_out[b] = eps
    f = wp.vec3(0.0)
    if two_way == 0:
        f = drag_force(u - v, d, eps, rho_f, mu_f, drag_law)
    else:  # the drag the cell's momentum sink was built with (see relax_cell_momentum)
        f = beta[b] * (u + cell_velocity_change[cell] - v)
    m_f = rho_f * vol
    f = f + pressure_factor * m_f * a_f - buoyancy_factor * m_f * gravity
    if added_mass > 0.0:
        a_p = wp.vec3(0.0)
        if seen[b] != 0:
            a_p = (v - v_prev[b]) / dt
        f = f + added_mass * m_f * (pressure_factor * a_f - a_p)
    v_prev[b] = v
    seen[b] = 1
    force[b] = force[b] + f


@wp.func
def drag_force(u_rel: wp.vec3, d: float, eps: float, rho_f: float, mu_f: float, drag_law: int):
    """The drag law chosen by ``drag_law`` (0: Di Felice, 1: Schiller-Naumann) [N]."""
    if drag_law == 0:
        return di_felice_drag(u_rel, d, eps, rho_f, mu_f)
    return schiller_naumann_drag(u_rel, d, rho_f, mu_f)


@wp.func
def cell_fluid_mass(solid: float, cell_volume: float, min_voidage: float, rho_f: float):
    """Fluid mass in a coarse cell [kg]: rho_f max(eps, min_voidage) V_c."""
    return rho_f * wp.max(1.0 - solid / cell_volume, min_voidage) * cell_volume


@wp.kernel
def gather_drag_exchange(
    body_q: wp.array(dtype=wp.vec3),
    body_v: wp.array(dtype=wp.vec3),
    body_active: wp.array(dtype=int),
    body_world: wp.array(dtype=int),
    body_radius: wp.array(dtype=float),
    velocity: wp.array3d(dtype=wp.vec3),
    origin: wp.vec3,
    inv_h: float,
    solid: wp.array(dtype=float),
    c_origin: wp.vec3,
    inv_c: float,
    cnx: int,
    cny: int,
    cnz: int,
    cell_volume: float,
    rho_f: float,
    mu_f: float,
    drag_law: int,
    min_voidage: float,
    cell_momentum: wp.array(dtype=wp.vec3),
    beta: wp.array(dtype=float),
    cell_beta: wp.array(dtype=float),
    cell_source: wp.array(dtype=wp.vec3),
):
    """Two-way, pass 1: per body the linearised drag coefficient beta_i [kg/s] at the previous
    step's cell velocity; per cell B_c = sum beta_i [kg/s] and S_c = sum beta_i (u0_i - v_i) [N]."""
    b = wp.tid()
    if body_active[b] == 0:
        beta[b] = 0.0
        return
    x = body_q[b]
    u0 = sample_vec3(velocity, origin, inv_h, x)
    c = body_world[b] * cnx * cny * cnz + coarse_cell(x, c_origin, inv_c, cnx, cny, cnz)
    eps = wp.max(1.0 - solid[c] / cell_volume, min_voidage)
    m_c = cell_fluid_mass(solid[c], cell_volume, min_voidage, rho_f)
    slip = wp.length(u0 + cell_momentum[c] / m_c - body_v[b])
    probe = wp.max(slip, 1.0e-9)  # beta is the drag law's F / |u_rel|, finite as |u_rel| -> 0
    k = drag_force(wp.vec3(probe, 0.0, 0.0), 2.0 * body_radius[b], eps, rho_f, mu_f, drag_law)[0] / probe
    beta[b] = k
    wp.atomic_add(cell_beta, c, k)
    wp.atomic_add(cell_source, c, k * (u0 - body_v[b]))


@wp.kernel
def relax_cell_momentum(
    cell_beta: wp.array(dtype=float),
    cell_source: wp.array(dtype=wp.vec3),
    solid: wp.array(dtype=float),
    inv_tau: wp.array(dtype=float),
    ncell: int,
    cell_volume: float,
    min_voidage: float,
    rho_f: float,
    relaxation: float,
    dt: float,
    cell_momentum: wp.array(dtype=wp.vec3),
    cell_velocity_change: wp.array(dtype=wp.vec3),
):
    """Two-way, pass 2 (per world and cell): P_c <- (P_c - dt S_c) / (1 + r dt / tau_c + dt B_c / m_c)
    [kg m/s]; du_c = P_c / m_c [m/s]."""
    c = wp.tid()
    m_c = cell_fluid_mass(solid[c], cell_volume, min_voidage, rho_f)
    p = (cell_momentum[c] - dt * cell_source[c]) / (
        1.0 + relaxation * dt * inv_tau[c % ncell] + dt * cell_beta[c] / m_c)
    cell_momentum[c] = p
    cell_velocity_change[c] = p / m_c


@register_body_force
class GridFluidForces(BodyForceModel):
    """Drag, undisturbed-flow (pressure-gradient) force, buoyancy and added mass from a flow
    sampled on a :class:`pump.flow.FlowGrid` (see the module docstring for the equations).

    Args:
        grid: the sampled flow (velocity, Du/Dt; fluid density and viscosity).
        drag: 'di_felice' (local voidage, default) or 'schiller_naumann' (dilute).
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
                 **values: float) -> None:
        super().__init__(**values)
        if not isinstance(grid, FlowGrid):
            raise ConfigError(f"grid_fluid: grid must be a pump.flow.FlowGrid, got {type(grid).__name__}")
        if drag not in DRAG_LAWS:
            raise ConfigError(f"grid_fluid: unknown drag law '{drag}'; valid: {list(DRAG_LAWS)}")
        if not isinstance(two_way, (bool, np.bool_)):
            raise ConfigError(f"grid_fluid: two_way must be true or false, got {two_way!r}")
        if isinstance(relaxation, bool) or not isinstance(relaxation, (int, float, np.floating, np.integer)) \
                or not (math.isfinite(relaxation) and 0.0 <= relaxation <= 100.0):
            raise ConfigError(f"grid_fluid: relaxation must be a number in [0, 100] (factor on |u0| / cell), "
                              f"got {relaxation!r}")
        self.grid = grid
        self.drag = drag
        self.two_way = bool(two_way)
        self.relaxation = float(relaxation)
        self.cell_momentum = None  # two-way: (worlds * cells) vec3 [kg m/s], set by bind
        self.cell_velocity_change = None  # two-way: du_c (worlds * cells) vec3 [m/s]

    def describe(self) -> dict:
        return {**super().describe(), "drag": self.drag, "grid_spacing": self.grid.spacing,
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
        m = ctx.model
        dev = ctx.device
        g = self.grid
        self._velocity = wp.array(np.ascontiguousarray(g.velocity), dtype=wp.vec3, device=dev)
        self._acceleration = wp.array(np.ascontiguousarray(g.acceleration), dtype=wp.vec3, device=dev)
        self._origin = wp.vec3(*np.asarray(g.origin, dtype=float))
        self._inv_h = 1.0 / g.spacing
        c = self.values["voidage_cell"]
        self._cdims = self.coarse_shape
        self._num_worlds = m.num_worlds
        self._c_origin = self._origin
        self._inv_c = 1.0 / c
        self._cell_volume = c**3
        ncell = int(np.prod(self._cdims))
        self._solid = wp.zeros(max(m.num_worlds * ncell, 1), dtype=float, device=dev)
        self._v_prev = wp.array(m.initial["body_v"], dtype=wp.vec3, device=dev)
        self._seen = wp.zeros(m.num_bodies, dtype=int, device=dev)
        self.voidage = wp.ones(m.num_bodies, dtype=float, device=dev)
        if self.two_way:
            n = max(m.num_worlds * ncell, 1)
            idx = np.stack(np.meshgrid(*[np.arange(k) for k in self._cdims], indexing="ij"), -1).reshape(-1, 3)
            centres = np.asarray(g.origin, dtype=float) + (idx + 0.5) * c
            speed = np.linalg.norm(g.interpolate(centres), axis=1)
            inv_tau = np.where(speed > 0.0, speed / c, 0.0)  # 1 / flow-through time [1/s]; 0 in still fluid
            self._inv_tau = wp.array(inv_tau.astype(np.float32), dtype=float, device=dev)
            self.cell_momentum = wp.zeros(n, dtype=wp.vec3, device=dev)
            self.cell_velocity_change = wp.zeros(n, dtype=wp.vec3, device=dev)
            self._cell_beta = wp.zeros(n, dtype=float, device=dev)
            self._cell_source = wp.zeros(n, dtype=wp.vec3, device=dev)
            self._beta = wp.zeros(m.num_bodies, dtype=float, device=dev)
        else:  # placeholders for the kernel's two-way arguments
            self._beta = wp.zeros(1, dtype=float, device=dev)
            self._one_way_velocity_change = wp.zeros(1, dtype=wp.vec3, device=dev)

    def launch(self, ctx: BodyForceContext, state_in, state_out, dt: float) -> None:
        m = ctx.model
        dev = ctx.device
        cnx, cny, cnz = self._cdims
        self._solid.zero_()
        wp.launch(scatter_solid_volume, dim=m.num_bodies, inputs=[
            state_in.body_q, state_in.body_active, m.body_world, ctx.body_volume, self._c_origin, self._inv_c,
            cnx, cny, cnz, self._solid], device=dev)
        v = self.values
        rho_f, mu_f, law = float(self.grid.density), float(self.grid.viscosity), DRAG_LAWS.index(self.drag)
        if self.two_way:
            self._cell_beta.zero_()
            self._cell_source.zero_()
            wp.launch(gather_drag_exchange, dim=m.num_bodies, inputs=[
                state_in.body_q, state_in.body_v, state_in.body_active, m.body_world, ctx.body_radius,
                self._velocity, self._origin, self._inv_h, self._solid, self._c_origin, self._inv_c, cnx, cny, cnz,
                self._cell_volume, rho_f, mu_f, law, v["min_voidage"], self.cell_momentum, self._beta,
                self._cell_beta, self._cell_source], device=dev)
            wp.launch(relax_cell_momentum, dim=self.cell_momentum.shape[0], inputs=[
                self._cell_beta, self._cell_source, self._solid, self._inv_tau, cnx * cny * cnz, self._cell_volume,
                v["min_voidage"], rho_f, self.relaxation, float(dt), self.cell_momentum,
                self.cell_velocity_change], device=dev)
        velocity_change = self.cell_velocity_change if self.two_way else self._one_way_velocity_change
        wp.launch(fluid_forces, dim=m.num_bodies, inputs=[
            state_in.body_q, state_in.body_v, state_in.body_active, m.body_world, ctx.body_volume, ctx.body_radius,
            self._velocity, self._acceleration, self._origin, self._inv_h,
            self._solid, self._c_origin, self._inv_c, cnx, cny, cnz, self._cell_volume,
            rho_f, mu_f, law, v["min_voidage"],
            v["pressure_gradient"], v["buoyancy"], v["added_mass"], ctx.gravity, float(dt),
            self._v_prev, self._seen, int(self.two_way), self._beta, velocity_change, ctx.force, self.voidage],
            device=dev)
