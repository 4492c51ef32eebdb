"""A contact law: one registered sub-model per kind, plus its parameter table layout."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

from ..errors import ConfigError
from .base import KINDS, PAIR_TYPES, REGISTRY, ParameterSpec, SubModel

#: Which mass damps a clump's contact (:attr:`ContactLaw.clump_damping_mass`); the first is the default.
CLUMP_DAMPING_MASSES = ("contact_point", "body")

#: The keys of a law's config mapping (:meth:`ContactLaw.to_config`), in the order every record lists them.
CONFIG_KEYS = ("normal", "tangential", "rolling", "cohesion", "track_wear", "clump_damping_mass")
#: Settings added after records, model fingerprints and DEM caches were written: a config lists
#: them only when they are not their default, so the text of an unchanged law stays the same.
CONFIG_KEYS_LISTED_WHEN_SET = ("clump_damping_mass",)


@dataclass(frozen=True)
class ContactLaw:
    """Composition of contact sub-models by name (see :mod:`warpdem.contact.base`).

    Args:
        normal, tangential, rolling, cohesion: registered sub-model names.
        track_wear: accumulate per-triangle wall contact energy and impulse.
        clump_damping_mass: the mass m_i [kg] that sizes a clump's contact damping (m* in the
            normal and tangential dashpots, F^d = -2 sqrt(5/6) beta sqrt(S m*) v; seed paper
            eqs. (5), (9)), with m* = m_i m_j / (m_i + m_j) (a wall: m* = m_i):

            - ``"contact_point"`` (default): the mass felt at the contact point along the normal,
              m_i = 1 / (1/m + |r x n|^2 / I_mean) (:func:`warpdem.kernels.mass_felt_at`; r: the
              member sphere's centre from the body's centre of mass [m], I_mean: mean principal
              moment [kg m^2]). An off-centre contact also turns the body, so the contact point
              moves with less than m; damped for that mass, it rebounds with the restitution it
              is given (Kruggel-Emden et al. 2008, Powder Technol. 188:153).
            - ``"body"``: the whole-body mass, m_i = m (LIGGGHTS ``fix multisphere`` and many
              codes). An off-centre contact is then over-damped: its rebound at the contact
              point is below the set restitution.

            Spheres, and contacts on a line through a clump's centre of mass, feel m either way.
    """

    normal: str = "hertz"
    tangential: str = "history"
    rolling: str = "none"
    cohesion: str = "none"
    track_wear: bool = True
    clump_damping_mass: str = "contact_point"
    submodels: dict[str, SubModel] = field(init=False, repr=False, compare=False)
    # the registered classes: two laws naming the same sub-models are equal (and share a
    # compiled kernel) only while the names resolve to the same classes
    implementation: tuple[type[SubModel], ...] = field(init=False, repr=False, compare=True)

    def __post_init__(self) -> None:
        if self.clump_damping_mass not in CLUMP_DAMPING_MASSES:
            raise ConfigError(f"unknown clump_damping_mass {self.clump_damping_mass!r}; valid: "
                              f"{list(CLUMP_DAMPING_MASSES)} (the mass felt at the contact point, or the whole-body mass)")
        subs = {}
        for kind in KINDS:
            name = getattr(self, kind)
            if name not in REGISTRY[kind]:
                raise ConfigError(
                    f"unknown {kind} contact model '{name}'; registered: {sorted(REGISTRY[kind])} "
                    "(a sub-model of your own: load its file first, e.g. plugins: [my_effects.py] "
                    "or warpdem.contact.load_module('my_effects.py'))"
                )
            subs[kind] = REGISTRY[kind][name]()
        object.__setattr__(self, "submodels", subs)
        object.__setattr__(self, "implementation", tuple(type(subs[k]) for k in KINDS))
        self.specs  # noqa: B018 - conflicting parameter declarations fail here, not later

    def __reduce__(self):
        # pickled by names: the receiving process resolves them in its own registry (load the
        # same plugins there first)
        return (type(self), tuple(self.to_config(every_key=True).values()))

    # ------------------------------------------------------------------ config <-> law
    @classmethod
    def from_config(cls, raw: Mapping[str, Any], where: str = "contact_law") -> "ContactLaw":
        """A law from a config mapping ``{rolling: epsd2, cohesion: sjkr, ...}`` (the keys of
        :data:`CONFIG_KEYS`; those left out keep their defaults); a ContactLaw is returned as is.
        Unknown keys and sub-models are named in the error, after ``where``."""
        if isinstance(raw, cls):
            return raw
        if not isinstance(raw, Mapping):
            raise ConfigError(f"{where}: expected a mapping of sub-model kinds to names {list(CONFIG_KEYS)}, got {raw!r}")
        bad = sorted(set(raw) - set(CONFIG_KEYS))
        if bad:
            raise ConfigError(f"{where}: unknown key(s) {bad}; valid: {list(CONFIG_KEYS)}")
        try:
            return cls(**dict(raw))
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None

    def to_config(self, every_key: bool = False) -> dict[str, Any]:
        """The law as the mapping :meth:`from_config` reads back, keys in :data:`CONFIG_KEYS` order.
        A setting of :data:`CONFIG_KEYS_LISTED_WHEN_SET` is listed only when it is not its default
        (records, fingerprints and cache ids of an unchanged law stay the same); ``every_key``
        lists every key (a checkpoint)."""
        return {k: getattr(self, k) for k in CONFIG_KEYS
                if every_key or k not in CONFIG_KEYS_LISTED_WHEN_SET or getattr(self, k) != _DEFAULTS[k]}

    def to_record(self) -> dict[str, Any]:
        """:meth:`to_config` plus :meth:`describe`, the references and every parameter (unit,
        bounds, default, description): the JSON-able record of the law in results and reports."""
        out = self.to_config()
        out["describe"] = self.describe()
        out["references"] = self.references()
        out["parameters"] = {n: {"unit": s.unit, "bounds": list(s.bounds), "default": s.default,
                                 "description": s.description} for n, s in self.specs.items()}
        return out

    @property
    def specs(self) -> dict[str, ParameterSpec]:
        """Declared base parameters (e.g. ``mu_s``) in table-column order."""
        out: dict[str, ParameterSpec] = {}
        owner: dict[str, str] = {}
        for kind in KINDS:
            sub = self.submodels[kind]
            for spec in sub.parameters:
                if spec.name in out and out[spec.name] != spec:
                    # two sub-models may share a parameter only if they declare it identically
                    raise ConfigError(
                        f"contact law {self.describe()}: parameter '{spec.name}' is declared differently by "
                        f"{owner[spec.name]} ({out[spec.name]}) and {kind} '{sub.name}' ({spec})"
                    )
                out.setdefault(spec.name, spec)
                owner.setdefault(spec.name, f"{kind} '{sub.name}'")
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

    @property
    def needs_body_kinematics(self) -> bool:
        """Whether a sub-model reads the body fields of :class:`~warpdem.contact.ContactInput`
        (``arm_body``, ``w_body``, ``i_body``): a compile-time switch of the contact stages."""
        return any(bool(getattr(s, "needs_body_kinematics", False)) for s in self.submodels.values())

    @property
    def pair_antisymmetric(self) -> bool:
        """Whether every sub-model's sphere-sphere force is antisymmetric (``SubModel.pair_antisymmetric``):
        then a pair may be evaluated once, the partner getting the reaction (``pair_evaluation="half"``)."""
        return all(bool(getattr(s, "pair_antisymmetric", False)) for s in self.submodels.values())

    def describe(self) -> str:
        """``hertz+mindlin+rolling:epsd+cohesion:none``; a non-default clump damping mass is
        appended (``+clump_damping:body``), so the default law's text is unchanged."""
        text = f"{self.normal}+{self.tangential}+rolling:{self.rolling}+cohesion:{self.cohesion}"
        if self.clump_damping_mass != CLUMP_DAMPING_MASSES[0]:
            text += f"+clump_damping:{self.clump_damping_mass}"
        return text

    def references(self) -> dict[str, str]:
        return {k: f"{s.name}: {s.reference}" for k, s in self.submodels.items()}


_DEFAULTS = {k: ContactLaw.__dataclass_fields__[k].default for k in CONFIG_KEYS}
