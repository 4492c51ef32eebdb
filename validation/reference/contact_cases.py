"""Single contacts run in LIGGGHTS-PUBLIC 3.8 and in warpdem, side by side (issue 27, item 2).

A :class:`ContactCase` is plain data: one sphere on a flat triangle-mesh wall, or two spheres;
their material, the contact law, the initial positions and velocities, gravity, the time step
and the duration. The same case

(a) writes a LIGGGHTS deck (``atom_style granular``, ``units si``, ``pair_style gran model hertz
    tangential history [rolling_friction X] [cohesion Y]``, ``fix wall/gran ... mesh`` on an STL
    written here, ``fix nve/sphere``, ``dump custom`` of position, velocity, force, angular
    velocity and torque), runs it (:func:`validation.reference.liggghts.run_deck`) and reads the
    histories back (:func:`run_liggghts`);
(b) runs in warpdem on the CPU with the same time step and returns the same histories
    (:func:`run_warpdem`);
(c) reduces both to figures (:func:`derived_figures`): rebound normal and tangential velocity,
    spin after an oblique impact, peak normal force, rolling distance until the sphere stops,
    pull-off force and work of separation of a cohesive contact pulled apart at constant speed.

Geometry (SI units). Wall cases: the floor z = 0 (normal +z) is one large triangle
(:data:`WALL_TRIANGLE`: the sphere touches one face), or a square whose shared edge or vertex
lies under the sphere (:data:`WALL_MESHES`). Sphere-sphere cases: sphere 0 at -x, sphere 1 at
+x, gravity off, moving towards each other at half the relative speed each. The contact normal
``n`` points from the partner to sphere 0, the tangent ``t`` is the direction of sphere 0's
initial tangential velocity (or of its contact point's slip), and spin is read about ``n x t``;
the figures are of sphere 0 (the normal rebound velocity of a pair is the relative one).

Forces: warpdem's per-sphere contact force and torque of the step that starts from a recorded
state; LIGGGHTS' ``f`` of the same step number minus gravity (``fix gravity`` adds m g to f).

A pulled case (``pulled=True``) moves sphere 0 at its constant initial velocity and holds sphere
1 (LIGGGHTS ``fix move linear`` and no integrator; warpdem: the states are reset to the
prescribed motion after every step), so the force history is a function of the overlap and the
normal speed alone.
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from .liggghts import read_dump, run_deck

__all__ = ["WALL_TRIANGLE", "WALL_MESHES", "TOLERANCES", "ContactCase", "ContactHistories", "Comparison", "CASES",
           "case_by_name", "run_liggghts", "run_warpdem", "prepare_warpdem", "derived_figures", "compare_case",
           "compare_cases", "equilibrium_overlap", "deck_text", "warpdem_law"]

Vec3 = tuple[float, float, float]
GRAVITY = 9.81  # m/s^2, along -z in both codes

#: The wall: one triangle in z = 0 with normal +z (counter-clockwise seen from above) [m]
WALL_TRIANGLE = np.array([(-0.1, -0.1, 0.0), (0.3, -0.1, 0.0), (-0.1, 0.3, 0.0)])
_SQUARE = np.array([(-0.1, -0.1, 0.0), (0.1, -0.1, 0.0), (0.1, 0.1, 0.0), (-0.1, 0.1, 0.0), (0.0, 0.0, 0.0)])
#: Floor meshes in z = 0 (vertices [m], faces; normal +z): ``triangle`` (the sphere at the origin
#: touches one face), ``edge`` (a square of two triangles whose diagonal runs through the
#: origin: the sphere sits on the shared edge) and ``vertex`` (a square of four triangles meeting
#: at the origin: the sphere sits on the shared vertex)
WALL_MESHES: dict[str, tuple[np.ndarray, np.ndarray]] = {
    "triangle": (WALL_TRIANGLE, np.array([[0, 1, 2]])),
    "edge": (_SQUARE[:4], np.array([[0, 1, 2], [0, 2, 3]])),
    "vertex": (_SQUARE, np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])),
}

#: Relative tolerance of each figure (issue 27: rebound velocities and peak forces 1 %, rolling
#: distance 2 %, cohesive pull-off force 1 %; spin and work of separation held to 1 % as well)
TOLERANCES = {
    "rebound_normal_velocity": 0.01,
    "rebound_tangential_velocity": 0.01,
    "rebound_spin": 0.01,
    "peak_normal_force": 0.01,
    "rolling_distance": 0.02,
    "pull_off_force": 0.01,
    "work_of_separation": 0.01,
}

UNITS = {"rebound_normal_velocity": "m/s", "rebound_tangential_velocity": "m/s", "rebound_spin": "rad/s",
         "peak_normal_force": "N", "rolling_distance": "m", "pull_off_force": "N", "work_of_separation": "J"}


@dataclass(frozen=True)
class ContactCase:
    """One contact experiment, runnable in LIGGGHTS and in warpdem.

    Material and law (the same for the sphere(s) and the wall): ``radius`` [m] (sphere 1:
    ``partner_radius``, None: the same), ``density`` [kg/m^3], ``youngs_modulus`` [Pa],
    ``poisson_ratio``, ``restitution``, ``friction`` (mu_s), ``rolling`` (``none``/``cdt``/
    ``epsd``/``epsd2``) with ``rolling_friction`` (mu_r), ``cohesion`` (``none``/``sjkr``/
    ``sjkr2``) with ``cohesion_energy_density`` (k [J/m^3]); ``wall``: the floor mesh of a
    wall case (:data:`WALL_MESHES`). ``warpdem_normal`` and ``warpdem_tangential`` are
    warpdem's normal and tangential sub-models (LIGGGHTS always runs ``hertz`` and ``history``;
    ``hertz_liggghts`` is Hertz with LIGGGHTS' wall contact point); ``warpdem_rolling`` and
    ``warpdem_cohesion`` name another warpdem sub-model than the LIGGGHTS one (e.g.
    ``cdt_liggghts``: the variants that follow LIGGGHTS' definitions; ``sjkr_reduced``: LIGGGHTS' ``tangential_reduce on``).
    ``tangential_reduce`` appends that LIGGGHTS cohesion keyword (``on``/``off``; None:
    LIGGGHTS' default, off).

    Kinematics: ``positions``, ``velocities`` and ``angular_velocities`` of sphere 0 and, for
    ``partner == "sphere"``, sphere 1 [m, m/s, rad/s]; ``gravity`` on (-z) or off; ``pulled``
    (see the module docstring). ``dt`` [s], ``duration`` [s], ``output_every`` [steps].

    ``quantities``: the figures compared; ``expect_agreement``: False for a comparison that
    documents a known difference of definitions (``note`` says which), reported but not
    held to the tolerances.
    """

    name: str
    partner: str
    positions: tuple[Vec3, ...]
    velocities: tuple[Vec3, ...]
    duration: float
    quantities: tuple[str, ...]
    angular_velocities: tuple[Vec3, ...] = ()
    radius: float = 0.009
    partner_radius: float | None = None
    density: float = 2650.0
    youngs_modulus: float = 1.0e7
    poisson_ratio: float = 0.3
    restitution: float = 0.6
    friction: float = 0.5
    wall: str = "triangle"
    rolling: str = "none"
    rolling_friction: float = 0.0
    cohesion: str = "none"
    cohesion_energy_density: float = 0.0
    warpdem_normal: str = "hertz"
    warpdem_tangential: str = "history"
    warpdem_rolling: str | None = None
    warpdem_cohesion: str | None = None
    tangential_reduce: bool | None = None
    gravity: bool = False
    pulled: bool = False
    dt: float = 1.0e-6
    output_every: int = 42
    expect_agreement: bool = True
    note: str = ""

    def __post_init__(self) -> None:
        n = 1 if self.partner == "wall" else 2 if self.partner == "sphere" else 0
        if n == 0:
            raise ValueError(f"case {self.name}: partner must be 'wall' or 'sphere', got {self.partner!r}")
        if len(self.positions) != n or len(self.velocities) != n:
            raise ValueError(f"case {self.name}: needs {n} position(s) and velocity(ies)")
        if not self.angular_velocities:
            object.__setattr__(self, "angular_velocities", ((0.0, 0.0, 0.0),) * n)
        unknown = set(self.quantities) - set(TOLERANCES)
        if unknown:
            raise ValueError(f"case {self.name}: unknown quantities {sorted(unknown)}")

    # ------------------------------------------------------------------ derived geometry
    @property
    def num_spheres(self) -> int:
        return len(self.positions)

    @property
    def radii(self) -> tuple[float, ...]:
        """Radius of each sphere [m]."""
        if self.partner == "wall":
            return (self.radius,)
        return (self.radius, self.partner_radius or self.radius)

    @property
    def masses(self) -> tuple[float, ...]:
        """m = rho 4/3 pi r^3 of each sphere [kg]."""
        return tuple(self.density * 4.0 / 3.0 * math.pi * r**3 for r in self.radii)

    @property
    def mass(self) -> float:
        """Mass of sphere 0 [kg]."""
        return self.masses[0]

    @property
    def steps(self) -> int:
        return int(round(self.duration / self.dt))

    @property
    def normal(self) -> np.ndarray:
        """Unit normal from the partner to sphere 0 at the start."""
        if self.partner == "wall":
            return np.array([0.0, 0.0, 1.0])
        d = np.subtract(self.positions[0], self.positions[1])
        return d / np.linalg.norm(d)

    @property
    def tangent(self) -> np.ndarray:
        """Unit tangential direction of the impact: sphere 0's initial velocity relative to the
        partner, normal part removed; without one, the slip of the contact point (spin); without
        either, the world axis least aligned with the normal."""
        n, r = self.normal, self.radius
        r1 = self.radii[-1]
        v = np.subtract(self.velocities[0], self.velocities[1] if self.partner == "sphere" else (0.0, 0.0, 0.0))
        slip = v + np.cross(self.angular_velocities[0], -r * n)
        if self.partner == "sphere":
            slip = slip - np.cross(self.angular_velocities[1], r1 * n)
        for u in (v, slip):
            ut = u - np.dot(u, n) * n
            if np.linalg.norm(ut) > 1e-9:
                return ut / np.linalg.norm(ut)
        axis = np.eye(3)[int(np.argmin(np.abs(n)))]
        axis = axis - np.dot(axis, n) * n
        return axis / np.linalg.norm(axis)

    @property
    def spin_axis(self) -> np.ndarray:
        """n x t: the axis about which friction spins sphere 0."""
        return np.cross(self.normal, self.tangent)

    def law_text(self, engine: str) -> str:
        """Short description of the law each code runs, e.g. ``hertz+history+epsd2+sjkr``."""
        if engine == "warpdem":
            parts = [self.warpdem_normal, self.warpdem_tangential, self.warpdem_rolling or self.rolling,
                     self.warpdem_cohesion or self.cohesion]
        else:
            parts = ["hertz", "history", self.rolling, self.cohesion]
            if self.tangential_reduce is not None:
                parts.append(f"tangential_reduce {'on' if self.tangential_reduce else 'off'}")
        return "+".join(p for p in parts if p != "none")


@dataclass
class ContactHistories:
    """Sampled histories of one run (n samples, s spheres; SI units).

    ``force`` and ``torque`` are the contact force [N] and torque [N m] on each sphere (gravity
    excluded), evaluated at the recorded state."""

    engine: str
    time: np.ndarray  # (n,)
    position: np.ndarray  # (n, s, 3)
    velocity: np.ndarray  # (n, s, 3)
    angular_velocity: np.ndarray  # (n, s, 3)
    force: np.ndarray  # (n, s, 3)
    torque: np.ndarray  # (n, s, 3)
    wall_s: float = 0.0
    version: str = ""


@dataclass(frozen=True)
class Comparison:
    """One figure of one case in both codes; ``rel_diff`` = (warpdem - LIGGGHTS) / |LIGGGHTS|."""

    case: str
    quantity: str
    unit: str
    liggghts: float
    warpdem: float
    tolerance: float
    expect_agreement: bool
    note: str = ""

    @property
    def rel_diff(self) -> float:
        return (self.warpdem - self.liggghts) / abs(self.liggghts) if self.liggghts != 0 else math.inf

    @property
    def agrees(self) -> bool:
        return abs(self.rel_diff) <= self.tolerance

    def as_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out["rel_diff"] = self.rel_diff
        out["agrees"] = self.agrees
        return out


# ---------------------------------------------------------------------------- helpers
def effective_youngs_modulus(case: ContactCase) -> float:
    """E* = E / (2 (1 - nu^2)) for two bodies of the case's material [Pa]."""
    return case.youngs_modulus / (2.0 * (1.0 - case.poisson_ratio**2))


def cohesion_area(case: ContactCase, delta: float) -> float:
    """Contact area A(delta) [m^2] of the case's cohesion model (0 without one), written from
    LIGGGHTS-PUBLIC 3.8 src/cohesion_model_sjkr.h and src/cohesion_model_sjkr2.h, d the centre
    distance (wall: to the contact point):

    - sjkr, wall:   pi (r^2 - d^2), d = r - delta
    - sjkr, pair:   -pi/4 (d - r_i - r_j)(d + r_i - r_j)(d - r_i + r_j)(d + r_i + r_j) / d^2
    - sjkr2, wall:  2 pi r delta
    - sjkr2, pair:  2 pi (2 R*) delta
    """
    r = case.radii
    if case.cohesion == "sjkr":
        if case.partner == "wall":
            d = r[0] - delta
            return math.pi * (r[0] * r[0] - d * d)
        d = r[0] + r[1] - delta
        ri, rj = r
        return -math.pi / 4.0 * ((d - ri - rj) * (d + ri - rj) * (d - ri + rj) * (d + ri + rj)) / (d * d)
    if case.cohesion == "sjkr2":
        return 2.0 * math.pi * (r[0] if case.partner == "wall" else 2.0 * r[0] * r[1] / (r[0] + r[1])) * delta
    return 0.0


def equilibrium_overlap(case: ContactCase, load: float = 0.0) -> float:
    """Overlap delta [m] at which the contact carries ``load`` [N] at rest: 4/3 E* sqrt(R*)
    delta^1.5 - k A(delta) = load (Hertz minus cohesion; the stable root; R* = r at a wall)."""
    from scipy.optimize import brentq

    r = case.radii
    r_eff = r[0] if case.partner == "wall" else r[0] * r[1] / (r[0] + r[1])
    e_star, k = effective_youngs_modulus(case), case.cohesion_energy_density

    def net(d: float) -> float:
        return 4.0 / 3.0 * e_star * math.sqrt(r_eff) * d**1.5 - k * cohesion_area(case, d) - load

    hi = 1e-9
    while net(hi) <= 0.0:  # past the attractive well, onto the repulsive branch
        hi *= 2.0
        if hi > r_eff:
            raise ValueError(f"case {case.name}: no equilibrium overlap for load {load} N")
    return brentq(net, hi / 2.0, hi, xtol=1e-15) if net(hi / 2.0) < 0.0 else hi


# ---------------------------------------------------------------------------- LIGGGHTS
def _stl(vertices: np.ndarray, faces: np.ndarray) -> str:
    """ASCII STL of a triangle mesh (vertices [m], faces: vertex indices, counter-clockwise)."""
    facets = []
    for f in faces:
        tri = vertices[f]
        n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        n = n / np.linalg.norm(n)
        verts = "\n".join(f"      vertex {x:.9g} {y:.9g} {z:.9g}" for x, y, z in tri)
        facets.append(f"  facet normal {n[0]:.9g} {n[1]:.9g} {n[2]:.9g}\n    outer loop\n{verts}\n"
                      "    endloop\n  endfacet")
    return "solid wall\n" + "\n".join(facets) + "\nendsolid wall\n"


def _box(case: ContactCase) -> np.ndarray:
    """(3, 2) simulation box holding the spheres over the whole run (and the wall)."""
    pos = np.asarray(case.positions, float)
    vel = np.asarray(case.velocities, float)
    reach = np.abs(vel) * case.duration + max(case.radii) + 0.01
    reach[:, 2] += 0.5 * GRAVITY * case.duration**2 if case.gravity else 0.0
    lo, hi = (pos - reach).min(axis=0), (pos + reach).max(axis=0)
    if case.partner == "wall":
        verts = WALL_MESHES[case.wall][0]
        lo = np.minimum(lo, verts.min(axis=0) - 0.01)
        hi = np.maximum(hi, verts.max(axis=0) + 0.01)
    return np.stack([lo, hi], axis=1)


def _data_file(case: ContactCase) -> str:
    box = _box(case)
    lines = ["LIGGGHTS data file written by validation/reference/contact_cases.py", "",
             f"{case.num_spheres} atoms", "1 atom types", ""]
    lines += [f"{box[k, 0]:.9g} {box[k, 1]:.9g} {a}lo {a}hi" for k, a in enumerate("xyz")]
    lines += ["", "Atoms", ""]  # atom_style granular: id type diameter density x y z
    lines += [f"{i + 1} 1 {2.0 * r:.12g} {case.density:.12g} {p[0]:.15g} {p[1]:.15g} {p[2]:.15g}"
              for i, (p, r) in enumerate(zip(case.positions, case.radii))]
    lines += ["", "Velocities", ""]  # id vx vy vz wx wy wz
    lines += [f"{i + 1} {v[0]:.15g} {v[1]:.15g} {v[2]:.15g} {w[0]:.15g} {w[1]:.15g} {w[2]:.15g}"
              for i, (v, w) in enumerate(zip(case.velocities, case.angular_velocities))]
    return "\n".join(lines) + "\n"


DUMP_COLUMNS = ("id", "x", "y", "z", "vx", "vy", "vz", "fx", "fy", "fz", "omegax", "omegay", "omegaz",
                "tqx", "tqy", "tqz")


def deck_text(case: ContactCase) -> str:
    """The LIGGGHTS input deck of ``case`` (reads ``spheres.data`` and, for a wall, ``wall.stl``)."""
    models = "model hertz tangential history"  # LIGGGHTS' order: model, tangential, cohesion, rolling_friction
    if case.cohesion != "none":
        models += f" cohesion {case.cohesion}"
    if case.rolling != "none":
        models += f" rolling_friction {case.rolling}"
    options = ""
    if case.tangential_reduce is not None and case.cohesion != "none":
        options = f" tangential_reduce {'on' if case.tangential_reduce else 'off'}"
    props = [f"fix m1 all property/global youngsModulus peratomtype {case.youngs_modulus:.12g}",
             f"fix m2 all property/global poissonsRatio peratomtype {case.poisson_ratio:.12g}",
             f"fix m3 all property/global coefficientRestitution peratomtypepair 1 {case.restitution:.12g}",
             f"fix m4 all property/global coefficientFriction peratomtypepair 1 {case.friction:.12g}"]
    if case.rolling != "none":
        props.append(f"fix m5 all property/global coefficientRollingFriction peratomtypepair 1 "
                     f"{case.rolling_friction:.12g}")
    if case.rolling == "epsd":  # warpdem's epsd has no dashpot: LIGGGHTS' viscous part off
        props.append("fix m6 all property/global coefficientRollingViscousDamping peratomtypepair 1 0")
    if case.cohesion != "none":
        props.append(f"fix m7 all property/global cohesionEnergyDensity peratomtypepair 1 "
                     f"{case.cohesion_energy_density:.12g}")
    lines = [f"# contact case '{case.name}' (validation/reference/contact_cases.py)",
             "atom_style granular", "atom_modify map array", "boundary f f f", "newton off",
             "communicate single vel yes", "units si", "read_data spheres.data",
             f"neighbor {0.2 * max(case.radii):.9g} bin", "neigh_modify delay 0", *props,
             f"pair_style gran {models}{options}", "pair_coeff * *", f"timestep {case.dt:.12g}"]
    if case.gravity:
        lines.append(f"fix gravity all gravity {GRAVITY} vector 0.0 0.0 -1.0")
    if case.partner == "wall":
        lines += ["fix wall all mesh/surface file wall.stl type 1",
                  f"fix walls all wall/gran {models} mesh n_meshes 1 meshes wall{options}"]
    if case.pulled:
        v = case.velocities[0]
        lines += ["group pulled id 1", f"fix pull pulled move linear {v[0]:.15g} {v[1]:.15g} {v[2]:.15g}"]
        # sphere 1 (if any) is held: no integrator acts on it
    else:
        lines.append("fix integrate all nve/sphere")
    fmt = " ".join(["%d"] + ["%.15g"] * (len(DUMP_COLUMNS) - 1))
    lines += [f"dump history all custom {case.output_every} history.dump {' '.join(DUMP_COLUMNS)}",
              f'dump_modify history format "{fmt}" sort id', f"run {case.steps}"]
    return "\n".join(lines) + "\n"


def run_liggghts(case: ContactCase, folder: str | Path) -> ContactHistories:
    """Run ``case`` in LIGGGHTS in ``folder`` (deck, data file, STL, log, dump kept there)."""
    files: dict[str, str] = {"spheres.data": _data_file(case)}
    if case.partner == "wall":
        files["wall.stl"] = _stl(*WALL_MESHES[case.wall])
    run = run_deck(deck_text(case), folder, files, timeout_s=600, screen_file="screen.liggghts")
    frames = read_dump(run.path("history.dump"))
    s = case.num_spheres

    def block(*cols: str) -> np.ndarray:
        return np.array([f.vectors(*cols) for f in frames]).reshape(len(frames), s, 3)

    force = block("fx", "fy", "fz")
    if case.gravity:
        force[:, :, 2] += np.asarray(case.masses)[None, :] * GRAVITY  # fix gravity's m g is part of LIGGGHTS' f
    return ContactHistories("liggghts", np.array([f.step for f in frames]) * case.dt, block("x", "y", "z"),
                            block("vx", "vy", "vz"), block("omegax", "omegay", "omegaz"), force,
                            block("tqx", "tqy", "tqz"), run.wall_s, run.version)


# ---------------------------------------------------------------------------- warpdem
def warpdem_law(case: ContactCase):
    """The :class:`warpdem.ContactLaw` warpdem runs for ``case``."""
    import warpdem as wd

    return wd.ContactLaw(normal=case.warpdem_normal, tangential=case.warpdem_tangential,
                         rolling=case.warpdem_rolling or case.rolling,
                         cohesion=case.warpdem_cohesion or case.cohesion)


def warpdem_simulation(case: ContactCase, device: str = "cpu"):
    """The :class:`warpdem.Simulation` of ``case`` at its start (no step taken)."""
    import warpdem as wd

    law = warpdem_law(case)
    b = wd.ModelBuilder(contact_law=law, gravity=(0.0, 0.0, -GRAVITY if case.gravity else 0.0))
    b.add_material(wd.Material("case", case.youngs_modulus, case.poisson_ratio, case.density))
    for p, r, v, w in zip(case.positions, case.radii, case.velocities, case.angular_velocities):
        b.add_sphere(p, r, "case", velocity=v, angular_velocity=w)
    if case.partner == "wall":
        b.add_wall(WALL_MESHES[case.wall], "case")
    params = {"restitution": case.restitution, "mu_s": case.friction}
    if law.rolling != "none":
        params["mu_r"] = case.rolling_friction
    if law.cohesion != "none":
        params["cohesion_energy_density"] = case.cohesion_energy_density
    b.set_contact_parameters(**{f"{k}_{pt}": v for k, v in params.items() for pt in ("pp", "pw")})
    speed = max(float(np.linalg.norm(v)) for v in case.velocities)
    # between two samples run_warpdem takes one step, then one to restore the graph's state
    # parity, then output_every - 2 steps: one replay of the captured graph
    steps_per_graph = max(2, case.output_every - 2 - (case.output_every % 2))
    return wd.Simulation(b.finalize(device), case.dt, v_ref=max(speed, 0.1), steps_per_graph=steps_per_graph)


def prepare_warpdem(cases: Sequence[ContactCase], device: str = "cpu") -> int:
    """Create the contact kernels of every law the cases use before any of them runs, so that
    Warp compiles each stage module once with all of them (built one after the other, every new
    law recompiles the modules with all laws before it: 70 s instead of 16 s for 6 laws on a
    cold kernel cache). Returns the number of distinct laws."""
    seen = {}
    for case in cases:
        law = warpdem_law(case)
        if law not in seen:
            seen[law] = warpdem_simulation(case, device)  # its constructor builds the stage kernels
    return len(seen)


def run_warpdem(case: ContactCase, device: str = "cpu") -> ContactHistories:
    """Run ``case`` in warpdem (float32 kernels) with the case's time step on ``device``.

    Sample k holds the state after k * output_every steps and the contact force and torque
    evaluated from that state (the force of the next step), as LIGGGHTS' dump holds x(n) and
    the f(n) computed from it. Between samples the steps replay Warp's captured graph; a pulled
    case steps one by one and is reset to its prescribed motion after every step."""
    import warp as wp

    import warpdem as wd

    sim = warpdem_simulation(case, device)
    s, n_steps, every = case.num_spheres, case.steps, case.output_every
    samples = n_steps // every + 1
    hist = {k: np.zeros((samples, s, 3)) for k in ("position", "velocity", "angular_velocity", "force", "torque")}
    x0 = np.asarray(case.positions, dtype=np.float64)
    v0 = np.asarray(case.velocities, dtype=np.float64)

    def hold(step: int) -> None:
        """Reset the pulled sphere to x0 + v t and the partner sphere to rest where it began."""
        st = sim.state
        q, v, w = st.body_q.numpy(), st.body_v.numpy(), st.body_w.numpy()
        q[0], v[0], w[0] = x0[0] + v0[0] * step * case.dt, v0[0], 0.0
        if s > 1:
            q[1], v[1], w[1] = x0[1], 0.0, 0.0
        st.body_q.assign(q)
        st.body_v.assign(v)
        st.body_w.assign(w)

    t0 = time.perf_counter()
    step = 0
    for k in range(samples):
        st = sim.state
        hist["position"][k] = st.body_q.numpy()
        hist["velocity"][k] = st.body_v.numpy()
        hist["angular_velocity"][k] = st.body_w.numpy()
        sim.run(1)  # the contact force and torque of this state
        step += 1
        hist["force"][k] = sim.solver.sphere_f.numpy()
        hist["torque"][k] = sim.solver.sphere_t.numpy()
        if k == samples - 1:
            break
        if case.pulled:
            hold(step)
            for _ in range(every - 1):
                sim.run(1)
                step += 1
                hold(step)
        elif every > 1:
            sim.run(every - 1)
            step += every - 1
    wp.synchronize()
    times = np.arange(samples) * every * case.dt
    return ContactHistories("warpdem", times, hist["position"], hist["velocity"], hist["angular_velocity"],
                            hist["force"], hist["torque"], time.perf_counter() - t0, f"warpdem {wd.__version__}")


# ---------------------------------------------------------------------------- figures
def derived_figures(case: ContactCase, h: ContactHistories) -> dict[str, float]:
    """The case's figures from one run's histories (sphere 0; SI units):

    - ``rebound_normal_velocity``: (v - v_partner) . n at the end (> 0: separating) [m/s]
    - ``rebound_tangential_velocity``: v . t at the end [m/s]
    - ``rebound_spin``: w . (n x t) at the end [rad/s]
    - ``peak_normal_force``: max over samples of F . n (repulsive > 0) [N]
    - ``rolling_distance``: max over samples of (x - x_0) . t, the way rolled until the sphere
      first stops [m]
    - ``pull_off_force``: max over samples of -F . n, the largest attraction [N]
    - ``work_of_separation``: -integral F . v dt over the pull (trapezoid rule), the work needed
      to pull the contact apart [J]
    """
    n, t, axis = case.normal, case.tangent, case.spin_axis
    v_end = h.velocity[-1, 0]
    fn = h.force[:, 0] @ n
    out = {}
    for q in case.quantities:
        if q == "rebound_normal_velocity":
            v_rel = v_end if case.partner == "wall" else v_end - h.velocity[-1, 1]
            out[q] = float(v_rel @ n)
        elif q == "rebound_tangential_velocity":
            out[q] = float(v_end @ t)
        elif q == "rebound_spin":
            out[q] = float(h.angular_velocity[-1, 0] @ axis)
        elif q == "peak_normal_force":
            out[q] = float(fn.max())
        elif q == "rolling_distance":
            out[q] = float(((h.position[:, 0] - h.position[0, 0]) @ t).max())
        elif q == "pull_off_force":
            out[q] = float((-fn).max())
        elif q == "work_of_separation":
            power = -np.einsum("ij,ij->i", h.force[:, 0], h.velocity[:, 0])
            out[q] = float(np.trapezoid(power, h.time))
    return out


def compare_case(case: ContactCase, folder: str | Path) -> tuple[list[Comparison], dict[str, ContactHistories]]:
    """Run ``case`` in both codes (LIGGGHTS in ``folder``); one :class:`Comparison` per figure."""
    return _rows(case, run_liggghts(case, folder), run_warpdem(case))


def _rows(case: ContactCase, lig: ContactHistories, wdm: ContactHistories):
    fl, fw = derived_figures(case, lig), derived_figures(case, wdm)
    rows = [Comparison(case.name, q, UNITS[q], fl[q], fw[q], TOLERANCES[q], case.expect_agreement, case.note)
            for q in case.quantities]
    return rows, {"liggghts": lig, "warpdem": wdm}


def compare_cases(cases: Sequence[ContactCase], root: str | Path, liggghts_workers: int = 4
                  ) -> tuple[list[Comparison], dict[str, dict[str, ContactHistories]]]:
    """Run many cases: the LIGGGHTS runs (each in ``root/<case name>``) in ``liggghts_workers``
    threads while warpdem runs the cases one by one in this thread (its laws' kernels created
    first, :func:`prepare_warpdem`). A LIGGGHTS process spends most of its ~0.35 s starting
    up, so they overlap well with warpdem's work."""
    from concurrent.futures import ThreadPoolExecutor

    root = Path(root)
    with ThreadPoolExecutor(max_workers=max(1, liggghts_workers)) as pool:
        pending = {c.name: pool.submit(run_liggghts, c, root / c.name) for c in cases}
        prepare_warpdem(cases)
        warp_runs = {c.name: run_warpdem(c) for c in cases}
        lig_runs = {name: f.result() for name, f in pending.items()}
    rows, histories = [], {}
    for c in cases:
        r, h = _rows(c, lig_runs[c.name], warp_runs[c.name])
        rows += r
        histories[c.name] = h
    return rows, histories


# ---------------------------------------------------------------------------- the cases
RADIUS = 0.009  # m: gravel of d = 18 mm
GAP = 2.0e-5  # m: distance to contact at the start of an impact
IMPACT_SPEED = 1.0  # m/s: normal (sphere-sphere: relative) approach speed of an impact
COHESION = 1.0e5  # J/m^3: cohesion energy density k
UNEQUAL = {"radius": 0.008, "partner_radius": 0.010}  # m: d = 16 and 20 mm
ROLLING_FRICTION = 0.2  # mu_r


def _contact_time(case: ContactCase, normal_speed: float, wall: bool) -> float:
    """Hertz contact duration 2.87 (m*^2 / (R* E*^2 v))^(1/5) [s] (Johnson 1985, eq. 11.24)."""
    m, r = case.masses, case.radii
    m_eff = m[0] if wall else m[0] * m[1] / (m[0] + m[1])
    r_eff = r[0] if wall else r[0] * r[1] / (r[0] + r[1])
    e_star = effective_youngs_modulus(case)
    return 2.87 * (m_eff**2 / (r_eff * e_star**2 * normal_speed)) ** 0.2


def impact(name: str, partner: str, angle_deg: float = 0.0, speed: float = IMPACT_SPEED, spin: float = 0.0,
           quantities: Sequence[str] | None = None, **settings) -> ContactCase:
    """A sphere hitting the wall, or two spheres hitting each other (centre-of-mass frame), at
    ``angle_deg`` from the normal with (relative) speed ``speed`` [m/s], the tangential part
    along +x (wall) or +z (spheres); sphere 0 spinning at ``spin`` [rad/s] about +y; gravity
    off; run until the contact is over (1.6 Hertz contact times, twice that with cohesion)."""
    a = math.radians(angle_deg)
    vn, vt = speed * math.cos(a), speed * math.sin(a)
    r = settings.get("radius", RADIUS)
    r1 = settings.get("partner_radius") or r
    if partner == "wall":
        pos = ((0.0, 0.0, r + GAP),)
        vel = ((vt, 0.0, -vn),)
        spins = ((0.0, spin, 0.0),)
    else:
        pos = ((-(r + GAP / 2.0), 0.0, 0.0), (r1 + GAP / 2.0, 0.0, 0.0))
        vel = ((vn / 2.0, 0.0, vt / 2.0), (-vn / 2.0, 0.0, -vt / 2.0))
        spins = ((0.0, spin, 0.0), (0.0, 0.0, 0.0))
    if quantities is None:
        quantities = ["rebound_normal_velocity", "peak_normal_force"]
        if angle_deg or spin:
            quantities[1:1] = ["rebound_tangential_velocity", "rebound_spin"]
    probe = ContactCase(name, partner, pos, vel, 1.0, tuple(quantities), angular_velocities=spins, **settings)
    slow = 2.0 if probe.cohesion != "none" else 1.0  # cohesion holds the contact longer
    duration = GAP / vn + slow * 1.6 * _contact_time(probe, vn, partner == "wall")
    return dataclasses.replace(probe, duration=round(duration / probe.dt) * probe.dt)


def rolling_on_plane(name: str, rolling: str, rolling_friction: float = ROLLING_FRICTION, speed: float = 0.1,
                     **settings) -> ContactCase:
    """A sphere resting on the floor (gravity on, at its equilibrium overlap) launched rolling
    along +x with v = w r [m/s]; run until it has stopped (a constant rolling torque
    mu_r r m g decelerates it by a = mu_r g / 1.4; the duration is 1.5 v / a)."""
    probe = ContactCase(name, "wall", ((0.0, 0.0, 0.0),), ((speed, 0.0, 0.0),), 1.0, ("rolling_distance",),
                        rolling=rolling, rolling_friction=rolling_friction, gravity=True, dt=1.0e-5, **settings)
    delta = equilibrium_overlap(probe, probe.mass * GRAVITY)
    duration = 1.5 * speed / (rolling_friction * GRAVITY / 1.4)
    return dataclasses.replace(probe, positions=((0.0, 0.0, probe.radius - delta),),
                               angular_velocities=((0.0, speed / probe.radius, 0.0),),
                               duration=round(duration / probe.dt) * probe.dt)


def pull_off(name: str, partner: str, cohesion: str, k: float = COHESION, speed: float = 0.01,
             **settings) -> ContactCase:
    """A cohesive contact at rest at its equilibrium overlap (Hertz = k A, no load) pulled apart
    along its normal at ``speed`` [m/s] (sphere 0 moved, the partner held) until it opens;
    gravity off. The pull-off force is the largest attraction on the way (for 18 mm gravel and
    k = 1e5 J/m^3 about 0.05 N of cohesion plus ~0.02 N of the normal dashpot at 0.01 m/s); the
    time step only sets how finely the overlap is sampled (v dt = 5e-8 m)."""
    r = settings.get("radius", RADIUS)
    r1 = settings.get("partner_radius") or r
    dt = settings.pop("dt", 5.0e-6)
    probe = ContactCase(name, partner, ((0.0, 0.0, 0.0),) * (1 if partner == "wall" else 2),
                        ((0.0, 0.0, 0.0),) * (1 if partner == "wall" else 2), 1.0,
                        ("pull_off_force", "work_of_separation"), cohesion=cohesion, cohesion_energy_density=k,
                        pulled=True, dt=dt, output_every=1, **settings)
    start = equilibrium_overlap(probe)
    if partner == "wall":
        pos, vel = ((0.0, 0.0, r - start),), ((0.0, 0.0, speed),)
    else:
        pos = ((-(r + r1 - start), 0.0, 0.0), (0.0, 0.0, 0.0))
        vel = ((-speed, 0.0, 0.0), (0.0, 0.0, 0.0))
    duration = 1.1 * start / speed
    return dataclasses.replace(probe, positions=pos, velocities=vel, duration=round(duration / dt) * dt)


NOTE_WALL_POINT = ("warpdem 'hertz' puts a wall contact's point on the wall (lever r - delta), LIGGGHTS at half the "
                   "overlap (r - delta/2); 'hertz_liggghts' follows LIGGGHTS")
NOTE_CDT = ("warpdem 'cdt' is EDEM's rolling friction (total F_n, lever = distance to the contact point, reversal "
            "guard); LIGGGHTS cdt uses the elastic k_n delta and R*; 'cdt_liggghts' follows LIGGGHTS")
NOTE_REDUCE = ("warpdem 'sjkr_reduced' lets the friction and rolling limits see the cohesion (LIGGGHTS "
               "tangential_reduce on); LIGGGHTS 3.8's default (off), and warpdem's 'sjkr', leave it out")
NOTE_EPSD = ("warpdem 'epsd' caps the rolling torque at mu_r R* max(F_n, 0) (Ai et al. 2011), LIGGGHTS epsd at "
             "mu_r R* |F_n|: they differ once damping makes F_n negative at the end of an impact")
NOTE_MINDLIN = ("warpdem 'mindlin' caps spring + dashpot at mu F_n and resets the spring (Luding 2008); LIGGGHTS "
                "history caps the spring alone and drops the dashpot while sliding")


def _cases() -> tuple[ContactCase, ...]:
    """The comparison set. Cases named ``...-default`` run warpdem's default sub-model where a
    LIGGGHTS variant exists (``hertz`` for ``hertz_liggghts``, ``cdt`` for ``cdt_liggghts``,
    ``sjkr_reduced`` against LIGGGHTS' default ``sjkr``); ``...-reduce_on`` runs LIGGGHTS with
    ``tangential_reduce on`` against warpdem's ``sjkr_reduced``. Cases with ``expect_agreement`` False document a known
    difference of definitions (``note``); the others are held to :data:`TOLERANCES`."""
    k, mu_r = COHESION, ROLLING_FRICTION
    lg = {"warpdem_normal": "hertz_liggghts"}  # LIGGGHTS' wall contact point (irrelevant between spheres)
    cases = [
        impact("normal_impact_pw", "wall"),
        impact("normal_impact_pp", "sphere"),
        impact("oblique30_pp", "sphere", 30),
        impact("oblique60_pp", "sphere", 60),
        impact("oblique30_pw", "wall", 30, **lg),
        impact("oblique60_pw", "wall", 60, **lg),
        impact("oblique30_pw-default", "wall", 30, expect_agreement=False, note=NOTE_WALL_POINT),
        impact("oblique60_pw-default", "wall", 60, expect_agreement=False, note=NOTE_WALL_POINT),
        impact("oblique30_mindlin_pp", "sphere", 30, warpdem_tangential="mindlin", expect_agreement=False,
               note=NOTE_MINDLIN),
        impact("oblique60_mindlin_pp", "sphere", 60, warpdem_tangential="mindlin", expect_agreement=False,
               note=NOTE_MINDLIN),
        impact("spinning_pp", "sphere", spin=100.0),
    ]
    for rolling in ("epsd2", "epsd"):
        diff = {} if rolling == "epsd2" else {"expect_agreement": False, "note": NOTE_EPSD}
        cases += [impact(f"oblique45_{rolling}_pw", "wall", 45, rolling=rolling, rolling_friction=mu_r, **diff, **lg),
                  impact(f"spinning_{rolling}_pp", "sphere", spin=100.0, rolling=rolling, rolling_friction=mu_r),
                  rolling_on_plane(f"rolling_{rolling}_pw", rolling)]
    cases += [
        impact("oblique45_cdt_pw", "wall", 45, rolling="cdt", rolling_friction=mu_r, warpdem_rolling="cdt_liggghts",
               **lg),
        impact("spinning_cdt_pp", "sphere", spin=100.0, rolling="cdt", rolling_friction=mu_r,
               warpdem_rolling="cdt_liggghts", **lg),
        rolling_on_plane("rolling_cdt_pw", "cdt", warpdem_rolling="cdt_liggghts", **lg),
        impact("oblique45_cdt_pw-default", "wall", 45, rolling="cdt", rolling_friction=mu_r, expect_agreement=False,
               note=NOTE_CDT),
        impact("spinning_cdt_pp-default", "sphere", spin=100.0, rolling="cdt", rolling_friction=mu_r,
               expect_agreement=False, note=NOTE_CDT),
        rolling_on_plane("rolling_cdt_pw-default", "cdt"),
    ]
    for coh in ("sjkr", "sjkr2"):
        for partner, tag in (("wall", "pw"), ("sphere", "pp")):
            cases += [impact(f"normal_impact_{coh}_{tag}", partner, speed=0.5, cohesion=coh, cohesion_energy_density=k),
                      pull_off(f"pull_off_{coh}_{tag}", partner, coh, k)]
        cases.append(pull_off(f"pull_off_{coh}_unequal_pp", "sphere", coh, k, **UNEQUAL))
    cases.append(impact("oblique45_epsd2_unequal_pp", "sphere", 45, spin=50.0, rolling="epsd2", rolling_friction=mu_r,
                        **UNEQUAL))
    # the sphere on a mesh edge or vertex: one contact in both codes (LIGGGHTS' contact history
    # drops the edge/vertex duplicates of a face contact; warpdem merges them)
    for wall in ("edge", "vertex"):
        cases += [impact(f"normal_impact_pw_{wall}", "wall", wall=wall),
                  pull_off(f"pull_off_sjkr_pw_{wall}", "wall", "sjkr", k, wall=wall)]
    rolling_edge = rolling_on_plane("rolling_epsd2_pw_edge", "epsd2", wall="edge")
    cases.append(dataclasses.replace(rolling_edge, positions=((-0.0015, 0.0, rolling_edge.positions[0][2]),)))
    # cohesion with friction and rolling resistance: which F_n the limits see
    coh = {"cohesion": "sjkr", "cohesion_energy_density": k}
    for partner, tag in (("wall", "pw"), ("sphere", "pp")):
        cases.append(impact(f"oblique45_epsd2_sjkr_{tag}", partner, 45, speed=0.5, rolling="epsd2",
                            rolling_friction=mu_r, **coh, **lg))
    cases += [
        impact("oblique45_epsd2_sjkr_pp-reduce_on", "sphere", 45, speed=0.5, rolling="epsd2", rolling_friction=mu_r,
               tangential_reduce=True, warpdem_cohesion="sjkr_reduced", **coh, **lg),
        impact("oblique45_epsd2_sjkr_pp-default", "sphere", 45, speed=0.5, rolling="epsd2", rolling_friction=mu_r,
               warpdem_cohesion="sjkr_reduced", expect_agreement=False, note=NOTE_REDUCE, **coh, **lg),
        rolling_on_plane("rolling_epsd2_sjkr_pw", "epsd2", **coh, **lg),
        rolling_on_plane("rolling_epsd2_sjkr_pw-reduce_on", "epsd2", tangential_reduce=True,
                         warpdem_cohesion="sjkr_reduced", **coh, **lg),
        rolling_on_plane("rolling_epsd2_sjkr_pw-default", "epsd2", warpdem_cohesion="sjkr_reduced",
                         expect_agreement=False, note=NOTE_REDUCE, **coh, **lg),
    ]
    return tuple(cases)


CASES: tuple[ContactCase, ...] = _cases()


def case_by_name(name: str) -> ContactCase:
    """The case of :data:`CASES` called ``name``."""
    for c in CASES:
        if c.name == name:
            return c
    raise KeyError(f"no contact case '{name}'; known: {[c.name for c in CASES]}")
