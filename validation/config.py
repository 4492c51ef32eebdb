"""The diagnosis config (``warpdem diagnose CONFIG``), checked with pydantic before any DEM runs.

Every problem is reported at once with its path in the file (``parameters.mu_s_pp``,
``diagnosis.replicates``), then the model is checked against the engine's declarations
(parameter names, admissible bounds, effect names). Example: ``validation/configs/first_diagnosis.yaml``.

.. code-block:: yaml

    name: hidden-rolling
    measurements: lab.yaml            # measurement file (warpdem-measurements/2; v1 loads too), relative to this file
    output: results/diagnosis         # default: results/diagnosis_<name> (relative to the working directory)
    device: null                      # null: cuda if present, else cpu
    processes: auto                   # CPU: worlds split over one process per core
    executor: {kind: ray, address: auto}  # optional: DEM batches on a Ray cluster (docs/scale_out.md)
    scale: paper                      # experiment preset (paper | quick)
    experiments: {drum: {scale: short}}   # per experiment: settings for every condition
    model:
      contact_law: {rolling: none}    # the base law (every sub-model by name)
      material: null                  # default: the measurement file's material
      plugins: []                     # files of extra sub-models / shape families
    parameters: {mu_s_pp: [0.1, 0.9], mu_s_pw: [0.1, 0.9]}   # calibrated base parameters
    fixed: {restitution_pp: 0.6, restitution_pw: 0.6}
    candidates: default               # or a list: [rolling_resistance, cohesion, shape, rolling:cdt]
    effect_ranges: {mu_r_pp: [0, 0.3]}    # design range of an effect parameter (default: declared)
    add: []                           # effects to add whatever the ranking (--add EFFECT)
    proposals: auto                   # conditions to forecast when candidates tie, or a list of
                                      # {experiment, quantity, settings, label, n_repeats,
                                      #  expected_standard_error, lab_hours} (docs/diagnosis.md)
    max_proposed_conditions: 6        # with auto: new conditions forecast at most (validation.proposals)
    diagnosis: {replicates: 2}        # validation.settings.DiagnosisSettings fields, e.g.
                                      # model_discrepancy: fidelity (none | {KEY: sd}): model error
                                      # designs_up_front: auto (true | false): every design in one call
                                      # replicated_fraction: 1.0 (0.34: a third of the sets replicated)
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Annotated, Optional, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model, field_validator

from warpdem import ConfigError
from warpdem.config_io import check_device, load_config_file, parse_processes
from warpdem.config_schema import Flag, Number, Pair, Text, WholeNumber

from .settings import BOUNDS, DiagnosisSettings

#: a finite number >= 0
NonNegativeNumber = Annotated[Number, Field(ge=0)]

__all__ = ["DiagnosisConfig", "load_diagnosis_config", "format_validation_error"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ModelSection(_Strict):
    contact_law: dict[str, Any] = Field(default_factory=lambda: {"rolling": "none"})
    material: dict[str, Any] | None = None
    plugins: list[str] = Field(default_factory=list)


class ProposalSection(_Strict):
    experiment: str
    quantity: str
    settings: dict[str, Any] = Field(default_factory=dict)
    label: str = ""
    n_repeats: WholeNumber = Field(3, ge=1)
    expected_standard_error: Optional[Number] = Field(None, ge=0)
    lab_hours: Optional[Number] = Field(None, gt=0)  # None: from the experiment's LAB_SETTINGS / LAB_EFFORT


class _DiagnosisSectionChecks(_Strict):
    @field_validator("designs_up_front", mode="before", check_fields=False)
    @classmethod
    def _auto_true_false(cls, v: Any) -> Any:
        if isinstance(v, bool) or v == "auto":
            return v
        if v in ("true", "false"):  # quoted in the YAML
            return v == "true"
        raise ValueError("must be auto, true or false")


#: the schema of a setting's type in the config (a type not listed here needs a line below)
_SETTING_TYPES: dict[str, Any] = {
    "int": WholeNumber, "float": Number, "bool": Flag,
    "str | Mapping[str, float]": Union[Literal["fidelity", "none"], dict[str, NonNegativeNumber]],
    "bool | str": Union[bool, Literal["auto"]],
}


def _diagnosis_section() -> type[_Strict]:
    """The ``diagnosis:`` section: one field per :class:`DiagnosisSettings` field (its default and
    bounds, :data:`validation.settings.BOUNDS`) but ``add``, a key of its own at the top level."""
    section = {f.name: (_SETTING_TYPES[f.type], Field(f.default, **f.metadata.get(BOUNDS, {})))
               for f in dataclasses.fields(DiagnosisSettings) if f.name != "add"}
    return create_model("DiagnosisSection", __base__=_DiagnosisSectionChecks, __module__=__name__, **section)


DiagnosisSection = _diagnosis_section()


class DiagnosisConfig(_Strict):
    """The whole diagnosis config; see the module docstring."""

    name: Text = "diagnosis"
    measurements: Text
    output: str | None = None
    device: str | None = None
    processes: Union[int, Literal["auto"]] = "auto"
    executor: Optional[dict[str, Any]] = None
    scale: Literal["paper", "quick"] = "paper"
    experiments: dict[Literal["baffle", "drum", "cylinder"], dict[str, Any]] = Field(default_factory=dict)
    model: ModelSection = Field(default_factory=ModelSection)
    parameters: dict[str, Pair]
    fixed: dict[str, Number] = Field(default_factory=dict)
    candidates: Union[Literal["default"], list[str]] = "default"
    effect_ranges: dict[str, Pair] = Field(default_factory=dict)
    add: list[str] = Field(default_factory=list)
    proposals: Union[Literal["auto", "none"], list[ProposalSection]] = "auto"
    max_proposed_conditions: WholeNumber = Field(6, ge=0)
    diagnosis: DiagnosisSection = Field(default_factory=DiagnosisSection)
    cache: str | None = None
    cache_code_version: Literal["match", "any"] = "match"
    progress: Flag = True

    @field_validator("processes", mode="before")
    @classmethod
    def _positive_processes(cls, v: Any) -> Any:
        try:
            return parse_processes(v, "processes")
        except ConfigError:
            raise ValueError("must be a whole number >= 1 or 'auto'") from None

    @field_validator("parameters")
    @classmethod
    def _nonempty(cls, v: dict) -> dict:
        if not v:
            raise ValueError("give at least one calibrated parameter: name -> [lower, upper]")
        return v


def format_validation_error(exc: ValidationError, source: str) -> str:
    """One line per problem, with its path in the file."""
    lines = [f"{source}: {len(exc.errors())} problem(s) in the config:"]
    for e in exc.errors():
        path = ".".join(str(p) for p in e["loc"]) or "(top level)"
        msg = e["msg"].removeprefix("Value error, ")
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
        lines.append(f"  {path}: {msg} (got {e.get('input')!r})" if e["type"] != "missing" else f"  {path}: missing")
    return "\n".join(lines)


def load_diagnosis_config(path: str | os.PathLike) -> tuple[DiagnosisConfig, Path]:
    """Read and check a diagnosis config; returns (config, folder of the file). Errors are
    :class:`ConfigError` listing every problem with its path."""
    p = Path(path)
    raw = load_config_file(p, "diagnosis config")
    if not isinstance(raw, dict):
        raise ConfigError(f"{p}: the top level must be a mapping of keys, got {type(raw).__name__}")
    try:
        cfg = DiagnosisConfig.model_validate(raw)
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc, str(p))) from None
    check_device(cfg.device, f"{p}: device", present=False)  # present here: checked when it runs
    return cfg, p.parent
