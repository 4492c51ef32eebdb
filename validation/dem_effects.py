"""Candidate effects of the DEM model, read from the engine's declarations (nothing hand-listed).

An effect is one of:

- a contact sub-model of kind ``rolling`` or ``cohesion`` that the base law lacks
  (``rolling_resistance`` = the kind's ``default_candidate`` sub-model, LIGGGHTS ``epsd2``;
  ``cohesion`` = ``sjkr``; any other registered one as ``"rolling:cdt"``, ``"cohesion:sjkr2"``);
  its parameters are the sub-model's declared ones, per pair type (``mu_r_pp``, ``mu_r_pw``);
- a shape family the base material lacks (``shape`` = ``elongated``; ``"shape:<family>"``).

Each parameter's design range and "effect off" value come from its :class:`ParameterSpec`
(``design_range``, ``off_value``), or from the diagnosis config. :class:`DEMEffect` also knows
how to switch itself on in a :class:`~calibration.model_description.ModelDescription`.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping

from calibration.materials import BulkMaterial
from calibration.model_description import ModelDescription
from warpdem import ConfigError
from warpdem.contact import PAIR_TYPES, REGISTRY, ParameterSpec

from .effects import CandidateEffect, EffectParameter

__all__ = ["DEMEffect", "EFFECT_KINDS", "resolve_effect", "default_effects", "apply_effects"]

#: contact sub-model kinds that are physical effects a base law may lack, with plain words
EFFECT_KINDS = {"rolling": ("rolling_resistance", "rolling resistance"), "cohesion": ("cohesion", "cohesion")}
SHAPE = ("shape", "particle shape")


@dataclass(frozen=True)
class DEMEffect:
    """An effect of the DEM model: ``kind`` (rolling, cohesion or shape), the sub-model or shape
    family ``model``, and the :class:`CandidateEffect` (plain data) the diagnosis ranks."""

    kind: str
    model: str
    candidate: CandidateEffect

    @property
    def name(self) -> str:
        return self.candidate.name

    def apply(self, description: ModelDescription, base_material: BulkMaterial) -> ModelDescription:
        """``description`` with this effect switched on (parameters still at their design values)."""
        if self.kind == "shape":
            mat = description.material or base_material
            if mat.diameter is None:
                raise ConfigError(f"effect '{self.name}': the base material {mat.name!r} is not spheres with a "
                                  "diameter range, so a shape family cannot replace it")
            off = {p.name: p.reference for p in self.candidate.parameters}
            shaped = BulkMaterial.shaped(self.model, mat.diameter[0], mat.diameter[1], particle=mat.particle,
                                         solids_fraction=mat.solids_fraction, **off)
            return dataclasses.replace(description, material=shaped)
        law = dataclasses.replace(description.contact_law, **{self.kind: self.model})
        return dataclasses.replace(description, contact_law=law)


def _contact_effect(kind: str, model: str, name: str, label: str,
                    ranges: Mapping[str, Any] | None) -> DEMEffect:
    cls = REGISTRY[kind][model]
    params = []
    for spec in cls.parameters:
        for pt in PAIR_TYPES:
            params.append(_effect_parameter(f"{spec.name}_{pt}", spec, ranges, name))
    return DEMEffect(kind, model, CandidateEffect(name, tuple(params), label,
                                                  f"{kind} sub-model '{model}': {cls.reference}"))


def _effect_parameter(full: str, spec: ParameterSpec, ranges: Mapping[str, Any] | None, effect: str) -> EffectParameter:
    off = spec.off_value if spec.off_value is not None else spec.bounds[0]
    lo, hi = spec.exploration_range
    if ranges and full in ranges:
        r = ranges[full]
        if not (isinstance(r, (list, tuple)) and len(r) == 2):
            raise ConfigError(f"effect '{effect}': range of {full} must be [lower, upper], got {r!r}")
        lo, hi = float(r[0]), float(r[1])
        if not (spec.bounds[0] <= lo < hi <= spec.bounds[1]):
            raise ConfigError(f"effect '{effect}': range of {full} [{lo}, {hi}] must lie within its admissible "
                              f"bounds {list(spec.bounds)} {spec.unit} with lower < upper")
    if not lo <= off <= hi:
        raise ConfigError(f"effect '{effect}': the range of {full} [{lo}, {hi}] must contain {off}, the value at "
                          "which the effect is off (so the base model is part of the augmented one)")
    return EffectParameter(full, spec.unit, lo, hi, off, spec.description)


def resolve_effect(token: str, ranges: Mapping[str, Any] | None = None) -> DEMEffect:
    """``"rolling_resistance"``, ``"cohesion"``, ``"shape"`` or ``"kind:model"`` -> :class:`DEMEffect`."""
    from warpdem.shape_families import available_shape_families, shape_family

    if not isinstance(token, str) or not token:
        raise ConfigError(f"candidate effect must be a name, got {token!r}")
    kind, _, model = token.partition(":")
    by_name = {v[0]: k for k, v in EFFECT_KINDS.items()}
    if kind in by_name:
        kind = by_name[kind]
    if kind in EFFECT_KINDS:
        models = {n: c for n, c in REGISTRY[kind].items() if n != "none"}
        if not model:
            preferred = [n for n, c in models.items() if getattr(c, "default_candidate", False)]
            model = (preferred or sorted(models))[0]
        if model not in models:
            raise ConfigError(f"candidate effect '{token}': no {kind} sub-model '{model}'; registered: {sorted(models)}")
        base_name, label = EFFECT_KINDS[kind]
        name = base_name if not _ or model == _default_model(kind) else f"{base_name}:{model}"
        return _contact_effect(kind, model, name, label if name == base_name else f"{label} ({model})", ranges)
    if kind == SHAPE[0]:
        families = available_shape_families()
        model = model or ("elongated" if "elongated" in families else families[0])
        if model not in families:
            raise ConfigError(f"candidate effect '{token}': no shape family '{model}'; registered: {families}")
        fam = shape_family(model)
        params = tuple(_effect_parameter(s.name, s, ranges, token) for s in fam.parameters)
        name = SHAPE[0] if model == "elongated" else f"shape:{model}"
        return DEMEffect("shape", model, CandidateEffect(name, params, f"{SHAPE[1]} ({model})",
                                                         f"shape family '{model}': {fam.reference}"))
    valid = [v[0] for v in EFFECT_KINDS.values()] + [SHAPE[0]]
    raise ConfigError(f"unknown candidate effect '{token}'; valid: {valid} or 'kind:model' "
                      f"(e.g. rolling:cdt, cohesion:sjkr2, shape:elongated)")


def _default_model(kind: str) -> str:
    models = {n: c for n, c in REGISTRY[kind].items() if n != "none"}
    preferred = [n for n, c in models.items() if getattr(c, "default_candidate", False)]
    return (preferred or sorted(models))[0]


def default_effects(description: ModelDescription, base_material: BulkMaterial,
                    ranges: Mapping[str, Any] | None = None) -> list[DEMEffect]:
    """Every effect the base lacks: a rolling or cohesion kind left at ``none``, and shape when the
    material is plain spheres."""
    out = []
    for kind in EFFECT_KINDS:
        if getattr(description.contact_law, kind) == "none":
            out.append(resolve_effect(EFFECT_KINDS[kind][0], ranges))
    mat = description.material or base_material
    if mat.diameter is not None and not getattr(mat, "shape", None):
        out.append(resolve_effect(SHAPE[0], ranges))
    return out


def apply_effects(description: ModelDescription, effects: list[DEMEffect], base_material: BulkMaterial
                  ) -> ModelDescription:
    """The base description with every effect of ``effects`` switched on, in order."""
    for e in effects:
        description = e.apply(description, base_material)
    return description
