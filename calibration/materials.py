"""Bulk materials of the standard experiments (spec: /work/shared/spec/experiments.md,
"Default material"): plain spheres with a diameter distribution, or a number-fraction mix
of multi-sphere clump templates (seed paper Tables 2-3), plus the particle's elastic
:class:`warpdem.Material`.

``sample_particles(material, n=... | mass=..., rng)`` draws the particles to add to a model;
positions come from :mod:`calibration.filling`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from warpdem import GRAVEL, ConfigError, Material

__all__ = ["BulkMaterial", "ParticleSample", "sample_particles", "scale_template"]


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


@dataclass(frozen=True)
class BulkMaterial:
    """A granular material: particle shape/size description and elastic solid.

    Exactly one of:
        diameter: (d_min, d_max) [m]; sphere diameters uniform by number in [d_min, d_max]
            (d_min == d_max: one size).
        clumps: ((template, number fraction), ...) of clump templates
            (``warpdem.clump_geometry.ClumpTemplate``); fractions are normalised to 1.
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

    def __post_init__(self) -> None:
        if (self.diameter is None) == (self.clumps is None):
            raise ConfigError("BulkMaterial: give exactly one of 'diameter' (spheres) or 'clumps' (clump mix)")
        if not isinstance(self.particle, Material):
            raise ConfigError(f"BulkMaterial: particle must be a warpdem.Material, got {type(self.particle).__name__}")
        if not (0.0 < float(self.solids_fraction) < 1.0):
            raise ConfigError(f"BulkMaterial: solids_fraction must lie in (0, 1), got {self.solids_fraction}")
        if self.diameter is not None:
            d = np.atleast_1d(np.asarray(self.diameter, dtype=float)).ravel()
            if d.size == 1:
                d = np.array([d[0], d[0]])
            if d.size != 2 or not np.all(np.isfinite(d)) or d[0] <= 0 or d[1] < d[0]:
                raise ConfigError(f"BulkMaterial: diameter must be d > 0 m or (d_min, d_max) with "
                                  f"0 < d_min <= d_max [m], got {self.diameter!r}")
            if d[1] > 1.0:
                raise ConfigError(f"BulkMaterial: diameter {d[1]} m looks like millimetres; give metres")
            object.__setattr__(self, "diameter", (float(d[0]), float(d[1])))
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

    _CONFIG_KEYS = ("type", "diameter", "fill_level", "size_scale", "density", "youngs_modulus", "poisson_ratio",
                    "solids_fraction", "name")

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | "BulkMaterial") -> "BulkMaterial":
        """Build from a mapping (YAML/JSON), SI units::

            {type: spheres, diameter: [0.016, 0.020]}            # or diameter: 0.018
            {type: gravel, fill_level: medium, size_scale: 1.0}
        Optional for both: density [kg/m^3], youngs_modulus [Pa], poisson_ratio, solids_fraction, name.
        """
        if isinstance(cfg, BulkMaterial):
            return cfg
        if not isinstance(cfg, Mapping):
            raise ConfigError(f"material config must be a mapping, got {type(cfg).__name__}")
        unknown = sorted(set(cfg) - set(cls._CONFIG_KEYS))
        if unknown:
            raise ConfigError(f"material config: unknown key(s) {unknown}; valid: {list(cls._CONFIG_KEYS)}")
        kind = cfg.get("type", "spheres")
        particle = Material(f"{kind}_particle", float(cfg.get("youngs_modulus", GRAVEL.youngs_modulus)),
                            float(cfg.get("poisson_ratio", GRAVEL.poisson_ratio)),
                            float(cfg.get("density", GRAVEL.density)))
        if not any(k in cfg for k in ("youngs_modulus", "poisson_ratio", "density")):
            particle = GRAVEL
        phi = float(cfg.get("solids_fraction", 0.60))
        if kind == "spheres":
            for bad in ("fill_level", "size_scale"):
                if bad in cfg:
                    raise ConfigError(f"material config: '{bad}' applies to type 'gravel', not 'spheres'")
            if "diameter" not in cfg:
                raise ConfigError("material config: type 'spheres' needs 'diameter' [m] (a number or [d_min, d_max])")
            d = np.atleast_1d(np.asarray(cfg["diameter"], dtype=float))
            out = cls.spheres(float(d[0]), float(d[-1]), particle=particle, solids_fraction=phi,
                              name=cfg.get("name"))
        elif kind == "gravel":
            if "diameter" in cfg:
                raise ConfigError("material config: 'diameter' applies to type 'spheres', not 'gravel'")
            out = cls.gravel(cfg.get("fill_level", "medium"), particle=particle, solids_fraction=phi,
                             size_scale=float(cfg.get("size_scale", 1.0)))
            if "name" in cfg:
                out = BulkMaterial(particle=out.particle, clumps=out.clumps, solids_fraction=phi, name=cfg["name"],
                                   source=out.source)
        else:
            raise ConfigError(f"material config: unknown type {kind!r}; valid: 'spheres', 'gravel'")
        return out

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
        else:
            out.update(type="clumps", mix={getattr(t, "name", f"t{i}"): round(f, 6) for i, (t, f) in enumerate(self.clumps)},
                       spheres_per_clump={getattr(t, "name", f"t{i}"): int(len(t.radii))
                                          for i, (t, _) in enumerate(self.clumps)})
        out.update({k: v for k, v in self.source.items() if k not in out})
        return out


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
