"""The strict schema of a pump config (``warpdem pump CONFIG``), every section checked at load
before any model is built (:func:`load_config`, also importable from :mod:`pump.run`).

The sections' types and ranges are declared here (an unknown key, ``seed: 1.5``,
``fluid.density: heavy`` or ``coupling.two_way: "yes"`` is refused naming it); what depends on
other sections is :func:`cross_section_problems`: the design built (leading edge inside the
eye and the impeller), the contact parameters against the law's declarations, the fluid
parameters against the fluid forces' declarations, the particles' material built, the injection
window inside the run, the particles it injects (at least one, at most what the machine holds),
the trajectory world among the worlds, the flow grid's size and the DEM step count.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Literal, Mapping

from pydantic import Field

from warpdem import ConfigError
from warpdem.config_io import check_sphere_memory
from warpdem.config_schema import Flag, Number, Section, Text, WholeNumber, dataclass_section, raise_problems, validate_section

from .design import PumpDesign
from .geometry import COMPONENTS

__all__ = ["PumpFile", "cross_section_problems", "load_config", "DEFAULTS", "SECTIONS", "MAX_STEPS", "MAX_GRID_POINTS", "MAX_PARTICLES_PER_WORLD"]

#: the most DEM steps a run may take (about 200 times the paper case's): a time step or revolution
#: count that needs more is refused at load
MAX_STEPS = 100_000_000
#: the most points of the sampled flow grid (:meth:`pump.flow.PumpFlow.sample`)
MAX_GRID_POINTS = 60_000_000
#: the most particles one world may inject (the paper case injects about 30 per world)
MAX_PARTICLES_PER_WORLD = 200_000

Component = Literal[COMPONENTS]  # type: ignore[valid-type]


class Geometry(Section):
    resolution: Number = Field(1.0, gt=0)
    meshes: dict[Component, Text] = Field(default_factory=dict)
    mesh_scale: Number = Field(1.0, gt=0)


class Fluid(Section):
    density: Number = Field(998.2, gt=0)
    viscosity: Number = Field(1.002e-3, gt=0)
    grid_spacing: Number = Field(0.003, gt=0)
    drag: Literal["di_felice", "schiller_naumann"] = "di_felice"
    # where the drag reads the fluid velocity: the centre, or the mean over the particle's sphere
    # (Faxen, a^2/6 lap u) or volume (a^2/10 lap u) (pump/coupling.py)
    drag_velocity: Literal["centre", "surface_average", "volume_average"] = "centre"
    # rotation factor k of the side rooms' core, c_u = k omega r (pump/flow.py; 0.5 without leakage)
    side_room_rotation: Number = Field(0.5, ge=0, le=1)
    added_mass: Number = 0.5
    pressure_gradient: Number = 1.0
    buoyancy: Number = 1.0
    voidage_cell: Number = 0.05


class Coupling(Section):
    two_way: Flag = False
    relaxation: Number = Field(1.0, ge=0, le=100)


class Particles(Section):
    material: dict[Text, Any] = Field(default_factory=lambda: {"type": "spheres", "diameter": [0.010, 0.025]})
    volume_fraction: Number = Field(0.01, gt=0, lt=0.6)
    rate: Number | None = Field(None, gt=0)
    inject_from: Number = Field(0.0, ge=0)
    inject_until: Number | None = Field(None, gt=0)


class Wall(Section):
    youngs_modulus: Number = Field(2.0e11, gt=0)
    poisson_ratio: Number = Field(0.3, ge=0, lt=0.5)
    density: Number = Field(7850.0, gt=0)


class Run(Section):
    revolutions: Number = Field(15.0, gt=0)
    dt: Number = Field(1.0e-5, gt=0)
    worlds: WholeNumber = Field(1, ge=1)
    update_every: Number = Field(5.0e-4, gt=0)
    record_every: Number = Field(2.0e-3, gt=0)
    vtk_every: Number = Field(0.02, gt=0)
    max_contacts: WholeNumber = Field(16, ge=1)
    steps_per_graph: WholeNumber = Field(50, ge=1)
    trajectory_world: WholeNumber = Field(0, ge=0)


class Wear(Section):
    dnv_K: Number = Field(2.0e-9, gt=0)
    dnv_n: Number = Field(2.6, gt=0)
    target_density: Number = Field(7800.0, gt=0)
    archard_k: Number = Field(1.0e-2, gt=0)
    hardness: Number = Field(1.18e9, gt=0)
    finnie_k: Number = Field(0.0, ge=0)
    spin_up_revolutions: Number = Field(2.0, ge=0)
    block_revolutions: Number = Field(1.0, gt=0)


#: seed paper Sec. 4.2 optimum (friction) and Table 6 (restitution 0.6)
CONTACT_DEFAULTS = {"rolling": "epsd", "mu_s_pp": 0.323, "mu_r_pp": 0.061, "mu_s_pw": 0.316, "mu_r_pw": 0.441,
                    "restitution_pp": 0.6, "restitution_pw": 0.6}


class PumpFile(Section):
    """The whole pump config (keys: :mod:`pump.run`'s docstring)."""

    name: Text = Field("pump", min_length=1)
    device: Text | None = "cpu"
    output: Text = Field("results/pump", min_length=1)
    seed: WholeNumber = Field(0, ge=0)
    design: dataclass_section(PumpDesign, ("derived",)) = Field(  # type: ignore[valid-type]
        default_factory=lambda: dataclass_section(PumpDesign, ("derived",))())
    geometry: Geometry = Field(default_factory=Geometry)
    fluid: Fluid = Field(default_factory=Fluid)
    coupling: Coupling = Field(default_factory=Coupling)
    particles: Particles = Field(default_factory=Particles)
    contact: dict[Text, Any] = Field(default_factory=dict)
    wall: Wall = Field(default_factory=Wall)
    run: Run = Field(default_factory=Run)
    wear: Wear = Field(default_factory=Wear)
    gravity: tuple[Number, Number, Number] = (0.0, -9.81, 0.0)
    notes: Text = ""


def _contact_problems(contact: Mapping[str, Any]) -> list[str]:
    """``contact``: the rolling model by name, every other key a declared parameter of that law
    (``mu_s_pp``, ``restitution_pw``, ...) with a number inside its admissible range."""
    import warpdem as wd
    from calibration.model_description import ModelDescription

    try:
        law = wd.ContactLaw(rolling=contact["rolling"])
    except (ConfigError, TypeError) as exc:
        return [f"contact.rolling: {exc}"]
    model, problems = ModelDescription(law), []
    for name, value in contact.items():
        if name == "rolling":
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            problems.append(f"contact.{name} must be a number, got {value!r}")
            continue
        try:
            model.check_value(name, value, "contact")
        except ConfigError as exc:
            problems.append(str(exc))
    return problems


def _fluid_problems(fluid: Mapping[str, Any]) -> list[str]:
    """The fluid forces' parameters (added_mass, pressure_gradient, buoyancy, voidage_cell) inside
    the ranges :class:`pump.coupling.GridFluidForces` declares."""
    from .coupling import GridFluidForces

    problems = []
    for spec in GridFluidForces.parameters:
        if spec.name in fluid and not spec.bounds[0] <= fluid[spec.name] <= spec.bounds[1]:
            problems.append(f"fluid.{spec.name} = {fluid[spec.name]!r} is outside its admissible range "
                            f"[{spec.bounds[0]:g}, {spec.bounds[1]:g}] {spec.unit} ({spec.description})")
    return problems


def cross_section_problems(cfg: Mapping[str, Any]) -> list[str]:
    """What one section cannot check alone, on a config of plain sections (defaults filled in);
    each problem one line naming its keys, nothing built but the design and the material."""
    from calibration.materials import BulkMaterial

    from .inlet import injection_rate

    problems = _contact_problems(cfg["contact"]) + _fluid_problems(cfg["fluid"])
    run, pc = cfg["run"], cfg["particles"]
    if run["trajectory_world"] >= run["worlds"]:
        problems.append(f"run.trajectory_world = {run['trajectory_world']} but the run has {run['worlds']} world(s) "
                        f"(indices 0-{run['worlds'] - 1})")
    for component, path in cfg["geometry"]["meshes"].items():
        if not Path(path).is_file():
            problems.append(f"geometry.meshes.{component}: mesh file not found: {path} (relative to the working folder)")
    window_ok = pc["inject_until"] is None or pc["inject_until"] > pc["inject_from"]
    if not window_ok:
        problems.append(f"particles.inject_until = {pc['inject_until']:g} s must be after particles.inject_from = "
                        f"{pc['inject_from']:g} s")
    try:
        design = PumpDesign.from_config(cfg["design"])
    except ConfigError as exc:
        return problems + [f"design: {str(exc).removeprefix('pump design: ')}"]
    try:
        material = BulkMaterial.from_config(pc["material"])
    except (ConfigError, ValueError, TypeError) as exc:
        return problems + [f"particles.material: {exc}"]
    t_end = run["revolutions"] * design.revolution_time
    steps = t_end / run["dt"]
    if steps > MAX_STEPS:
        problems.append(f"run: {run['revolutions']:g} revolution(s) of {design.revolution_time:.3g} s at run.dt = "
                        f"{run['dt']:g} s are {steps:.3g} DEM steps; the limit is {MAX_STEPS:.0e} steps (MAX_STEPS in "
                        "pump/config_schema.py): raise run.dt or run fewer revolutions")
    grid_points = (2.0 * design.r2 / cfg["fluid"]["grid_spacing"]) ** 3  # the impeller's box alone: a lower bound
    if grid_points > MAX_GRID_POINTS:
        problems.append(f"fluid.grid_spacing = {cfg['fluid']['grid_spacing']:g} m samples the flow on more than "
                        f"{grid_points:.3g} points; the limit is {MAX_GRID_POINTS:.0e} (MAX_GRID_POINTS in "
                        "pump/config_schema.py): give a coarser grid_spacing")
    if run["record_every"] > t_end:
        problems.append(f"run.record_every = {run['record_every']:g} s is longer than the run ({run['revolutions']:g} "
                        f"revolution(s) = {t_end:.3g} s): nothing would be recorded; record more often")
    wear = cfg["wear"]
    if wear["spin_up_revolutions"] + wear["block_revolutions"] > run["revolutions"]:
        problems.append(f"wear.spin_up_revolutions ({wear['spin_up_revolutions']:g}) + wear.block_revolutions "
                        f"({wear['block_revolutions']:g}) exceed run.revolutions ({run['revolutions']:g}): the run would "
                        "take no wear sample; run more revolutions or shorten the spin-up")
    if not window_ok:
        return problems
    if pc["inject_from"] >= t_end:
        return problems + [f"particles.inject_from = {pc['inject_from']:g} s is after the run's end "
                           f"({run['revolutions']:g} revolution(s) = {t_end:.3g} s): inject earlier or run more "
                           "revolutions"]
    mean_volume = material.mean_particle_mass / material.particle.density
    rate = pc["rate"] if pc["rate"] is not None else injection_rate(pc["volume_fraction"], design.flow_rate,
                                                                   mean_volume)
    window = (t_end if pc["inject_until"] is None else min(pc["inject_until"], t_end)) - pc["inject_from"]
    particles = rate * window
    source = "particles.rate" if pc["rate"] is not None else "particles.volume_fraction"
    if particles < 1.0:
        problems.append(f"the run injects no particle: {rate:.3g} particles/s ({source}) for {window:.3g} s "
                        f"(particles.inject_from to the run's end or particles.inject_until) make {particles:.2g}: "
                        f"raise {source}, run more revolutions or widen the injection window")
    elif particles > MAX_PARTICLES_PER_WORLD:
        problems.append(f"{source}: the run injects about {particles:.3g} particles per world ({rate:.3g}/s for "
                        f"{window:.3g} s); the limit is {MAX_PARTICLES_PER_WORLD} (MAX_PARTICLES_PER_WORLD in "
                        f"pump/config_schema.py): lower {source} or run fewer revolutions")
    else:
        per_particle = 1.0 if material.is_spheres else float(sum(f * len(t.radii) for t, f in material.clumps))
        try:
            check_sphere_memory(particles * per_particle * run["worlds"], "run.worlds",
                                f"run fewer worlds or lower {source} ({run['worlds']} world(s) of about "
                                f"{particles:.3g} particles)")
        except ConfigError as exc:
            problems.append(str(exc))
    return problems


SECTIONS = tuple(PumpFile.model_fields)
#: each section's defaults (what a config that leaves a key out runs with)
DEFAULTS = {name: PumpFile.model_fields[name].default_factory().model_dump()
            for name in ("geometry", "fluid", "coupling", "particles", "wall", "run", "wear")}
DEFAULTS["contact"] = dict(CONTACT_DEFAULTS)


def load_config(path_or_dict: str | Path | dict, where: str | None = None) -> dict:
    """Read and check a pump config (YAML path or mapping) against its schema
    (:class:`pump.config_schema.PumpFile`) and the rules between its sections; returns plain
    sections with the defaults filled in. Every problem is listed in one ConfigError naming
    ``where`` (the file a mapping came from) and each key."""
    if isinstance(path_or_dict, dict):
        raw = dict(path_or_dict)
        where = where or "config"
    else:
        from warpdem.config_io import load_config_file

        p = Path(path_or_dict)
        raw = load_config_file(p, "pump config")
        if raw is None:
            raise ConfigError(f"{p}: the file is empty; a pump config names at least its output and run "
                              "(pump/configs/quick_pump.yaml)")
        where = str(p)
    doc = validate_section(PumpFile, raw, where)
    cfg = doc.model_dump()
    cfg["design"] = doc.design.model_dump(exclude_unset=True)  # PumpDesign keeps its own defaults
    cfg["contact"] = {**CONTACT_DEFAULTS, **doc.contact}
    cfg["gravity"] = list(doc.gravity)
    problems = []
    try:
        from warpdem.config_io import check_device

        check_device(cfg["device"], "device", present=False)  # a GPU config loads anywhere; pump_main runs it
    except ConfigError as exc:
        problems.append(str(exc))
    raise_problems(where, problems + cross_section_problems(cfg))
    return cfg
