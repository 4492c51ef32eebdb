"""The strict schema of an experiment's settings, derived from the experiment's dataclass fields.

Every place a user's file gives experiment settings (an experiment config's ``settings``, a
campaign response's ``settings``, a measurement file's condition ``settings``, a diagnosis's
``experiments``) reaches :meth:`Experiment.from_config`, which checks the names (unknown setting)
and then the types here, before the dataclass checks the values: ``fill_mass: true``,
``seed: abc``, ``max_contacts: many`` or ``fill_per_world: "yes"`` is refused naming the setting.

Types follow the field's annotation: ``float`` -> a finite number, ``int`` -> a whole number,
``bool`` -> true/false, ``str`` -> text, ``tuple[float, float]`` -> ``[low, high]``,
``dict[str, float]`` -> names to numbers (each optional where the field is ``X | None``); fields
that hold objects (material, contact law, wall material, plugins) are checked by the experiment.
"""
from __future__ import annotations

from typing import Any, Mapping

from pydantic import ValidationError

from warpdem import ConfigError
from warpdem.config_schema import Section, dataclass_section, problem_lines

__all__ = ["settings_model", "check_setting_types"]


def settings_model(experiment: type) -> type[Section]:
    """A :class:`~warpdem.config_schema.Section` with one field per setting of ``experiment``
    (a dataclass; ``scale`` left out), every field optional (only given settings are checked)."""
    return dataclass_section(experiment, ("scale",))


def check_setting_types(experiment: type, settings: Mapping[str, Any], name: str | None = None) -> dict[str, Any]:
    """``settings`` with whole numbers given as ``2.0`` made ``2``; a setting whose value has the
    wrong type for its field (``fill_mass: true``, ``seed: abc``) is a ConfigError naming ``name``
    (default: the experiment's) and the setting. Unknown names are the caller's check (refused
    before, with the list of valid settings)."""
    model = settings_model(experiment)
    given = {k: v for k, v in settings.items() if k in model.model_fields}
    try:
        checked = model.model_validate(given)
    except ValidationError as exc:
        lines = problem_lines(exc, model)
        label = name or getattr(experiment, "name", experiment.__name__)
        raise ConfigError(f"{label}: " + "; ".join(lines)) from None
    out = dict(settings)
    for k, v in given.items():
        if isinstance(v, float) and isinstance(getattr(checked, k), int):
            out[k] = getattr(checked, k)
    return out
