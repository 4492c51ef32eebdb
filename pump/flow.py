"""Simplified analytic flow in the pump (no Navier-Stokes solve), and its sampling on a grid.

All velocities are absolute (stationary frame); the field is passage-averaged, so it is
axisymmetric in the impeller and steady in the stationary frame (the blades are resolved by the
DEM walls, not by the fluid). Cylindrical components (c_r, c_u, c_z) about the pump axis z:

* Suction pipe (r <= R_in, z >= b2): uniform axial flow c_z = -U, U = Q / (pi R_in^2).
* Eye corner (r <= R_in, 0 <= z < b2): axisymmetric stagnation-point flow turning the flow
  radial, Stokes stream function psi = -(Q / 2 pi) (r / R_in)^2 (z / b2):
  c_r = Q r / (2 pi R_in^2 b2), c_z = -Q z / (pi R_in^2 b2). It matches the pipe flow at
  z = b2 and the radial flow at r = R_in exactly (continuous velocity, div c = 0).
* Impeller (R_in < r <= r2, width b2): meridional velocity from continuity
  c_m = Q / (2 pi r b2) (no blade blockage: passage average); no swirl ahead of the blades
  (r < r1). Along the blades the relative flow follows the blade angle with a deviation
  (slip) that goes linearly in r from the inlet incidence to Wiesner's slip at the outlet:
  c_u = u - c_m / tan beta_B(r) - Delta(r), Delta(r1) = u1 - c_m1 / tan beta_1B (so c_u(r1) = 0,
  axial inlet without pre-swirl), Delta(r2) = (1 - gamma) u2 (so c_u(r2) = gamma u2 -
  c_m2 / tan beta_2B, Wiesner 1967; Gulich 2014 ch. 3).
* Vaneless gap and volute (r > r2): the radial flow widens linearly from b2 to b3 across the
  gap, c_r = Q / (2 pi r b(r)); the angular momentum r c_u falls linearly from K_2 = r2 c_u2 to
  the volute's free-vortex constant K_v (:mod:`pump.design`) at r3 and stays K_v beyond
  (free vortex c_u = K_v / r, Pfleiderer/Stepanoff volute).
* Discharge duct (x >= r3, y > 0): parallel flow along +y with the free-vortex profile
  u_y = K_v / x, so the throat section and the duct carry the same Q and the profile is
  continuous at the throat.
* Side rooms (r <= r2 between a disc and the casing's side liner: b2 < z < b2 + g in front,
  -g < z < 0 behind; g = ``design.side_gap``): a core in solid-body rotation, c_u = k omega r,
  c_r = c_z = 0, with the rotation factor k = ``side_room_rotation`` (default 0.5). Between a
  rotating disc and a stationary wall with separate boundary layers (the turbulent regime IV of
  Daily & Nece 1960, J. Basic Eng. 82:217) the core turns at a fraction k of the disc speed; with no
  leakage through the side room and the same wall friction on disc and casing k_0 = 0.5 (Gulich
  2003, Forsch. Ingenieurwes. 68:87, eq. T1.3 with r_w = r2; Gulich 2014, ch. 9). Pressure from
  the core's radial equilibrium, p*(r) = p*(r2) - rho k^2 omega^2 (r2^2 - r^2) / 2 (the side-room
  pressure behind the axial thrust, Gulich 2014, ch. 9), p*(r2) the impeller's outlet pressure.
  Not modelled: the leakage flow through the side rooms (to the eye seal in front), the disc's
  and the liner's boundary layers (outward pumping on the disc, inward flow on the liner: Daily &
  Nece's secondary flow, which carries particles along the liner), expelling vanes (which raise k
  towards 1).

Pressure (piezometric, p* = p - rho g.x, relative to the suction pipe's static pressure):
Bernoulli p* = p0_t - rho c^2 / 2 where the flow is irrotational (pipe, eye, vaneless inlet);
rothalpy conservation along the blades (Bernoulli in the rotating frame, inviscid),
p* = p0_t + rho (u^2 - w^2) / 2; radial equilibrium in the gap and the volute,
dp*/dr = rho (c_u^2 / r - c_r dc_r/dr), integrated from r2; no streamwise gradient in the duct.
The side rooms (above) are in radial equilibrium with their rotating core.
The particle force uses the fluid acceleration Du/Dt sampled on the grid (Maxey & Riley's
undisturbed-flow force rho_f V Du/Dt, which equals -V grad p where no blade force acts); the
pressure field is for output and for the consistency check -grad p / rho = Du/Dt.

Outside the fluid the formulas are continued (not zeroed), so trilinear interpolation near the
walls does not mix in zeros: each zone's formula continues beyond its walls (above the front wall
the pipe's where the pipe wall is the nearer wall, else the side room's or the volute's; behind
the back wall the side room's and the volute's).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warpdem.errors import ConfigError

from .design import G
from .geometry import PumpGeometry, blade_angle_at

WATER_DENSITY = 998.2  # [kg/m^3] at 20 C
WATER_VISCOSITY = 1.002e-3  # dynamic viscosity [Pa s] at 20 C
#: rotation factor k of the side rooms' core without leakage (Daily & Nece 1960; Gulich 2003, eq. T1.3)
SIDE_ROOM_ROTATION = 0.5


@dataclass
class PumpFlow:
    """Analytic passage-averaged flow of a :class:`PumpGeometry` (stationary frame).

    Args:
        geometry: the pump.
        density: fluid density [kg/m^3]; viscosity: dynamic viscosity [Pa s].
        side_room_rotation: rotation factor k [-] of the side rooms' core, c_u = k omega r (module
            docstring; 0.5: no leakage, Daily & Nece 1960, Gulich 2003), in [0, 1].
    """

    geometry: PumpGeometry
    density: float = WATER_DENSITY
    viscosity: float = WATER_VISCOSITY
    side_room_rotation: float = SIDE_ROOM_ROTATION

    def __post_init__(self) -> None:
        if not (self.density > 0 and math.isfinite(self.density)):
            raise ConfigError(f"fluid density must be > 0 kg/m^3, got {self.density}")
        if not (self.viscosity > 0 and math.isfinite(self.viscosity)):
            raise ConfigError(f"fluid viscosity must be > 0 Pa s, got {self.viscosity}")
        k = self.side_room_rotation
        if isinstance(k, bool) or not isinstance(k, (int, float)) or not (math.isfinite(k) and 0.0 <= k <= 1.0):
            raise ConfigError(f"side_room_rotation (the side rooms' core rotation c_u / (omega r)) must be a number "
                              f"in [0, 1], got {k!r}")
        d = self.geometry.design
        self.q = d.flow_rate
        self.omega = d.omega
        # deviation (slip) at the blade inlet and outlet [m/s]
        self.delta1 = d.u1 - d.c_m1 / math.tan(math.radians(d.beta1_deg))
        self.delta2 = (1.0 - d.slip_factor) * d.u2
        # radial-equilibrium pressure beyond r2 on a fine 1-D grid
        self._r_eq = np.linspace(d.r2, 2.0 * d.r_throat + 0.1, 4000)
        self._p_eq = self._radial_equilibrium(self._r_eq)
        self._p2 = float(self._impeller_pressure(np.array([d.r2]))[0])

    # ------------------------------------------------------------------ components
    def impeller_swirl(self, r: np.ndarray) -> np.ndarray:
        """c_u(r) [m/s] in the impeller (0 ahead of the blades)."""
        d = self.geometry.design
        r = np.asarray(r, dtype=float)
        xi = np.clip((r - d.r1) / (d.r2 - d.r1), 0.0, 1.0)
        c_m = self.q / (2.0 * np.pi * np.maximum(r, 1e-9) * d.b2)
        cu = self.omega * r - c_m / np.tan(blade_angle_at(d, r)) - (self.delta1 + (self.delta2 - self.delta1) * xi)
        return np.where(r <= d.r1, 0.0, cu)

    def volute_width(self, r: np.ndarray) -> np.ndarray:
        d = self.geometry.design
        s = np.clip((np.asarray(r, dtype=float) - d.r2) / (d.r3 - d.r2), 0.0, 1.0)
        return d.b2 + (d.b3 - d.b2) * s

    def angular_momentum(self, r: np.ndarray) -> np.ndarray:
        """r c_u [m^2/s] beyond the impeller (r >= r2)."""
        d = self.geometry.design
        s = np.clip((np.asarray(r, dtype=float) - d.r2) / (d.r3 - d.r2), 0.0, 1.0)
        return d.k_impeller + (d.k_volute - d.k_impeller) * s

    def side_room_swirl(self, r: np.ndarray) -> np.ndarray:
        """c_u = k omega r [m/s] of the side rooms' rotating core."""
        return self.side_room_rotation * self.omega * np.asarray(r, dtype=float)

    def side_room_pressure(self, r: np.ndarray) -> np.ndarray:
        """p*(r) = p*(r2) - rho k^2 omega^2 (r2^2 - r^2) / 2 [Pa] in the side rooms (radial equilibrium
        of the rotating core)."""
        d = self.geometry.design
        kw = self.side_room_rotation * self.omega
        return self._p2 - 0.5 * self.density * kw**2 * (d.r2**2 - np.asarray(r, dtype=float) ** 2)

    def _radial_equilibrium(self, r: np.ndarray) -> np.ndarray:
        d = self.geometry.design
        rho = self.density
        p2 = self._impeller_pressure(np.array([d.r2]))[0]
        cu = self.angular_momentum(r) / r
        cr = self.q / (2.0 * np.pi * r * self.volute_width(r))
        dcr = np.gradient(cr, r)
        dpdr = rho * (cu**2 / r - cr * dcr)
        return p2 + np.concatenate([[0.0], np.cumsum(0.5 * (dpdr[1:] + dpdr[:-1]) * np.diff(r))])

    def _impeller_pressure(self, r: np.ndarray) -> np.ndarray:
        """p* in the blade region from rothalpy, Bernoulli ahead of the blades [Pa]."""
        d = self.geometry.design
        rho = self.density
        p0t = 0.5 * rho * d.inlet_velocity**2
        c_m = self.q / (2.0 * np.pi * r * d.b2)
        cu = self.impeller_swirl(r)
        u = self.omega * r
        w2 = c_m**2 + (u - cu) ** 2
        return np.where(r <= d.r1, p0t - 0.5 * rho * c_m**2, p0t + 0.5 * rho * (u**2 - w2))

    # ------------------------------------------------------------------ field
    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Velocity (n, 3) [m/s] and piezometric pressure (n,) [Pa] at points x (n, 3) [m]."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        geo = self.geometry
        d = geo.design
        rho = self.density
        r = np.hypot(x[:, 0], x[:, 1])
        rs = np.maximum(r, 1e-12)
        er = np.stack([x[:, 0] / rs, x[:, 1] / rs, np.zeros(len(x))], -1)
        eu = np.stack([-er[:, 1], er[:, 0], np.zeros(len(x))], -1)
        z = x[:, 2]
        R, b2 = d.r_inlet, d.b2
        U = d.inlet_velocity
        p0t = 0.5 * rho * U**2
        cr = np.zeros(len(x))
        cu = np.zeros(len(x))
        cz = np.zeros(len(x))
        p = np.zeros(len(x))

        # zones; beyond the walls each zone's formula is continued (module docstring): above the front
        # wall the pipe's where the pipe wall is nearer than the front wall, so that interpolation next
        # to either wall sees the flow on its fluid side
        above = z - geo.z_front
        pipe = ((r <= R) & (z >= b2)) | ((above > 0.0) & (r - R < above))
        corner = (r <= R) & (z >= 0.0) & (z < b2)
        side = (r <= d.r2) & ((z < 0.0) | (z > b2)) & ~pipe
        imp = (r > R) & (r <= d.r2) & (z >= 0.0) & (z <= b2)
        duct = (x[:, 0] >= d.r3) & (x[:, 1] > 0.0)
        vol = (r > d.r2) & ~duct

        cz[pipe] = -U
        p[pipe] = 0.0
        zc = np.clip(z[corner], 0.0, b2)
        cr[corner] = self.q * r[corner] / (2.0 * np.pi * R**2 * b2)
        cz[corner] = -self.q * zc / (np.pi * R**2 * b2)
        p[corner] = p0t - 0.5 * rho * (cr[corner] ** 2 + cz[corner] ** 2)
        cr[imp] = self.q / (2.0 * np.pi * r[imp] * b2)
        cu[imp] = self.impeller_swirl(r[imp])
        p[imp] = self._impeller_pressure(r[imp])
        cu[side] = self.side_room_swirl(r[side])
        p[side] = self.side_room_pressure(r[side])
        cr[vol] = self.q / (2.0 * np.pi * r[vol] * self.volute_width(r[vol]))
        cu[vol] = self.angular_momentum(r[vol]) / r[vol]
        p[vol] = np.interp(r[vol], self._r_eq, self._p_eq)
        vel = cr[:, None] * er + cu[:, None] * eu
        vel[:, 2] = cz
        xd = x[duct, 0]
        vel[duct] = 0.0
        vel[duct, 1] = d.k_volute / xd
        p[duct] = np.interp(xd, self._r_eq, self._p_eq)
        return vel, p

    def velocity(self, x: np.ndarray) -> np.ndarray:
        return self.evaluate(x)[0]

    def pressure(self, x: np.ndarray) -> np.ndarray:
        return self.evaluate(x)[1]

    def sample(self, spacing: float = 0.003, margin: float = 0.01) -> "FlowGrid":
        """Sample velocity, pressure and the fluid acceleration Du/Dt = (u . grad) u (central
        differences; the field is steady in the stationary frame) on a regular grid covering
        the pump with ``margin`` [m] around it."""
        if not (spacing > 0 and math.isfinite(spacing)):
            raise ConfigError(f"flow grid spacing must be > 0 m, got {spacing}")
        lo, hi = self.geometry.bounds()
        lo = lo - margin
        hi = hi + margin
        shape = tuple(int(math.ceil((hi[k] - lo[k]) / spacing)) + 1 for k in range(3))
        if np.prod(shape) > 6e7:
            raise ConfigError(f"flow grid of {shape} points is too large; use a coarser spacing than {spacing} m")
        axes = [lo[k] + spacing * np.arange(shape[k]) for k in range(3)]
        pts = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        vel, p = self.evaluate(pts)
        vel = vel.reshape(*shape, 3)
        grads = [np.gradient(vel[..., c], spacing, edge_order=1) for c in range(3)]  # grads[c][k] = du_c/dx_k
        acc = np.stack([sum(vel[..., k] * grads[c][k] for k in range(3)) for c in range(3)], -1)
        return FlowGrid(origin=lo.astype(np.float64), spacing=float(spacing), velocity=vel.astype(np.float32),
                        acceleration=acc.astype(np.float32), pressure=p.reshape(shape).astype(np.float32),
                        density=self.density, viscosity=self.viscosity)

    # ------------------------------------------------------------------ checks
    def euler_head(self, field=None, n_theta: int = 360, n_z: int = 24, radius: float | None = None) -> float:
        """Euler head H_E = omega int r c_u c_r dA / (g Q) through the cylinder r (default r2)
        over the impeller width [m]; ``field`` maps points to velocities (default the
        analytic field, e.g. ``FlowGrid.interpolate_velocity`` for the sampled one)."""
        d = self.geometry.design
        r = d.r2 - 1e-9 if radius is None else radius
        f = field or self.velocity
        th = (np.arange(n_theta) + 0.5) * 2 * np.pi / n_theta
        zz = (np.arange(n_z) + 0.5) * d.b2 / n_z
        T, Z = np.meshgrid(th, zz, indexing="ij")
        pts = np.stack([r * np.cos(T).ravel(), r * np.sin(T).ravel(), Z.ravel()], -1)
        v = f(pts)
        er = pts[:, :2] / r
        c_r = np.sum(v[:, :2] * er, axis=1)
        c_u = v[:, 1] * er[:, 0] - v[:, 0] * er[:, 1]
        da = r * (2 * np.pi / n_theta) * (d.b2 / n_z)
        flux = np.sum(c_r) * da
        return float(self.omega * np.sum(r * c_u * c_r) * da / (G * flux))

    def flow_rates(self, field=None, n: int = 200) -> dict[str, float]:
        """Volume flow [m^3/s] through the suction pipe (mid-length disc), the impeller outlet
        (cylinder just inside r2 over b2), the volute throat (theta -> 2 pi section) and the
        discharge duct (mid-length section), from ``field`` (default analytic)."""
        geo = self.geometry
        d = geo.design
        f = field or self.velocity
        out = {}
        # suction pipe disc (midpoint rule in r and theta)
        rr = (np.arange(n) + 0.5) * d.r_inlet / n
        th = (np.arange(2 * n) + 0.5) * np.pi / n
        Rr, T = np.meshgrid(rr, th, indexing="ij")
        z = geo.z_front + 0.5 * d.inlet_length
        pts = np.stack([(Rr * np.cos(T)).ravel(), (Rr * np.sin(T)).ravel(), np.full(Rr.size, z)], -1)
        out["inlet"] = float(np.sum(-f(pts)[:, 2] * Rr.ravel()) * (d.r_inlet / n) * (np.pi / n))
        # impeller outlet
        r = d.r2 - 0.004
        th = (np.arange(4 * n) + 0.5) * 2 * np.pi / (4 * n)
        zz = (np.arange(n // 4) + 0.5) * d.b2 / (n // 4)
        T, Z = np.meshgrid(th, zz, indexing="ij")
        pts = np.stack([r * np.cos(T).ravel(), r * np.sin(T).ravel(), Z.ravel()], -1)
        v = f(pts)
        c_r = (v[:, 0] * pts[:, 0] + v[:, 1] * pts[:, 1]) / r
        out["impeller_outlet"] = float(np.sum(c_r) * r * (2 * np.pi / (4 * n)) * (d.b2 / (n // 4)))
        # volute throat: the section at theta = 2 pi - 1 deg (r3 .. r_o), tangential component
        th0 = 2 * np.pi - np.radians(1.0)
        ro = geo.spiral_radius(th0)
        rr = d.r3 + (np.arange(n) + 0.5) * (ro - d.r3) / n
        zz = geo.z_back + (np.arange(n // 4) + 0.5) * d.b3 / (n // 4)
        Rr, Z = np.meshgrid(rr, zz, indexing="ij")
        pts = np.stack([(Rr * math.cos(th0)).ravel(), (Rr * math.sin(th0)).ravel(), Z.ravel()], -1)
        v = f(pts)
        c_u = -v[:, 0] * math.sin(th0) + v[:, 1] * math.cos(th0)
        out["volute_throat"] = float(np.sum(c_u) * ((ro - d.r3) / n) * (d.b3 / (n // 4)))
        # discharge duct mid-length
        xs = d.r3 + (np.arange(n) + 0.5) * d.throat_height / n
        X, Z = np.meshgrid(xs, zz, indexing="ij")
        pts = np.stack([X.ravel(), np.full(X.size, 0.5 * geo.outlet_y), Z.ravel()], -1)
        out["discharge"] = float(np.sum(f(pts)[:, 1]) * (d.throat_height / n) * (d.b3 / (n // 4)))
        return out


@dataclass
class FlowGrid:
    """A flow field sampled on a regular grid (node-centred): ``velocity`` (nx, ny, nz, 3)
    [m/s], ``acceleration`` Du/Dt (nx, ny, nz, 3) [m/s^2], ``pressure`` (nx, ny, nz) [Pa];
    node (i, j, k) sits at origin + spacing * (i, j, k) [m]. Interpolation is trilinear with
    coordinates clamped to the grid (the same rule as :func:`pump.coupling.sample_vec3`)."""

    origin: np.ndarray
    spacing: float
    velocity: np.ndarray
    acceleration: np.ndarray
    pressure: np.ndarray
    density: float = WATER_DENSITY
    viscosity: float = WATER_VISCOSITY

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.pressure.shape)

    def _weights(self, x: np.ndarray):
        x = np.atleast_2d(np.asarray(x, dtype=float))
        n = np.asarray(self.shape)
        g = (x - self.origin) / self.spacing
        g = np.clip(g, 0.0, n - 1.000001)
        i0 = np.floor(g).astype(int)
        f = g - i0
        return i0, f

    def interpolate(self, x: np.ndarray, name: str = "velocity") -> np.ndarray:
        """Trilinear interpolation of one field ('velocity', 'acceleration', 'pressure') at x (n, 3)."""
        a = getattr(self, name)
        i0, f = self._weights(x)
        out = 0.0
        for dx in (0, 1):
            for dy in (0, 1):
                for dz in (0, 1):
                    w = ((f[:, 0] if dx else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1])
                         * (f[:, 2] if dz else 1 - f[:, 2]))
                    v = a[i0[:, 0] + dx, i0[:, 1] + dy, i0[:, 2] + dz]
                    out = out + (w[:, None] * v if v.ndim == 2 else w * v)
        return np.asarray(out, dtype=np.float64)

    def interpolate_velocity(self, x: np.ndarray) -> np.ndarray:
        return self.interpolate(x, "velocity")

    def pressure_gradient(self) -> np.ndarray:
        """grad p* (nx, ny, nz, 3) [Pa/m] by central differences."""
        return np.stack(np.gradient(self.pressure.astype(np.float64), self.spacing), -1)

    @property
    def nbytes(self) -> int:
        return int(self.velocity.nbytes + self.acceleration.nbytes + self.pressure.nbytes)

    @classmethod
    def uniform(cls, velocity, lower, upper, spacing: float, density: float = WATER_DENSITY,
                viscosity: float = WATER_VISCOSITY) -> "FlowGrid":
        """A uniform flow (zero acceleration, zero pressure) on a box [lower, upper] [m]: still
        fluid with velocity (0, 0, 0), or a uniform stream."""
        lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        shape = tuple(int(math.ceil((hi[k] - lo[k]) / spacing)) + 1 for k in range(3))
        vel = np.broadcast_to(np.asarray(velocity, dtype=np.float32), (*shape, 3)).copy()
        return cls(lo, float(spacing), vel, np.zeros((*shape, 3), np.float32), np.zeros(shape, np.float32),
                   density, viscosity)
