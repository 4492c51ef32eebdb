"""The strict schema of a campaign config (``warpdem calibrate CONFIG``), every section and
sub-section, checked at load before any DEM runs (:func:`calibration.campaign.parse_config`).

The types (:mod:`warpdem.config_schema`) refuse ``replicates: two``, ``fill_mass: true``,
``batch_worlds: 2.5``, a quoted number or an unknown key anywhere. What depends on other
sections is checked after by :func:`calibration.campaign.parse_config` (parameter names and
ranges against the contact law's declarations, each response's experiment built with its
settings, unique response names, one tolerance per response, DEM targets naming every
calibrated parameter, target files and conditions that exist, VTK samples inside the design).
"""
from __future__ import annotations

import numbers
from typing import Annotated, Any, Literal, Mapping, Union

from pydantic import Discriminator, Field, Tag, ValidationInfo, field_validator

from warpdem import ConfigError
from warpdem.config_io import parse_processes
from warpdem.config_schema import Flag, Number, Pair, Section, Text, WholeNumber

__all__ = ["CampaignFile", "ResponseSection", "TargetFromFile", "TargetFromDEM", "VtkOutput", "CheckpointSettings",
           "SECTIONS_ALLOWED_EMPTY"]

#: sections a YAML file may leave empty (``confirmation:``): their defaults
SECTIONS_ALLOWED_EMPTY = ("optimisation", "confirmation", "sensitivity", "surrogate", "design", "checkpoints", "fixed")


class VtkOutput(Section):
    """Config section ``vtk``: which DEM runs of a campaign write a ParaView time series
    (``particles.pvd`` and ``wall_<name>.pvd`` with the experiment's VTK fields).

    every: simulated time between frames [s]. samples: design sample indices to record (default
    none). replicate: which of a sample's loose fills (world) to record, when a response runs
    ``replicates`` > 1. targets / confirmation / validation: also record the first DEM run of each
    response's DEM target, of each confirmation round, of the validation. folder: under the
    campaign's output folder (or absolute); one sub-folder per run, e.g. ``sample_003/<response>``.
    """

    every: Number = Field(gt=0)
    samples: list[WholeNumber] = Field(default_factory=list)
    replicate: WholeNumber = Field(0, ge=0)
    targets: Flag = False
    confirmation: Flag = False
    validation: Flag = False
    folder: Text = Field("vtk", min_length=1)

    @field_validator("samples")
    @classmethod
    def _inside_design(cls, v: list[int], info: ValidationInfo) -> list[int]:
        n = (info.context or {}).get("design_samples")
        bad = [i for i in v if i < 0 or (n is not None and i >= n)]
        if bad:
            raise ValueError(f"sample index(es) {bad} outside the design" +
                             (f" (design.samples = {n}: indices 0-{n - 1})" if n is not None else " (indices start at 0)"))
        if len(set(v)) != len(v):
            raise ValueError(f"sample index(es) listed twice: {sorted({i for i in v if v.count(i) > 1})}")
        return sorted(v)


class CheckpointSettings(Section):
    """Config section ``checkpoints``: a campaign's batches save their simulation into
    ``<output>/checkpoints/`` while they run, so a killed campaign resumes mid-batch
    (:class:`calibration.experiments.checkpoints.BatchCheckpoints`; docs/campaign_records.md).

    enabled: checkpoint the batches (default true). every_s: wall-clock seconds between saves [s]
    (>= 0; a save also ends every batch's protocol)."""

    enabled: Flag = True
    every_s: Number = Field(120.0, ge=0)


def _tolerance(value: Any) -> Any:
    """``tolerance_deg``: a number > 0, or a list of them (one per response)."""
    items = value if isinstance(value, list) else [value]
    if not items:
        raise ValueError("must be > 0 deg: a number, or a list of one per response")
    for x in items:
        if isinstance(x, bool) or not isinstance(x, numbers.Real) or not 0 < float(x) < float("inf"):
            raise ValueError("must be > 0 deg: a finite number, or a list of one per response")
    return [float(x) for x in value] if isinstance(value, list) else float(value)


class Optimisation(Section):
    pop_size: WholeNumber = Field(100, ge=4)
    n_generations: WholeNumber = Field(100, ge=1)
    seed: WholeNumber = Field(1, ge=0)
    tolerance_deg: Annotated[Any, Field(validate_default=False)] = None
    n_dense: WholeNumber = Field(50_000, ge=100)

    @field_validator("tolerance_deg")
    @classmethod
    def _positive(cls, v: Any) -> Any:
        return None if v is None else _tolerance(v)


class Confirmation(Section):
    runs: WholeNumber = Field(1, ge=1)
    refine_rounds: WholeNumber = Field(0, ge=0)


class Sensitivity(Section):
    n: WholeNumber = Field(4096, ge=16)


class Surrogate(Section):
    n_splits: WholeNumber = Field(5, ge=2)
    n_repeats: WholeNumber = Field(2, ge=1)


class Design(Section):
    samples: WholeNumber = Field(24, ge=2)
    held_out: WholeNumber = Field(6, ge=0)
    seed: WholeNumber = Field(0, ge=0)


class TargetFromFile(Section):
    """A target measured in the lab: ``{file, experiment, condition}`` of a measurement file
    (relative to the working folder, else to the config's folder)."""

    file: Text = Field(min_length=1)
    experiment: Text
    condition: Text


class TargetFromDEM(Section):
    """A target made by the DEM at known parameters (a recovery test): ``{dem_at: {...}, runs}``."""

    dem_at: dict[Text, Number] = Field(min_length=1)
    runs: WholeNumber = Field(1, ge=1)


def _target_kind(value: Any) -> str | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, numbers.Real):
        return "(angle)"
    if isinstance(value, Mapping):
        return "(file)" if "file" in value else "(dem_at)" if "dem_at" in value else None
    return None


Target = Annotated[
    Union[Annotated[Annotated[Number, Field(gt=0, lt=90)], Tag("(angle)")],
          Annotated[TargetFromFile, Tag("(file)")],
          Annotated[TargetFromDEM, Tag("(dem_at)")]],
    Discriminator(_target_kind, custom_error_type="target",
                  custom_error_message="must be an angle in deg (0-90), {file: ..., experiment: ..., condition: ...} "
                                       "(a measurement file) or {dem_at: {parameter: value, ...}, runs: N}")]


class ResponseSection(Section):
    """One response (``responses[i]``, ``validation``): an experiment, its settings, its target."""

    name: Text = Field(min_length=1)
    experiment: Text
    scale: Text = "quick"
    settings: dict[Text, Any] = Field(default_factory=dict)
    target: Target
    replicates: WholeNumber = Field(1, ge=1)

    @field_validator("settings")
    @classmethod
    def _no_vtk(cls, v: dict[str, Any]) -> dict[str, Any]:
        vtk_keys = sorted(k for k in v if k.startswith("vtk_"))
        if vtk_keys:
            raise ValueError(f"{vtk_keys}: a campaign asks for VTK output in its top-level 'vtk' section "
                             "(vtk: {every: 0.05, samples: [0]}), which gives every run its own folder")
        return v


def _processes(value: Any) -> Any:
    try:
        return parse_processes(value)
    except ConfigError:
        raise ValueError("must be a whole number >= 1 or 'auto'") from None


class CampaignFile(Section):
    """The whole campaign config (documented in ``calibration/configs/quick_calibration.yaml``)."""

    name: Text | None = None
    device: Text | None = None
    processes: Annotated[Any, Field(validate_default=False)] = "auto"
    executor: Any = None
    output: Text = Field("results/calibration", min_length=1)
    contact_law: Any = None
    material: Any = None
    plugins: Any = None
    parameters: dict[Text, Pair] = Field(min_length=1)
    fixed: dict[Text, Number] = Field(default_factory=dict)
    design: Design = Field(default_factory=Design)
    batch_worlds: WholeNumber = Field(8, ge=1)
    responses: list[ResponseSection] = Field(min_length=1)
    validation: ResponseSection | None = None
    optimisation: Optimisation = Field(default_factory=Optimisation)
    confirmation: Confirmation = Field(default_factory=Confirmation)
    surrogate: Surrogate = Field(default_factory=Surrogate)
    sensitivity: Sensitivity = Field(default_factory=Sensitivity)
    fills: Literal["independent", "shared"] = "independent"
    vtk: VtkOutput | None = None
    checkpoints: CheckpointSettings = Field(default_factory=CheckpointSettings)

    @field_validator("processes")
    @classmethod
    def _processes_ok(cls, v: Any) -> Any:
        return _processes(v)
