"""Candidate physical effects and model versions (base model + the effects switched on).

A :class:`CandidateEffect` is plain data: a name (e.g. ``"rolling_resistance"``), words for the
reader (``"rolling resistance"``) and the extra parameters the effect brings, each with its range
and its **reference** value, the value at which the effect is off (``mu_r = 0``, cohesion energy
density ``0 J/m3``, ``aspect_ratio = 1``).  The range is the effect's prior: the evidence of
:mod:`validation.evidence` charges for the part of it the data rule out.

A :class:`ModelVersion` is the base parameter space plus the effects switched on; its
:attr:`ModelVersion.space` is the box a design samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.designs import Parameter, ParameterSpace

__all__ = ["EffectParameter", "CandidateEffect", "ModelVersion"]


@dataclass(frozen=True)
class EffectParameter:
    """An extra parameter of an effect: range ``[lower, upper]`` in ``unit``, ``reference`` = effect off."""

    name: str
    unit: str
    lower: float
    upper: float
    reference: float
    description: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"effect parameter name must be a non-empty string, got {self.name!r}")
        lo, hi, ref = float(self.lower), float(self.upper), float(self.reference)
        if not all(math.isfinite(v) for v in (lo, hi, ref)):
            raise ValueError(f"effect parameter {self.name!r}: bounds and reference must be finite")
        if not lo < hi:
            raise ValueError(f"effect parameter {self.name!r}: lower {lo} must be < upper {hi}")
        if not lo <= ref <= hi:
            raise ValueError(f"effect parameter {self.name!r}: reference (effect off) {ref} lies outside [{lo}, {hi}]")

    def as_parameter(self) -> Parameter:
        return Parameter(self.name, self.lower, self.upper, self.unit, self.description)

    @property
    def far_bound(self) -> float:
        """The bound farthest from the reference: the effect at full strength."""
        return self.upper if abs(self.upper - self.reference) >= abs(self.reference - self.lower) else self.lower


@dataclass(frozen=True)
class CandidateEffect:
    """A physical effect the model may lack: ``name`` (identifier), ``label`` (words), parameters."""

    name: str
    parameters: tuple[EffectParameter, ...]
    label: str = ""
    description: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"effect name must be a non-empty string, got {self.name!r}")
        params = tuple(self.parameters)
        if not params:
            raise ValueError(f"effect {self.name!r} needs at least one parameter")
        for p in params:
            if not isinstance(p, EffectParameter):
                raise TypeError(f"effect {self.name!r}: parameters must be EffectParameter, got {type(p).__name__}")
        object.__setattr__(self, "parameters", params)

    @property
    def words(self) -> str:
        return self.label or self.name.replace("_", " ")

    @property
    def parameter_names(self) -> list[str]:
        return [p.name for p in self.parameters]

    def to_dict(self) -> dict:
        return {"name": self.name, "label": self.words, "description": self.description,
                "parameters": [{"name": p.name, "unit": p.unit, "lower": p.lower, "upper": p.upper,
                                "reference": p.reference, "description": p.description} for p in self.parameters]}


@dataclass(frozen=True)
class ModelVersion:
    """The base parameter box plus the effects switched on (in the order they were added)."""

    base: ParameterSpace
    effects: tuple[CandidateEffect, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.base, ParameterSpace):
            raise TypeError(f"base must be a calibration.designs.ParameterSpace, got {type(self.base).__name__}")
        object.__setattr__(self, "effects", tuple(self.effects))
        self.space  # noqa: B018 -- raises on clashing parameter names

    @property
    def space(self) -> ParameterSpace:
        params = list(self.base.parameters)
        seen = {p.name: "the base model" for p in params}
        for e in self.effects:
            for p in e.parameters:
                if p.name in seen:
                    raise ValueError(f"parameter {p.name!r} of effect {e.name!r} is already a parameter of {seen[p.name]}")
                seen[p.name] = f"effect {e.name!r}"
                params.append(p.as_parameter())
        return ParameterSpace(tuple(params))

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    @property
    def name(self) -> str:
        """``"base"`` or ``"base + rolling resistance + ..."``."""
        return " + ".join(["base"] + [e.words for e in self.effects])

    def with_effect(self, effect: CandidateEffect) -> "ModelVersion":
        if effect.name in self.effect_names:
            raise ValueError(f"effect {effect.name!r} is already part of {self.name}")
        return ModelVersion(self.base, self.effects + (effect,))

    def parameter_sets(self, X: np.ndarray) -> list[dict[str, float]]:
        """Rows of a design matrix (physical units) as ``{name: value}`` dicts."""
        space = self.space
        X = np.atleast_2d(np.asarray(X, dtype=float))
        return [space.as_dict(x) for x in X]
