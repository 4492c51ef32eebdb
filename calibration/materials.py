"""Bulk materials of the standard experiments (docs/experiments.md,
"Default material"): plain spheres with a diameter distribution, a number-fraction mix
of multi-sphere clump templates (seed paper Tables 2-3), or a shape family
(:mod:`warpdem.shape_families`, e.g. ``elongated`` with a continuous ``aspect_ratio``) over
a volume-equivalent diameter distribution, plus the particle's elastic :class:`warpdem.Material`.

Shape parameters are calibrated like contact parameters: ``material.shape_parameters``
declares them (unit, default, admissible bounds) and ``material.with_shape_parameters(...)``
gives the same size distribution with another shape, e.g. one material per world.

``sample_particles(material, n=... | mass=..., rng)`` draws the particles to add to a model;
positions come from :mod:`calibration.filling`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np

from warpdem import GRAVEL, ConfigError, Material
from warpdem.contact import ParameterSpec

__all__ = ["BulkMaterial", "ParticleShape", "ParticleSample", "sample_particles", "scale_template",
           "equal_number_size_classes"]


def diameter_range(value: Any, what: str, note: str = "") -> tuple[float, float]:
    """``d`` or ``(d_min, d_max)`` [m] as ``(d_min, d_max)``; a clear ConfigError naming ``what``
    for anything else (non-finite, d_min > d_max, or values that look like millimetres)."""
    try:
        d = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    except (TypeError, ValueError):
        d = np.zeros(0)
    if d.size == 1:
        d = np.array([d[0], d[0]])
    if d.size != 2 or not np.all(np.isfinite(d)) or d[0] <= 0 or d[1] < d[0]:
        raise ConfigError(f"{what}: diameter must be d > 0 m or (d_min, d_max) with 0 < d_min <= d_max [m]{note}, "
                          f"got {value!r}")
    if d[1] > 1.0:
        raise ConfigError(f"{what}: diameter {d[1]} m looks like millimetres; give metres")
    return float(d[0]), float(d[1])


def scale_template(template, factor: float):
    """A clump template with every length multiplied by ``factor`` (same density):
    volume and mass scale with factor^3, principal inertia with factor^5."""
    from warpdem.clump_geometry import ClumpTemplate

    f = float(factor)
    if not (f > 0 and math.isfinite(f)):
        raise ConfigError(f"clump size_scale must be > 0, got {factor}")
    if f == 1.0:
        return template
    return ClumpTemplate(template.name, np.asarray(template.centers) * f, np.asarray(template.radii) * f,
                         template.density, template.volume * f**3, template.mass * f**3,
                         np.asarray(template.inertia_principal) * f**5, template.rotation,
                         np.asarray(template.offset) * f, template.volume_error * f**3)


def equal_number_size_classes(d_min: float, d_max: float, size_classes: int) -> tuple[float, ...]:
    """Representative diameters [m] of ``size_classes`` equal-number classes of a diameter
    distribution uniform by number in [d_min, d_max] [m]: class k spans
    [d_min + k w, d_min + (k + 1) w], w = (d_max - d_min) / size_classes, and is represented by
    its mean-volume diameter cbrt(mean d^3) = cbrt((hi^4 - lo^4) / (4 (hi - lo))), so the
    classes (equal number fractions) keep the distribution's mean particle volume exactly.
    One class when d_min == d_max."""
    if d_max == d_min:
        return (float(d_min),)
    edges = np.linspace(d_min, d_max, int(size_classes) + 1)
    lo, hi = edges[:-1], edges[1:]
    return tuple(float(x) for x in np.cbrt((hi**4 - lo**4) / (4.0 * (hi - lo))))


@dataclass(frozen=True)
class ParticleShape:
    """A shape family at fixed parameter values over a volume-equivalent size distribution.

    Attributes:
        family: registered :mod:`warpdem.shape_families` name (e.g. ``"elongated"``).
        values: ((name, value), ...) of every declared parameter (defaults filled in), sorted.
        diameter: (d_min, d_max) [m]: volume-equivalent diameters, uniform by number.
        size_classes: equal-number size classes, one clump template each
            (:func:`equal_number_size_classes`).
    """

    family: str
    values: tuple[tuple[str, float], ...]
    diameter: tuple[float, float]
    size_classes: int = 5

    def __post_init__(self) -> None:
        from warpdem.shape_families import shape_family

        fam = shape_family(self.family)
        object.__setattr__(self, "values", tuple(sorted(fam.check_parameters(**dict(self.values)).items())))
        object.__setattr__(self, "diameter", diameter_range(self.diameter, f"shape '{self.family}'",
                                                            " (volume-equivalent)"))
        k = self.size_classes
        if isinstance(k, bool) or int(k) != k or int(k) < 1:
            raise ConfigError(f"shape '{self.family}': size_classes must be a positive integer, got {k!r}")
        object.__setattr__(self, "size_classes", int(k))

    @property
    def parameters(self) -> dict[str, float]:
        """Parameter values by name."""
        return dict(self.values)

    @property
    def class_diameters(self) -> tuple[float, ...]:
        """Volume-equivalent diameter [m] of each size class (equal number fractions)."""
        return equal_number_size_classes(*self.diameter, self.size_classes)

    def templates(self, density: float) -> tuple[Any, ...]:
        """One clump template per size class at ``density`` [kg/m^3]."""
        from warpdem.shape_families import shape_family

        fam = shape_family(self.family)
        return tuple(fam.template(d, density, **self.parameters) for d in self.class_diameters)

    def label(self) -> str:
        a, b = self.diameter
        sizes = f"{a * 1e3:g} mm" if a == b else f"{a * 1e3:g}-{b * 1e3:g} mm"
        pars = ", ".join(f"{k}={v:g}" for k, v in self.values)
        return f"{self.family} ({pars}) d_eq={sizes}"

    def record(self) -> dict[str, Any]:
        """Config-like JSON-able record: ``{type: shaped, shape, <parameters>, diameter, size_classes}``."""
        return {"type": "shaped", "shape": self.family, **self.parameters, "diameter": list(self.diameter),
                "size_classes": self.size_classes}


@dataclass(frozen=True)
class BulkMaterial:
    """A granular material: particle shape/size description and elastic solid.

    Exactly one of:
        diameter: (d_min, d_max) [m]; sphere diameters uniform by number in [d_min, d_max]
            (d_min == d_max: one size).
        clumps: ((template, number fraction), ...) of clump templates
            (``warpdem.clump_geometry.ClumpTemplate``); fractions are normalised to 1.
        shape: a :class:`ParticleShape` (shape family + parameters + volume-equivalent size
            distribution); ``clumps`` is then derived from it (one template per size class,
            equal number fractions) and any ``clumps`` passed in is replaced.
    Attributes:
        particle: elastic properties and density [kg/m^3] of the solid (templates are
            re-densified to it).
        solids_fraction: bulk solids fraction used to convert a bulk volume into a mass
            (spec B: 0.60 unless the material says otherwise).
        name: label in results.
        source: how it was built (for reports), e.g. ``{"type": "gravel", "fill_level": "low"}``.
    """

    particle: Material = GRAVEL
    diameter: tuple[float, float] | None = None
    clumps: tuple[tuple[Any, float], ...] | None = None
    solids_fraction: float = 0.60
    name: str = "bulk"
    source: Mapping[str, Any] = field(default_factory=dict, compare=False)
    shape: ParticleShape | None = None

    def __post_init__(self) -> None:
        if self.shape is not None:
            if not isinstance(self.shape, ParticleShape):
                raise ConfigError(f"BulkMaterial: shape must be a ParticleShape, got {type(self.shape).__name__}")
            if self.diameter is not None:
                raise ConfigError("BulkMaterial: a shaped material takes its sizes from shape.diameter; "
                                  "do not give 'diameter' too")
            if isinstance(self.particle, Material):
                templates = self.shape.templates(self.particle.density)
                object.__setattr__(self, "clumps", tuple((t, 1.0 / len(templates)) for t in templates))
        if (self.diameter is None) == (self.clumps is None):
            raise ConfigError("BulkMaterial: give exactly one of 'diameter' (spheres) or 'clumps' (clump mix)")
        if not isinstance(self.particle, Material):
            raise ConfigError(f"BulkMaterial: particle must be a warpdem.Material, got {type(self.particle).__name__}")
        if not (0.0 < float(self.solids_fraction) < 1.0):
            raise ConfigError(f"BulkMaterial: solids_fraction must lie in (0, 1), got {self.solids_fraction}")
        if self.diameter is not None:
            object.__setattr__(self, "diameter", diameter_range(self.diameter, "BulkMaterial"))
        else:
            mix = []
            for item in self.clumps:
                try:
                    tpl, frac = item
                except (TypeError, ValueError):
                    raise ConfigError("BulkMaterial: clumps must be a sequence of (template, fraction) pairs") from None
                for attr in ("centers", "radii", "mass", "inertia_principal", "volume"):
                    if not hasattr(tpl, attr):
                        raise ConfigError(f"BulkMaterial: clump template {tpl!r} has no '{attr}' "
                                          f"(expected a warpdem.clump_geometry.ClumpTemplate)")
                frac = float(frac)
                if not (frac >= 0 and math.isfinite(frac)):
                    raise ConfigError(f"BulkMaterial: number fraction of '{getattr(tpl, 'name', '?')}' must be "
                                      f">= 0, got {frac}")
                if hasattr(tpl, "with_density") and abs(tpl.density - self.particle.density) > 1e-9 * tpl.density:
                    tpl = tpl.with_density(self.particle.density)
                mix.append((tpl, frac))
            total = sum(f for _, f in mix)
            if not mix or total <= 0:
                raise ConfigError("BulkMaterial: clump mix is empty or all fractions are 0")
            object.__setattr__(self, "clumps", tuple((t, f / total) for t, f in mix))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def spheres(cls, d_min: float, d_max: float | None = None, particle: Material = GRAVEL,
                solids_fraction: float = 0.60, name: str | None = None) -> "BulkMaterial":
        """Spheres with diameters uniform by number in [d_min, d_max] [m] (fixed if d_max is None)."""
        d_max = d_min if d_max is None else d_max
        label = name or (f"spheres d={d_min * 1e3:g} mm" if d_max == d_min else
                         f"spheres d={d_min * 1e3:g}-{d_max * 1e3:g} mm")
        return cls(particle=particle, diameter=(d_min, d_max), solids_fraction=solids_fraction, name=label,
                   source={"type": "spheres", "diameter": [d_min, d_max]})

    @classmethod
    def clump_mix(cls, mix: Sequence[tuple[Any, float]] | Mapping[str, tuple[Any, float]],
                  particle: Material = GRAVEL, solids_fraction: float = 0.60, size_scale: float = 1.0,
                  name: str = "clump mix") -> "BulkMaterial":
        """A mix of clump templates by number fraction; ``size_scale`` enlarges all lengths."""
        items = list(mix.values()) if isinstance(mix, Mapping) else list(mix)
        items = [(scale_template(t, size_scale), f) for t, f in items]
        return cls(particle=particle, clumps=tuple(items), solids_fraction=solids_fraction, name=name,
                   source={"type": "clumps", "size_scale": size_scale})

    @classmethod
    def gravel(cls, fill_level: str | int = "medium", particle: Material = GRAVEL, solids_fraction: float = 0.60,
               size_scale: float = 1.0) -> "BulkMaterial":
        """The seed paper's gravel: five shape classes (Table 3 number fractions) filled with
        clumps at ``fill_level`` (Table 2), via :mod:`warpdem.shapes` (imported lazily)."""
        try:
            from warpdem.shapes import gravel_shape_mix, gravel_templates
        except ImportError as exc:  # pragma: no cover - depends on the other module being present
            raise ConfigError(f"the gravel clump mix needs warpdem.shapes, which failed to import: {exc}") from exc
        templates = gravel_templates(fill_level=fill_level, density=particle.density)
        fractions = gravel_shape_mix()
        mix = [(scale_template(templates[k], size_scale), fractions[k]) for k in fractions]
        label = f"gravel clumps ({fill_level} fill" + (f", x{size_scale:g}" if size_scale != 1.0 else "") + ")"
        return cls(particle=particle, clumps=tuple(mix), solids_fraction=solids_fraction, name=label,
                   source={"type": "gravel", "fill_level": fill_level, "size_scale": size_scale})

    @classmethod
    def shaped(cls, family: str, d_min: float, d_max: float | None = None, size_classes: int = 5,
               particle: Material = GRAVEL, solids_fraction: float = 0.60, name: str | None = None,
               **shape_parameters: float) -> "BulkMaterial":
        """Clumps of a shape family (:func:`warpdem.available_shape_families`) whose
        volume-equivalent diameters are uniform by number in [d_min, d_max] [m] (fixed if
        d_max is None), discretised into ``size_classes`` equal-number classes, one template
        each; ``shape_parameters`` (e.g. ``aspect_ratio=1.5``) default to the family's
        defaults and are checked against their admissible bounds."""
        d_max = d_min if d_max is None else d_max
        shape = ParticleShape(family, tuple(shape_parameters.items()), (d_min, d_max), size_classes)
        return cls(particle=particle, solids_fraction=solids_fraction, name=name or shape.label(),
                   source=shape.record(), shape=shape)

    _CONFIG_KEYS = ("type", "diameter", "fill_level", "size_scale", "density", "youngs_modulus", "poisson_ratio",
                    "solids_fraction", "name", "shape", "size_classes")

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | "BulkMaterial") -> "BulkMaterial":
        """Build from a mapping (YAML/JSON), SI units::

            {type: spheres, diameter: [0.016, 0.020]}            # or diameter: 0.018
            {type: gravel, fill_level: medium, size_scale: 1.0}
            {shape: elongated, aspect_ratio: 1.5, diameter: [0.016, 0.020], size_classes: 5}
        The last is a shape family (``type: shaped`` optional): ``diameter`` is the
        volume-equivalent diameter [m], the family's parameters are keys of their own
        (defaults where omitted), ``size_classes`` defaults to 5.
        Optional for all: density [kg/m^3], youngs_modulus [Pa], poisson_ratio, solids_fraction, name.
        """
        if isinstance(cfg, BulkMaterial):
            return cfg
        if not isinstance(cfg, Mapping):
            raise ConfigError(f"material config must be a mapping, got {type(cfg).__name__}")
        kind = cfg.get("type", "shaped" if "shape" in cfg else "spheres")
        family = None
        valid = list(cls._CONFIG_KEYS)
        if kind == "shaped":
            from warpdem.shape_families import shape_family

            if "shape" not in cfg:
                raise ConfigError("material config: type 'shaped' needs 'shape' (a shape family name, e.g. "
                                  "'elongated')")
            try:
                family = shape_family(cfg["shape"])
            except ConfigError as exc:
                raise ConfigError(f"material config: {exc}") from None
            valid += [p.name for p in family.parameters]
        unknown = sorted(set(cfg) - set(valid))
        if unknown:
            hint = _shape_parameter_hint(unknown) if family is None else ""
            raise ConfigError(f"material config: unknown key(s) {unknown}; valid: {valid}{hint}")
        particle = Material(f"{kind}_particle", float(cfg.get("youngs_modulus", GRAVEL.youngs_modulus)),
                            float(cfg.get("poisson_ratio", GRAVEL.poisson_ratio)),
                            float(cfg.get("density", GRAVEL.density)))
        if not any(k in cfg for k in ("youngs_modulus", "poisson_ratio", "density")):
            particle = GRAVEL
        phi = float(cfg.get("solids_fraction", 0.60))
        if kind == "spheres":
            for bad in ("fill_level", "size_scale", "shape", "size_classes"):
                if bad in cfg:
                    raise ConfigError(f"material config: '{bad}' does not apply to type 'spheres'")
            if "diameter" not in cfg:
                raise ConfigError("material config: type 'spheres' needs 'diameter' [m] (a number or [d_min, d_max])")
            d = np.atleast_1d(np.asarray(cfg["diameter"], dtype=float))
            out = cls.spheres(float(d[0]), float(d[-1]), particle=particle, solids_fraction=phi,
                              name=cfg.get("name"))
        elif kind == "gravel":
            for bad in ("diameter", "shape", "size_classes"):
                if bad in cfg:
                    raise ConfigError(f"material config: '{bad}' does not apply to type 'gravel'")
            out = cls.gravel(cfg.get("fill_level", "medium"), particle=particle, solids_fraction=phi,
                             size_scale=float(cfg.get("size_scale", 1.0)))
            if "name" in cfg:
                out = BulkMaterial(particle=out.particle, clumps=out.clumps, solids_fraction=phi, name=cfg["name"],
                                   source=out.source)
        elif kind == "shaped":
            for bad in ("fill_level", "size_scale"):
                if bad in cfg:
                    raise ConfigError(f"material config: '{bad}' applies to type 'gravel', not a shape family")
            if "diameter" not in cfg:
                raise ConfigError(f"material config: shape '{family.name}' needs 'diameter' [m] (volume-equivalent; "
                                  f"a number or [d_min, d_max])")
            d = np.atleast_1d(np.asarray(cfg["diameter"], dtype=float))
            params = {p.name: cfg[p.name] for p in family.parameters if p.name in cfg}
            out = cls.shaped(family.name, float(d[0]), float(d[-1]), size_classes=cfg.get("size_classes", 5),
                             particle=particle, solids_fraction=phi, name=cfg.get("name"), **params)
        else:
            raise ConfigError(f"material config: unknown type {kind!r}; valid: 'spheres', 'gravel', 'shaped'")
        return out

    # ------------------------------------------------------------------ shape parameters
    @property
    def shape_parameters(self) -> dict[str, ParameterSpec]:
        """Declared shape parameters by name (empty for plain spheres and fixed clump mixes)."""
        if self.shape is None:
            return {}
        from warpdem.shape_families import shape_family

        return shape_family(self.shape.family).parameter_specs

    @property
    def shape_parameter_values(self) -> dict[str, float]:
        """Current shape parameter values by name (empty without a shape family)."""
        return {} if self.shape is None else self.shape.parameters

    def with_shape_parameters(self, **values: float) -> "BulkMaterial":
        """A new material with the same particle solid and size distribution and the given
        shape parameters (the others keep their current values). ConfigError for a name the
        material does not declare or a value outside its admissible range."""
        if not values:
            return self
        if self.shape is None:
            raise ConfigError(f"material '{self.name}' has no shape parameters (got {sorted(values)}); build it "
                              f"from a shape family, e.g. BulkMaterial.shaped('elongated', d_min, d_max, "
                              f"aspect_ratio=...) or a config with 'shape: elongated'")
        from warpdem.shape_families import shape_family

        family = shape_family(self.shape.family)
        unknown = sorted(set(values) - set(family.parameter_specs))
        if unknown:
            raise ConfigError(f"material '{self.name}' (shape '{family.name}'): unknown shape parameter(s) "
                              f"{unknown}; valid: {list(family.parameter_specs)}")
        shape = replace(self.shape, values=tuple({**self.shape.parameters, **values}.items()))
        name = shape.label() if self.name == self.shape.label() else self.name
        return replace(self, clumps=None, shape=shape, name=name, source={**dict(self.source), **shape.record()})

    # ------------------------------------------------------------------ properties
    @property
    def is_spheres(self) -> bool:
        return self.diameter is not None

    @property
    def mean_particle_mass(self) -> float:
        """Expected mass of one particle [kg] (number-weighted)."""
        if self.is_spheres:
            a, b = self.diameter
            mean_d3 = a**3 if b == a else (b**4 - a**4) / (4.0 * (b - a))
            return self.particle.density * math.pi / 6.0 * mean_d3
        return float(sum(f * t.mass for t, f in self.clumps))

    @property
    def smallest_sphere(self) -> tuple[float, float]:
        """(radius [m], mass [kg]) of the smallest sphere any fill of this material can hold: the
        size distribution's lower end (spheres), the smallest member of any template (clumps, with
        the body's mass split by member volume as the engine does). What the time step follows."""
        if self.is_spheres:
            r = 0.5 * self.diameter[0]
            return r, self.particle.density * 4.0 / 3.0 * math.pi * r ** 3
        best = (math.inf, math.inf)
        for t, _ in self.clumps:
            radii = np.asarray(t.radii, float)
            masses = t.mass * radii ** 3 / np.sum(radii ** 3)
            best = (min(best[0], float(radii.min())), min(best[1], float(masses.min())))
        return best

    @property
    def max_bounding_radius(self) -> float:
        """Largest particle's enclosing radius [m]."""
        if self.is_spheres:
            return 0.5 * self.diameter[1]
        return float(max(_bounding_radius(t) for t, _ in self.clumps))

    @property
    def mean_diameter(self) -> float:
        """Number-mean volume-equivalent diameter [m]."""
        if self.is_spheres:
            return 0.5 * (self.diameter[0] + self.diameter[1])
        return float(sum(f * (6.0 * t.volume / math.pi) ** (1.0 / 3.0) for t, f in self.clumps))

    def describe(self) -> dict[str, Any]:
        """JSON-able summary for result files."""
        out: dict[str, Any] = {"name": self.name, "density": self.particle.density,
                               "youngs_modulus": self.particle.youngs_modulus,
                               "poisson_ratio": self.particle.poisson_ratio, "solids_fraction": self.solids_fraction}
        if self.is_spheres:
            out.update(type="spheres", diameter=list(self.diameter))
        elif self.shape is not None:
            from warpdem.shape_families import shape_family

            fam = shape_family(self.shape.family)
            out.update(type="shaped", shape=fam.name, shape_parameters=self.shape.parameters,
                       diameter=list(self.shape.diameter), size_classes=self.shape.size_classes,
                       class_diameters=[round(d, 9) for d in self.shape.class_diameters],
                       spheres_per_clump=int(len(self.clumps[0][0].radii)),
                       surface_bumpiness=round(fam.surface_bumpiness(**self.shape.parameters), 6),
                       shape_reference=fam.reference)
        else:
            out.update(type="clumps", mix={getattr(t, "name", f"t{i}"): round(f, 6) for i, (t, f) in enumerate(self.clumps)},
                       spheres_per_clump={getattr(t, "name", f"t{i}"): int(len(t.radii))
                                          for i, (t, _) in enumerate(self.clumps)})
        out.update({k: v for k, v in self.source.items() if k not in out})
        return out


def _shape_parameter_hint(keys: Sequence[str]) -> str:
    """' (... is a parameter of shape family X; add shape: X)' for keys some family declares."""
    try:
        from warpdem.shape_families import available_shape_families, shape_family
    except ImportError:  # pragma: no cover
        return ""
    for fam in available_shape_families():
        hit = [k for k in keys if k in shape_family(fam).parameter_specs]
        if hit:
            return f" ({hit[0]!r} is a parameter of shape family '{fam}': add 'shape: {fam}')"
    return ""


def _bounding_radius(t) -> float:
    c = np.asarray(t.centers, dtype=float)
    return float(np.max(np.linalg.norm(c, axis=1) + np.asarray(t.radii, dtype=float)))


@dataclass(frozen=True)
class ParticleSample:
    """Particles drawn from a :class:`BulkMaterial` (not yet placed).

    Attributes:
        template: (n,) index into ``material.clumps``, or -1 for a free sphere.
        radius: (n,) sphere radius [m] (spheres) or the template's bounding radius (clumps).
        bounding_radius: (n,) radius of the particle's enclosing sphere about its centre of mass [m].
        mass: (n,) [kg]; equivalent_diameter: (n,) volume-equivalent diameter [m].
    """

    material: BulkMaterial
    template: np.ndarray
    radius: np.ndarray
    bounding_radius: np.ndarray
    mass: np.ndarray
    equivalent_diameter: np.ndarray

    @property
    def n(self) -> int:
        return int(self.template.shape[0])

    @property
    def total_mass(self) -> float:
        return float(self.mass.sum())

    @property
    def solid_volume(self) -> float:
        return float(np.sum(math.pi / 6.0 * self.equivalent_diameter**3))

    def members(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Member sphere offsets (k, 3) [m] in the body frame and radii (k,) [m] of particle i."""
        k = int(self.template[i])
        if k < 0:
            return np.zeros((1, 3)), np.array([self.radius[i]])
        t = self.material.clumps[k][0]
        return np.array(t.centers, dtype=float), np.array(t.radii, dtype=float)


def _largest_remainder(n: int, fractions: np.ndarray) -> np.ndarray:
    raw = n * fractions
    counts = np.floor(raw).astype(int)
    rest = n - counts.sum()
    if rest > 0:
        counts[np.argsort(-(raw - counts), kind="stable")[:rest]] += 1
    return counts


def sample_particles(material: BulkMaterial, n: int | None = None, mass: float | None = None,
                     rng: np.random.Generator | int | None = None) -> ParticleSample:
    """Draw particles of ``material``: exactly ``n`` of them, or as many as bring the total
    closest to ``mass`` [kg].

    Spheres: diameters uniform by number in the material's range. Clumps: class counts
    follow the number fractions exactly (largest remainder), in random order.
    """
    if (n is None) == (mass is None):
        raise ConfigError("sample_particles: give exactly one of n (a count) or mass [kg]")
    if not isinstance(material, BulkMaterial):
        raise ConfigError(f"sample_particles: material must be a BulkMaterial, got {type(material).__name__}")
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    if n is not None:
        if int(n) != n or int(n) < 1:
            raise ConfigError(f"sample_particles: n must be a positive integer, got {n}")
        n = int(n)
    else:
        mass = float(mass)
        if not (mass > 0 and math.isfinite(mass)):
            raise ConfigError(f"sample_particles: mass must be > 0 kg, got {mass}")
        if mass < 0.5 * material.mean_particle_mass:
            raise ConfigError(f"sample_particles: mass {mass} kg is less than half a particle "
                              f"({material.mean_particle_mass:.3g} kg)")
    rho = material.particle.density
    if material.is_spheres:
        a, b = material.diameter
        if n is None:
            est = int(math.ceil(1.5 * mass / material.mean_particle_mass)) + 10
            d = rng.uniform(a, b, est) if b > a else np.full(est, a)
            m = rho * math.pi / 6.0 * d**3
            cum = np.cumsum(m)
            k = int(np.searchsorted(cum, mass))
            n = k + 1 if k == 0 or abs(cum[k] - mass) < abs(cum[k - 1] - mass) else k
            d = d[:n]
        else:
            d = rng.uniform(a, b, n) if b > a else np.full(n, a)
        r = 0.5 * d
        return ParticleSample(material, np.full(n, -1), r, r.copy(), rho * math.pi / 6.0 * d**3, d)
    fr = np.array([f for _, f in material.clumps])
    masses = np.array([t.mass for t, _ in material.clumps])
    if n is None:
        n0 = max(1, int(round(mass / material.mean_particle_mass)))
        best = None
        for cand in range(max(1, n0 - 5), n0 + 6):
            tot = float(_largest_remainder(cand, fr) @ masses)
            if best is None or abs(tot - mass) < best[0]:
                best = (abs(tot - mass), cand)
        n = best[1]
    counts = _largest_remainder(n, fr)
    tidx = rng.permutation(np.repeat(np.arange(len(fr)), counts))
    br = np.array([_bounding_radius(t) for t, _ in material.clumps])[tidx]
    deq = np.array([(6.0 * t.volume / math.pi) ** (1.0 / 3.0) for t, _ in material.clumps])[tidx]
    return ParticleSample(material, tidx, br.copy(), br, masses[tidx], deq)
