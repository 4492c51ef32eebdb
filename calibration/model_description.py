"""The DEM model a job simulates, as one value: contact law (every sub-model) + bulk material.

A :class:`ModelDescription` is built once from a config (``contact_law:``, ``material:``,
``plugins:``) and travels whole to the campaign, the experiments, the fills and the builder;
no layer rebuilds a contact law from a name. It knows every parameter a design may vary:

- contact parameters, declared by the law's sub-models (``mu_s`` -> ``mu_s_pp``, ``mu_s_pw``),
- shape parameters, declared by the material's shape family (e.g. ``aspect_ratio``),

with their units and admissible bounds, so a config is checked before any DEM runs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import warpdem as wd
from warpdem import ConfigError
from warpdem.contact import PAIR_TYPES, ParameterSpec

from .materials import BulkMaterial

__all__ = ["ModelDescription", "contact_law_from_config", "contact_law_to_dict", "load_plugins"]


def load_plugins(paths: Sequence[str], base_dir: Path | str = ".") -> tuple[str, ...]:
    """Import user modules of contact sub-models / shape families (files relative to
    ``base_dir`` or importable module names); returns the resolved names, in order."""
    if not paths:
        return ()
    from warpdem import contact

    loader = getattr(contact, "load_module", None)
    if loader is None:  # pragma: no cover - the engine always has it
        raise ConfigError("this warpdem has no plugin loader (warpdem.contact.load_module)")
    resolved = []
    for p in paths:
        if not isinstance(p, str) or not p:
            raise ConfigError(f"plugins: expected a file path or module name, got {p!r}")
        cand = Path(base_dir) / p
        target = str(cand.resolve()) if (p.endswith(".py") or cand.exists()) else p
        if target.endswith(".py") and not Path(target).exists():
            raise ConfigError(f"plugins: file not found: {cand}")
        loader(target)
        resolved.append(target)
    return tuple(resolved)


def contact_law_from_config(raw: Any, where: str = "contact_law") -> wd.ContactLaw:
    """A :class:`warpdem.ContactLaw` from a mapping ``{rolling: epsd2, cohesion: sjkr, ...}``
    (:meth:`warpdem.ContactLaw.from_config`; a ContactLaw is returned as is, None gives the
    calibration's default law, rolling ``epsd``); unknown keys and models are named in the error.
    ``clump_damping_mass: contact_point | body`` picks the mass that damps a clump's contacts
    (:class:`warpdem.ContactLaw`; default ``contact_point``)."""
    if raw is None:
        return wd.ContactLaw(rolling="epsd")
    return wd.ContactLaw.from_config(raw, where)


def contact_law_to_dict(law: wd.ContactLaw) -> dict[str, Any]:
    """Every sub-model of a law, its parameters (unit, bounds) and references, JSON-able
    (:meth:`warpdem.ContactLaw.to_record`)."""
    return law.to_record()


@dataclass(frozen=True)
class ModelDescription:
    """Contact law + bulk material (None: each experiment's scale default) + loaded plugins."""

    contact_law: wd.ContactLaw = field(default_factory=lambda: wd.ContactLaw(rolling="epsd"))
    material: BulkMaterial | None = None
    plugins: tuple[str, ...] = ()

    @classmethod
    def from_config(cls, raw: Mapping[str, Any], base_dir: Path | str = ".", where: str = "") -> "ModelDescription":
        """From the ``contact_law``, ``material`` and ``plugins`` keys of a job config (the
        plugins are imported first, so the law may name their sub-models)."""
        pre = f"{where}: " if where else ""
        plugins = raw.get("plugins") or []
        if isinstance(plugins, str):
            plugins = [plugins]
        if not isinstance(plugins, Sequence):
            raise ConfigError(f"{pre}plugins: expected a list of files or module names, got {plugins!r}")
        loaded = load_plugins(list(plugins), base_dir)
        law = contact_law_from_config(raw.get("contact_law"), f"{pre}contact_law")
        mat = raw.get("material")
        if mat is not None and not isinstance(mat, BulkMaterial):
            if not isinstance(mat, Mapping):
                raise ConfigError(f"{pre}material: expected a mapping, got {mat!r}")
            try:
                mat = BulkMaterial.from_config(mat)
            except ConfigError as exc:
                raise ConfigError(f"{pre}material: {exc}") from None
        return cls(law, mat, loaded)

    # ------------------------------------------------------------------ parameters
    def shape_specs(self, material: BulkMaterial | None = None) -> dict[str, ParameterSpec]:
        """Shape parameters of ``material`` (default: this description's) by name."""
        m = material if material is not None else self.material
        return dict(getattr(m, "shape_parameters", None) or {}) if m is not None else {}

    def parameter_specs(self, material: BulkMaterial | None = None) -> dict[str, ParameterSpec]:
        """Every variable parameter by full name: contact (``mu_s_pp`` ...) then shape."""
        out = {f"{n}_{pt}": s for n, s in self.contact_law.specs.items() for pt in PAIR_TYPES}
        out.update(self.shape_specs(material))
        return out

    @property
    def parameter_names(self) -> list[str]:
        return list(self.parameter_specs())

    def check_value(self, name: str, value: Any, where: str = "") -> float:
        """``value`` as a float within ``name``'s admissible bounds, or a ConfigError naming both."""
        pre = f"{where}: " if where else ""
        specs = self.parameter_specs()
        if name not in specs:
            raise ConfigError(f"{pre}unknown parameter '{name}' for contact law {self.contact_law.describe()}"
                              f"{' and material ' + self.material.name if self.material is not None else ''}; "
                              f"valid: {list(specs)}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{pre}{name} must be a number, got {value!r}") from None
        s = specs[name]
        lo, hi = s.bounds
        if not (math.isfinite(v) and lo <= v <= hi):
            raise ConfigError(f"{pre}{name} = {value!r} outside its admissible range [{lo}, {hi}] {s.unit}")
        return v

    def check_bounds(self, name: str, bounds: Any, where: str = "") -> tuple[float, float]:
        """A design range [lower, upper] within ``name``'s admissible bounds, lower < upper."""
        pre = f"{where}: " if where else ""
        if not (isinstance(bounds, Sequence) and not isinstance(bounds, str) and len(bounds) == 2):
            raise ConfigError(f"{pre}{name} must be [lower, upper], got {bounds!r}")
        lo = self.check_value(name, bounds[0], where)
        hi = self.check_value(name, bounds[1], where)
        if not lo < hi:
            raise ConfigError(f"{pre}{name}: lower bound {lo} must be below the upper bound {hi}")
        return lo, hi

    def split(self, parameter_set: Mapping[str, float]) -> tuple[dict[str, float], dict[str, float]]:
        """(contact parameters, shape parameters) of one parameter set."""
        shape = set(self.shape_specs())
        contact = {k: float(v) for k, v in parameter_set.items() if k not in shape}
        return contact, {k: float(v) for k, v in parameter_set.items() if k in shape}

    def describe(self) -> dict[str, Any]:
        """JSON-able record of the whole model (every sub-model, material, plugins)."""
        return {"contact_law": contact_law_to_dict(self.contact_law),
                "material": None if self.material is None else self.material.describe(),
                "plugins": list(self.plugins)}
