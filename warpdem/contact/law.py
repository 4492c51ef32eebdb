"""A contact law: one registered sub-model per kind, plus its parameter table layout."""
from __future__ import annotations

from dataclasses import dataclass, field

from ..errors import ConfigError
from .base import KINDS, PAIR_TYPES, REGISTRY, ParameterSpec, SubModel


@dataclass(frozen=True)
class ContactLaw:
    """Composition of contact sub-models by name (see :mod:`warpdem.contact.base`).

    Args:
        normal, tangential, rolling, cohesion: registered sub-model names.
        track_wear: accumulate per-triangle wall contact energy and impulse.
    """

    normal: str = "hertz"
    tangential: str = "mindlin"
    rolling: str = "none"
    cohesion: str = "none"
    track_wear: bool = True
    submodels: dict[str, SubModel] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        subs = {}
        for kind in KINDS:
            name = getattr(self, kind)
            if name not in REGISTRY[kind]:
                raise ConfigError(
                    f"unknown {kind} contact model '{name}'; registered: {sorted(REGISTRY[kind])}"
                )
            subs[kind] = REGISTRY[kind][name]()
        object.__setattr__(self, "submodels", subs)

    @property
    def specs(self) -> dict[str, ParameterSpec]:
        """Declared base parameters (e.g. ``mu_s``) in table-column order."""
        out: dict[str, ParameterSpec] = {}
        for kind in KINDS:
            for spec in self.submodels[kind].parameters:
                out.setdefault(spec.name, spec)
        return out

    @property
    def parameter_names(self) -> list[str]:
        """Full calibration names, e.g. ``['restitution_pp', 'restitution_pw', 'mu_s_pp', ...]``."""
        return [f"{name}_{pt}" for name in self.specs for pt in PAIR_TYPES]

    def column(self, base_name: str) -> int:
        """Column of a base parameter in the per-world parameter table."""
        names = list(self.specs)
        if base_name not in names:
            raise ConfigError(f"contact law {self.describe()} has no parameter '{base_name}'; it has {names}")
        return names.index(base_name)

    def split_name(self, full_name: str) -> tuple[str, int]:
        """``'mu_s_pw'`` -> (``'mu_s'``, pair type index 1); clear error for unknown names."""
        for i, pt in enumerate(PAIR_TYPES):
            suffix = "_" + pt
            if full_name.endswith(suffix) and full_name[: -len(suffix)] in self.specs:
                return full_name[: -len(suffix)], i
        raise ConfigError(
            f"unknown contact parameter '{full_name}' for law {self.describe()}; valid: {self.parameter_names}"
        )

    @property
    def needs_tangential_history(self) -> bool:
        return self.submodels["tangential"].needs_history

    @property
    def needs_rolling_history(self) -> bool:
        return self.submodels["rolling"].needs_history

    def describe(self) -> str:
        return f"{self.normal}+{self.tangential}+rolling:{self.rolling}+cohesion:{self.cohesion}"

    def references(self) -> dict[str, str]:
        return {k: f"{s.name}: {s.reference}" for k, s in self.submodels.items()}
