"""Shared machinery of the standard experiments (definitions: docs/experiments.md).

One :meth:`Experiment.run` builds ONE :class:`warpdem.Model` with one world per parameter
set (same loose fill and shared walls in every world, per-world contact parameters),
runs the experiment's protocol and measures each world with
:mod:`calibration.measurement`.

Protocol clock: wall motions are part of the immutable model, so their start time must be
known when it is built. Every experiment starts its motion at ``t_motion`` = the longest a fill
of its settings and material may settle (:meth:`Experiment.motion_start`); when the fills settle
earlier the state's clock is moved forward to ``t_motion`` (walls are at rest before their start,
so nothing else depends on time). Reported simulated times are the phases actually simulated,
without the jump.

Batches: the walls' height and ``t_motion`` follow the settings and the material (the tallest
loose column the fill mass can form, :meth:`Experiment.loose_top_bound`), not the fills a batch
drew, and the time step follows the material's smallest possible sphere; so a world's result
does not depend on the worlds it shares a batch (or a process) with.

Batch checkpoints: :mod:`calibration.experiments.checkpoints`; the protocol steps they resume:
:mod:`calibration.experiments.run_context`.
"""
from __future__ import annotations

import dataclasses
import math
import os
import sys
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Mapping, Sequence

import numpy as np
import trimesh

import warpdem as wd
from warpdem import ConfigError, ContactOverflowError, StabilityError
from warpdem.config_io import BYTES_PER_SPHERE as _BYTES_PER_SPHERE
from warpdem.config_io import machine_memory

from ..executor import LocalExecutor, RayExecutor
from ..filling import (Box, FillError, FillResult, VerticalCylinder, add_fill, fill_body_ids, hold_batches,
                       insertion_region, pour_fill, poured_fill, random_fill, region_volume, release_batches)
from ..materials import BulkMaterial, sample_particles
from .checkpoints import BatchCheckpoint, BatchCheckpoints, clear_checkpoints, decode_value
from .results_json import jsonable as _jsonable
from .run_context import RunContext

if TYPE_CHECKING:
    from warpdem.timestep import TimeStepLimits

__all__ = ["BatchCheckpoints", "Experiment", "ExperimentResult", "RunContext", "clear_checkpoints",
           "normalize_parameter_sets", "rectangle", "fit_to_dict"]

G = 9.81
#: the most particles one world's fill may hold (the paper-scale fills hold 750 to 1800): a larger
#: fill is refused when the experiment is built, before any DEM (:meth:`Experiment.check_size`)
MAX_PARTICLES_PER_WORLD = 200_000
#: memory one sphere of a world takes at most [bytes] (warpdem.config_io.BYTES_PER_SPHERE)
BYTES_PER_SPHERE = _BYTES_PER_SPHERE
#: the loosest a loose fill's column packs, as solids volume / (floor area x column height) of the
#: random placement before settling (calibration.filling.random_fill); measured (2026-11-28, 4 fills
#: each): spheres 0.27, the paper's gravel clumps 0.19, rods of aspect ratio 3.5 (the elongated
#: family's largest) 0.14. The walls' height and the motion start follow the column this bound
#: allows (:meth:`Experiment.loose_top_bound`); a fill that rises above it is refused.
LOOSE_SOLIDS_FRACTION_BOUND = 0.10
#: the fills an experiment can start from (``fill_mode``): "loose" (a random-sequential-addition
#: column, settled) or "poured" (batches inserted at rest and poured, as LIGGGHTS' insert/rate/region)
FILL_MODES = ("loose", "poured")
#: the largest ``pour_batch_fraction`` (random sequential addition jams near 0.3 of the volume)
MAX_POUR_BATCH_FRACTION = 0.3


@dataclass(frozen=True)
class PourPlan:
    """The schedule of a poured fill (:meth:`Experiment.pour_plan`): the insertion region (closed
    box or vertical cylinder) and its volume [m^3], the solid volume per batch [m^3], the number
    of batch times (from the most mass a fill can hold), the interval between them [s], the
    region's top and the fill's floor [m] and the free fall from that top to the floor [s]."""

    region: Box | VerticalCylinder
    volume: float
    batch_volume: float
    batches: int
    interval: float
    top: float
    floor: float
    t_fall: float

    @property
    def duration(self) -> float:
        """Simulated time [s] of the pour before the fill settles: one interval per batch time."""
        return self.batches * self.interval


# --------------------------------------------------------------------------- meshes
def rectangle(corner, u, v, subdivisions: int = 1) -> trimesh.Trimesh:
    """Planar rectangle ``corner + s u + t v`` (s, t in [0, 1]) [m], 2 triangles per cell."""
    c, u, v = (np.asarray(a, dtype=float) for a in (corner, u, v))
    if np.linalg.norm(np.cross(u, v)) == 0:
        raise ConfigError(f"rectangle: edges {u.tolist()} and {v.tolist()} are parallel")
    k = int(subdivisions)
    s = np.linspace(0.0, 1.0, k + 1)
    gs, gt = np.meshgrid(s, s, indexing="ij")
    verts = c + gs.reshape(-1, 1) * u + gt.reshape(-1, 1) * v
    faces = []
    for i in range(k):
        for j in range(k):
            a = i * (k + 1) + j
            faces += [[a, a + k + 1, a + k + 2], [a, a + k + 2, a + 1]]
    return trimesh.Trimesh(verts, np.array(faces), process=False)


# --------------------------------------------------------------------------- parameters
def normalize_parameter_sets(parameter_sets: Sequence[Mapping[str, float]] | Mapping[str, Any],
                             parameter_names: Sequence[str]) -> list[dict[str, float]]:
    """One dict per world from a list of dicts, a dict of equal-length arrays, or one dict of
    scalars (one world). Names must be among ``parameter_names`` (the model's contact law)."""
    if isinstance(parameter_sets, Mapping):
        if not parameter_sets:
            raise ConfigError("parameter sets ('parameters'): empty mapping; give at least one world")
        for k, v in parameter_sets.items():
            if any(isinstance(x, (bool, str)) for x in np.ravel(np.asarray(v, dtype=object))):
                raise ConfigError(f"parameter sets: '{k}' must be a number or a list of numbers, got {v!r}")
        try:
            arrays = {k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in parameter_sets.items()}
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"parameter sets: every value must be a number or a list of numbers ({exc})") from None
        lengths = {k: a.size for k, a in arrays.items()}
        if len(set(lengths.values())) != 1:
            raise ConfigError(f"parameter sets: arrays differ in length {lengths}")
        n = next(iter(lengths.values()))
        sets = [{k: float(a[i]) for k, a in arrays.items()} for i in range(n)]
    elif isinstance(parameter_sets, (str, bytes)) or not isinstance(parameter_sets, Sequence) \
            or not all(isinstance(s, Mapping) for s in parameter_sets):
        raise ConfigError("parameter sets ('parameters'): a list of mappings (one per world: {mu_s_pp: 0.3, ...}) or "
                          f"a mapping of equal-length lists, got {parameter_sets!r}")
    else:
        sets = [dict(s) for s in parameter_sets]
        if not sets:
            raise ConfigError("parameter sets ('parameters'): empty list; give at least one world (an empty dict uses defaults)")
    valid = list(parameter_names)
    for w, s in enumerate(sets):
        for k, v in s.items():
            if k not in valid:
                raise ConfigError(f"parameter set {w}: unknown contact parameter '{k}'; this contact law has {valid}")
            try:
                if isinstance(v, (bool, str)):
                    raise TypeError(v)
                value = float(v)
            except (TypeError, ValueError):
                raise ConfigError(f"parameter set {w}: '{k}' must be a number, got {v!r}") from None
            if not math.isfinite(value):
                raise ConfigError(f"parameter set {w}: '{k}' must be finite, got {v}")
            s[k] = value
    return sets


# --------------------------------------------------------------------------- results
def fit_to_dict(fit) -> dict[str, Any]:
    """JSON-able diagnostics of a :class:`~calibration.measurement.ProfileFit` (lengths in m)."""
    p = fit.profile
    return {"angle_deg": fit.angle_deg, "slope": fit.slope, "intercept_m": fit.intercept,
            "residual_rms_m": fit.residual_rms, "n_bins": fit.n_bins,
            "z_band_m": None if fit.z_band is None else list(fit.z_band),
            "x_fit_m": fit.x_fit, "z_fit_m": fit.z_fit, "profile_x_m": p.centres, "profile_z_m": p.heights,
            "profile_counts": p.counts}


@dataclass
class ExperimentResult:
    """Outcome of one world of an experiment run.

    status: "ok" or "failed" (``error`` holds the message; a failed world is never dropped). A world
        whose measurement failed keeps in ``observables`` what was measured before (A: the bulk
        density when no angle could be measured), the failed quantities None.
    angle_deg: the experiment's angle (``angle_name``: alpha_AoR_S, beta_AoR_D or gamma_s) [deg].
    bulk_density: fill bulk density [kg/m^3] where the spec asks for it (A), else None.
    observables: every measured quantity of this world by name (units in the experiment's
        ``OBSERVABLES``), e.g. ``static_angle`` [deg] and ``bulk_density`` [kg/m^3] (A),
        ``dynamic_angle`` [deg] (B), ``pile_angle`` [deg], ``pile_height`` [m], ``pile_formed``
        [1/0] (C; a material that spreads flat is an outcome: pile_formed 0, angle 0).
    diagnostics: fits, profile points, residuals, bin counts, snapshot spread, settling.
    timing: wall seconds, steps, simulated time [s] of the whole run (shared by its worlds).
    protocol: the experiment's settings, scale label and deviations from the paper scale.
    fit: the measurement object (ProfileFit / DrumResult / CylinderPileResult), not serialised.
    particles: (centres (m, 3), radii (m,)) [m] of the world at the final measurement, for plots.
    """

    experiment: str
    scale: str
    world: int
    parameters: dict[str, float]
    contact_parameters: dict[str, float]
    status: str = "ok"
    error: str | None = None
    angle_name: str = ""
    angle_deg: float | None = None
    bulk_density: float | None = None
    observables: dict[str, float | None] = field(default_factory=dict)
    diagnostics: dict[str, Any] = field(default_factory=dict)
    timing: dict[str, Any] = field(default_factory=dict)
    protocol: dict[str, Any] = field(default_factory=dict)
    fit: Any = field(default=None, repr=False)
    particles: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def fail(self, message: str) -> None:
        self.status, self.error, self.angle_deg = "failed", message, None

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict (NaN -> None; ``fit`` and ``particles`` left out)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in ("fit", "particles")}
        return _jsonable(d)


# --------------------------------------------------------------------------- base class
@dataclass
class Experiment:
    """Settings shared by all experiments (SI units).

    scale: "paper" (the spec's defaults) or "quick" (fewer, larger particles, shorter protocol;
        labelled in every result). material: a BulkMaterial (None: the scale's default).
    contact_law: the :class:`warpdem.ContactLaw` (every sub-model), or a mapping such as
        ``{rolling: epsd2, cohesion: sjkr}``; default Hertz-Mindlin + ``epsd`` rolling resistance.
        It reaches the fills and the builder as it is (never rebuilt from a name).
    plugins: user modules of sub-models / shape families loaded before the law was built (worker
        processes load them again).
    contact_defaults: parameters applied to every world before its own set (spec "Default
        material": restitution 0.6 for all pairs).
    dt: time step [s] (None: the recommended step of the material's smallest possible sphere,
        ``warpdem.time_step_limits_for``, the same for every batch);
        dt_rayleigh_fraction: the step as a fraction of the smallest sphere's Rayleigh time
        (capped by the stability limit; for time-step convergence studies); v_ref: impact
        speed of the stability check [m/s]; force_dt: accept dt above the limit.
    ke_per_particle: settled criterion [J] (spec A: 1e-6); fill_settle_max_time [s] (spec A: 1.5;
        extended by the fall time when the loose column stands above the walls).
    settle_check_interval, removal_interval: [s] between KE checks / removals of escaped particles.
    max_contacts: contact slots per sphere (at least min(16 + 8 (n - 1), 64) for clumps of n members);
        max_neighbours: neighbour-list slots per sphere (None:
        the solver's default). A run whose slots overflow is run again from the same fill with
        more slots (``overflow_retries`` times at most; recorded in ``timing["retries"]``).
    vtk_every: write a VTK time series (``particles.pvd``, ``wall_<name>.pvd``, for ParaView) of
        world ``vtk_world`` every this many simulated seconds into ``vtk_folder`` (None:
        ``experiment_<name>_<scale>/vtk``, under the CLI's default output folder); None: no VTK.
        A run that writes VTK runs in one process.
    seed: fill RNG seed. fill_per_world: a different loose fill in every world (default: the
        same fill everywhere); world w's fill is seeded by (seed, first_fill_index + w).
    fill_mode: "loose" (default: a random-sequential-addition column in the fill region, settled)
        or "poured" (as LIGGGHTS' ``insert/rate/region`` in the project's decks: batches of
        ``pour_batch_fraction`` of the insertion region's volume as solid, placed without overlap
        in the insertion region (the upper part of the fill region, :meth:`pour_plan`), released at
        rest one every ``max(pour_interval, free fall through the region's height)`` s, a particle
        that would overlap one in play kept back to the next batch time; then settled as a loose
        fill, at least the free fall from the region's top). Box and vertical cylinder only.
    """

    name: ClassVar[str] = "experiment"
    angle_name: ClassVar[str] = ""
    #: observables a run reports -> unit; the first is the experiment's angle
    OBSERVABLES: ClassVar[dict[str, str]] = {}
    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {"paper": {}}

    scale: str = "paper"
    material: BulkMaterial | None = None
    contact_law: wd.ContactLaw = field(default_factory=lambda: wd.ContactLaw(rolling="epsd"))
    plugins: tuple[str, ...] = ()
    contact_defaults: dict[str, float] = field(default_factory=lambda: {"restitution_pp": 0.6, "restitution_pw": 0.6})
    dt: float | None = None
    dt_rayleigh_fraction: float | None = None
    v_ref: float = 2.0
    force_dt: bool = False
    ke_per_particle: float = 1.0e-6
    fill_settle_max_time: float = 1.5
    settle_check_interval: float = 0.02
    removal_interval: float = 0.05
    max_contacts: int = 16
    max_neighbours: int | None = None
    overflow_retries: int = 2
    seed: int = 0
    fill_per_world: bool = False
    first_fill_index: int = 0
    wall_material: wd.Material = wd.PLEXIGLAS
    vtk_every: float | None = None
    vtk_world: int = 0
    vtk_folder: str | None = None
    fill_mode: str = "loose"
    pour_batch_fraction: float = 0.10
    pour_interval: float = 0.1

    # ------------------------------------------------------------------ config
    @classmethod
    def field_names(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls)]

    @classmethod
    def from_config(cls, scale: str = "paper", **overrides: Any) -> "Experiment":
        """The ``scale`` preset with ``overrides`` (any field; ``material`` may be a mapping for
        :meth:`BulkMaterial.from_config`). Unknown keys raise ConfigError."""
        if scale not in cls.PRESETS:
            raise ConfigError(f"{cls.name}: unknown scale {scale!r}; valid: {sorted(cls.PRESETS)}")
        names = cls.field_names()
        unknown = sorted(set(overrides) - set(names))
        if unknown:
            raise ConfigError(f"{cls.name}: unknown setting(s) {unknown}; valid: {sorted(n for n in names if n != 'scale')}")
        from .settings_schema import check_setting_types

        overrides = check_setting_types(cls, overrides)  # fill_mass: true, seed: abc (the values: __post_init__)
        kw = {**cls.PRESETS[scale], **overrides, "scale": scale}
        return cls(**kw)

    def __post_init__(self) -> None:
        if self.scale not in self.PRESETS:
            raise ConfigError(f"{self.name}: unknown scale {self.scale!r}; valid: {sorted(self.PRESETS)}")
        if isinstance(self.material, Mapping):
            self.material = BulkMaterial.from_config(self.material)
        elif self.material is not None and not isinstance(self.material, BulkMaterial):
            raise ConfigError(f"{self.name}: material must be a BulkMaterial or a mapping, got {type(self.material).__name__}")
        if isinstance(self.wall_material, Mapping):
            self.wall_material = wd.Material(**self.wall_material)
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, list):  # YAML lists -> tuples for tuple fields
                setattr(self, f.name, tuple(v))
        self._check_positive("v_ref", "ke_per_particle", "settle_check_interval", "removal_interval")
        self._check_nonnegative("fill_settle_max_time")
        if self.vtk_every is not None:
            self._check_positive("vtk_every")
        if not (isinstance(self.vtk_world, int) and self.vtk_world >= 0):
            raise ConfigError(f"{self.name}: vtk_world must be a world index >= 0, got {self.vtk_world!r}")
        if self.dt is not None:
            self._check_positive("dt")
        if self.dt_rayleigh_fraction is not None:
            self._check_positive("dt_rayleigh_fraction")
            if self.dt is not None:
                raise ConfigError(f"{self.name}: give dt or dt_rayleigh_fraction, not both")
        if int(self.max_contacts) < 1:
            raise ConfigError(f"{self.name}: max_contacts must be >= 1, got {self.max_contacts}")
        if self.max_neighbours is not None and int(self.max_neighbours) < 1:
            raise ConfigError(f"{self.name}: max_neighbours must be >= 1 or null, got {self.max_neighbours}")
        if int(self.overflow_retries) < 0:
            raise ConfigError(f"{self.name}: overflow_retries must be >= 0, got {self.overflow_retries}")
        from ..model_description import contact_law_from_config, load_plugins

        if isinstance(self.plugins, str):
            self.plugins = (self.plugins,)
        self.plugins = load_plugins(list(self.plugins)) if self.plugins else ()
        self.contact_law = contact_law_from_config(self.contact_law, f"{self.name}: contact_law")
        if not isinstance(self.contact_defaults, Mapping):
            raise ConfigError(f"{self.name}: contact_defaults must be a mapping of parameter names to values")
        self.validate()
        if self.fill_mode not in FILL_MODES:
            raise ConfigError(f"{self.name}: fill_mode must be one of {list(FILL_MODES)} ('loose': a random column "
                              f"settled; 'poured': batches poured as LIGGGHTS inserts them), got {self.fill_mode!r}")
        self._check_positive("pour_batch_fraction", "pour_interval")
        if self.pour_batch_fraction > MAX_POUR_BATCH_FRACTION:
            raise ConfigError(f"{self.name}: pour_batch_fraction must be at most {MAX_POUR_BATCH_FRACTION} (solid "
                              f"volume per batch / insertion region volume), got {self.pour_batch_fraction}")
        if self.fill_mode == "poured" and not self.fill_region().open_top:
            raise ConfigError(f"{self.name}: fill_mode 'poured' needs a fill region open at the top (the baffle box, "
                              f"the hollow cylinder); this experiment's is closed: use fill_mode 'loose'")

    def validate(self) -> None:
        """Experiment-specific checks (override)."""

    def check_size(self, worlds: int = 1) -> dict[str, float]:
        """Estimate one world's fill (particles, spheres, memory [bytes]) and refuse (ConfigError)
        a fill above :data:`MAX_PARTICLES_PER_WORLD` or ``worlds`` of them above the memory of this
        machine, naming the setting, the estimate and the limit. No DEM runs."""
        material = self.bulk_material()
        amount = self.fill_amount(material)
        particles = float(amount["n"]) if "n" in amount else float(amount["mass"]) / material.mean_particle_mass
        per_particle = 1.0 if material.is_spheres else float(sum(f * len(t.radii) for t, f in material.clumps))
        spheres = particles * per_particle
        memory = spheres * BYTES_PER_SPHERE * max(1, int(worlds))
        setting = "fill_mass" if "mass" in amount and hasattr(self, "fill_mass") else "the fill"
        given = f"{setting} = {getattr(self, 'fill_mass'):g} kg" if setting == "fill_mass" else setting
        if particles > MAX_PARTICLES_PER_WORLD:
            raise ConfigError(f"{self.name}: {given} makes about {particles:.3g} particles ({spheres:.3g} spheres, "
                              f"~{spheres * BYTES_PER_SPHERE / 1e9:.3g} GB) per world; the limit is "
                              f"{MAX_PARTICLES_PER_WORLD} particles per world (MAX_PARTICLES_PER_WORLD in "
                              "calibration/experiments/common.py; the paper fills hold 750 to 1800): give a smaller "
                              f"{setting}")
        total = _machine_memory()
        if total and memory > total:
            raise ConfigError(f"{self.name}: {given} in {worlds} world(s) needs about {memory / 1e9:.3g} GB "
                              f"({spheres:.3g} spheres per world at {BYTES_PER_SPHERE} bytes each); this machine "
                              f"has {total / 1e9:.3g} GB: give a smaller {setting} or fewer worlds per batch")
        return {"particles": particles, "spheres": spheres, "memory_bytes": memory}

    def _check_positive(self, *names: str) -> None:
        for n in names:
            v = getattr(self, n)
            if v is None or isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"{self.name}: {n} must be a positive finite number (SI units), got {v!r}"
                                  + _yaml_number_hint(v))

    def _check_nonnegative(self, *names: str) -> None:
        for n in names:
            v = getattr(self, n)
            if v is None or isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"{self.name}: {n} must be a finite number >= 0, got {v!r}")

    def _check_range(self, name: str, lo_hi_within: tuple[float, float] | None = None) -> None:
        v = getattr(self, name)
        if not (isinstance(v, tuple) and len(v) == 2 and all(math.isfinite(float(x)) for x in v) and v[1] > v[0]):
            raise ConfigError(f"{self.name}: {name} must be a pair (low, high) with low < high, got {v!r}")
        if lo_hi_within is not None and not (lo_hi_within[0] <= v[0] and v[1] <= lo_hi_within[1]):
            raise ConfigError(f"{self.name}: {name} {v} must lie within {lo_hi_within}")

    def settings(self) -> dict[str, Any]:
        """All settings as a JSON-able dict."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["material"] = self.bulk_material().describe()
        return _jsonable(d)

    def deviations_from_paper(self) -> dict[str, Any]:
        """Settings that differ from the paper-scale defaults (what makes a quick run quick)."""
        ref = type(self).from_config("paper")
        out = {}
        for f in dataclasses.fields(self):
            if f.name in ("scale", "material", "vtk_every", "vtk_world", "vtk_folder"):
                continue
            a, b = getattr(self, f.name), getattr(ref, f.name)
            if a != b:
                out[f.name] = {"value": _jsonable(a), "paper": _jsonable(b)}
        paper_label = ref.material.name if ref.material is not None else self.DEFAULT_MATERIAL_LABEL
        if self.material is not None and (ref.material is None or self.material != ref.material):
            out["material"] = {"value": self.material.name, "paper": paper_label}
        return out

    DEFAULT_MATERIAL_LABEL: ClassVar[str] = "gravel clumps (medium fill)"

    def vtk_directory(self) -> str:
        """Folder of the VTK time series (``vtk_folder``, or ``experiment_<name>_<scale>/vtk``)."""
        return self.vtk_folder or f"experiment_{self.name}_{self.scale}/vtk"

    def default_material(self) -> BulkMaterial:
        """Paper scale: the seed paper's gravel clump mix (medium fill, spec "Default material")."""
        return BulkMaterial.gravel("medium")

    def bulk_material(self) -> BulkMaterial:
        """``material``, or the default material (built once, not stored in ``material``)."""
        if self.material is not None:
            return self.material
        if getattr(self, "_default_material", None) is None:
            self._default_material = self.default_material()
        return self._default_material

    def shape_parameter_names(self) -> list[str]:
        """Shape parameters a parameter set may give (declared by the material's shape family)."""
        return list(getattr(self.bulk_material(), "shape_parameters", None) or {})

    @property
    def parameter_names(self) -> list[str]:
        """Every name a parameter set may hold: the law's contact parameters, then shape ones."""
        return [*self.contact_law.parameter_names, *self.shape_parameter_names()]

    # ------------------------------------------------------------------ hooks
    def fill_region(self):
        raise NotImplementedError

    def fill_amount(self, material: BulkMaterial) -> dict[str, float]:
        """``{"mass": kg}`` or ``{"n": count}`` for :func:`sample_particles`."""
        raise NotImplementedError

    def add_walls(self, builder: wd.ModelBuilder, fill_top: float, t_motion: float, material: BulkMaterial) -> None:
        """The walls, their motion starting at ``t_motion`` [s]; ``fill_top``: the highest a loose
        fill can reach [m] (:meth:`loose_top_bound`, not the fills drawn: walls are shared by the
        worlds of a batch)."""
        raise NotImplementedError

    def protocol(self, ctx: RunContext, t_motion: float) -> list[dict[str, Any]]:
        """Run the protocol; return per world ``{"angle": float, "fit": obj, "bulk_density": ...}``."""
        raise NotImplementedError

    # ------------------------------------------------------------------ run
    def fill_walls(self, builder: wd.ModelBuilder) -> None:
        """Static walls around a closed fill region, for :func:`~calibration.filling.pour_fill`."""
        raise NotImplementedError(f"{self.name}: no walls for a staged fill")

    def make_fill(self, material: BulkMaterial, rng: np.random.Generator, device: str | None = None) -> FillResult:
        """Loose fill (spec "Fill"); a closed region that one pass cannot hold is poured in stages."""
        sample = sample_particles(material, rng=rng, **self.fill_amount(material))
        region = self.fill_region()
        if self.fill_mode == "poured":
            plan = self.pour_plan(material)
            return poured_fill(region, plan.region, sample, plan.batch_volume, rng)
        if region.open_top:
            return random_fill(region, sample, rng)
        return pour_fill(region, sample, self.fill_walls, rng, device, self.ke_per_particle,
                         self.fill_settle_max_time, contact_law=self.contact_law)

    def fill_settle_times(self, fills: list[FillResult]) -> tuple[float, float]:
        """(min_time, max_time) [s] of the fill's settling: at least the free-fall time of the
        loose column's top; the spec's maximum is extended by it when the column stands above
        the walls' nominal height."""
        if self.fill_mode == "poured":  # as the LIGGGHTS decks: the fall from the insertion region's top
            t_fall = self.pour_plan(self.bulk_material()).t_fall
            return t_fall, self.fill_settle_max_time + t_fall
        floor = min(f.region.bounds[0][2] for f in fills)
        t_fall = max(math.sqrt(2.0 * max(f.top - floor, 0.0) / G) for f in fills)
        extra = t_fall if any(f.above_region for f in fills) else 0.0
        max_time = self.fill_settle_max_time + extra
        return min(t_fall, max_time), max_time

    def fill_settle_times_per_world(self, fills: list[FillResult], num_worlds: int) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`fill_settle_times` of each world's own fill (one fill shared, or one per world),
        so that a world's settling does not depend on the other worlds of its batch."""
        per = [self.fill_settle_times([fills[w if len(fills) > 1 else 0]]) for w in range(num_worlds)]
        return np.array([p[0] for p in per]), np.array([p[1] for p in per])

    def max_fill_mass(self, material: BulkMaterial) -> float:
        """The most mass [kg] one fill of ``material`` can hold: the fill mass and one heaviest
        particle (:func:`~calibration.materials.sample_particles` stops at the count closest to the
        mass), or the fill's count of the heaviest particles."""
        heaviest = (material.particle.density * math.pi / 6.0 * material.diameter[1] ** 3 if material.is_spheres
                    else max(float(t.mass) for t, _ in material.clumps))
        amount = self.fill_amount(material)
        return float(amount["mass"]) + heaviest if "mass" in amount else float(amount["n"]) * heaviest

    def loose_top_bound(self, material: BulkMaterial) -> float:
        """The highest top [m] a loose fill of these settings and ``material`` can reach, whatever
        a batch draws: a closed region's top; in an open one, the column of the most mass the fill
        can hold at :data:`LOOSE_SOLIDS_FRACTION_BOUND` over the region's floor, and one largest
        particle diameter, at least the region's top. The walls' height and the motion start
        follow it (the fills are checked against it: :meth:`check_fill_tops`)."""
        region = self.fill_region()
        lo, hi = region.bounds
        if self.fill_mode == "poured":  # the walls contain the insertion region
            return float(max(hi[2], self.pour_plan(material).top))
        if not region.open_top:
            return float(hi[2])
        area = (math.pi * region.radius ** 2 if hasattr(region, "radius")
                else float((hi[0] - lo[0]) * (hi[1] - lo[1])))
        column = self.max_fill_mass(material) / material.particle.density / (area * LOOSE_SOLIDS_FRACTION_BOUND)
        return float(max(hi[2], lo[2] + column + 2.0 * material.max_bounding_radius))

    def check_fill_tops(self, fills: list[FillResult], material: BulkMaterial) -> None:
        """Refuse (FillError) a fill whose loose column rises above :meth:`loose_top_bound`."""
        bound = self.loose_top_bound(material)
        for f in fills:
            if f.top > bound:
                raise FillError(f"{self.name}: a loose fill's column reaches {f.top:.3f} m, above the "
                                f"{bound:.3f} m the walls and the motion start are built for (its solids fraction "
                                f"{f.loose_solids_fraction:.3f} is below LOOSE_SOLIDS_FRACTION_BOUND = "
                                f"{LOOSE_SOLIDS_FRACTION_BOUND} in calibration/experiments/common.py): a wider "
                                "region or a smaller fill")

    def motion_start(self, material: BulkMaterial) -> float:
        """``t_motion`` [s]: the longest a fill of these settings and ``material`` may settle
        (``fill_settle_max_time``, and the free fall of :meth:`loose_top_bound` when that stands
        above the region; each world settles by its own fill, :meth:`fill_settle_times_per_world`),
        whatever fills a batch drew."""
        if self.fill_mode == "poured":
            plan = self.pour_plan(material)
            return plan.duration + self.fill_settle_max_time + plan.t_fall
        lo, hi = self.fill_region().bounds
        top = self.loose_top_bound(material)
        return self.fill_settle_max_time + (math.sqrt(2.0 * (top - lo[2]) / G) if top > hi[2] + 1e-12 else 0.0)

    def pour_plan(self, material: BulkMaterial) -> PourPlan:
        """The poured fill's schedule (``fill_mode: poured``), as the LIGGGHTS decks pour
        (validation/reference/liggghts_experiments.py): the insertion region
        (:func:`~calibration.filling.insertion_region` of the fill amount, inset from the walls by
        half the smallest radius (the decks' neighbour skin) and 1 mm); batches of
        ``pour_batch_fraction`` of its volume as solid, as many batch times as the most mass a fill
        can hold needs (:meth:`max_fill_mass`: the schedule follows the settings and the material,
        not the fill drawn); the interval is ``pour_interval`` (the decks' 0.1 s) or the free fall
        through the region's height if longer, so a batch released at rest has fallen out of the
        region before the next one is released."""
        region = self.fill_region()
        amount = self.fill_amount(material)
        density = material.particle.density
        mass = float(amount["mass"]) if "mass" in amount else float(amount["n"]) * material.mean_particle_mass
        inset = 0.5 * material.smallest_sphere[0] + 1.0e-3
        insert = insertion_region(region, mass / density, 2.0 * material.max_bounding_radius, inset)
        volume = region_volume(insert)
        batch_volume = float(self.pour_batch_fraction) * volume
        batches = max(1, int(math.ceil(self.max_fill_mass(material) / density / batch_volume)))
        lo, hi = insert.bounds
        floor = float(region.bounds[0][2])
        interval = max(float(self.pour_interval), math.sqrt(2.0 * float(hi[2] - lo[2]) / G))
        return PourPlan(insert, volume, batch_volume, batches, interval, float(hi[2]), floor,
                        math.sqrt(2.0 * (float(hi[2]) - floor) / G))

    def settle_fill(self, ctx: RunContext, remove_box=None):
        """The fill phase of a protocol: pour (``fill_mode: poured``, :meth:`pour`), then settle
        (spec "Fill": KE per particle below ``ke_per_particle``, :meth:`fill_settle_times_per_world`)."""
        if self.fill_mode == "poured":
            self.pour(ctx, remove_box)
        t_min, t_max = self.fill_settle_times_per_world(ctx.fills, ctx.num_worlds)
        return ctx.settle("fill_settle", t_max, t_min, remove_box)

    def pour(self, ctx: RunContext, remove_box=None) -> None:
        """Pour a poured fill: batch 0 falls from the start, the others wait out of play
        (inactive, above the region); after each interval every waiting particle of the batches
        due is inserted at rest where it overlaps none in play
        (:func:`~calibration.filling.release_batches`), the rest waits for the next batch time.
        Every world on the same clock (:meth:`pour_plan`); the particles still waiting after the
        last batch time stay out (as LIGGGHTS leaves what its overlap check refuses), counted in
        ``pour_not_inserted``."""
        plan = self.pour_plan(self.bulk_material())
        nw, model = ctx.num_worlds, ctx.model
        fills = [ctx.fill(w) for w in range(nw)]
        most = max(int(f.batch.max()) + 1 for f in fills)
        if most > plan.batches:  # e.g. a world's shape parameters made a heavier material
            raise FillError(f"{self.name}: a poured fill has {most} insertion batches, the schedule "
                            f"{plan.batches} (from the experiment's material): pour worlds of one material")
        ids = np.concatenate([fill_body_ids(model, w, f.sample) for w, f in enumerate(fills)])
        batch = np.concatenate([f.batch for f in fills])
        drop = np.concatenate([f.batch * f.batch_stride for f in fills])
        world = model.host["body_world"][ids]
        q0 = model.initial["body_q"][ids]
        ctx.once("pour_hold", lambda: hold_batches(ctx.sim, ids[batch > 0]))

        def release(k: int) -> list[list[int]]:
            q = ctx.sim.state.body_q.numpy()[ids]
            waiting = (ctx.sim.state.body_active.numpy()[ids] == 0) & np.all(q == q0, axis=1) & (batch > 0)
            due = np.nonzero(waiting & (batch <= k))[0]
            done = release_batches(ctx.sim, ids[due], drop[due])
            left = waiting.copy()
            left[due[done]] = False
            return [[int(np.count_nonzero(world[due[done]] == w)), int(np.count_nonzero(left & (world == w)))]
                    for w in range(nw)]

        counts = [[0, 0] for _ in range(nw)]
        for k in range(1, plan.batches + 1):
            ctx.advance("pour", plan.interval, remove_box)
            counts = ctx.once("pour_release", lambda k=k: release(k))
        for w in range(nw):
            ctx.diag[w].update(pour_batches=int(fills[w].batch.max()) + 1, pour_batch_times=plan.batches,
                               pour_interval_s=plan.interval, pour_region_top_m=plan.top,
                               pour_not_inserted=int(counts[w][1]))

    def _run_in_processes(self, parameter_sets: list, device: str | None, nproc: int,
                          checkpoints: BatchCheckpoints | None = None,
                          executor: RayExecutor | None = None) -> list[ExperimentResult]:
        """:meth:`run` with the worlds split into ``nproc`` contiguous chunks, one local process each,
        or one Ray task each when ``executor`` is given (each chunk checkpoints into its own slot)."""
        import concurrent.futures
        import multiprocessing

        wall0 = time.perf_counter()
        bounds = np.linspace(0, len(parameter_sets), nproc + 1).round().astype(int)
        chunks = [(int(a), parameter_sets[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]
        if executor is not None:
            on_gpu = str(device or "").startswith("cuda")
            parts = executor.map(_run_chunk_on_ray, [(self, sets, device, start, checkpoints)
                                                     for start, sets in chunks], on_gpu)
        else:
            ctx = multiprocessing.get_context("spawn")  # a clean interpreter: no inherited Warp/CUDA state
            # the workers import the user's sub-model modules before they unpickle the experiment
            with concurrent.futures.ProcessPoolExecutor(max_workers=nproc, mp_context=ctx,
                                                        initializer=_load_worker_plugins,
                                                        initargs=(tuple(self.plugins),)) as pool:
                futures = [pool.submit(_run_chunk, self, sets, device, start, checkpoints) for start, sets in chunks]
                parts = [f.result() for f in futures]
        wall = round(time.perf_counter() - wall0, 3)
        results = []
        for (start, _), part in zip(chunks, parts):
            for r in part:
                r.world += start
                r.timing = {**r.timing, "processes" if executor is None else "ray_tasks": nproc,
                            "chunk_first_world": start,
                            "chunk_wall_s": r.timing["wall_s"], "wall_s": wall, "worlds": len(parameter_sets),
                            "note": "timing of this world's chunk (one process); wall_s: the whole run"}
                results.append(r)
        return results

    def _build_model(self, law: wd.ContactLaw, material: BulkMaterial, fills: list[FillResult],
                     sets: list[dict[str, float]], defaults: dict[str, float], t_motion: float, device: str | None,
                     max_contacts: int, max_neighbours: int | None, materials: Sequence[BulkMaterial] | None = None):
        """Model (one world per parameter set), its Simulation, the time step and its limits."""
        nw = len(sets)
        builder = wd.ModelBuilder(num_worlds=nw, contact_law=law, max_contacts=max_contacts)
        builder.add_material(material.particle)
        if self.wall_material.name != material.particle.name:
            builder.add_material(self.wall_material)
        for w in range(nw):
            add_fill(builder, fills[w if len(fills) > 1 else 0], material.particle.name, w)
        self.add_walls(builder, self.loose_top_bound(material), t_motion, material)
        if defaults:
            builder.set_contact_parameters(**defaults)
        for w, ps in enumerate(sets):
            if ps:
                builder.set_contact_parameters(world=w, **ps)
        # a settled (poured) fill starts with its contacts' small Hertz overlaps: check leniently
        model = builder.finalize(device, overlap_tolerance=1.0 if any(f.settled for f in fills) else 0.05)
        # the step follows the materials' smallest possible sphere, not the smallest one these fills
        # drew: a world's step (and so its result) does not depend on the worlds it shares a batch
        # with, whatever the split over processes or Ray tasks (worlds of different shape parameters
        # are different materials: their batch takes the smallest of its materials)
        # (clumps: a template's members, which a fill may scale within its size class, so the model's
        # own limit still caps the step; spheres never draw below the distribution's lower end)
        kinds = {_material_key(m): m for m in (materials or [material])}
        by_material = wd.time_step_limits_for([(m.particle, *m.smallest_sphere) for m in kinds.values()], self.v_ref)
        drawn = wd.time_step_limits(model, self.v_ref)
        limits = by_material if by_material.recommended <= drawn.recommended else drawn
        if self.dt is not None:
            dt = self.dt
        elif self.dt_rayleigh_fraction is not None:
            dt = min(float(self.dt_rayleigh_fraction) * limits.rayleigh, limits.limit)
        else:
            dt = limits.recommended
        sim = wd.Simulation(model, dt, v_ref=self.v_ref, force=self.force_dt, max_neighbours=max_neighbours)
        return model, sim, dt, limits

    def run(self, parameter_sets: Sequence[Mapping[str, float]] | Mapping[str, Any], device: str | None = None,
            progress: bool = False, processes: int | str | None = 1,
            checkpoints: BatchCheckpoints | None = None,
            executor: LocalExecutor | RayExecutor | None = None) -> list[ExperimentResult]:
        """Run the experiment, one world per parameter set (contact parameters by the model's
        names, e.g. ``mu_s_pp``); returns one :class:`ExperimentResult` per world, in order.

        processes: on the CPU, split the worlds over this many processes ("auto": one per
        usable core). Warp runs CPU kernels on one thread, so this is how a CPU run uses several
        cores. Every world keeps its fill and parameters and gives the same results in any split:
        settled worlds wait at rest, and the time step, the walls' height and the motion start follow
        the settings and the material, not the fills a chunk drew (module docstring, "Batches").
        Ignored on CUDA, where one launch already runs every world. Scripts that use
        processes > 1 need the ``if __name__ == "__main__":`` guard (spawned interpreters).

        checkpoints: save the batch's simulation into ``checkpoints.folder`` while it runs and
        continue a saved one of this very batch (:class:`BatchCheckpoints`; module docstring).
        What was resumed, saves, their time [s] and size [bytes] are in ``timing["checkpoint"]``;
        the checkpoint is removed when the results are returned (unless
        ``keep_until_recorded``). Not with ``vtk_every`` (a VTK series is not resumable).

        executor: where the batches run (:mod:`calibration.executor`); a :class:`LocalExecutor`
        replaces ``processes`` by its own, a :class:`RayExecutor` splits the worlds into Ray tasks."""
        if isinstance(executor, LocalExecutor):
            processes, executor = executor.processes, None
        n_sets = len(parameter_sets) if isinstance(parameter_sets, Sequence) else 1
        self.check_size(n_sets)  # a fill the machine cannot hold is refused before any DEM
        ck = checkpoints if self.vtk_every is None else None
        on_gpu = str(device if device is not None else _preferred_device()).startswith("cuda")
        nproc = executor.task_count(n_sets, on_gpu) if executor is not None else cpu_processes(processes, device)
        if (nproc > 1 or executor is not None) and n_sets > 1 and self.vtk_every is None:
            inner = dataclasses.replace(ck, keep_until_recorded=True) if ck is not None else None
            results = self._run_in_processes(list(parameter_sets), device if device is not None or not on_gpu
                                             else "cuda", min(nproc, n_sets), inner, executor)
        else:
            results = self._run(parameter_sets, device, progress, ck)
        if ck is not None and not ck.keep_until_recorded:
            for slot in {(r.timing.get("checkpoint") or {}).get("slot") for r in results} - {None}:
                for f in ck.folder.glob(f"{slot}.*"):
                    f.unlink(missing_ok=True)
        return results

    def checkpoint_identity(self) -> dict[str, Any]:
        """What, besides the settings and parameter sets, makes a batch this batch (override:
        e.g. the drum's per-world speeds)."""
        return {}

    def _run(self, parameter_sets: Sequence[Mapping[str, float]] | Mapping[str, Any], device: str | None,
             progress: bool, checkpoints: BatchCheckpoints | None = None) -> list[ExperimentResult]:
        """:meth:`run` in this process: the batch's worlds and fills, its checkpoint, the protocol
        (run again with more slots after a contact overflow), one result per world."""
        wall0 = time.perf_counter()
        batch = self._batch_setup(parameter_sets, device)
        checkpoint, saved = self._open_checkpoint(batch, checkpoints)
        run = self._simulate_batch(batch, device, progress, checkpoint, saved, wall0)
        timing = self._batch_timing(batch, run, checkpoint, wall0)
        protocol = self._protocol_record(batch)
        results = [self._world_result(batch, run, w, timing, protocol) for w in range(batch.num_worlds)]
        run.ctx.log("done: " + ", ".join(f"w{r.world}={r.angle_deg:.2f}" if r.ok else f"w{r.world}=failed"
                                         for r in results))
        return results

    def _batch_setup(self, parameter_sets: Sequence[Mapping[str, float]] | Mapping[str, Any],
                     device: str | None) -> _BatchSetup:
        """The batch before its model is built: parameter sets split into contact and shape
        parameters, each world's material, the fills (checked against the walls' height), the
        motion start [s] and the slots per sphere to start with."""
        law = self.contact_law
        material = self.bulk_material()
        shape_names = list(self.shape_parameter_names())
        sets = normalize_parameter_sets(parameter_sets, [*law.parameter_names, *shape_names])
        defaults = normalize_parameter_sets([self.contact_defaults], law.parameter_names)[0]
        # shape parameters make a material per world; contact parameters go to the builder
        shapes = [{k: s.pop(k) for k in shape_names if k in s} for s in sets]
        materials = [material.with_shape_parameters(**sh) if sh else material for sh in shapes]
        fills = self._batch_fills(material, materials, device)
        self.check_fill_tops(fills, material)
        t_motion = self.motion_start(material)
        return _BatchSetup(law=law, material=material, sets=sets, defaults=defaults, shapes=shapes,
                           materials=materials, fills=fills, t_motion=t_motion,
                           max_contacts=max(int(self.max_contacts), _contact_slots(materials)),
                           max_neighbours=self.max_neighbours)

    def _batch_fills(self, material: BulkMaterial, materials: list[BulkMaterial],
                     device: str | None) -> list[FillResult]:
        """The batch's fills: one per world (``fill_per_world``, or worlds of different
        materials), else one that every world shares."""
        per_world = self.fill_per_world or len(set(map(_material_key, materials))) > 1
        if per_world:
            # a world's own fill: index first_fill_index + w (fill_per_world), else the shared seed
            return [self.make_fill(materials[w], np.random.default_rng(
                [self.seed, self.first_fill_index + w] if self.fill_per_world else self.seed), device)
                for w in range(len(materials))]
        return [self.make_fill(material, np.random.default_rng(self.seed), device)]

    def _open_checkpoint(self, batch: _BatchSetup, checkpoints: BatchCheckpoints | None
                         ) -> tuple[BatchCheckpoint | None, dict[str, Any] | None]:
        """The batch's checkpoint (None without ``checkpoints`` or with ``vtk_every``) and what it
        saved (None if nothing); a saved run's slot capacities and retries go into ``batch``."""
        if checkpoints is None or self.vtk_every is not None:
            return None, None
        checkpoint = BatchCheckpoint(checkpoints, self, {
            "parameter_sets": [{**a, **b} for a, b in zip(batch.sets, batch.shapes)],
            "contact_defaults": batch.defaults, **self.checkpoint_identity()})
        saved = checkpoint.read()
        if saved is not None:  # the slot capacities the saved run had grown to
            batch.max_contacts = int(saved["capacities"]["max_contacts"])
            batch.max_neighbours = saved["capacities"]["max_neighbours"]
            batch.retries = list(saved.get("retries") or [])
        return checkpoint, saved

    def _simulate_batch(self, batch: _BatchSetup, device: str | None, progress: bool,
                        checkpoint: BatchCheckpoint | None, saved: dict[str, Any] | None,
                        wall0: float) -> _BatchRun:
        """Build the model, continue the saved run if any, and run the protocol; after a contact
        slot overflow, again from the same fill with more slots (at most ``overflow_retries``
        times). ``wall0``: :func:`time.perf_counter` at the start of the run [s]."""
        build_s = None  # the build of this sitting's first attempt [s] (a resumed batch may have grown slots before)
        while True:
            model, sim, dt, limits = self._build_model(batch.law, batch.material, batch.fills, batch.sets,
                                                       batch.defaults, batch.t_motion, device, batch.max_contacts,
                                                       batch.max_neighbours, batch.materials)
            sim, resume = self._resume_saved(checkpoint, saved, model, device, sim)
            saved = None
            steps_before = int(sim.steps)
            # an unstable world is frozen and failed alone; the others of the batch run on
            sim.on_unstable = "freeze"
            ctx = self._run_context(batch, model, sim, dt, limits, progress, checkpoint, resume)
            if build_s is None:
                build_s = time.perf_counter() - wall0
            sim0 = time.perf_counter()
            outcome, fatal, again = self._run_protocol(batch, ctx, sim, sim0)
            if not again:
                break
        sim_s = time.perf_counter() - sim0
        return _BatchRun(model=model, sim=sim, dt=dt, limits=limits, ctx=ctx, outcome=outcome, fatal=fatal,
                         steps_before=steps_before, build_s=build_s, simulate_s=sim_s, unstable=sim.failed_worlds())

    def _resume_saved(self, checkpoint: BatchCheckpoint | None, saved: dict[str, Any] | None, model: wd.Model,
                      device: str | None, sim: wd.Simulation) -> tuple[wd.Simulation, dict[str, Any] | None]:
        """The simulation to run (the saved one, loaded into ``model``, where it matches) and the
        saved protocol state to resume (None: start the protocol from the beginning)."""
        if saved is None:
            return sim, None
        loaded = checkpoint.load(saved, model, device, sim.solver.max_neighbours)
        if loaded is None:
            return sim, None
        sim, resume = loaded, saved["protocol"]
        checkpoint.resumed = {"step": int(sim.steps), "time_s": round(sim.time, 9),
                              "protocol_step": len(resume["done"]),
                              "in_step": decode_value(resume["inner"])["label"] if resume.get("inner") else None}
        checkpoint.note(f"{checkpoint.slot}: continuing from step {sim.steps} (t = {sim.time:.3f} s, "
                        f"{len(resume['done'])} protocol step(s) done)")
        return sim, resume

    def _run_context(self, batch: _BatchSetup, model: wd.Model, sim: wd.Simulation, dt: float,
                     limits: TimeStepLimits, progress: bool, checkpoint: BatchCheckpoint | None,
                     resume: dict[str, Any] | None) -> RunContext:
        """The protocol's :class:`RunContext` for one attempt, which logs the batch's size and its
        time step ``dt`` [s] against the stability limit."""
        ctx = RunContext(self, sim, batch.fills, progress, checkpoint=checkpoint, resume=resume,
                         capacities={"max_contacts": batch.max_contacts, "max_neighbours": batch.max_neighbours},
                         retries=batch.retries)
        ctx.log(f"{batch.num_worlds} world(s), {model.num_bodies} bodies, {model.num_spheres} spheres, "
                f"dt={dt:.3g} s (limit {limits.limit:.3g} s)")
        return ctx

    def _run_protocol(self, batch: _BatchSetup, ctx: RunContext, sim: wd.Simulation,
                      sim0: float) -> tuple[list[dict[str, Any]], str | None, bool]:
        """Run the protocol once: (one outcome per world, the error that ended the whole batch or
        None, whether to run again after a contact slot overflow). ``sim0``:
        :func:`time.perf_counter` when the attempt began [s]."""
        outcome: list[dict[str, Any]] = [dict() for _ in range(batch.num_worlds)]
        fatal = None
        try:
            outcome = self.protocol(ctx, batch.t_motion)
            self._end_protocol(ctx)
        except ContactOverflowError as exc:
            fatal = f"{type(exc).__name__}: {exc}"
            if len(batch.retries) < int(self.overflow_retries):
                self._grow_slots(batch, ctx, sim, exc, sim0)
                return outcome, fatal, True
        except StabilityError as exc:
            fatal = f"{type(exc).__name__}: {exc}"
        return outcome, fatal, False

    def _end_protocol(self, ctx: RunContext) -> None:
        """After the protocol: refuse a resumed run whose protocol ran fewer steps than its
        checkpoint recorded; save the final checkpoint (unless a finished one was loaded as it is)."""
        if ctx._resume is not None and ctx._n_steps < len(ctx._done):
            raise RuntimeError(f"{self.name}: the protocol ran {ctx._n_steps} steps, its checkpoint "
                               f"recorded {len(ctx._done)}")
        if ctx._resume is None:  # the end (unless a finished checkpoint was loaded as it is)
            ctx.save_checkpoint(None)

    def _grow_slots(self, batch: _BatchSetup, ctx: RunContext, sim: wd.Simulation, exc: ContactOverflowError,
                    sim0: float) -> None:
        """More contact or neighbour slots per sphere after ``exc`` (1.5 x, neighbours at least
        1.25 x what the overflow needed), the retry recorded in ``batch.retries`` with the
        wall time it wasted [s] since ``sim0`` (:func:`time.perf_counter`)."""
        # slots are sized before the run; a denser packing than expected is not an
        # error of the user's: run again from the same fill with room to spare
        if exc.kind == "neighbours":
            old = sim.solver.max_neighbours
            batch.max_neighbours = max(int(math.ceil(1.25 * (exc.needed or 0))), int(math.ceil(1.5 * old)))
            new = batch.max_neighbours
        else:
            old = batch.max_contacts
            batch.max_contacts = new = int(math.ceil(1.5 * batch.max_contacts))
        batch.retries.append(dict(kind=exc.kind, capacity=old, needed=exc.needed, rerun_with=new,
                                  wasted_s=round(time.perf_counter() - sim0, 3)))
        ctx.log(f"{exc.kind} slots overflowed ({exc}); running again with {new} slots per sphere")

    def _batch_timing(self, batch: _BatchSetup, run: _BatchRun, checkpoint: BatchCheckpoint | None,
                      wall0: float) -> dict[str, Any]:
        """The ``timing`` every world's result carries: wall, build and simulation times [s],
        steps, the step [s], simulated phases [s], sizes, capacities, retries and the checkpoint."""
        model, sim, ctx, nw = run.model, run.sim, run.ctx, batch.num_worlds
        timing = {"wall_s": round(time.perf_counter() - wall0, 3), "build_s": round(run.build_s, 3),
                  "simulate_s": round(run.simulate_s, 3), "steps": int(sim.steps),
                  "steps_this_run": int(sim.steps) - run.steps_before, "dt_s": run.dt,
                  "simulated_s": round(sum(ctx.phases.values()), 6),
                  "phases_s": {k: round(v, 6) for k, v in ctx.phases.items()},
                  "worlds": nw, "spheres": int(model.num_spheres), "bodies": int(model.num_bodies),
                  "spheres_per_world": int(model.num_spheres // nw), "device": str(model.device),
                  "max_contacts": int(model.max_contacts), "max_neighbours": int(sim.solver.max_neighbours),
                  "retries": batch.retries,
                  "note": "timing is for the whole run (all worlds together, retries included)"}
        if checkpoint is not None:
            timing["checkpoint"] = checkpoint.summary()
        return timing

    def _protocol_record(self, batch: _BatchSetup) -> dict[str, Any]:
        """The ``protocol`` every world's result carries: scale, settings, deviations from the
        paper, contact law, material, motion start [s] and the fill (mass [kg], tops [m])."""
        fills, material = batch.fills, batch.material
        return {"scale": self.scale, "settings": self.settings(), "deviations_from_paper": self.deviations_from_paper(),
                "contact_law": batch.law.describe(), "material": material.describe(),
                "t_motion_start_s": batch.t_motion,
                "fill": {"particles_per_world": int(fills[0].sample.n),
                         "mass_per_world_kg": round(fills[0].sample.total_mass, 6),
                         "loose_top_m": round(max(f.top for f in fills), 6),
                         "loose_top_bound_m": round(self.loose_top_bound(material), 6),
                         "above_region": bool(any(f.above_region for f in fills)),
                         "pours": int(max(f.pours for f in fills))}}

    def _world_result(self, batch: _BatchSetup, run: _BatchRun, w: int, timing: dict[str, Any],
                      protocol: dict[str, Any]) -> ExperimentResult:
        """World ``w``'s result: its parameters, the model's contact parameters, what the protocol
        measured, and its failure (the batch's, an unstable world, a failed measurement, no angle)."""
        model = run.model
        cp = {n: float(model.get_contact_parameter(n)[w]) for n in model.parameter_names}
        r = ExperimentResult(self.name, self.scale, w, {**batch.sets[w], **batch.shapes[w]}, cp,
                             angle_name=self.angle_name, diagnostics=run.ctx.diag[w], timing=timing, protocol=protocol)
        o = run.outcome[w] if w < len(run.outcome) else {}
        r.fit = o.get("fit")
        r.particles = o.get("particles")
        r.bulk_density = o.get("bulk_density")
        self._judge_world(r, o, run, w)
        return r

    def _judge_world(self, r: ExperimentResult, o: Mapping[str, Any], run: _BatchRun, w: int) -> None:
        """Fail world ``w``'s result ``r`` with the first cause that applies, else set its angle
        [deg] and observables from the protocol's outcome ``o``."""
        if run.fatal is not None:
            r.fail(run.fatal)
        elif w in run.unstable:
            r.fail(f"unstable world ({run.unstable[w]}): frozen by the engine, its measurement is void")
        elif run.ctx.errors[w] is not None:
            r.fail(run.ctx.errors[w])
            # what was measured before the failed measurement stays (A: the fill's bulk density
            # when no angle could be measured after the lift); the failed quantity is None
            partial = {k: v for k, v in (o.get("observables") or {}).items() if v is not None}
            if partial:
                r.observables = {**{k: None for k in self.OBSERVABLES},
                                 **{k: float(v) for k, v in partial.items()}}
        elif o.get("angle") is None or not math.isfinite(o["angle"]):
            r.fail("no angle was measured")
        else:
            r.angle_deg = float(o["angle"])
            obs = {k: None for k in self.OBSERVABLES}
            if self.OBSERVABLES:
                obs[next(iter(self.OBSERVABLES))] = r.angle_deg
            obs.update(o.get("observables") or {})
            r.observables = {k: (None if v is None else float(v)) for k, v in obs.items()}


@dataclass
class _BatchSetup:
    """One batch of :meth:`Experiment._run` before its model is built: the contact law, the
    experiment's material and each world's (shape parameters make a world's own), the contact
    parameters per world and the defaults (by the law's names), the shape parameters per world,
    the fills (one shared or one per world), the motion start ``t_motion`` [s], and the contact
    and neighbour slots per sphere with the overflow retries so far (they grow after an overflow
    and are restored from a checkpoint)."""

    law: wd.ContactLaw
    material: BulkMaterial
    sets: list[dict[str, float]]
    defaults: dict[str, float]
    shapes: list[dict[str, float]]
    materials: list[BulkMaterial]
    fills: list[FillResult]
    t_motion: float
    max_contacts: int
    max_neighbours: int | None
    retries: list[dict[str, Any]] = field(default_factory=list)

    @property
    def num_worlds(self) -> int:
        """Worlds of the batch (one per parameter set)."""
        return len(self.sets)


@dataclass
class _BatchRun:
    """The batch's last (or only) attempt of :meth:`Experiment._simulate_batch`: its model,
    simulation, time step [s] and limits, the protocol's context and per-world outcome, the error
    that ended the whole batch (None if none), the steps done before this sitting, the build and
    simulation wall times [s], and the worlds the engine froze as unstable ({world: cause})."""

    model: wd.Model
    sim: wd.Simulation
    dt: float
    limits: TimeStepLimits
    ctx: RunContext
    outcome: list[dict[str, Any]]
    fatal: str | None
    steps_before: int
    build_s: float
    simulate_s: float
    unstable: dict[int, str]


def _contact_slots(materials: Sequence[BulkMaterial]) -> int:
    """Contact slots per sphere a batch's materials need at the start: a member sphere of a clump can
    touch every member of each neighbouring clump, so clumps of n members get 16 + 8 (n - 1) (rods
    close to a sphere, whose members nearly coincide, overflowed 36 slots), at most
    :data:`MAX_START_CONTACT_SLOTS`: the paper's 22-25-member gravel asked 208 slots and 8 x 208
    neighbour slots per sphere, 2.5e9 list entries for a batch of 37 worlds (past Warp's 2^31 array
    limit and ~10 GB). A batch that needs more overflows and runs again with 1.5 x the slots
    (``overflow_retries``)."""
    n = max((len(t.radii) for m in materials for t, _ in (m.clumps or ())), default=1)
    return min(16 + 8 * (n - 1), MAX_START_CONTACT_SLOTS)


#: the most contact slots per sphere a batch starts with (more only after an overflow)
MAX_START_CONTACT_SLOTS = 64


def _material_key(m: BulkMaterial) -> Any:
    """Identity of a material's particle description (materials equal by value compare equal)."""
    try:
        return hash(m)
    except TypeError:
        return id(m)


def _yaml_number_hint(value: Any) -> str:
    """A hint for a number that YAML read as text (``1.0e6``: YAML 1.1 needs ``1.0e+6``)."""
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return ""
        return " (text, not a number: YAML reads 1.0e6 as text; write 1.0e+6 or 1000000.0)"
    return ""


def _machine_memory() -> int | None:
    """Physical memory of this machine [bytes] (None where the platform does not say)."""
    return machine_memory()


def cpu_processes(processes: int | str | None, device: str | None) -> int:
    """Processes a CPU run uses: 1 on CUDA or when None; "auto" = usable cores."""
    import warp as wp

    if processes is None:
        return 1
    dev = str(device) if device is not None else str(wp.get_preferred_device())
    if processes == "auto":
        n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    else:
        try:
            n = int(processes)
        except (TypeError, ValueError):
            raise ConfigError(f"processes must be a positive integer or 'auto', got {processes!r}") from None
        if n < 1:
            raise ConfigError(f"processes must be >= 1 or 'auto', got {processes}")
    return 1 if str(dev).startswith("cuda") else n


def die_with_parent() -> None:
    """Linux: ask the kernel to kill this process when its parent dies (``kill -9`` of a campaign
    must not leave orphaned pool workers holding memory). A no-op elsewhere."""
    import ctypes
    import signal

    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
        except OSError:
            pass


def _load_worker_plugins(plugins: tuple[str, ...]) -> None:
    """Pool initializer: die with the parent; import the plugin modules a contact law names."""
    die_with_parent()
    if plugins:
        from ..model_description import load_plugins

        load_plugins(list(plugins))


def _preferred_device() -> str:
    import warp as wp

    return str(wp.get_preferred_device())


def _run_chunk_on_ray(exp: Experiment, parameter_sets: list, device: str | None, first_world: int,
                      checkpoints: BatchCheckpoints | None = None) -> list[ExperimentResult]:
    """A Ray task of :meth:`Experiment._run_in_processes`: load the law's plugins, run the chunk."""
    if exp.plugins:
        from ..model_description import load_plugins

        load_plugins(list(exp.plugins))
    return _run_chunk(exp, parameter_sets, device, first_world, checkpoints)


def _run_chunk(exp: Experiment, parameter_sets: list, device: str | None, first_world: int,
               checkpoints: BatchCheckpoints | None = None) -> list[ExperimentResult]:
    """Worker of :meth:`Experiment._run_in_processes`: worlds ``first_world ...`` of a run."""
    from warpdem.warp_output import quiet_warp

    quiet_warp()
    part = dataclasses.replace(exp, first_fill_index=exp.first_fill_index + first_world)
    return part.run(parameter_sets, device=device, progress=False, processes=1, checkpoints=checkpoints)
