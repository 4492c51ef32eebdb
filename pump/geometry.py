"""Procedural, component-tagged triangle meshes of the prototype slurry pump.

Frame: the pump axis is z; the impeller turns about +z (counter-clockwise seen from the suction
side, +z), so the flow goes towards +theta. Hub disc at z = 0, shroud disc at z = b2; the
suction pipe runs along +z above the eye; the tongue (cut-water) sits at theta = 0 (the +x
axis) and the discharge duct leaves it along +y. With gravity along -y the shaft is horizontal
and the discharge points up, as on the usual end-suction pump.

Two walls:

* ``impeller`` (rotating): hub disc (r <= r2), shroud disc with the eye (R_in <= r <= r2) and
  z blades with thickness: camber theta(r) = theta_0 - int_r1^r dr / (r tan beta(r)) (backswept,
  beta linear from beta_1B to beta_2B, i.e. a log spiral when they are equal), offset by +-t/2
  normal to the camber, rounded (semicircular) leading and trailing edges, spanning 0 <= z <= b2.
* ``casing`` (static): spiral outer wall r_o(theta) = r3 exp(k theta), k = Q / (2 pi K_v b3)
  (free-vortex volute, :mod:`pump.design`), flat side walls at z = -g and z = b2 + g (g the side
  clearance ``design.side_gap``), each split at r = r2 into the side-room liner (r <= r2: the
  suction liner facing the shroud, the back liner facing the hub) and the volute's side wall
  (r > r2), the tongue where the spiral starts (theta = 0), a straight rectangular discharge duct
  of the throat's section along +y, and the suction pipe (radius R_in) along +z, whose wall (the
  throatbush lip) reaches down to :data:`EYE_SEAL_CLEARANCE` above the shroud's eye.

Every triangle carries its component (index into :data:`COMPONENTS`); blade triangles also carry
a zone (:data:`BLADE_ZONES`: leading edge, pressure side, suction side, trailing edge). The walls
are open surfaces (two-sided for the DEM contact) of zero thickness.

Side rooms: the spaces between the discs and the side-room liners (b2 < z < b2 + g and -g < z < 0,
r <= r2). A sphere of radius a keeps its centre at least a from the shroud plane and from the liner,
so it enters the front side room only if g > 2 a (the gap exceeds its diameter); the back side room
likewise. With the 1 mm eye seal no particle reaches the front side room from the eye: the only way
in is the gap at the impeller's rim, r = r2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from warpdem.errors import ConfigError

from .design import PumpDesign

COMPONENTS = ("shroud", "blade", "hub", "volute", "tongue", "inlet", "outlet")
ROTATING = ("shroud", "blade", "hub")
STATIC = ("volute", "tongue", "inlet", "outlet")
BLADE_ZONES = ("none", "leading_edge", "pressure_side", "suction_side", "trailing_edge")
# fraction of the blade's radial extent (from r1) counted as its "head" (leading-edge zone)
LEADING_EDGE_FRACTION = 0.12
# particle regions for counts over time (see PumpGeometry.region_of)
REGIONS = ("outside", "inlet", "impeller", "volute", "discharge", "side_rooms")
#: axial running clearance between the suction pipe's lower end (the throatbush lip at r = R_in)
#: and the shroud's eye [m]: smaller than any particle, so the front side room connects to the eye
#: only through a gap no particle passes (the leakage flow through it is not modelled)
EYE_SEAL_CLEARANCE = 0.001


@dataclass
class TaggedMesh:
    """Triangle mesh [m] with a component index per face (and a blade zone per face)."""

    vertices: np.ndarray
    faces: np.ndarray
    component: np.ndarray
    zone: np.ndarray = field(default=None)

    def __post_init__(self) -> None:
        self.vertices = np.asarray(self.vertices, dtype=np.float64)
        self.faces = np.asarray(self.faces, dtype=np.int64)
        self.component = np.asarray(self.component, dtype=np.int64)
        if self.zone is None:
            self.zone = np.zeros(len(self.faces), dtype=np.int64)
        self.zone = np.asarray(self.zone, dtype=np.int64)
        if self.component.shape != (len(self.faces),) or self.zone.shape != (len(self.faces),):
            raise ConfigError("TaggedMesh: component and zone need one entry per face")

    @staticmethod
    def concatenate(parts: list["TaggedMesh"]) -> "TaggedMesh":
        verts, faces, comp, zone = [], [], [], []
        off = 0
        for p in parts:
            verts.append(p.vertices)
            faces.append(p.faces + off)
            comp.append(p.component)
            zone.append(p.zone)
            off += len(p.vertices)
        return TaggedMesh(np.concatenate(verts), np.concatenate(faces), np.concatenate(comp), np.concatenate(zone))

    @property
    def num_triangles(self) -> int:
        return int(len(self.faces))

    def areas(self) -> np.ndarray:
        """Triangle areas [m^2]."""
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)

    def centroids(self) -> np.ndarray:
        return self.vertices[self.faces].mean(axis=1)

    def component_names(self) -> np.ndarray:
        return np.asarray(COMPONENTS)[self.component]

    def to_trimesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.vertices, self.faces, process=False)


# ----------------------------------------------------------------------------- helpers
def _grid_faces(n_u: int, n_v: int, wrap_u: bool = False) -> np.ndarray:
    """Triangles of a structured (n_u x n_v) vertex grid, vertex index = i * n_v + j."""
    faces = []
    nu = n_u if wrap_u else n_u - 1
    for i in range(nu):
        i2 = (i + 1) % n_u
        for j in range(n_v - 1):
            a, b, c, d = i * n_v + j, i2 * n_v + j, i * n_v + j + 1, i2 * n_v + j + 1
            faces += [[a, b, d], [a, d, c]]
    return np.asarray(faces, dtype=np.int64)


def _tagged(verts: np.ndarray, faces: np.ndarray, component: str, zone: np.ndarray | int = 0) -> TaggedMesh:
    comp = np.full(len(faces), COMPONENTS.index(component), dtype=np.int64)
    z = np.broadcast_to(np.asarray(zone, dtype=np.int64), (len(faces),)).copy()
    return TaggedMesh(verts, faces, comp, z)


def annulus(r_inner: float, r_outer, z: float, n_theta: int, n_r: int, component: str,
            theta: np.ndarray | None = None) -> TaggedMesh:
    """Flat ring r_inner <= r <= r_outer (a scalar or one radius per theta) at height z [m];
    r_inner = 0 gives a disc (a fan of triangles at the centre)."""
    th = np.linspace(0.0, 2.0 * np.pi, n_theta, endpoint=False) if theta is None else np.asarray(theta)
    wrap = theta is None
    ro = np.broadcast_to(np.asarray(r_outer, dtype=float), th.shape)
    s = np.linspace(0.0, 1.0, n_r + 1)
    rr = r_inner + (ro[:, None] - r_inner) * s[None, :]
    if r_inner == 0.0:
        rr = rr[:, 1:]
    verts = np.stack([rr * np.cos(th)[:, None], rr * np.sin(th)[:, None], np.full_like(rr, z)], -1).reshape(-1, 3)
    faces = _grid_faces(len(th), rr.shape[1], wrap_u=wrap)
    if r_inner == 0.0:
        centre = len(verts)
        verts = np.vstack([verts, [[0.0, 0.0, z]]])
        nv = rr.shape[1]
        fan = [[centre, i * nv, ((i + 1) % len(th)) * nv] for i in range(len(th) if wrap else len(th) - 1)]
        faces = np.vstack([faces, np.asarray(fan, dtype=np.int64)])
    return _tagged(verts, faces, component)


def blade_camber(design: PumpDesign, n: int = 48, theta0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Camber line of one blade: radii (n,) [m] and angles theta (n,) [rad].

    theta(r) = theta0 - int_r1^r dr' / (r' tan beta(r')), beta linear in r from beta_1B to
    beta_2B (backswept for rotation about +z), integrated with the trapezoidal rule on a fine
    grid."""
    r1, r2 = design.r1, design.r2
    rf = np.linspace(r1, r2, 20 * n + 1)
    beta = np.radians(design.beta1_deg + (design.beta2_blade_deg - design.beta1_deg) * (rf - r1) / (r2 - r1))
    integrand = 1.0 / (rf * np.tan(beta))
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(rf))])
    r = np.linspace(r1, r2, n)
    return r, theta0 - np.interp(r, rf, cum)


def blade_angle_at(design: PumpDesign, r: np.ndarray) -> np.ndarray:
    """Blade angle beta_B(r) [rad] from the circumferential direction (linear in r)."""
    r = np.asarray(r, dtype=float)
    xi = np.clip((r - design.r1) / (design.r2 - design.r1), 0.0, 1.0)
    return np.radians(design.beta1_deg + (design.beta2_blade_deg - design.beta1_deg) * xi)


def blade(design: PumpDesign, theta0: float, n_camber: int = 40, n_cap: int = 6, n_z: int = 4) -> TaggedMesh:
    """One blade as a closed prism side surface (0 <= z <= b2; the end faces are covered by the
    hub and shroud discs). The pressure side faces +theta (the direction of rotation)."""
    r, th = blade_camber(design, n_camber, theta0)
    p = np.stack([r * np.cos(th), r * np.sin(th)], -1)
    t = np.gradient(p, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    nrm = np.stack([-t[:, 1], t[:, 0]], -1)  # left of the outward tangent
    e_theta = np.stack([-np.sin(th), np.cos(th)], -1)
    if np.mean(np.sum(nrm * e_theta, axis=1)) < 0:
        nrm = -nrm  # nrm points to the pressure side (+theta)
    h = 0.5 * design.blade_thickness
    pressure = p + h * nrm
    suction = p - h * nrm
    xi = (r - design.r1) / (design.r2 - design.r1)

    def cap(centre, start_dir, end_dir, outward):
        # semicircle from start_dir to end_dir bulging along outward (unit 2-vectors)
        ang = np.linspace(0.0, np.pi, n_cap + 1)[1:-1]
        return np.array([centre + h * (math.cos(a) * start_dir + math.sin(a) * outward) for a in ang])

    te_cap = cap(p[-1], nrm[-1], -nrm[-1], t[-1])
    le_cap = cap(p[0], -nrm[0], nrm[0], -t[0])
    ring = np.vstack([pressure, te_cap, suction[::-1], le_cap])
    nps = len(pressure)
    seg_zone = np.empty(len(ring), dtype=np.int64)  # zone of the segment starting at ring[i]
    seg_zone[:nps - 1] = np.where(xi[:-1] < LEADING_EDGE_FRACTION, 1, 2)
    seg_zone[nps - 1: nps + len(te_cap)] = 4
    xi_s = xi[::-1]
    k0 = nps + len(te_cap)
    seg_zone[k0: k0 + nps - 1] = np.where(xi_s[1:] < LEADING_EDGE_FRACTION, 1, 3)
    seg_zone[k0 + nps - 1:] = 1
    zs = np.linspace(0.0, design.b2, n_z + 1)
    m = len(ring)
    verts = np.concatenate([np.column_stack([ring, np.full(m, z)]) for z in zs])
    faces, zone = [], []
    for k in range(n_z):
        for i in range(m):
            a, b = k * m + i, k * m + (i + 1) % m
            c, d = a + m, b + m
            faces += [[a, b, d], [a, d, c]]
            zone += [seg_zone[i]] * 2
    return _tagged(verts, np.asarray(faces), "blade", np.asarray(zone))


def cylinder(radius: float, z0: float, z1: float, n_theta: int, n_z: int, component: str) -> TaggedMesh:
    th = np.linspace(0.0, 2.0 * np.pi, n_theta, endpoint=False)
    zs = np.linspace(z0, z1, n_z + 1)
    verts = np.stack([np.repeat(radius * np.cos(th), len(zs)), np.repeat(radius * np.sin(th), len(zs)),
                      np.tile(zs, n_theta)], -1)
    return _tagged(verts, _grid_faces(n_theta, len(zs), wrap_u=True), component)


def rectangle(origin, u, v, n_u: int, n_v: int, component: str) -> TaggedMesh:
    """Planar rectangle origin + s u + t v, s, t in [0, 1], split into n_u x n_v cells."""
    o, u, v = (np.asarray(a, dtype=float) for a in (origin, u, v))
    s = np.linspace(0.0, 1.0, n_u + 1)
    t = np.linspace(0.0, 1.0, n_v + 1)
    verts = (o + s[:, None, None] * u + t[None, :, None] * v).reshape(-1, 3)
    return _tagged(verts, _grid_faces(n_u + 1, n_v + 1), component)


# ----------------------------------------------------------------------------- the pump
@dataclass
class PumpGeometry:
    """The pump's meshes and the key dimensions used by the flow field and the particle regions.

    Attributes:
        design: the sizing (:class:`pump.design.PumpDesign`).
        impeller: rotating mesh (shroud, blade, hub); casing: static mesh (volute, tongue,
            inlet, outlet).
        inlet_top: z of the open end of the suction pipe [m]; outlet_y: y of the open end of the
            discharge duct [m] (particles beyond it have left the pump).
    """

    design: PumpDesign
    impeller: TaggedMesh
    casing: TaggedMesh
    inlet_top: float
    outlet_y: float
    user_components: tuple[str, ...] = ()

    # --------------------------------------------------------------- dimensions
    @property
    def z_front(self) -> float:
        """z of the casing's front (suction-side) wall [m]."""
        return self.design.b2 + self.design.side_gap

    @property
    def z_back(self) -> float:
        return -self.design.side_gap

    def spiral_radius(self, theta: np.ndarray) -> np.ndarray:
        """Volute outer wall r_o(theta) = r3 exp(k theta), theta in [0, 2 pi) from the tongue [m]."""
        th = np.mod(np.asarray(theta, dtype=float), 2.0 * np.pi)
        return self.design.r3 * np.exp(self.design.spiral_rate * th)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        v = np.vstack([self.impeller.vertices, self.casing.vertices])
        return v.min(axis=0), v.max(axis=0)

    def region_of(self, x: np.ndarray) -> np.ndarray:
        """Region index (:data:`REGIONS`) of points x (n, 3) [m] in the stationary frame:
        inlet (suction pipe and eye gap), impeller (r <= r2 between the discs, 0 <= z <= b2),
        side_rooms (r <= r2 between a disc and the casing's side liner), volute (r2 < r inside the
        spiral), discharge (the duct), else outside."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        d = self.design
        r = np.hypot(x[:, 0], x[:, 1])
        th = np.mod(np.arctan2(x[:, 1], x[:, 0]), 2.0 * np.pi)
        z = x[:, 2]
        out = np.zeros(len(x), dtype=np.int64)
        in_band = (z >= self.z_back) & (z <= self.z_front)
        pipe = (z >= d.b2) & (z <= self.inlet_top) & (r <= d.r_inlet)
        beside = in_band & (r <= d.r2) & ~pipe
        impeller = beside & (z >= 0.0) & (z <= d.b2)
        side = beside & ~impeller
        duct = in_band & (x[:, 0] >= d.r3) & (x[:, 0] <= d.r_throat) & (x[:, 1] >= 0.0) & (x[:, 1] <= self.outlet_y)
        volute = in_band & (r > d.r2) & (r <= self.spiral_radius(th)) & ~duct
        out[pipe] = 1
        out[impeller] = 2
        out[volute] = 3
        out[duct] = 4
        out[side] = 5
        return out


def build_pump(design: PumpDesign | None = None, resolution: float = 1.0,
               user_meshes: dict[str, str | Path] | None = None, mesh_scale: float = 1.0) -> PumpGeometry:
    """Build the pump's tagged meshes.

    Args:
        design: sizing (default :class:`PumpDesign()`, the paper's duty).
        resolution: multiplies the number of cells of every surface (1: about 8k impeller and
            13k casing triangles).
        user_meshes: optional {component: STL/OBJ path} replacing procedural components (e.g.
            ``{"blade": "my_blades.stl", "volute": "casing.obj"}``); shroud/blade/hub join the
            rotating impeller, the others the static casing. The flow field stays the analytic
            one of ``design``, so keep the user geometry consistent with it.
        mesh_scale: factor applied to user mesh coordinates (0.001 for millimetres).
    """
    d = design or PumpDesign()
    if not (resolution > 0 and math.isfinite(resolution)):
        raise ConfigError(f"build_pump: resolution must be > 0, got {resolution}")

    def n(k: float, lo: int = 2) -> int:
        return max(lo, int(round(k * resolution)))

    b2, g = d.b2, d.side_gap
    z_front, z_back = b2 + g, -g
    # ---- impeller
    n_th = n(96, 24)
    parts_imp = [annulus(0.0, d.r2, 0.0, n_th, n(16, 3), "hub"),
                 annulus(d.r_inlet, d.r2, b2, n_th, n(14, 3), "shroud")]
    for k in range(d.blades):
        parts_imp.append(blade(d, 2.0 * np.pi * k / d.blades, n_camber=n(40, 8), n_cap=n(6, 3), n_z=n(4, 2)))
    impeller = TaggedMesh.concatenate(parts_imp)
    # ---- casing
    n_sp = n(144, 36)
    th = np.linspace(0.0, 2.0 * np.pi, n_sp + 1)
    ro = d.r3 * np.exp(d.spiral_rate * th)
    zs = np.linspace(z_back, z_front, n(6, 2) + 1)
    sv = np.stack([np.repeat(ro * np.cos(th), len(zs)), np.repeat(ro * np.sin(th), len(zs)),
                   np.tile(zs, len(th))], -1)
    sf = _grid_faces(len(th), len(zs))
    spiral_theta = np.repeat(0.5 * (th[:-1] + th[1:]), 2 * (len(zs) - 1))
    comp = np.where(spiral_theta < np.radians(20.0), COMPONENTS.index("tongue"), COMPONENTS.index("volute"))
    spiral = TaggedMesh(sv, sf, comp)
    parts_cas = [spiral]
    # side walls: the side-room liners from the eye (front) / the axis (back) to r2, then the
    # volute's side walls from r2 to the spiral (split at r2 so that a triangle lies on one side)
    for z, r_in in ((z_front, d.r_inlet), (z_back, 0.0)):
        inner = annulus(r_in, d.r2, z, n_sp, n(8, 2), "volute")
        outer = annulus(d.r2, ro, z, n_sp + 1, n(10, 3), "volute", theta=th)
        parts_cas += [inner, outer]
    # discharge duct (along +y from the throat section at theta = 0)
    length = d.discharge_length
    n_len = n(length / 0.008, 4)
    n_w = n(6, 2)
    h = d.throat_height
    tongue_len = 0.03
    parts_cas += [
        rectangle((d.r3, 0.0, z_back), (0.0, tongue_len, 0.0), (0.0, 0.0, z_front - z_back), n(4, 1), n_w, "tongue"),
        rectangle((d.r3, tongue_len, z_back), (0.0, length - tongue_len, 0.0), (0.0, 0.0, z_front - z_back),
                  n_len, n_w, "outlet"),
        rectangle((d.r_throat, 0.0, z_back), (0.0, length, 0.0), (0.0, 0.0, z_front - z_back), n_len, n_w, "outlet"),
        rectangle((d.r3, 0.0, z_back), (h, 0.0, 0.0), (0.0, length, 0.0), n(4, 2), n_len, "outlet"),
        rectangle((d.r3, 0.0, z_front), (h, 0.0, 0.0), (0.0, length, 0.0), n(4, 2), n_len, "outlet"),
    ]
    # suction pipe, and its lip (the throatbush's) down to the eye seal clearance above the shroud
    top = z_front + d.inlet_length
    parts_cas.append(cylinder(d.r_inlet, z_front, top, n(48, 16), n(d.inlet_length / 0.01, 4), "inlet"))
    if g > EYE_SEAL_CLEARANCE:
        lip = b2 + EYE_SEAL_CLEARANCE
        parts_cas.append(cylinder(d.r_inlet, lip, z_front, n(48, 16), max(1, int(math.ceil((z_front - lip) / 0.01))),
                                  "inlet"))
    casing = TaggedMesh.concatenate(parts_cas)
    geo = PumpGeometry(d, impeller, casing, inlet_top=top, outlet_y=length)
    if user_meshes:
        geo = _replace_components(geo, user_meshes, mesh_scale)
    return geo


def load_component_mesh(path: str | Path, component: str, scale: float = 1.0) -> TaggedMesh:
    """A user STL/OBJ file as one component (coordinates times ``scale`` -> metres)."""
    if component not in COMPONENTS:
        raise ConfigError(f"unknown pump component '{component}'; components: {list(COMPONENTS)}")
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"mesh file for component '{component}' not found: {p}")
    try:
        m = trimesh.load(p, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types on bad files
        raise ConfigError(f"cannot read mesh file {p} for component '{component}': {exc}") from exc
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise ConfigError(f"mesh file {p} for component '{component}' holds no triangles")
    if not (scale > 0 and math.isfinite(scale)):
        raise ConfigError(f"mesh_scale must be > 0, got {scale}")
    return _tagged(np.asarray(m.vertices) * scale, np.asarray(m.faces), component)


def _replace_components(geo: PumpGeometry, user_meshes: dict, scale: float) -> PumpGeometry:
    for name in user_meshes:
        if name not in COMPONENTS:
            raise ConfigError(f"user mesh for unknown pump component '{name}'; components: {list(COMPONENTS)}")
    loaded = {k: load_component_mesh(v, k, scale) for k, v in user_meshes.items()}

    def rebuild(mesh: TaggedMesh, names: tuple[str, ...]) -> TaggedMesh:
        keep_parts = []
        for name in names:
            if name in loaded:
                keep_parts.append(loaded[name])
                continue
            sel = mesh.component == COMPONENTS.index(name)
            if not sel.any():
                continue
            used, inv = np.unique(mesh.faces[sel], return_inverse=True)
            keep_parts.append(TaggedMesh(mesh.vertices[used], inv.reshape(-1, 3), mesh.component[sel], mesh.zone[sel]))
        return TaggedMesh.concatenate(keep_parts)

    return PumpGeometry(geo.design, rebuild(geo.impeller, ROTATING), rebuild(geo.casing, STATIC), geo.inlet_top,
                        geo.outlet_y, tuple(sorted(loaded)))


def passage_clearances(geo: PumpGeometry) -> dict[str, float]:
    """Narrowest clear widths a particle must pass [m]: blade-to-blade throat at the leading
    edge and at the outlet (measured on the meshes at mid-span), the tongue clearance, the
    volute throat, the impeller outlet width and the suction pipe diameter."""
    d = geo.design
    imp = geo.impeller
    blade_sel = imp.component == COMPONENTS.index("blade")
    verts = imp.vertices[np.unique(imp.faces[blade_sel])]
    mid = np.abs(verts[:, 2] - 0.5 * d.b2) < 0.26 * d.b2
    pts = verts[mid, :2]
    r = np.hypot(pts[:, 0], pts[:, 1])
    th = np.arctan2(pts[:, 1], pts[:, 0])
    owner = np.round(np.mod(th - _camber_theta(d, r), 2 * np.pi) / (2 * np.pi / d.blades)).astype(int) % d.blades

    def min_gap(r_lo: float, r_hi: float) -> float:
        # shortest distance between blade k's surface points in the band and blade k+1's anywhere
        best = np.inf
        for k in range(d.blades):
            a = pts[(owner == k) & (r >= r_lo) & (r <= r_hi)]
            b = pts[owner == (k + 1) % d.blades]
            if len(a) and len(b):
                dist = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)).min()
                best = min(best, dist)
        return float(best)

    return dict(
        blade_throat_inlet=min_gap(d.r1, d.r1 + 0.2 * (d.r2 - d.r1)),
        blade_throat_outlet=min_gap(d.r2 - 0.2 * (d.r2 - d.r1), d.r2),
        tongue_clearance=float(d.r3 - d.r2),
        volute_throat=float(d.throat_height),
        impeller_width=float(d.b2),
        volute_width=float(d.b3),
        suction_pipe=float(2 * d.r_inlet),
    )


def _camber_theta(d: PumpDesign, r: np.ndarray) -> np.ndarray:
    rc, thc = blade_camber(d, 200, 0.0)
    return np.interp(np.clip(r, d.r1, d.r2), rc, thc)
