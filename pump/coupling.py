"""Fluid forces on the particles from a prescribed flow sampled on a grid (one-way coupling).

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

Not modelled: lift (Saffman, Magnus), fluid torque, the particles' effect on the flow (one-way
coupling; at 1 % solids eps^(2-chi) ~ 1.03, so the fluid's momentum sink is small), turbulence.
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
    cell = coarse_cell(x, c_origin, inv_c, cnx, cny, cnz)
    eps = wp.max(1.0 - solid[body_world[b] * cnx * cny * cnz + cell] / cell_volume, min_voidage)
    voidage_out[b] = eps
    u_rel = u - v
    f = wp.vec3(0.0)
    if drag_law == 0:
        f = di_felice_drag(u_rel, d, eps, rho_f, mu_f)
    else:
        f = schiller_naumann_drag(u_rel, d, rho_f, mu_f)
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


@register_body_force
class GridFluidForces(BodyForceModel):
    """Drag, undisturbed-flow (pressure-gradient) force, buoyancy and added mass from a flow
    sampled on a :class:`pump.flow.FlowGrid` (see the module docstring for the equations).

    Args:
        grid: the sampled flow (velocity, Du/Dt; fluid density and viscosity).
        drag: 'di_felice' (local voidage, default) or 'schiller_naumann' (dilute).
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

    def __init__(self, grid: FlowGrid, drag: str = "di_felice", **values: float) -> None:
        super().__init__(**values)
        if not isinstance(grid, FlowGrid):
            raise ConfigError(f"grid_fluid: grid must be a pump.flow.FlowGrid, got {type(grid).__name__}")
        if drag not in DRAG_LAWS:
            raise ConfigError(f"grid_fluid: unknown drag law '{drag}'; valid: {list(DRAG_LAWS)}")
        self.grid = grid
        self.drag = drag

    def describe(self) -> dict:
        return {**super().describe(), "drag": self.drag, "grid_spacing": self.grid.spacing,
                "grid_shape": list(self.grid.shape), "fluid_density": self.grid.density,
                "fluid_viscosity": self.grid.viscosity}

    def bind(self, ctx: BodyForceContext) -> None:
        m = ctx.model
        dev = ctx.device
        g = self.grid
        self._velocity = wp.array(np.ascontiguousarray(g.velocity), dtype=wp.vec3, device=dev)
        self._acceleration = wp.array(np.ascontiguousarray(g.acceleration), dtype=wp.vec3, device=dev)
        self._origin = wp.vec3(*np.asarray(g.origin, dtype=float))
        self._inv_h = 1.0 / g.spacing
        c = self.values["voidage_cell"]
        extent = np.asarray(g.shape, dtype=float) * g.spacing
        self._cdims = tuple(max(1, int(math.ceil(e / c))) for e in extent)
        self._c_origin = self._origin
        self._inv_c = 1.0 / c
        self._cell_volume = c**3
        ncell = int(np.prod(self._cdims))
        self._solid = wp.zeros(max(m.num_worlds * ncell, 1), dtype=float, device=dev)
        self._v_prev = wp.array(m.initial["body_v"], dtype=wp.vec3, device=dev)
        self._seen = wp.zeros(m.num_bodies, dtype=int, device=dev)
        self.voidage = wp.ones(m.num_bodies, dtype=float, device=dev)

    def launch(self, ctx: BodyForceContext, state_in, state_out, dt: float) -> None:
        m = ctx.model
        dev = ctx.device
        cnx, cny, cnz = self._cdims
        self._solid.zero_()
        wp.launch(scatter_solid_volume, dim=m.num_bodies, inputs=[
            state_in.body_q, state_in.body_active, m.body_world, ctx.body_volume, self._c_origin, self._inv_c,
            cnx, cny, cnz, self._solid], device=dev)
        v = self.values
        wp.launch(fluid_forces, dim=m.num_bodies, inputs=[
            state_in.body_q, state_in.body_v, state_in.body_active, m.body_world, ctx.body_volume, ctx.body_radius,
            self._velocity, self._acceleration, self._origin, self._inv_h,
            self._solid, self._c_origin, self._inv_c, cnx, cny, cnz, self._cell_volume,
            float(self.grid.density), float(self.grid.viscosity), DRAG_LAWS.index(self.drag), v["min_voidage"],
            v["pressure_gradient"], v["buoyancy"], v["added_mass"], ctx.gravity, float(dt),
            self._v_prev, self._seen, ctx.force, self.voidage], device=dev)
