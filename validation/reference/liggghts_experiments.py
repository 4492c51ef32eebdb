"""LIGGGHTS-PUBLIC 3.8 input decks written from the project's own experiments (issue 27).

The deck is derived from an :class:`calibration.experiments.Experiment` instance, never typed by
hand, so both codes run the same test:

* **walls**: :meth:`Experiment.add_walls` is called with a :class:`WallRecorder` in place of the
  :class:`warpdem.ModelBuilder`; every mesh it adds is written as an ASCII STL
  (``fix mesh/surface ... type 2``) and its :class:`warpdem.WallMotion` becomes a
  ``fix move/mesh`` (translation: ``linear``; rotation: ``rotate ... period``) that is defined
  when the protocol starts the motion and removed when a finite motion stops.
* **material**: atom type 1 = particles (E, nu, density of ``material.particle``), type 2 = the
  walls (``wall_material``); every contact parameter is a 2 x 2 ``peratomtypepair`` table
  (pp on 1-1, pw on 1-2, 2-1 and 2-2), from the law's defaults, the experiment's
  ``contact_defaults`` and the parameter set, in that order (as :meth:`Experiment.run`).
* **contact law**: ``hertz`` -> ``model hertz``; ``history`` -> ``tangential history``; rolling
  ``epsd2`` / ``cdt`` -> ``rolling_friction epsd2`` / ``cdt``; ``epsd`` -> ``rolling_friction
  epsd`` with ``coefficientRollingViscousDamping`` 0 (warpdem's epsd has no dashpot);
  cohesion ``sjkr`` / ``sjkr2`` -> ``cohesion sjkr`` / ``sjkr2 ... tangential_reduce off`` (LIGGGHTS
  3.8's default: the friction limits do not see the cohesion force); ``sjkr_reduced`` /
  ``sjkr2_reduced`` -> ``... tangential_reduce on`` (:data:`LAW_MAP`, :data:`TANGENTIAL_REDUCE`,
  :data:`APPROXIMATE`).
* **fill**: ``identical`` writes the fill warpdem starts from (:meth:`Experiment.make_fill` with
  the run's seed; ``read_data``); ``poured`` lets LIGGGHTS insert the same mass of the same size
  distribution (diameters uniform by number as :func:`calibration.materials.sample_particles`
  draws them, as equal-number size classes: the packaged 3.8 binary has ``radius constant``
  templates only) with ``insert/rate/region`` into the upper part of the fill region, in batches
  that fall and settle under the full law.
* **protocol**: the experiment's phases with its times: a settle phase is a ``run`` loop of
  ``settle_check_interval`` chunks that stops when the kinetic energy (translational +
  rotational) per particle is below ``ke_per_particle`` after the phase's minimum time, or at its
  maximum time (``Simulation.settle``); at its end translational velocities are set to zero
  (warpdem pauses a settled world at rest; LIGGGHTS 3.8's ``set`` cannot zero ``omega``, which
  is left as it is, below ~1e-6 J per particle). Motions run for the experiment's step counts
  (``round(duration / dt)``, as ``RunContext.advance``).
* **outputs**: ``write_dump ... id type x y z radius mass vx vy vz omegax omegay omegaz`` after the fill settled and at
  the instants the protocol measures (baffle and cylinder: the end; drum: every snapshot),
  read back by :mod:`validation.reference.liggghts_readback` through ``calibration.measurement``.

Where the deck cannot match warpdem exactly it says so in :attr:`ExperimentDeck.notes`.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

import warpdem as wd
from calibration.experiments.common import Experiment
from calibration.filling import FillResult, HorizontalCylinder, VerticalCylinder, Box
from calibration.materials import equal_number_size_classes

__all__ = ["CapturedWall", "WallRecorder", "capture_walls", "stl_text", "LAW_MAP", "liggghts_model_keywords",
           "contact_parameter_table", "fill_for_index", "warpdem_time_step", "ExperimentDeck", "write_deck",
           "FILL_MODES", "DUMP_COLUMNS", "UnsupportedLaw", "sphere_data_file"]

#: fill modes: the project's own fill, or LIGGGHTS' own insertion (module docstring)
FILL_MODES = ("identical", "poured")
#: columns of every dump the deck writes
DUMP_COLUMNS = ("id", "type", "x", "y", "z", "radius", "mass", "vx", "vy", "vz", "omegax", "omegay", "omegaz")
PARTICLE_TYPE, WALL_TYPE = 1, 2

#: warpdem sub-model -> LIGGGHTS keyword per kind (None: no keyword, the sub-model is off).
#: ``hertz``/``hertz_liggghts`` differ only in the wall contact point (r - delta vs LIGGGHTS'
#: r - delta/2, :data:`APPROXIMATE`); ``sjkr_reduced``/``sjkr2_reduced`` let the friction limits see
#: the cohesion, which LIGGGHTS does with ``tangential_reduce on`` (:data:`TANGENTIAL_REDUCE`).
LAW_MAP: dict[str, dict[str, str | None]] = {
    "normal": {"hertz": "hertz", "hertz_liggghts": "hertz"},
    "tangential": {"history": "history"},
    "rolling": {"none": None, "epsd2": "epsd2", "cdt": "cdt", "cdt_liggghts": "cdt", "epsd": "epsd"},
    "cohesion": {"none": None, "sjkr": "sjkr", "sjkr2": "sjkr2", "sjkr_reduced": "sjkr", "sjkr2_reduced": "sjkr2"},
}
#: cohesion sub-model -> LIGGGHTS ``tangential_reduce`` (on: the Coulomb and rolling limits see
#: F_n with the cohesion, as warpdem's sjkr_reduced; off, LIGGGHTS 3.8's default and warpdem's sjkr: without it)
TANGENTIAL_REDUCE = {"sjkr": False, "sjkr2": False, "sjkr_reduced": True, "sjkr2_reduced": True}
#: sub-models whose LIGGGHTS keyword is a close, not an exact, counterpart -> what differs
APPROXIMATE = {
    "hertz": "wall contact point: warpdem 'hertz' at r - delta from the sphere centre (rigid wall), LIGGGHTS at "
             "r - delta/2 (src/surface_model_default.h); spin and tangential rebound at walls differ by O(delta/r) "
             "('hertz_liggghts' is exact)",
    "cdt": "warpdem 'cdt' is EDEM's (full F_n, lever to the contact point, reversal guard); LIGGGHTS cdt uses "
           "k_n delta and R* without guard ('cdt_liggghts' is exact)",
    "epsd": "warpdem 'epsd' has no dashpot: LIGGGHTS rolling_friction epsd with coefficientRollingViscousDamping 0",
}


#: warpdem base parameter -> LIGGGHTS ``fix property/global`` name (peratomtypepair)
PROPERTY_NAMES = {"restitution": "coefficientRestitution", "mu_s": "coefficientFriction",
                  "mu_r": "coefficientRollingFriction", "cohesion_energy_density": "cohesionEnergyDensity"}


class UnsupportedLaw(ValueError):
    """A warpdem contact law with no LIGGGHTS counterpart in :data:`LAW_MAP`."""


# --------------------------------------------------------------------------- walls
@dataclass(frozen=True)
class CapturedWall:
    """One wall an experiment adds: its mesh (vertices (V, 3) [m], faces (T, 3)), material
    name, motion (None: fixed) and the builder's world index (-1: every world)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    material: str
    motion: wd.WallMotion | None
    world: int = -1

    @property
    def fix_id(self) -> str:
        """LIGGGHTS fix id of the mesh: ``wall_`` + the name with non-identifier characters as ``_``."""
        return "wall_" + re.sub(r"[^A-Za-z0-9_]", "_", self.name).strip("_")

    @property
    def stl_name(self) -> str:
        return f"{self.fix_id}.stl"

    def triangles(self) -> np.ndarray:
        """(T, 3, 3) triangle corners [m]."""
        return self.vertices[self.faces]


class WallRecorder:
    """Stands in for :class:`warpdem.ModelBuilder` in :meth:`Experiment.add_walls`: records the
    walls instead of building a model (only ``add_wall`` and ``num_worlds`` are used there)."""

    def __init__(self, num_worlds: int = 1) -> None:
        self.num_worlds = int(num_worlds)
        self.walls: list[CapturedWall] = []

    def add_wall(self, mesh, material, world: int = -1, motion: wd.WallMotion | None = None,
                 name: str | None = None, **_: Any) -> int:
        if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
            verts, faces = np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)
        else:
            verts, faces = (np.asarray(a) for a in mesh)
        mat = material if isinstance(material, str) else getattr(material, "name", str(material))
        moving = motion if motion is not None and not motion.is_static else None
        self.walls.append(CapturedWall(name or f"wall{len(self.walls)}", verts.astype(float), faces.astype(np.int64),
                                       mat, moving, int(world)))
        return len(self.walls) - 1


def capture_walls(exp: Experiment, fill_top: float, t_motion: float = 0.0) -> list[CapturedWall]:
    """Every wall ``exp.add_walls`` adds for a fill whose loose top is ``fill_top`` [m] (walls
    are raised above a tall loose column), with the motion starting at ``t_motion`` [s]."""
    rec = WallRecorder(1)
    exp.add_walls(rec, float(fill_top), float(t_motion), exp.bulk_material())
    names = [w.fix_id for w in rec.walls]
    if len(set(names)) != len(names):
        raise ValueError(f"{exp.name}: wall names {names} collide as LIGGGHTS ids")
    return rec.walls


def stl_text(wall: CapturedWall) -> str:
    """ASCII STL of a wall (LIGGGHTS reads ASCII STL only); coordinates [m] to 1e-12 m."""
    tri = wall.triangles()
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    out = [f"solid {wall.fix_id}"]
    for t, nn in zip(tri, n):
        out.append(f"  facet normal {nn[0]:.9e} {nn[1]:.9e} {nn[2]:.9e}")
        out.append("    outer loop")
        out.extend(f"      vertex {v[0]:.12e} {v[1]:.12e} {v[2]:.12e}" for v in t)
        out.append("    endloop")
        out.append("  endfacet")
    out.append(f"endsolid {wall.fix_id}")
    return "\n".join(out) + "\n"


def _swept_bounds(wall: CapturedWall, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box [m] of a wall over ``duration`` [s] of its motion (a rotating wall: the box
    of its vertices' circles about the axis)."""
    v = wall.vertices
    lo, hi = v.min(0), v.max(0)
    m = wall.motion
    if m is None:
        return lo, hi
    t = min(duration, m.stop - m.start)
    shift = np.asarray(m.velocity) * t
    lo, hi = np.minimum(lo, lo + shift), np.maximum(hi, hi + shift)
    w = np.asarray(m.angular_velocity)
    if np.linalg.norm(w) > 0:
        # the vertices sweep circles about the axis a through o: along a they keep their
        # coordinate s, across it they reach rho in every direction perpendicular to a
        a = w / np.linalg.norm(w)
        o = np.asarray(m.origin)
        rel = v - o
        s = rel @ a
        rho = float(np.linalg.norm(rel - np.outer(s, a), axis=1).max())
        ends = np.stack([a * s.min(), a * s.max()])
        perp = rho * np.sqrt(np.clip(1.0 - a**2, 0.0, 1.0))
        lo = np.minimum(lo, o + ends.min(0) - perp)
        hi = np.maximum(hi, o + ends.max(0) + perp)
    return lo, hi


# --------------------------------------------------------------------------- contact law
def liggghts_model_keywords(law: wd.ContactLaw, tangential_reduce: bool | None = None) -> str:
    """``model hertz tangential history [cohesion Y] [rolling_friction X] [tangential_reduce on|off]``
    for a warpdem law, as ``pair_style gran`` takes it (LIGGGHTS parses the keywords in this order
    only). ``tangential_reduce``: None: as the law's cohesion sub-model means it
    (:data:`TANGENTIAL_REDUCE`); True/False: force it (True with warpdem's ``sjkr``: LIGGGHTS' ``tangential_reduce on``)."""
    models, settings = _models_and_settings(law, tangential_reduce)
    return " ".join(w for w in (models, settings) if w)


def _models_and_settings(law: wd.ContactLaw, tangential_reduce: bool | None) -> tuple[str, str]:
    """The model keywords and the settings (``fix wall/gran`` takes the settings after ``mesh ...``)."""
    words = []
    for kind, key in (("normal", "model"), ("tangential", "tangential"), ("cohesion", "cohesion"),
                      ("rolling", "rolling_friction")):
        name = getattr(law, kind)
        if name not in LAW_MAP[kind]:
            raise UnsupportedLaw(f"{kind} sub-model '{name}' has no LIGGGHTS counterpart here; mapped: "
                                 f"{sorted(LAW_MAP[kind])}")
        value = LAW_MAP[kind][name]
        if value is not None:
            words.append(f"{key} {value}")
    settings = ""
    if law.cohesion != "none":
        reduce = TANGENTIAL_REDUCE[law.cohesion] if tangential_reduce is None else bool(tangential_reduce)
        settings = f"tangential_reduce {'on' if reduce else 'off'}"
    return " ".join(words), settings


def contact_parameter_table(exp: Experiment, parameters: Mapping[str, float]) -> dict[str, float]:
    """Every contact parameter of the law by calibration name (``mu_s_pp`` ...): the law's
    defaults, then ``exp.contact_defaults``, then ``parameters`` (as :meth:`Experiment.run`)."""
    law = exp.contact_law
    table = {f"{name}_{pt}": float(spec.default) for name, spec in law.specs.items() for pt in ("pp", "pw")}
    for source in (exp.contact_defaults, parameters):
        for k, v in source.items():
            if k not in table:
                raise ValueError(f"unknown contact parameter '{k}' for law {law.describe()}; valid: {sorted(table)}")
            table[k] = float(v)
    return table


def _property_lines(exp: Experiment, table: Mapping[str, float]) -> list[str]:
    """``fix property/global`` lines: E and nu per atom type, every pair parameter per type pair."""
    p, w = exp.bulk_material().particle, exp.wall_material
    lines = [f"fix mat_E all property/global youngsModulus peratomtype {p.youngs_modulus:.10g} {w.youngs_modulus:.10g}",
             f"fix mat_nu all property/global poissonsRatio peratomtype {p.poisson_ratio:.10g} {w.poisson_ratio:.10g}"]
    for base, spec in exp.contact_law.specs.items():
        if base not in PROPERTY_NAMES:
            raise UnsupportedLaw(f"contact parameter '{base}' has no LIGGGHTS property here; mapped: {sorted(PROPERTY_NAMES)}")
        pp, pw = table[f"{base}_pp"], table[f"{base}_pw"]
        lines.append(f"fix mat_{base} all property/global {PROPERTY_NAMES[base]} peratomtypepair 2 "
                     f"{pp:.10g} {pw:.10g} {pw:.10g} {pw:.10g}")
    if exp.contact_law.rolling == "epsd":
        lines.append("fix mat_eta_r all property/global coefficientRollingViscousDamping peratomtypepair 2 0 0 0 0")
    return lines


# --------------------------------------------------------------------------- fill and time step
def fill_for_index(exp: Experiment, fill_index: int, device: str | None = "cpu") -> FillResult:
    """The loose fill warpdem starts world 0 from when run with ``fill_per_world=True`` and
    ``first_fill_index=fill_index`` (seeded by ``(exp.seed, fill_index)``)."""
    return exp.make_fill(exp.bulk_material(), np.random.default_rng([exp.seed, int(fill_index)]), device)


def warpdem_time_step(exp: Experiment, fill: FillResult) -> float:
    """The time step [s] :meth:`Experiment.run` uses for this fill: ``exp.dt``, else
    ``dt_rayleigh_fraction`` x the Rayleigh time capped by the limit, else the recommended step
    of :func:`warpdem.time_step_limits` (it depends on the spheres only)."""
    if exp.dt is not None:
        return float(exp.dt)
    from calibration.filling import add_fill

    material = exp.bulk_material()
    b = wd.ModelBuilder(1, contact_law=exp.contact_law)
    b.add_material(material.particle)
    add_fill(b, fill, material.particle.name, 0)
    limits = wd.time_step_limits(b.finalize("cpu", check_overlaps=False), exp.v_ref)
    if exp.dt_rayleigh_fraction is not None:
        return float(min(float(exp.dt_rayleigh_fraction) * limits.rayleigh, limits.limit))
    return float(limits.recommended)


# --------------------------------------------------------------------------- the deck
@dataclass
class ExperimentDeck:
    """A LIGGGHTS deck and its files for one run of an experiment.

    deck: the input script; files: name -> text (STL meshes, the data file of an identical fill);
    dt: time step [s]; fill_mode; n_particles: atoms the deck starts with (identical) or asks
    LIGGGHTS to insert (poured, expected number); dumps: dump file -> what it holds;
    settings: the protocol numbers written into the deck (times [s], step counts);
    notes: where the deck cannot match warpdem exactly.
    """

    experiment: str
    deck: str
    files: dict[str, str]
    dt: float
    fill_mode: str
    n_particles: int
    dumps: dict[str, str]
    settings: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


class _DeckText:
    """Lines of a deck with helpers for the repeated protocol blocks."""

    def __init__(self, dt: float, ke_per_particle: float, check_interval: float) -> None:
        self.lines: list[str] = []
        self.dt = dt
        self.ke = ke_per_particle
        self.chunk = max(1, int(round(check_interval / dt)))
        self.phases: dict[str, dict[str, Any]] = {}

    def add(self, *lines: str) -> None:
        self.lines.extend(lines)

    def steps(self, seconds: float) -> int:
        return int(round(seconds / self.dt))

    def settle(self, name: str, max_time: float, min_time: float) -> None:
        """``Simulation.settle``: chunks of ``chunk`` steps; after each, stop when KE per particle
        < threshold and at least ``min_time`` has passed, or at ``max_time``; then v = 0."""
        n_max = int(round(max_time / self.dt))
        full, rest = divmod(n_max, self.chunk)
        # the first chunk index i (1-based) with i * chunk * dt >= min_time (warpdem: done * dt >= min - 1e-12)
        i_min = max(1, int(math.ceil((min_time - 1e-12) / (self.chunk * self.dt) - 1e-9)))
        self.phases[name] = {"max_time_s": max_time, "min_time_s": min_time, "max_steps": n_max,
                             "chunk_steps": self.chunk, "min_chunks": i_min}
        self.add(f"# --- settle '{name}': KE/particle < {self.ke:g} J after {min_time:.6g} s, at most {max_time:.6g} s "
                 f"({n_max} steps in chunks of {self.chunk})",
                 f'print "PHASE {name} start step ${{step_now}} time ${{time_now}} atoms ${{atoms_now}}"')
        if full > 0:
            self.add(f"variable {name}_i loop {full}",
                     f"label {name}_loop",
                     f"run {self.chunk} post no",
                     f'if "${{ke_per_particle}} < {self.ke:.10g} && ${{{name}_i}} >= {i_min}" then "jump SELF {name}_met"',
                     f"next {name}_i",
                     f"jump SELF {name}_loop")
        if rest > 0:
            self.add(f"run {rest} post no")
        if full > 0:
            # the loop ran out (or max_time < one chunk): the maximum time is reached
            self.add(f'print "PHASE {name} end step ${{step_now}} time ${{time_now}} atoms ${{atoms_now}} '
                     f'ke_per_particle ${{ke_per_particle}} met 0"',
                     f"jump SELF {name}_done",
                     f"label {name}_met",
                     f'print "PHASE {name} end step ${{step_now}} time ${{time_now}} atoms ${{atoms_now}} '
                     f'ke_per_particle ${{ke_per_particle}} met 1"',
                     f"label {name}_done")
        else:
            self.add(f'print "PHASE {name} end step ${{step_now}} time ${{time_now}} atoms ${{atoms_now}} '
                     f'ke_per_particle ${{ke_per_particle}} met 0"')
        self.add("velocity all set 0.0 0.0 0.0 units box")

    def advance(self, name: str, seconds: float) -> int:
        n = self.steps(seconds)
        self.phases[name] = {"time_s": n * self.dt, "steps": n}
        self.add(f"# --- advance '{name}': {n} steps ({n * self.dt:.6g} s)",
                 f'print "PHASE {name} start step ${{step_now}} time ${{time_now}} atoms ${{atoms_now}}"')
        if n > 0:
            self.add(f"run {n} post no")
        self.add(f'print "PHASE {name} end step ${{step_now}} time ${{time_now}} atoms ${{atoms_now}} '
                 f'ke_per_particle ${{ke_per_particle}}"')
        return n

    def dump(self, filename: str) -> None:
        """A ``dump custom`` of every atom now; reals to 15 significant digits (default: 6)."""
        fmt = " ".join("%d" if c in ("id", "type") else "%.15g" for c in DUMP_COLUMNS)
        self.add(f'write_dump all custom {filename} {" ".join(DUMP_COLUMNS)} modify format "{fmt}"')

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def _motion_command(wall: CapturedWall, fix_name: str) -> str:
    """``fix move/mesh`` of a wall's motion (translation or rotation; not both)."""
    m = wall.motion
    v, w = np.asarray(m.velocity, float), np.asarray(m.angular_velocity, float)
    if np.any(v) and np.any(w):
        raise UnsupportedLaw(f"wall '{wall.name}': a combined translation and rotation is not written (two "
                             "superposed fix move/mesh would move the rotation origin)")
    if np.any(v):
        return f"fix {fix_name} all move/mesh mesh {wall.fix_id} linear {v[0]:.10g} {v[1]:.10g} {v[2]:.10g}"
    rate = float(np.linalg.norm(w))
    axis = w / rate
    o = m.origin
    return (f"fix {fix_name} all move/mesh mesh {wall.fix_id} rotate origin {o[0]:.10g} {o[1]:.10g} {o[2]:.10g} "
            f"axis {axis[0]:.10g} {axis[1]:.10g} {axis[2]:.10g} period {2.0 * math.pi / rate:.12g}")


def _prime_seed(k: int) -> int:
    """A prime > 10000 (LIGGGHTS insertion seeds must be), different for every k >= 0."""
    n = 15485863 + 2000 * int(k)
    while True:
        if n % 2 and all(n % d for d in range(3, int(n**0.5) + 1, 2)):
            return n
        n += 1


@dataclass(frozen=True)
class _Pour:
    """Insertion region of the ``poured`` mode: its ``region`` commands, volume [m^3], top z [m]
    (the height the walls must reach) and the floor z [m] under it (for the fall time)."""

    region: list[str]
    volume: float
    top: float
    floor: float


def _pour_region(exp: Experiment, skin: float) -> _Pour:
    """Insertion region in the upper part of the experiment's fill region, inset by ``skin`` + 1 mm
    from its walls. Box and vertical cylinder: from one largest diameter above an estimate of the
    settled bed's top (solids fraction 0.6), max(4 largest diameters, a quarter of the bed height)
    high; horizontal cylinder (closed drum): its upper half."""
    material = exp.bulk_material()
    d_max = 2.0 * material.max_bounding_radius
    mass = exp.fill_amount(material).get("mass")
    solid = mass / material.particle.density
    reg = exp.fill_region()
    inset = skin + 1e-3  # LIGGGHTS: insertion at least half a skin clear of the mesh walls
    if isinstance(reg, Box):
        (x0, y0, z0), (x1, y1, _) = reg.lower, reg.upper
        bed = z0 + solid / 0.6 / ((x1 - x0) * (y1 - y0))
        lo = bed + d_max
        hi = lo + max(4.0 * d_max, 0.25 * (bed - z0))
        return _Pour([f"region pour_region block {x0 + inset:.10g} {x1 - inset:.10g} {y0 + inset:.10g} "
                      f"{y1 - inset:.10g} {lo:.10g} {hi:.10g} units box"],
                     (x1 - x0 - 2 * inset) * (y1 - y0 - 2 * inset) * (hi - lo), hi, z0)
    if isinstance(reg, VerticalCylinder):
        (cx, cy), R, z0 = reg.center, reg.radius, reg.z0
        bed = z0 + solid / 0.6 / (math.pi * R**2)
        lo = bed + d_max
        hi = lo + max(4.0 * d_max, 0.25 * (bed - z0))
        r_in = R - inset
        return _Pour([f"region pour_region cylinder z {cx:.10g} {cy:.10g} {r_in:.10g} {lo:.10g} {hi:.10g} units box"],
                     math.pi * r_in**2 * (hi - lo), hi, z0)
    if isinstance(reg, HorizontalCylinder):
        (cx, cz), R, y0, y1 = reg.center, reg.radius, reg.y0, reg.y1
        r_in = R - inset
        # the upper half of the drum (the bed of a 40 % fill reaches about 0.16 R below the axis;
        # insertion avoids settled particles by its overlap check)
        return _Pour([f"region pour_cyl cylinder y {cx:.10g} {cz:.10g} {r_in:.10g} {y0 + inset:.10g} {y1 - inset:.10g} units box",
                      f"region pour_half block {cx - R:.10g} {cx + R:.10g} {y0:.10g} {y1:.10g} {cz:.10g} {cz + R:.10g} units box",
                      "region pour_region intersect 2 pour_cyl pour_half"],
                     0.5 * math.pi * r_in**2 * (y1 - y0 - 2 * inset), cz + R, cz - R)
    raise TypeError(f"{exp.name}: no pour region for a fill region of type {type(reg).__name__}")


def write_deck(exp: Experiment, parameters: Mapping[str, float], fill_mode: str = "identical", fill_index: int = 0,
               fill: FillResult | None = None, dt: float | None = None, rpm: float | None = None,
               pour_batch_fraction: float = 0.15, pour_interval: float = 0.1, size_classes: int = 6,
               tangential_reduce: bool | None = None) -> ExperimentDeck:
    """The LIGGGHTS deck of ``exp`` with contact ``parameters`` (calibration names, e.g.
    ``mu_s_pp``; the drum's ``rpm`` may be among them).

    fill_mode: "identical" (warpdem's fill ``fill_index``, or ``fill`` if given) or "poured"
        (LIGGGHTS inserts the same mass; its seeds follow ``fill_index``).
    dt: time step [s] (None: :func:`warpdem_time_step` of the identical fill, i.e. warpdem's).
    pour_batch_fraction: poured mode: solid volume inserted per batch / insertion region volume;
    pour_interval: [s] between batches (a batch falls clear of the region in less);
    size_classes: poured mode: the diameter range as this many equal-number classes of their
    mean-volume diameters (:func:`calibration.materials.equal_number_size_classes`; LIGGGHTS 3.8 as
    packaged has only ``radius constant`` templates);
    tangential_reduce: cohesion only: None writes what the law means (:data:`TANGENTIAL_REDUCE`),
    True/False forces LIGGGHTS' ``tangential_reduce`` (False: LIGGGHTS' default, the friction
    limits without the cohesion force; not warpdem's ``sjkr``).
    """
    if fill_mode not in FILL_MODES:
        raise ValueError(f"fill_mode must be one of {FILL_MODES}, got {fill_mode!r}")
    params = dict(parameters)
    if exp.name == "drum":
        rpm = float(params.pop("rpm", rpm if rpm is not None else exp.rpm))
    material = exp.bulk_material()
    if not material.is_spheres:
        raise UnsupportedLaw(f"{exp.name}: only sphere materials are written (clumps need fix multisphere)")
    law = exp.contact_law
    model_words = liggghts_model_keywords(law, tangential_reduce)
    wall_models, wall_settings = _models_and_settings(law, tangential_reduce)
    table = contact_parameter_table(exp, params)
    notes: list[str] = []
    if fill is None and (fill_mode == "identical" or dt is None):
        fill = fill_for_index(exp, fill_index)
    if dt is None:
        dt = warpdem_time_step(exp, fill)
    r_min, r_max = 0.5 * material.diameter[0], 0.5 * material.diameter[1]
    skin = 0.5 * r_min
    d = _DeckText(dt, exp.ke_per_particle, exp.settle_check_interval)
    files: dict[str, str] = {}

    # ---- fill and walls (the walls are raised above the loose column, as warpdem does)
    if fill_mode == "identical":
        loose_top = float(fill.top)
        t_min_fill, t_max_fill = exp.fill_settle_times([fill])
        n_particles = int(fill.sample.n)
        pour = None
    else:
        pour = _pour_region(exp, skin)
        loose_top = pour.top
        n_particles = int(round(exp.fill_amount(material)["mass"] / material.mean_particle_mass))
    walls = capture_walls(exp, loose_top, 0.0)
    protocol_time = _protocol_duration(exp, rpm, loose_top)
    lo = np.min([_swept_bounds(w, protocol_time)[0] for w in walls], axis=0)
    hi = np.max([_swept_bounds(w, protocol_time)[1] for w in walls], axis=0)
    rb_lo, rb_hi = (np.asarray(a, float) for a in exp.remove_box())
    # domain = the removal box, grown to hold every wall over the protocol (LIGGGHTS stops when a
    # mesh leaves the domain); atoms leaving it are lost, as warpdem removes them
    margin = 1e-3 + r_max
    dom_lo = np.maximum(rb_lo, lo - margin)
    dom_hi = np.minimum(rb_hi, hi + margin)
    dom_lo = np.minimum(dom_lo, lo - 1e-3)
    dom_hi = np.maximum(dom_hi, hi + 1e-3)
    dom_hi[2] = max(dom_hi[2], loose_top + 2 * r_max)  # the loose column (identical fill) or the pour region
    if np.any(np.abs(rb_hi - dom_hi) > 5e-3) or np.any(np.abs(rb_lo - dom_lo) > 5e-3):
        notes.append("atoms leave at the simulation domain's faces (lost atoms), warpdem removes them outside "
                     f"remove_box {rb_lo.round(4).tolist()}..{rb_hi.round(4).tolist()} m; the domain is "
                     f"{dom_lo.round(4).tolist()}..{dom_hi.round(4).tolist()} m (the walls bound it where they differ)")

    d.add(f"# LIGGGHTS deck of the warpdem experiment '{exp.name}' (scale {exp.scale}), written by "
          "validation/reference/liggghts_experiments.py",
          f"# contact law {law.describe()}; fill {fill_mode} (index {fill_index}); dt {dt:.6g} s",
          "atom_style granular", "atom_modify map array", "boundary f f f", "newton off",
          "communicate single vel yes", "units si")
    box_line = (f"{dom_lo[0]:.10g} {dom_hi[0]:.10g} {dom_lo[1]:.10g} {dom_hi[1]:.10g} {dom_lo[2]:.10g} {dom_hi[2]:.10g}")
    if fill_mode == "identical":
        x = fill.positions[: fill.placed]
        r = fill.sample.radius
        if np.any(x - r[:, None] < dom_lo) or np.any(x + r[:, None] > dom_hi):
            raise ValueError(f"{exp.name}: the fill does not lie inside the LIGGGHTS domain {box_line}")
        files["fill.data"] = sphere_data_file(x, r, material.particle.density, dom_lo, dom_hi)
        d.add("read_data fill.data")
    else:
        d.add(f"region domain block {box_line} units box", "create_box 2 domain")
    # hard_particles: LIGGGHTS refuses E > 1e9 Pa in SI units without it (the Plexiglas walls: 7.5e9 Pa)
    d.add(f"neighbor {skin:.6g} bin", "neigh_modify delay 0", "hard_particles yes", *_property_lines(exp, table),
          f"pair_style gran {model_words}", "pair_coeff * *", f"timestep {dt:.12g}",
          "fix gravity all gravity 9.81 vector 0.0 0.0 -1.0")
    for w in walls:
        files[w.stl_name] = stl_text(w)
        d.add(f"fix {w.fix_id} all mesh/surface file {w.stl_name} type {WALL_TYPE}")
    d.add(f"fix walls all wall/gran {wall_models} mesh n_meshes {len(walls)} meshes "
          + " ".join(w.fix_id for w in walls) + (f" {wall_settings}" if wall_settings else ""),
          "fix integrate all nve/sphere",
          "compute ke_translation all ke", "compute ke_rotation all erotate/sphere",
          "compute radius all property/atom radius", "variable top atom z+c_radius",
          "compute top_max all reduce max v_top",
          "variable ke_per_particle equal (c_ke_translation+c_ke_rotation)/(atoms+1e-30)",
          "variable step_now equal step", "variable time_now equal step*dt", "variable atoms_now equal atoms",
          "variable top_now equal c_top_max",
          "thermo_style custom step atoms v_ke_per_particle c_top_max", "thermo 1000",
          "thermo_modify lost ignore norm no",
          "fix timestep_check all check/timestep/gran 1000 0.25 0.25")

    # ---- the fill
    if fill_mode == "poured":
        solid = exp.fill_amount(material)["mass"] / material.particle.density
        batch = pour_batch_fraction * pour.volume
        batches = max(1, int(math.ceil(solid / batch)))
        every = max(1, d.steps(pour_interval))
        t_insert = batches * every * dt
        mass = exp.fill_amount(material)["mass"]
        classes = equal_number_size_classes(2 * r_min, 2 * r_max, int(size_classes))
        seeds = [_prime_seed(len(classes) * 7 * fill_index + k) for k in range(len(classes) + 2)]
        d.add(f"# --- poured fill: {mass:.6g} kg, diameters uniform by number in [{2 * r_min:.6g}, {2 * r_max:.6g}] m "
              f"as {len(classes)} equal-number classes, {batches} batch(es) every {every} steps",
              *pour.region)
        for k, dk in enumerate(classes):
            d.add(f"fix pour_template_{k} all particletemplate/sphere {seeds[k]} atom_type {PARTICLE_TYPE} density "
                  f"constant {material.particle.density:.10g} radius constant {0.5 * dk:.10g}")
        weight = 1.0 / len(classes)
        d.add(f"fix pour_distribution all particledistribution/discrete/numberbased {seeds[-2]} {len(classes)} "
              + " ".join(f"pour_template_{k} {weight:.12g}" for k in range(len(classes))),
              f"fix pour all insert/rate/region seed {seeds[-1]} distributiontemplate pour_distribution mass {mass:.10g} "
              f"massrate {mass / t_insert:.10g} insert_every {every} overlapcheck yes all_in yes vel constant 0 0 0 "
              "region pour_region ntry_mc 10000")
        d.advance("pour", t_insert)
        d.add("unfix pour")
        t_fall = math.sqrt(2.0 * max(pour.top - pour.floor, 0.0) / 9.81)
        t_min_fill, t_max_fill = t_fall, exp.fill_settle_max_time + t_fall
        notes.append(f"poured fill: {batches} insertion batch(es) of <= {pour_batch_fraction:g} of the insertion "
                     f"region's volume in {t_insert:.3g} s, then settled at least {t_min_fill:.3g} s (fall from the "
                     f"region top) and at most {t_max_fill:.3g} s (fill_settle_max_time + fall time)")
    d.settle("fill_settle", t_max_fill, t_min_fill)
    d.dump("after_fill.dump")
    settings: dict[str, Any] = {"dt_s": dt, "domain_m": [dom_lo.tolist(), dom_hi.tolist()], "skin_m": skin,
                                "loose_top_m": loose_top, "fill_settle_s": [t_min_fill, t_max_fill],
                                "contact_parameters": table, "model": model_words, "walls": [w.fix_id for w in walls]}

    # ---- the experiment's protocol
    dumps: dict[str, str] = {"after_fill.dump": "the settled fill before the motion (baffle: h_fill and bulk "
                                                "density; cylinder: the fill's mean diameter)"}
    if exp.name == "baffle":
        dumps.update(_baffle_protocol(exp, d, walls))
    elif exp.name == "drum":
        dumps.update(_drum_protocol(exp, d, walls, rpm, settings))
    elif exp.name == "cylinder":
        dumps.update(_cylinder_protocol(exp, d, walls, material, settings))
    else:
        raise UnsupportedLaw(f"no LIGGGHTS protocol for experiment '{exp.name}'")
    settings["phases"] = d.phases
    notes.append("after every settle phase translational velocities are set to 0 (warpdem pauses a settled world "
                 "at rest); LIGGGHTS 3.8's 'set' has no omega keyword, so angular velocities are kept")
    notes.append("particles leaving the domain are lost at the next re-neighbouring; warpdem removes them every "
                 f"{exp.removal_interval:g} s and at every settle check")
    for kind in ("normal", "rolling"):
        if getattr(law, kind) in APPROXIMATE:
            notes.append(f"{kind} '{getattr(law, kind)}': {APPROXIMATE[getattr(law, kind)]}")
    if law.rolling in ("epsd", "epsd2"):
        notes.append("rolling spring: LIGGGHTS keeps the stored torque as it is, warpdem turns it into the current "
                     "tangent plane (only matters while the contact normal rotates); at a wall LIGGGHTS turns it by "
                     "w (r - delta/2) / (r - delta) per step, O(delta/r)")
    if law.cohesion != "none":
        notes.append("cohesion at walls: LIGGGHTS scales the wall force by the mesh's area_ratio, warpdem merges the "
                     "triangles of one flat contact (ratio 1)")
        if tangential_reduce is not None and tangential_reduce != TANGENTIAL_REDUCE[law.cohesion]:
            notes.append(f"NOT the warpdem law: tangential_reduce {'on' if tangential_reduce else 'off'} forced, "
                         f"warpdem '{law.cohesion}' means {'on' if TANGENTIAL_REDUCE[law.cohesion] else 'off'}")
    return ExperimentDeck(exp.name, d.text(), files, dt, fill_mode, n_particles, dumps, settings, notes)


def _protocol_duration(exp: Experiment, rpm: float | None, loose_top: float) -> float:
    """An upper bound of the simulated time after the fill settles [s] (sizes the domain that
    must hold the moving walls)."""
    if exp.name == "baffle":
        return max(exp.lift_duration, exp.max_time_after_lift)
    if exp.name == "drum":
        return 60.0 / float(rpm) * (int(exp.discard) + int(exp.record))
    if exp.name == "cylinder":
        # the lift ends when the bottom edge is the clearance above the pile top (below the loose top)
        clearance = exp.lift_clearance if exp.lift_clearance is not None else 2.0 * exp.bulk_material().max_bounding_radius
        return (loose_top + clearance) / exp.lift_speed + exp.max_time_after_lift
    return 0.0


def sphere_data_file(x: np.ndarray, r: np.ndarray, density: float, lo: np.ndarray, hi: np.ndarray) -> str:
    """``read_data`` file of spheres at ``x`` [m] of radii ``r`` [m] and ``density`` [kg/m^3] in the
    box ``lo``..``hi`` [m] (atom_style granular: id type diameter density x y z; 2 atom types,
    the particles of type 1)."""
    out = ["LIGGGHTS data file: warpdem spheres", "", f"{len(x)} atoms", "2 atom types", "",
           f"{lo[0]:.10g} {hi[0]:.10g} xlo xhi", f"{lo[1]:.10g} {hi[1]:.10g} ylo yhi", f"{lo[2]:.10g} {hi[2]:.10g} zlo zhi",
           "", "Atoms", ""]
    out += [f"{i + 1} {PARTICLE_TYPE} {2.0 * ri:.15g} {density:.10g} {p[0]:.15g} {p[1]:.15g} {p[2]:.15g}"
            for i, (p, ri) in enumerate(zip(x, r))]
    return "\n".join(out) + "\n"


def _wall(walls: Sequence[CapturedWall], moving: bool = True) -> CapturedWall:
    found = [w for w in walls if (w.motion is not None) == moving]
    if len(found) != 1:
        raise UnsupportedLaw(f"expected one moving wall, found {[w.name for w in found]}")
    return found[0]


def _baffle_protocol(exp, d: _DeckText, walls: Sequence[CapturedWall]) -> dict[str, str]:
    """Spec A: measure the fill, lift the baffle for lift_duration, settle for the rest of
    max_time_after_lift, measure the pile (BaffleBox.protocol)."""
    baffle = _wall(walls)
    d.add(_motion_command(baffle, "lift"))
    d.advance("lift", exp.lift_duration)
    d.add("unfix lift")
    d.settle("after_lift_settle", max(exp.max_time_after_lift - exp.lift_duration, 0.0), 0.0)
    d.dump("final.dump")
    return {"final.dump": "the pile at the end (static angle)"}


def _drum_protocol(exp, d: _DeckText, walls: Sequence[CapturedWall], rpm: float,
                   settings: dict[str, Any]) -> dict[str, str]:
    """Spec B: rotate from the settled fill; a dump at every snapshot time of the recorded
    revolutions (RotatingDrum.protocol, step counts rounded as RunContext.advance)."""
    from calibration.measurement import revolution_snapshot_times

    drum = _wall(walls)
    spin = wd.WallMotion.rotation(np.asarray(drum.motion.angular_velocity) / np.linalg.norm(drum.motion.angular_velocity),
                                  rpm, origin=drum.motion.origin)
    drum = CapturedWall(drum.name, drum.vertices, drum.faces, drum.material, spin, drum.world)
    times = np.round(revolution_snapshot_times(rpm, int(exp.discard), int(exp.record), t0=0.0,
                                               frames=int(exp.frames_per_revolution)).ravel(), 9)
    d.add(_motion_command(drum, "spin"))
    now, dumps, frames = 0.0, {}, []
    for k, t in enumerate(np.unique(times)):
        n = d.steps(t - now)
        now += n * d.dt
        d.advance(f"rotation_{k:03d}", n * d.dt)
        name = f"snapshot_{k:03d}.dump"
        d.dump(name)
        dumps[name] = f"snapshot at {t:.6g} s after the rotation started"
        frames.append(float(t))
    settings["rpm"] = rpm
    settings["snapshot_times_s"] = times.tolist()
    settings["snapshot_files"] = [f"snapshot_{frames.index(float(t)):03d}.dump" for t in times]
    return dumps


def _cylinder_protocol(exp, d: _DeckText, walls: Sequence[CapturedWall], material,
                       settings: dict[str, Any]) -> dict[str, str]:
    """Spec C: lift until the bottom edge is the clearance above the pile top (measured in the
    deck after the fill settled), keep lifting while it settles (HollowCylinder.protocol)."""
    shell = _wall(walls)
    clearance = exp.lift_clearance if exp.lift_clearance is not None else 2.0 * material.max_bounding_radius
    speed = float(np.linalg.norm(shell.motion.velocity))
    d.add("run 0 post no",
          f"variable lift_steps equal round((c_top_max+{clearance:.10g})/{speed:.10g}/dt)",
          f'print "PHASE lift_plan pile_top ${{top_now}} lift_steps ${{lift_steps}}"',
          "variable lift_steps_fixed equal ${lift_steps}",
          _motion_command(shell, "lift"),
          f'print "PHASE lift start step ${{step_now}} time ${{time_now}} atoms ${{atoms_now}}"',
          "run ${lift_steps_fixed} post no",
          f'print "PHASE lift end step ${{step_now}} time ${{time_now}} atoms ${{atoms_now}} '
          f'ke_per_particle ${{ke_per_particle}}"')
    d.phases["lift"] = {"steps": "round((pile top + clearance) / speed / dt)", "clearance_m": clearance,
                        "speed_m_s": speed}
    d.settle("after_lift_settle", exp.max_time_after_lift, 0.0)
    d.dump("final.dump")
    settings["lift_clearance_m"] = clearance
    return {"final.dump": "the pile at the end (pile angle and height)"}
