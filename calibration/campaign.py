"""Calibration campaign: design -> DEM runs (batched as worlds) -> surrogate -> NSGA-II ->
sensitivity -> confirmation runs -> validation on another experiment (seed paper, Fig. 9).

Data flows one way and every stage writes what it produced into the output folder:

==========================  ===================================================================
``samples.jsonl``           one line per (design sample, response) DEM result as it arrives;
                            an interrupted campaign resumes from it and loses nothing; failed
                            runs are kept with their error (never dropped silently)
``runs.jsonl``              one line per DEM target, confirmation round and validation run, so
                            that a re-run does not repeat them
``sittings.json``           start and wall time of every sitting (the total is their sum)
``results.json``            every number: design, surrogate CV choice and held-out metrics,
                            NSGA-II Pareto set and compromise, acceptable set ranges, Sobol
                            indices, confirmation and validation runs with relative errors
``*.png``                   predicted vs simulated, acceptable set, sensitivity
``summary.md``              a short human-readable account
``vtk/``                    on request (config section ``vtk``): ParaView ``.pvd`` series of
                            chosen design samples, targets, confirmation and validation runs
``checkpoints/``            the simulation of the batch under way (config section
                            ``checkpoints``), so a killed campaign resumes mid-batch; removed
                            once the batch is recorded (docs/campaign_records.md)
==========================  ===================================================================

Every record carries a fingerprint of what determines it (parameters, experiment and settings,
material, contact law, plugins, fixed parameters, fills, code version: :mod:`calibration.campaign_records`);
a resume refuses records whose setup differs from the config, naming the difference.

The configuration (YAML/JSON) is documented in ``calibration/configs/quick_calibration.yaml``.
"""
from __future__ import annotations

import dataclasses
import itertools
import json
import os
import sys
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np
import warp as wp

import warpdem as wd
from warpdem import ConfigError
from warpdem.config_io import check_device, check_output_folder, load_config_file, positive_int_arg
from warpdem.config_schema import raise_problems, validate_section

from .campaign_records import (RECORD_FORMAT, append_records, code_version, describe_differences, fingerprint,
                               is_campaign_record, plain, plugin_hashes, read_records, write_atomic)
from .campaign_schema import (SECTIONS_ALLOWED_EMPTY, CampaignFile, CheckpointSettings, ResponseSection,
                              TargetFromDEM, TargetFromFile, VtkOutput)
from .designs import Parameter, ParameterSpace, latin_hypercube
from .experiments import make_experiment
from .experiments.checkpoints import BatchCheckpoints, clear_checkpoints
from .executor import RayExecutor, executor_from_config
from .experiments.common import _jsonable, cpu_processes
from .measurement.errors import MeasurementError
from .measurement.records import load_measurements
from .model_description import ModelDescription

if TYPE_CHECKING:
    from .optimisation import CalibrationResult, NSGA2Settings
    from .surrogates import CVSurrogate

FILL_MODES = ("independent", "shared")
# first loose-fill index of each kind of DEM run when fills are independent: design sample i uses
# fills i*replicates ..., so the target, the confirmation rounds and the validation never reuse a
# fill of the design or of each other (no accidental common random numbers)
TARGET_FILLS, CONFIRMATION_FILLS, VALIDATION_FILLS = 1_000_000, 2_000_000, 3_000_000


# ----------------------------------------------------------------------------- configuration
@dataclass
class Response:
    """A measured response: an experiment, its settings, and the target it must match [deg]."""

    name: str
    experiment: str
    scale: str = "quick"
    settings: dict[str, Any] = field(default_factory=dict)
    target: Any = None  # float [deg], {file, experiment, condition}, or {dem_at: {parameters}, runs}
    replicates: int = 1  # DEM runs per sample with different loose fills (extra worlds), averaged
    target_deg: float | None = None
    target_std_deg: float | None = None
    target_source: str = ""


@dataclass
class CampaignConfig:
    name: str
    space: ParameterSpace
    responses: list[Response]
    validation: Response | None = None
    fixed: dict[str, float] = field(default_factory=dict)
    model: ModelDescription = field(default_factory=ModelDescription)
    samples: int = 24
    held_out: int = 6
    seed: int = 0
    batch_worlds: int = 8
    device: str | None = None
    processes: int | str = "auto"
    executor: Any = None  # calibration.executor: local processes (None) or a Ray cluster
    fills: str = "independent"  # "independent": a new loose fill for every world; "shared": one fill per batch
    output: str = "results/calibration"
    optimisation: dict[str, Any] = field(default_factory=dict)
    confirmation_runs: int = 1
    refine_rounds: int = 0
    surrogate: dict[str, Any] = field(default_factory=dict)
    sobol_n: int = 2**12
    vtk: VtkOutput | None = None  # ParaView series of chosen runs (config section ``vtk``)
    checkpoints: CheckpointSettings = field(default_factory=CheckpointSettings)
    # where batches checkpoint (set by Campaign to <output>/checkpoints when enabled; None: nowhere)
    checkpoint_folder: Path | None = None
    base_dir: Path = Path(".")


def _response_of(section: ResponseSection) -> Response:
    target = section.target
    if isinstance(target, (TargetFromFile, TargetFromDEM)):
        target = target.model_dump()
    return Response(name=section.name, experiment=section.experiment, scale=section.scale,
                    settings=dict(section.settings), target=target, replicates=section.replicates)


def _response(d: Any, where: str) -> Response:
    """One response section (``responses[i]`` or ``validation``) checked by its schema."""
    return _response_of(validate_section(ResponseSection, d, where))


def target_file(target: Mapping[str, Any], base_dir: Path) -> Path:
    """The measurement file of a ``{file, experiment, condition}`` target: relative to the working
    folder if it is there, else to the config's folder ``base_dir``."""
    path = Path(target["file"])
    return path if path.is_absolute() or path.exists() else base_dir / path


def load_config(path: str | os.PathLike) -> CampaignConfig:
    """Read and check a campaign configuration; every error names the offending key."""
    path = Path(path)
    raw = load_config_file(path, "calibration config")
    return parse_config(raw, base_dir=path.parent, source=str(path))


def _model_problems(raw: Mapping[str, Any], doc: CampaignFile, base_dir: Path,
                    problems: list[str]) -> tuple[ModelDescription | None, list[Parameter], dict[str, float]]:
    """The model (contact law, material, plugins), the calibrated parameters (names declared by
    the law or the material's shape family, ranges within their admissible bounds) and the fixed
    ones; each problem appended to ``problems``."""
    try:
        model = ModelDescription.from_config(raw, base_dir=base_dir)
    except ConfigError as exc:
        problems.append(str(exc))
        return None, [], {}
    plist, fixed = [], {}
    for name, bounds in doc.parameters.items():
        try:  # unknown names and ranges outside the sub-model's admissible bounds fail here, before any DEM
            lo, hi = model.check_bounds(name, list(bounds), "parameters")
        except ConfigError as exc:
            problems.append(str(exc))
            continue
        spec = model.parameter_specs()[name]
        plist.append(Parameter(name, lo, hi, spec.unit, spec.description))
    for name, value in doc.fixed.items():
        try:
            fixed[name] = model.check_value(name, value, "fixed")
        except ConfigError as exc:
            problems.append(str(exc))
    both = sorted(set(fixed) & set(doc.parameters))
    if both:
        problems.append(f"{both} both calibrated ('parameters') and fixed ('fixed'): keep each in one of them")
    return model, plist, fixed


def _response_problems(responses: Sequence[Response], cfg: CampaignConfig, doc: CampaignFile,
                       problems: list[str]) -> None:
    """Each response's experiment built with its settings and fill size (name, scale, setting
    names, types and values), its target (DEM targets: every calibrated parameter, values in
    their admissible ranges; file targets: the file, its experiment and condition exist) and the
    VTK replicate; each problem appended to ``problems``."""
    model = cfg.model
    names = [r.name for r in responses]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        problems.append(f"response name(s) {twice} given twice (responses and validation): each response's angles "
                        "are filed under its name, so names must be unique")
    for resp in responses:
        where = f"response '{resp.name}'"
        settings = dict(resp.settings)
        if model.material is not None and "material" not in settings:
            settings["material"] = model.material
        try:  # each experiment is built now, not when its DEM starts
            exp = make_experiment(resp.experiment, resp.scale, contact_law=model.contact_law, plugins=model.plugins,
                                  **settings)
            if exp.material is not None:  # the default (paper) material is checked when its run starts
                exp.check_size(cfg.batch_worlds * resp.replicates)
        except ConfigError as exc:
            problems.append(f"{where}: {exc}")
        t = resp.target
        if isinstance(t, Mapping) and "dem_at" in t:  # names and values now, not after the design ran
            for k, v in t["dem_at"].items():
                try:
                    model.check_value(k, v, f"{where} target dem_at")
                except ConfigError as exc:
                    problems.append(str(exc))
            calibrated = [p.name for p in cfg.space.parameters]
            missing = [p for p in calibrated if p not in t["dem_at"] and p not in cfg.fixed]
            if missing:
                problems.append(f"{where} target dem_at: no value for the calibrated parameter(s) {missing}; a DEM "
                                f"target needs every one of {calibrated}")
        elif isinstance(t, Mapping) and "file" in t:  # the file and its condition now (--max-samples never reads it)
            try:
                load_measurements(target_file(t, cfg.base_dir)).condition(t["experiment"], t["condition"])
            except (ConfigError, MeasurementError) as exc:
                problems.append(f"{where} target: {exc}")
        if cfg.vtk is not None and cfg.vtk.replicate >= resp.replicates:
            problems.append(f"vtk.replicate: {cfg.vtk.replicate} but {where} runs {resp.replicates} fill(s) per "
                            f"sample (replicate indices 0-{resp.replicates - 1})")


def parse_config(raw: Any, base_dir: Path = Path("."), source: str = "<config>") -> CampaignConfig:
    """A campaign config checked whole before any DEM runs: the schema
    (:class:`~calibration.campaign_schema.CampaignFile`: every section, key and type), then what
    depends on several sections; every problem is listed in one ConfigError naming ``source``."""
    if isinstance(raw, Mapping):
        raw = {k: v for k, v in raw.items() if not (k in SECTIONS_ALLOWED_EMPTY and v is None)}
    design = raw.get("design") if isinstance(raw, Mapping) else None
    n_design = design.get("samples", 24) if isinstance(design, Mapping) else None
    doc = validate_section(CampaignFile, raw, source,
                           context={"design_samples": n_design if isinstance(n_design, int) else None})
    problems: list[str] = []
    model, plist, fixed = _model_problems(raw, doc, base_dir, problems)
    if model is None or len(plist) < len(doc.parameters):  # the rest is checked against the model
        raise_problems(source, problems)
    opt = doc.optimisation.model_dump(exclude_unset=True)
    cfg = CampaignConfig(
        name=doc.name if doc.name is not None else Path(source).stem, space=ParameterSpace(tuple(plist)),
        responses=[_response_of(r) for r in doc.responses],
        validation=_response_of(doc.validation) if doc.validation is not None else None,
        fixed=fixed, model=model, samples=doc.design.samples, held_out=doc.design.held_out,
        seed=doc.design.seed, batch_worlds=doc.batch_worlds, device=doc.device, processes=doc.processes,
        fills=doc.fills, output=doc.output, optimisation=opt, confirmation_runs=doc.confirmation.runs,
        refine_rounds=doc.confirmation.refine_rounds, surrogate=doc.surrogate.model_dump(exclude_unset=True),
        sobol_n=doc.sensitivity.n, vtk=doc.vtk, checkpoints=doc.checkpoints, base_dir=base_dir)
    try:
        check_device(doc.device, "device", present=False)  # a GPU config loads anywhere; the run checks the device
    except ConfigError as exc:
        problems.append(str(exc))
    _response_problems(cfg.responses + ([cfg.validation] if cfg.validation else []), cfg, doc, problems)
    tol = opt.get("tolerance_deg")
    if isinstance(tol, list) and len(tol) != len(cfg.responses):
        problems.append(f"optimisation.tolerance_deg has {len(tol)} value(s) for {len(cfg.responses)} response(s) "
                        f"{[r.name for r in cfg.responses]}: give one per response, in their order, or a single number")
    if not cfg.held_out < cfg.samples - len(plist):
        problems.append(f"design.held_out ({cfg.held_out}) must leave more training samples than parameters "
                        f"({cfg.samples} samples, {len(plist)} parameters)")
    try:
        cpu_processes(cfg.processes, "cpu")
        cfg.executor = executor_from_config(doc.executor, cfg.processes, "executor")
    except ConfigError as exc:
        problems.append(str(exc))
    raise_problems(source, problems)
    return cfg


# ----------------------------------------------------------------------------- DEM runs
def run_response(resp: Response, parameter_sets: list[dict[str, float]], cfg: CampaignConfig,
                 progress: bool = False, first_fill: int = 0,
                 vtk_folder: str | os.PathLike | None = None) -> list[dict[str, Any]]:
    """Run one experiment with one world per (parameter set, replicate); returns one record per
    parameter set with the replicate mean (``angle_deg``), the replicate angles and their spread.

    With ``cfg.fills == "independent"`` every world gets its own loose fill, numbered from
    ``first_fill`` (world k uses fill ``first_fill + k``), so that the design, the target, the
    confirmation and the validation runs never share a fill. With ``"shared"`` one fill serves a
    whole batch (replicates still get a fill each, numbered from 0), a common-random-numbers
    design: the surrogate sees a smoother response, biased by that one fill. At small particle
    counts the angle is a rough function of the parameters, and the fill-to-fill spread is the
    noise floor any calibration against this experiment can reach.

    ``vtk_folder``: write a ParaView series of world ``cfg.vtk.replicate`` (every ``cfg.vtk.every``
    simulated seconds) into this folder; the experiment then runs in one process.

    ``cfg.checkpoint_folder`` (set by :class:`Campaign`): the batch checkpoints there every
    ``cfg.checkpoints.every_s`` wall seconds and continues a checkpoint of this very batch; the
    checkpoint stays until the caller has recorded the results (:func:`clear_checkpoints`). A run
    that writes VTK is not checkpointed."""
    r = resp.replicates
    settings = dict(resp.settings)
    if vtk_folder is not None:
        if cfg.vtk is None:
            raise ValueError("run_response: vtk_folder given but the config has no 'vtk' section")
        settings.update(vtk_every=cfg.vtk.every, vtk_world=cfg.vtk.replicate, vtk_folder=str(vtk_folder))
    if cfg.fills == "independent":
        settings["fill_per_world"] = True
        settings["first_fill_index"] = int(first_fill)
    elif r > 1:
        settings["fill_per_world"] = True
    model = cfg.model
    if model.material is not None and "material" not in settings:
        settings["material"] = model.material
    exp = make_experiment(resp.experiment, resp.scale, contact_law=model.contact_law, plugins=model.plugins,
                          **settings)
    sets = [{**cfg.fixed, **p} for p in parameter_sets for _ in range(r)]
    t0 = time.perf_counter()
    checkpoints = None
    if cfg.checkpoint_folder is not None and vtk_folder is None:
        checkpoints = BatchCheckpoints(cfg.checkpoint_folder, cfg.checkpoints.every_s, keep_until_recorded=True)
    try:
        results = exp.run(sets, device=cfg.device, progress=progress, processes=cfg.processes,
                          checkpoints=checkpoints, executor=cfg.executor)
    except (wd.StabilityError, wd.ContactOverflowError) as exc:  # the whole batch failed
        return [dict(status="failed", error=f"{type(exc).__name__}: {exc}", angle_deg=None) for _ in parameter_sets]
    wall = time.perf_counter() - t0
    out = []
    for k in range(len(parameter_sets)):
        group = results[k * r:(k + 1) * r]
        angles = [g.angle_deg for g in group if g.ok and g.angle_deg is not None]
        errors = [g.error for g in group if not g.ok]
        rec = dict(status="ok" if angles else "failed", error="; ".join(e for e in errors if e) or None,
                   angle_deg=float(np.mean(angles)) if angles else None, replicate_angles_deg=angles,
                   replicate_std_deg=float(np.std(angles, ddof=1)) if len(angles) > 1 else None,
                   wall_s=round(wall, 2), worlds=len(sets))
        out.append(rec)
    return out


def _calls(n_sets: int, record: Mapping[int, Any]) -> list[tuple[int, int]]:
    """How :func:`run_recorded` splits ``n_sets`` parameter sets into calls of
    :func:`run_response`: ``(start, end)`` ranges; a set at a position in ``record`` runs alone."""
    calls, k = [], 0
    while k < n_sets:
        if k in record:
            calls.append((k, k + 1))
            k += 1
            continue
        end = next((j for j in range(k, n_sets) if j in record), n_sets)
        calls.append((k, end))
        k = end
    return calls


def run_recorded(resp: Response, parameter_sets: list[dict[str, float]], cfg: CampaignConfig,
                 first_fill: int = 0, record: Mapping[int, Path] | None = None,
                 progress: bool = False) -> list[dict[str, Any]]:
    """:func:`run_response`, except that each parameter set at a position in ``record`` runs as a
    batch of its own writing its VTK series into ``record[position]``; the other sets run in
    contiguous batches as before. Every set keeps its loose fills (with independent fills, the set
    at position k uses fills ``first_fill + k * replicates ...`` however the batch is split).
    Records of recorded sets carry ``vtk``: the series' folder; every record carries
    ``dem_wall_share_s``, its share of its call's wall time [s] (their sum is the DEM time)."""
    record = {k: v for k, v in (record or {}).items() if 0 <= k < len(parameter_sets)}
    r = resp.replicates
    out: list[dict[str, Any]] = []
    for start, end in _calls(len(parameter_sets), record):
        if start in record:
            recs = run_response(resp, parameter_sets[start:end], cfg, progress=progress,
                                first_fill=first_fill + start * r, vtk_folder=record[start])
            recs = [dict(rec, vtk=str(record[start])) for rec in recs]
        else:
            recs = run_response(resp, parameter_sets[start:end], cfg, progress=progress, first_fill=first_fill + start * r)
        out += [dict(rec, dem_wall_share_s=round(float(rec.get("wall_s") or 0.0) / (end - start), 3)) for rec in recs]
    return out


def planned_fills(cfg: CampaignConfig, resp: Response, n_sets: int, first_fill: int = 0,
                  record: Mapping[int, Any] | None = None) -> list[list[int] | str]:
    """The loose-fill indices each of ``n_sets`` parameter sets gets from :func:`run_recorded`
    (world fills are seeded by the experiment's ``seed`` setting and the index). Independent
    fills: set k uses ``first_fill + k * replicates + j``. Shared fills: one fill per call
    (``"shared"``), or with replicates fill ``w`` for world ``w`` of its call."""
    r = resp.replicates
    if cfg.fills == "independent":
        return [[first_fill + k * r + j for j in range(r)] for k in range(n_sets)]
    if r == 1:
        return ["shared"] * n_sets
    rec = {k: None for k in (record or {}) if 0 <= k < n_sets}
    return [[(k - start) * r + j for j in range(r)] for start, end in _calls(n_sets, rec) for k in range(start, end)]


def setup_components(cfg: CampaignConfig, resp: Response) -> dict[str, Any]:
    """What determines every DEM result of ``resp`` in this campaign except the parameter values
    and fill indices (the ``setup`` part of a record's fingerprint: :mod:`calibration.campaign_records`)."""
    law = cfg.model.contact_law
    return plain({
        "format": RECORD_FORMAT,
        "experiment": dict(name=resp.experiment, scale=resp.scale, settings=plain(resp.settings, numbers_as_float=True),
                           replicates=resp.replicates),
        "material": ("the experiment's scale default" if cfg.model.material is None
                     else plain(cfg.model.material.describe(), numbers_as_float=True)),
        "contact_law": law.describe() + ("" if law.track_wear else "+track_wear:off"),
        "plugins": plugin_hashes(cfg.model.plugins, law),
        "fixed": plain(cfg.fixed, numbers_as_float=True),
        "fills": cfg.fills,
        "code": code_version(),
    })


def determined_by(cfg: CampaignConfig, resp: Response, parameters: Any, fills: Any) -> dict[str, Any]:
    """A record's ``determined_by``: the response's setup and this record's point (parameter
    values, one mapping or a list of them, and loose-fill indices)."""
    return {"setup": setup_components(cfg, resp), "point": plain({"parameters": parameters, "fills": fills})}


RunGroup = Callable[[Response, list[dict[str, float]], int, "Mapping[int, Path] | None"], list[dict[str, Any]]]


def resolve_target(resp: Response, cfg: CampaignConfig, log, vtk_folder: Path | None = None,
                   run: RunGroup | None = None) -> None:
    """Fill ``resp.target_deg`` from a number, a measurement file, or a DEM run at known parameters
    (``vtk_folder``: the first of those runs writes its VTK series there). ``run(resp,
    parameter_sets, first_fill, record)`` runs the DEM (default :func:`run_recorded`; a campaign
    passes one that records the runs and reuses a recorded one)."""
    t = resp.target
    if t is None:
        raise ConfigError(f"response '{resp.name}': no target given")
    if isinstance(t, (int, float)):
        resp.target_deg, resp.target_source = float(t), "config"
        return
    if not isinstance(t, Mapping):
        raise ConfigError(f"response '{resp.name}': target must be a number or a mapping, got {t!r}")
    if "file" in t:
        path = target_file(t, cfg.base_dir)
        for k in ("experiment", "condition"):
            if k not in t:
                raise ConfigError(f"response '{resp.name}': target from a file needs '{k}'")
        stats = load_measurements(path).condition(t["experiment"], t["condition"]).stats()
        resp.target_deg, resp.target_std_deg = float(stats.mean_deg), stats.std_deg
        resp.target_source = f"{path}: {t['experiment']}/{t['condition']} (n = {stats.n})"
        return
    if "dem_at" in t:
        bad = set(t) - {"dem_at", "runs"}
        if bad:
            raise ConfigError(f"response '{resp.name}': target: unknown key(s) {sorted(bad)}; valid: ['dem_at', 'runs']")
        truth = {k: float(v) for k, v in t["dem_at"].items()}
        runs = int(t.get("runs", 1))
        if runs < 1:
            raise ConfigError(f"response '{resp.name}': target runs must be >= 1, got {runs}")
        log(f"target '{resp.name}': DEM at known parameters {truth}, {runs} run(s) x {resp.replicates} fill(s)")
        if run is None:
            def run(resp_, sets, first_fill, record):
                return run_recorded(resp_, sets, cfg, first_fill=first_fill, record=record)
        recs = run(resp, [truth] * runs, TARGET_FILLS, {0: vtk_folder} if vtk_folder is not None else None)
        angles = [a for rec in recs if rec["status"] == "ok" for a in rec["replicate_angles_deg"]]
        if len(angles) < runs * resp.replicates:
            errs = "; ".join(str(rec["error"]) for rec in recs if rec["error"])
            raise ConfigError(f"response '{resp.name}': a DEM run producing the target failed: {errs} (recorded; "
                              "--retry-failed runs it again)")
        resp.target_deg = float(np.mean(angles))
        resp.target_std_deg = float(np.std(angles, ddof=1)) if len(angles) > 1 else None
        resp.target_source = f"DEM at {truth}, mean of {len(angles)} loose fill(s)"
        return
    raise ConfigError(f"response '{resp.name}': target mapping needs 'file' or 'dem_at', got keys {sorted(t)}")


def _fill_contiguous_batches(indices: Sequence[int], size: int) -> list[list[int]]:
    """Split sorted sample indices into batches of at most ``size`` consecutive indices, so that
    each sample keeps its own fills (a batch's worlds take consecutive fill numbers) even when a
    resumed campaign runs only the samples missing here and there."""
    batches: list[list[int]] = []
    for i in indices:
        if batches and len(batches[-1]) < size and batches[-1][-1] == i - 1:
            batches[-1].append(i)
        else:
            batches.append([i])
    return batches


# ----------------------------------------------------------------------------- the campaign
NEW_FOLDER_HINT = ("Run into a new output folder (--out NEW_DIR, or --new-folder to use the first of <output>-2, "
                   "<output>-3, ... whose records fit); the records here are left as they are.")


def _record_label(rec: Mapping[str, Any]) -> str:
    if "index" in rec:
        return f"sample {rec['index']} of response '{rec.get('response')}'"
    return f"{rec.get('kind', 'run')} of response '{rec.get('response')}'"


class Campaign:
    """Runs a :class:`CampaignConfig` end to end, resumably, into ``output``.

    ``retry_failed``: run again the design samples and the targets / confirmation / validation
    runs recorded as failed (their old records stay; the newest is used)."""

    def __init__(self, cfg: CampaignConfig, output: str | os.PathLike | None = None, verbose: bool = True,
                 retry_failed: bool = False) -> None:
        self.out = Path(output or cfg.output)
        self.out.mkdir(parents=True, exist_ok=True)
        # batches checkpoint into <output>/checkpoints (a copy of the config carries the folder)
        self.checkpoint_folder = self.out / "checkpoints" if cfg.checkpoints.enabled else None
        self.cfg = dataclasses.replace(cfg, checkpoint_folder=self.checkpoint_folder)
        self.verbose = verbose
        self.retry_failed = retry_failed
        self.samples_path = self.out / "samples.jsonl"
        self.runs_path = self.out / "runs.jsonl"
        self.sittings_path = self.out / "sittings.json"
        self.refine_rounds = cfg.refine_rounds
        # this sitting: written into sittings.json with its wall time after every record
        self.sitting_id = f"{time.strftime('%Y%m%dT%H%M%S')}-{uuid.uuid4().hex[:6]}"
        self._sitting_t0 = time.perf_counter()
        self._sitting_started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        self._sample_records: list[dict[str, Any]] = []  # every line of samples.jsonl, in order
        self._run_records: list[dict[str, Any]] = []     # every line of runs.jsonl, in order

    def vtk_folder(self, kind: str, response: str) -> Path:
        """Folder of one run's VTK series: ``<output>/<vtk.folder>/<kind>/<response>`` (kind e.g.
        ``sample_003``, ``target``, ``confirmation_round0``, ``validation``)."""
        assert self.cfg.vtk is not None
        return self.out / self.cfg.vtk.folder / kind / response

    def log(self, msg: str) -> None:
        if self.verbose:
            print(f"[calibrate {time.strftime('%H:%M:%S')}] {msg}", flush=True)

    #: what :meth:`design` gives, in words (results.json and summary.md)
    design_kind = "Latin hypercube samples"

    def design(self) -> np.ndarray:
        """The design points, one row per sample in the order of ``cfg.space`` (a subclass may
        give fixed points instead of the Latin hypercube: calibration/reproduction.py)."""
        return latin_hypercube(self.cfg.space, self.cfg.samples, seed=self.cfg.seed)

    def held_out_mask(self, n: int) -> np.ndarray:
        """Which of the ``n`` design samples only test the surrogate (True: held out): the last
        ``cfg.held_out`` ones (a subclass with fixed points may hold out others, e.g. the seed
        paper's validation rows: calibration/reproduction.py)."""
        return np.arange(n) >= n - self.cfg.held_out

    # ------------------------------------------------------------------ records
    def _read(self) -> tuple[list[tuple[int, dict]], list[tuple[int, dict]]]:
        """Both record files as ``(line number, record)``; a torn last line is cut off (logged)."""
        samples = read_records(self.samples_path, self.log, is_campaign_record)
        runs = read_records(self.runs_path, self.log, is_campaign_record)
        self._sample_records = [rec for _, rec in samples]
        self._run_records = [rec for _, rec in runs]
        return samples, runs

    def _done(self) -> dict[tuple[int, str], dict]:
        """The newest record of every (design sample, response) in ``samples.jsonl``."""
        samples, _ = self._read()
        return {(rec["index"], rec["response"]): rec for _, rec in samples}

    def _responses_by_name(self) -> dict[str, Response]:
        return {r.name: r for r in self.cfg.responses + ([self.cfg.validation] if self.cfg.validation else [])}

    def check_records(self) -> dict[tuple[int, str], dict]:
        """Read ``samples.jsonl`` and ``runs.jsonl`` and refuse (ConfigError) to reuse records that
        do not belong to this config: a record without a fingerprint (record format 1), a record
        whose fingerprint does not match its contents (edited or damaged), a record whose setup
        (experiment and settings, material, contact law, plugins, fixed parameters, fill mode,
        code version) differs from this config's (every difference named, recorded vs config), or
        design samples of another design (:meth:`_check_records_match_design`). Returns the newest
        record of every (design sample, response)."""
        samples, runs = self._read()
        setups = {name: setup_components(self.cfg, resp) for name, resp in self._responses_by_name().items()}
        differences: dict[str, set[str]] = {}
        for path, lines in ((self.samples_path, samples), (self.runs_path, runs)):
            for line_no, rec in lines:
                where = f"{path}: line {line_no} ({_record_label(rec)})"
                if "fingerprint" not in rec or not isinstance(rec.get("determined_by"), Mapping):
                    raise ConfigError(f"{where} has no fingerprint: it was written by a warpdem that did not record "
                                      "what determines a result (record format 1), so it cannot be checked against "
                                      f"this config and is not reused. {NEW_FOLDER_HINT}")
                if fingerprint(rec["determined_by"]) != rec["fingerprint"]:
                    raise ConfigError(f"{where}: its fingerprint does not match what it records as determining it; "
                                      f"the file was edited or damaged. {NEW_FOLDER_HINT}")
                name = rec.get("response")
                if name not in setups:  # samples: named by the design check; runs: not used
                    continue
                for line in describe_differences(rec["determined_by"].get("setup") or {}, setups[name]):
                    differences.setdefault(line, set()).add(name)
        if differences:
            lines = []
            for line, names in differences.items():
                lines.append(f"  response(s) {', '.join(sorted(names))}: {line}" if line.startswith("experiment ")
                             else f"  {line}")
            raise ConfigError(f"{self.out}: the records here were made with another setup than this config, so a "
                              f"resume would mix their results with new ones:\n" + "\n".join(sorted(set(lines))) +
                              f"\n{NEW_FOLDER_HINT}")
        done = {(rec["index"], rec["response"]): rec for _, rec in samples}
        self._check_records_match_design(done, self.design(), [p.name for p in self.cfg.space.parameters])
        return done

    def _check_records_match_design(self, done: Mapping[tuple[int, str], dict], X: np.ndarray,
                                    names: Sequence[str]) -> None:
        """Refuse records made with another design (other ranges, seed, sample count or response
        names): matched by sample number alone they would pair new points with old angles."""
        responses = {r.name for r in self.cfg.responses}
        for (i, name), rec in sorted(done.items()):
            where = f"{self.samples_path}: sample {i} of response '{name}'"
            if name not in responses:
                raise ConfigError(f"{where}: this config has no such response ({sorted(responses)}); the records "
                                  "belong to another campaign: use a new output folder (--out)")
            if i >= len(X):
                raise ConfigError(f"{where}: the design now has only {len(X)} samples; the records belong to "
                                  "another design: use a new output folder (--out)")
            given = rec.get("parameters") or {}
            for j, n in enumerate(names):
                v = given.get(n)
                if v is None or not np.isclose(float(v), X[i, j], rtol=1e-9, atol=1e-12):
                    raise ConfigError(f"{where}: recorded {n} = {v} but the design now has {X[i, j]:.6g}; the "
                                      "design changed (range, seed or sample count) since these records were "
                                      "made: use a new output folder (--out) or delete samples.jsonl")

    def sample_record(self, resp: Response, index: int, parameters: Mapping[str, float], fills: Any,
                      result: Mapping[str, Any]) -> dict[str, Any]:
        """The ``samples.jsonl`` record of design sample ``index`` of ``resp``: the DEM result,
        the parameter values, the device, the sitting, ``determined_by`` and ``fingerprint``."""
        by = determined_by(self.cfg, resp, dict(parameters), fills)
        rec = dict(index=int(index), response=resp.name, parameters=dict(parameters), **result)
        if rec.get("vtk"):  # the series' folder, relative to the output folder
            rec["vtk"] = os.path.relpath(rec["vtk"], self.out)
        rec.update(device=str(self.cfg.device or ("cuda" if wp.is_cuda_available() else "cpu")),
                   sitting=self.sitting_id, determined_by=by, fingerprint=fingerprint(by))
        return plain(rec)

    def run_group(self, kind: str, resp: Response, parameter_sets: list[dict[str, float]], first_fill: int,
                  record: Mapping[int, Path] | None = None, round_: int = 0) -> list[dict[str, Any]]:
        """:func:`run_recorded` for a DEM target, a confirmation round or the validation
        (``kind``), recorded in ``runs.jsonl``: a run recorded with the same fingerprint (same
        setup, parameter sets and fills) is returned instead of run again (a failed one too,
        unless ``retry_failed``). A recorded run writes no VTK series."""
        fills = planned_fills(self.cfg, resp, len(parameter_sets), first_fill, record)
        by = determined_by(self.cfg, resp, [dict(p) for p in parameter_sets], fills)
        fp = fingerprint(by)
        for rec in reversed(self._run_records):
            if rec.get("kind") == kind and rec.get("response") == resp.name and rec.get("fingerprint") == fp:
                if self.retry_failed and any(r.get("status") != "ok" for r in rec["results"]):
                    break
                self.log(f"{kind} {resp.name}: recorded in {self.runs_path.name} (sitting {rec.get('sitting')}), "
                         "not run again")
                return rec["results"]
        results = run_recorded(resp, parameter_sets, self.cfg, first_fill=first_fill, record=record)
        results = [dict(r, vtk=os.path.relpath(r["vtk"], self.out)) if r.get("vtk") else r for r in results]
        rec = plain(dict(kind=kind, response=resp.name, round=round_, parameter_sets=parameter_sets, results=results,
                         device=str(self.cfg.device or ("cuda" if wp.is_cuda_available() else "cpu")),
                         sitting=self.sitting_id, determined_by=by, fingerprint=fp))
        append_records(self.runs_path, [rec])
        self._run_records.append(rec)
        self._clear_checkpoints()
        self.note_sitting()
        return rec["results"]

    def _clear_checkpoints(self) -> None:
        """Remove the batch checkpoints once a batch's results are recorded (batches run one
        after another, so every checkpoint in the folder belongs to the batch just recorded or
        to an abandoned one)."""
        if self.checkpoint_folder is not None:
            clear_checkpoints(self.checkpoint_folder)

    # ------------------------------------------------------------------ wall time over sittings
    def _sittings(self) -> list[dict[str, Any]]:
        """The sittings recorded in ``sittings.json`` other than this one."""
        if not self.sittings_path.exists():
            return []
        try:
            items = json.loads(self.sittings_path.read_text())
            assert isinstance(items, list) and all(isinstance(x, dict) and "wall_s" in x for x in items)
        except (ValueError, AssertionError):
            kept = self.sittings_path.with_name(self.sittings_path.name + ".damaged")
            os.replace(self.sittings_path, kept)
            self.log(f"{self.sittings_path}: unreadable, moved to {kept.name}; the total wall time counts this "
                     "sitting on")
            return []
        return [x for x in items if x.get("id") != self.sitting_id]

    def note_sitting(self, finished: bool = False) -> list[dict[str, Any]]:
        """Write this sitting's wall time so far [s] into ``sittings.json`` (atomically, after every
        record, so a killed sitting counts up to its last record); returns every sitting."""
        me = dict(id=self.sitting_id, started=self._sitting_started, wall_s=round(time.perf_counter() - self._sitting_t0, 1), finished=finished)
        items = self._sittings() + [me]
        write_atomic(self.sittings_path, json.dumps(items, indent=1) + "\n")
        return items

    def run_design(self, progress: bool = True, max_samples: int | None = None,
                   retry_failed: bool = False, responses: Sequence[str] | None = None) -> dict[tuple[int, str], dict]:
        """Run every (sample, response) not yet in ``samples.jsonl``, batch by batch.

        ``max_samples``: run at most this many new design samples per response in this call (a
        campaign too long for one sitting is run in parts; ``samples.jsonl`` keeps every part).
        ``retry_failed``: run failed samples again (their old records stay in the file; the
        newest record of a sample is the one used). ``responses``: run only these responses.
        Records of another setup or design are refused first (:meth:`check_records`)."""
        X = self.design()
        names = [p.name for p in self.cfg.space.parameters]
        done = self.check_records()
        if retry_failed or self.retry_failed:
            done = {k: r for k, r in done.items() if r["status"] == "ok"}
        if max_samples is not None and max_samples < 1:
            raise ConfigError(f"max_samples must be >= 1, got {max_samples}")
        known = [r.name for r in self.cfg.responses]
        unknown = sorted(set(responses or ()) - set(known))
        if unknown:
            raise ConfigError(f"unknown response(s) {unknown}; this campaign has {known}")
        for resp in self.cfg.responses:
            if responses is not None and resp.name not in responses:
                continue
            todo = [i for i in range(len(X)) if (i, resp.name) not in done]
            if max_samples is not None:
                todo = todo[:max_samples]
            if not todo:
                continue
            wanted = set(self.cfg.vtk.samples) if self.cfg.vtk is not None else set()
            skipped = sorted(wanted - set(todo))
            if skipped:
                self.log(f"{resp.name}: sample(s) {skipped} are in {self.samples_path.name} already and are not "
                         "run again, so they write no VTK (use a new output folder to record them)")
            self.log(f"{resp.name}: {len(todo)} of {len(X)} samples to run ({resp.experiment}, scale {resp.scale})")
            bar = None
            if progress:
                from tqdm import tqdm

                bar = tqdm(total=len(todo), desc=resp.name, unit="sample")
            for batch in _fill_contiguous_batches(todo, self.cfg.batch_worlds):
                sets = [dict(zip(names, map(float, X[i]))) for i in batch]
                # world k of the batch uses fill (batch[0] + k) * replicates + j: sample i's own fills
                record = {k: self.vtk_folder(f"sample_{i:03d}", resp.name) for k, i in enumerate(batch) if i in wanted}
                first_fill = batch[0] * resp.replicates
                fills = planned_fills(self.cfg, resp, len(batch), first_fill, record)
                results = run_recorded(resp, sets, self.cfg, first_fill=first_fill, record=record)
                new = [self.sample_record(resp, i, p, f, res) for i, p, f, res in zip(batch, sets, fills, results)]
                append_records(self.samples_path, new)  # whole lines, flushed and fsynced
                self._clear_checkpoints()
                for rec in new:
                    done[(rec["index"], resp.name)] = rec
                self._sample_records += new
                self.note_sitting()
                if bar is not None:
                    bar.update(len(batch))
            if bar is not None:
                bar.close()
        return done

    # ------------------------------------------------------------------ analysis
    def run(self, progress: bool = True) -> dict[str, Any]:
        """The whole campaign, resumably: targets, the design's DEM runs, the surrogate, NSGA-II,
        confirmation (with sequential refinement), sensitivity and validation; writes
        ``results.json``, ``summary.md`` and ``report.html`` and returns what ``results.json`` holds."""
        # the analysis' modules load before any DEM runs (a broken install fails first)
        from . import optimisation, reports_surrogate, sensitivity, surrogates  # noqa: F401

        t_start = time.perf_counter()
        res = self._results_header()
        self.check_records()  # records of another setup or design: refused before any DEM runs
        self._resolve_targets(res)
        done = self._run_design_timed(res, progress)
        Xtr, Ytr, Xte, Yte = self._training_data(res, done)
        sur = self._design_surrogate(res, Xtr, Ytr, Xte, Yte)
        cal, settings = self._first_optimisation(res, sur, Xtr)
        rounds, sur, cal = self._confirm_and_refine(res, sur, cal, settings, Xtr, Ytr)
        self._plot_acceptable_set(cal)
        self._sensitivity(res, sur)
        self._validate(res, rounds[-1]["parameters"])
        self._record_vtk_series(res)
        self._record_wall_times(res, t_start)
        self._write_results(res)
        return res

    def _results_header(self) -> dict[str, Any]:
        """The start of ``results.json``: campaign name, parameter names, fixed parameters, model,
        contact law and device."""
        cfg = self.cfg
        pnames = [p.name for p in cfg.space.parameters]
        return dict(name=cfg.name, parameters=pnames, fixed=cfg.fixed, model=cfg.model.describe(),
                    contact_law=cfg.model.contact_law.describe(),
                    device=str(cfg.device or ("cuda" if wp.is_cuda_available() else "cpu")))

    def _all_responses(self) -> list[Response]:
        """The calibrated responses, then the validation (if any)."""
        return self.cfg.responses + ([self.cfg.validation] if self.cfg.validation else [])

    def _run_target(self, resp: Response, sets: list[dict[str, float]], first_fill: int,
                    record: Mapping[int, Path] | None) -> list[dict[str, Any]]:
        """A DEM target's runs (:meth:`run_group` of kind "target"), for :func:`resolve_target`."""
        return self.run_group("target", resp, sets, first_fill, record)

    def _resolve_targets(self, res: dict[str, Any]) -> None:
        """Every response's target [deg] (from its file or DEM at known parameters), logged and
        recorded in ``res["targets"]``."""
        cfg = self.cfg
        for resp in self._all_responses():
            resolve_target(resp, cfg, self.log, vtk_folder=self.vtk_folder("target", resp.name)
                           if cfg.vtk is not None and cfg.vtk.targets else None, run=self._run_target)
            self.log(f"target {resp.name} = {resp.target_deg:.3f} deg ({resp.target_source})")
        res["targets"] = {r.name: dict(deg=r.target_deg, std_deg=r.target_std_deg, source=r.target_source)
                          for r in self._all_responses()}

    def _run_design_timed(self, res: dict[str, Any], progress: bool) -> dict[tuple[int, str], dict]:
        """:meth:`run_design`, with its wall time in this sitting [s] and the design's DEM time over
        every sitting [s] recorded in ``res``; returns the newest record of every (sample, response)."""
        t0 = time.perf_counter()
        done = self.run_design(progress)
        res["campaign_wall_s"] = round(time.perf_counter() - t0, 1)  # the design's part of this sitting
        # DEM time of the design over every sitting (a resumed campaign ran part of it before),
        # failed runs that were retried included
        res["design_dem_wall_s_all_sessions"] = round(
            sum(float(r.get("dem_wall_share_s") or 0.0) for r in self._sample_records), 1)
        return done

    def _training_data(self, res: dict[str, Any], done: Mapping[tuple[int, str], dict]
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The design's points and angles [deg] (recorded in ``res["design"]`` with the failed
        runs), split into training and held-out rows of the successful samples: ``(Xtr, Ytr, Xte,
        Yte)``. Refuses (RuntimeError) too few successful training samples for a surrogate."""
        cfg = self.cfg
        X = self.design()
        rnames = [r.name for r in cfg.responses]
        Y = np.array([[done[(i, n)]["angle_deg"] if done[(i, n)]["status"] == "ok" else np.nan for n in rnames]
                      for i in range(len(X))], dtype=float)
        failed = [dict(index=i, response=n, error=done[(i, n)]["error"]) for i in range(len(X)) for n in rnames
                  if done[(i, n)]["status"] != "ok"]
        res["design"] = dict(samples=len(X), held_out=cfg.held_out, seed=cfg.seed, X=X, Y=Y, failed=failed,
                             kind=self.design_kind)
        ok = np.all(np.isfinite(Y), axis=1)
        tr = ~self.held_out_mask(len(X))
        if ok[tr].sum() <= len(cfg.space.parameters) + 1:
            raise RuntimeError(f"only {ok[tr].sum()} successful training samples; see {self.samples_path}")
        return X[tr & ok], Y[tr & ok], X[~tr & ok], Y[~tr & ok]

    def _fit_surrogate(self, Xtr: np.ndarray, Ytr: np.ndarray) -> CVSurrogate:
        """The cross-validated surrogate of the training points ``Xtr`` and angles ``Ytr`` [deg]."""
        cfg = self.cfg
        from .surrogates import cross_validated_surrogate

        return cross_validated_surrogate(Xtr, Ytr, space=cfg.space, response_names=[r.name for r in cfg.responses],
                                         seed=cfg.seed,
                                         n_splits=int(cfg.surrogate.get("n_splits", min(5, len(Xtr) // 2))),
                                         n_repeats=int(cfg.surrogate.get("n_repeats", 2)))

    def _design_surrogate(self, res: dict[str, Any], Xtr: np.ndarray, Ytr: np.ndarray, Xte: np.ndarray,
                          Yte: np.ndarray) -> CVSurrogate:
        """The surrogate of the design's training samples, recorded in ``res["surrogate"]`` with its
        error on the held-out samples (R^2, RMSE [deg], relative errors; plotted) where there are any."""
        from .reports_surrogate import plot_predicted_vs_simulated
        from .surrogates import r2_score, relative_errors, rmse

        self.log(f"surrogate: cross-validated choice on {len(Xtr)} training samples")
        sur = self._fit_surrogate(Xtr, Ytr)
        res["surrogate"] = sur.summary()
        if len(Xte):
            P = sur.predict(Xte)
            res["surrogate"]["held_out"] = dict(n=len(Xte), r2=r2_score(Yte, P), rmse_deg=rmse(Yte, P),
                                                relative_errors=relative_errors(Yte, P))
            plot_predicted_vs_simulated(Yte, P, [r.name for r in self.cfg.responses],
                                        path=str(self.out / "surrogate_held_out.png"))
        return sur

    def _calibrate(self, sur: CVSurrogate, Xtr: np.ndarray, settings: NSGA2Settings) -> CalibrationResult:
        """NSGA-II on the surrogate ``sur`` towards the targets [deg] (within ``tolerance_deg``),
        its acceptable set supported by the training points ``Xtr``."""
        from .optimisation import calibrate

        cfg = self.cfg
        return calibrate(sur, [r.target_deg for r in cfg.responses], cfg.space,
                         tolerance=cfg.optimisation.get("tolerance_deg"), settings=settings,
                         response_names=[r.name for r in cfg.responses],
                         n_dense=int(cfg.optimisation.get("n_dense", 50_000)), support_X=Xtr)

    def _first_optimisation(self, res: dict[str, Any], sur: CVSurrogate, Xtr: np.ndarray
                            ) -> tuple[CalibrationResult, NSGA2Settings]:
        """The NSGA-II settings of the config and the first optimisation on the design's
        surrogate, recorded in ``res["optimisation"]``."""
        from .optimisation import NSGA2Settings

        opt = {k: v for k, v in self.cfg.optimisation.items() if k in ("pop_size", "n_generations", "seed")}
        settings = NSGA2Settings(**opt)
        self.log(f"NSGA-II: population {settings.pop_size}, {settings.n_generations} generations")
        cal = self._calibrate(sur, Xtr, settings)
        res["optimisation"] = cal.to_dict()
        return cal, settings

    def _confirm_and_refine(self, res: dict[str, Any], sur: CVSurrogate, cal: CalibrationResult,
                            settings: NSGA2Settings, Xtr: np.ndarray, Ytr: np.ndarray
                            ) -> tuple[list[dict[str, Any]], CVSurrogate, CalibrationResult]:
        """Confirmation: DEM at the compromise (Table 9). If it misses a target by more than the
        tolerance [deg], the confirmed point joins the training set and the surrogate and NSGA-II
        are redone (sequential refinement), at most ``refine_rounds`` times. Records every round in
        ``res["confirmation"]``; returns the rounds and the last surrogate and optimisation."""
        pnames = [p.name for p in self.cfg.space.parameters]
        rnames = [r.name for r in self.cfg.responses]
        tol_deg = np.broadcast_to(np.asarray(cal.tolerance, dtype=float), (len(rnames),))
        rounds = []
        for rnd in range(self.refine_rounds + 1):
            x_best = dict(zip(pnames, map(float, cal.compromise_x)))
            conf = {resp.name: self._confirmation(resp, rnd, x_best, sur, cal) for resp in self.cfg.responses}
            rounds.append(dict(parameters=x_best, responses=conf))
            errs = [c["abs_error_deg"] for c in conf.values()]
            if any(e is None for e in errs) or all(e <= t for e, t in zip(errs, tol_deg)) or rnd == self.refine_rounds:
                break
            Xtr = np.vstack([Xtr, cal.compromise_x[None]])
            Ytr = np.vstack([Ytr, [[conf[n]["dem_deg"] for n in rnames]]])
            self.log(f"refinement round {rnd + 1}: surrogate refitted with {len(Xtr)} samples")
            sur = self._fit_surrogate(Xtr, Ytr)
            cal = self._calibrate(sur, Xtr, settings)
            res["optimisation"] = cal.to_dict()
        res["confirmation"] = dict(rounds[-1], rounds=rounds)
        return rounds, sur, cal

    def _confirmation(self, resp: Response, rnd: int, x_best: dict[str, float], sur: CVSurrogate,
                      cal: CalibrationResult) -> dict[str, Any]:
        """Confirmation round ``rnd`` of ``resp``: DEM at the compromise ``x_best``, its mean angle
        [deg] over the fills against the target and the surrogate's prediction (errors in % and deg)."""
        cfg = self.cfg
        rnames = [r.name for r in cfg.responses]
        recs = self.run_group("confirmation", resp, [x_best] * cfg.confirmation_runs,
                              first_fill=CONFIRMATION_FILLS + 10_000 * rnd,
                              record={0: self.vtk_folder(f"confirmation_round{rnd}", resp.name)}
                              if cfg.vtk is not None and cfg.vtk.confirmation else None, round_=rnd)
        angles = [a for r in recs if r["status"] == "ok" for a in r["replicate_angles_deg"]]
        dem = float(np.mean(angles)) if angles else None
        conf = dict(
            dem_deg=dem, dem_fills=angles,
            dem_std_deg=float(np.std(angles, ddof=1)) if len(angles) > 1 else None,
            target_deg=resp.target_deg, target_std_deg=resp.target_std_deg,
            surrogate_deg=float(sur.predict(cal.compromise_x[None])[0][rnames.index(resp.name)]),
            relative_error_pct=None if dem is None else abs(dem - resp.target_deg) / resp.target_deg * 100,
            abs_error_deg=None if dem is None else abs(dem - resp.target_deg),
            failed=[r["error"] for r in recs if r["status"] != "ok"])
        self.log(f"confirmation {resp.name} (round {rnd}): DEM {dem} deg vs target {resp.target_deg:.3f} deg")
        return conf

    def _plot_acceptable_set(self, cal: CalibrationResult) -> None:
        """``acceptable_set.png`` of the last optimisation."""
        from .optimisation import plot_acceptable_set

        plot_acceptable_set(cal, path=str(self.out / "acceptable_set.png"))

    def _sensitivity(self, res: dict[str, Any], sur: CVSurrogate) -> None:
        """Sobol indices of the surrogate ``sur`` (``res["sensitivity"]``, ``sensitivity.png``)."""
        from .sensitivity import plot_sensitivity, sobol_indices

        cfg = self.cfg
        sob = sobol_indices(sur, cfg.space, n=cfg.sobol_n, response_names=[r.name for r in cfg.responses])
        res["sensitivity"] = dict(first_order=sob.first_order, total_order=sob.total_order,
                                  percent_total=sob.percent_contribution("total"), n=sob.n,
                                  parameters=sob.parameter_names, responses=sob.response_names)
        plot_sensitivity(sob, path=str(self.out / "sensitivity.png"))

    def _validate(self, res: dict[str, Any], parameters: dict[str, float]) -> None:
        """DEM of the validation experiment (if any) at the confirmed ``parameters``: its mean angle
        [deg] against the measured one and the relative error [%] (``res["validation"]``)."""
        cfg = self.cfg
        if cfg.validation is None:
            return
        v = cfg.validation
        recs = self.run_group("validation", v, [parameters], first_fill=VALIDATION_FILLS,
                              record={0: self.vtk_folder("validation", v.name)}
                              if cfg.vtk is not None and cfg.vtk.validation else None)
        angles = [a for r in recs if r["status"] == "ok" for a in r["replicate_angles_deg"]]
        dem = float(np.mean(angles)) if angles else None
        res["validation"] = dict(experiment=v.experiment, scale=v.scale, dem_deg=dem, measured_deg=v.target_deg,
                                 measured_std_deg=v.target_std_deg,
                                 relative_error_pct=None if dem is None else abs(dem - v.target_deg) / v.target_deg * 100,
                                 failed=[r["error"] for r in recs if r["status"] != "ok"])
        self.log(f"validation {v.name}: DEM {dem} deg vs measured {v.target_deg:.3f} deg")

    def _record_vtk_series(self, res: dict[str, Any]) -> None:
        """Every VTK series written by this campaign (any sitting), relative to the output folder
        (``res["vtk_series"]``; only with a ``vtk`` section)."""
        cfg = self.cfg
        if cfg.vtk is not None:
            root = self.out / cfg.vtk.folder
            res["vtk_series"] = sorted(str(p.parent.relative_to(self.out)) if p.is_relative_to(self.out) else str(p.parent)
                                       for p in root.glob("*/*/particles.pvd"))

    def _record_wall_times(self, res: dict[str, Any], t_start: float) -> None:
        """DEM wall time over every sitting, this sitting's :meth:`run` since ``t_start``
        (:func:`time.perf_counter`), and the sittings' wall times [s]; marks this sitting finished."""
        res["dem_wall_s_all_sittings"] = round(res["design_dem_wall_s_all_sessions"] + sum(
            float(r.get("dem_wall_share_s") or 0.0) for rec in self._run_records for r in rec.get("results", [])), 1)
        res["analysis_wall_s"] = round(time.perf_counter() - t_start, 1)  # this sitting's run(), targets included
        sittings = self.note_sitting(finished=True)
        res["wall_s_this_sitting"] = sittings[-1]["wall_s"]
        res["wall_s"] = round(sum(float(x["wall_s"]) for x in sittings), 1)  # over every sitting [s]
        res["sittings"] = len(sittings)

    def _write_results(self, res: dict[str, Any]) -> None:
        """``results.json``, ``summary.md`` and ``report.html`` into the output folder."""
        write_atomic(self.out / "results.json", json.dumps(_jsonable(res), indent=1))
        write_atomic(self.out / "summary.md", summary_markdown(res))
        from .report_campaign import write_campaign_report

        write_campaign_report(_jsonable(res), self.out)  # report.html: verdict, warnings, figures
        self.log(f"done in {res['wall_s']} s: {self.out / 'summary.md'}")


def _material_label(res: Mapping[str, Any]) -> str:
    mat = (res.get("model") or {}).get("material")
    if not mat:
        return "each experiment's scale default"
    return str(mat.get("name", mat)) if isinstance(mat, Mapping) else str(mat)


def summary_markdown(res: Mapping[str, Any]) -> str:
    """Short Markdown account of a campaign."""
    from .report_campaign import campaign_verdict

    lines = [f"# Calibration: {res['name']}", ""]
    try:
        verdict, _ = campaign_verdict(res)
    except ValueError:  # no confirmation runs: nothing to judge
        verdict = None
    if verdict is not None:
        lines += [f"**{verdict.headline}**", ""]
        lines += [f"- {d}" for d in verdict.details] + [""] if verdict.details else []
    lines += [f"Parameters calibrated: {', '.join(res['parameters'])}; "
             f"fixed: {res['fixed']}; device: {res['device']}.", "",
             f"Contact law: {res['contact_law']}; material: {_material_label(res)}.", "", "## Targets", ""]
    for n, t in res["targets"].items():
        spread = "" if t.get("std_deg") is None else f", std {t['std_deg']:.2f} deg between repeats"
        lines.append(f"- {n}: {t['deg']:.3f} deg ({t['source']}{spread})")
    d = res["design"]
    lines += ["", f"## Design: {d['samples']} {d.get('kind', 'Latin hypercube samples')} ({d['held_out']} held out), "
              f"{len(d['failed'])} failed runs; design DEM time {res.get('design_dem_wall_s_all_sessions', '?')} s "
              f"over all sittings (this sitting's design part: {res['campaign_wall_s']} s)", ""]
    s = res["surrogate"]
    if "held_out" in s:
        r2 = np.atleast_1d(s["held_out"]["r2"])
        rm = np.atleast_1d(s["held_out"]["rmse_deg"])
        for k, n in enumerate(res["targets"]):
            if k < len(r2):
                lines.append(f"- surrogate {n}: held-out R^2 = {r2[k]:.3f}, RMSE = {rm[k]:.2f} deg")
    o = res["optimisation"]
    comp = {k: round(v, 4) for k, v in res["confirmation"]["parameters"].items()}
    sur = {n: round(c["surrogate_deg"], 3) for n, c in res["confirmation"]["responses"].items()}
    ranges = {k: [round(float(a), 3) for a in v] for k, v in (o.get("acceptable_ranges") or {}).items()}
    lines += ["", "## NSGA-II", "", f"- compromise: {comp}", f"- surrogate at the compromise: {sur} deg",
              f"- acceptable set: {o.get('acceptable_set_size', '?')} parameter sets within tolerance; their ranges "
              f"(the ambiguity of the calibration): {ranges}", ""]
    lines += ["## Confirmation (DEM at the compromise)", "",
              "DEM: mean over its loose fills, +- their standard deviation where there are several.", "",
              "| response | target | surrogate | DEM | abs. error | rel. error |",
              "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for n, c in res["confirmation"]["responses"].items():
        dem = "failed" if c["dem_deg"] is None else f"{c['dem_deg']:.2f}"
        if c["dem_deg"] is not None and c.get("dem_std_deg") is not None:
            dem += f" +- {c['dem_std_deg']:.2f}"
        ae = "-" if c["abs_error_deg"] is None else f"{c['abs_error_deg']:.2f}"
        re_ = "-" if c["relative_error_pct"] is None else f"{c['relative_error_pct']:.2f} %"
        lines.append(f"| {n} | {c['target_deg']:.2f} | {c['surrogate_deg']:.2f} | {dem} | {ae} | {re_} |")
    if "validation" in res:
        v = res["validation"]
        dem = "failed" if v["dem_deg"] is None else f"{v['dem_deg']:.2f} deg"
        rel = "-" if v["relative_error_pct"] is None else f"{v['relative_error_pct']:.2f} %"
        lines += ["", "## Validation", "", f"- {v['experiment']} ({v['scale']} scale): DEM {dem} vs measured "
                  f"{v['measured_deg']:.2f} deg, relative error {rel}"]
    if res.get("vtk_series"):
        lines += ["", "## VTK series (open the .pvd files in ParaView)", ""]
        lines += [f"- `{f}/particles.pvd` (and `wall_*.pvd`)" for f in res["vtk_series"]]
    if "sittings" in res:
        lines += ["", f"Total wall time {res['wall_s']} s over {res['sittings']} sitting(s) "
                  f"({res['wall_s_this_sitting']} s in this one); DEM time {res['dem_wall_s_all_sittings']} s.", ""]
    else:
        lines += ["", f"Total wall time {res['wall_s']} s.", ""]
    return "\n".join(lines)


def first_fitting_folder(cfg: CampaignConfig, output: str | os.PathLike) -> Path:
    """``output`` if it is new or its records fit ``cfg``, else the first of ``<output>-2``,
    ``<output>-3``, ... that is (``warpdem calibrate --new-folder``: a changed config goes on in
    its own folder, and running it again resumes there)."""
    base = Path(output)
    for k in itertools.count(1):
        folder = base if k == 1 else base.with_name(f"{base.name}-{k}")
        if not folder.exists():
            return folder
        try:
            Campaign(cfg, folder, verbose=False).check_records()
        except ConfigError as exc:
            print(f"warpdem calibrate: {folder} holds records of another setup or design "
                  f"({str(exc).splitlines()[0][:200]}...); trying {base.name}-{k + 1}", file=sys.stderr)
            continue
        return folder
    raise AssertionError("unreachable")


def calibrate_main(argv: Sequence[str] | None = None) -> int:
    """``warpdem calibrate CONFIG [--out DIR] [--device cpu|cuda]``."""
    import argparse

    ap = argparse.ArgumentParser(prog="warpdem calibrate", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config")
    ap.add_argument("--out", default=None, help="output folder (default: the config's 'output')")
    ap.add_argument("--device", default=None)
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--retry-failed", action="store_true", help="run the samples recorded as failed again")
    ap.add_argument("--only", nargs="+", default=None, metavar="RESPONSE",
                    help="with --max-samples: run only these responses (e.g. alpha_static)")
    ap.add_argument("--max-samples", type=positive_int_arg, default=None,
                    help="run at most N new design samples per response, then stop before the analysis "
                         "(run the command again to continue; nothing already run is repeated)")
    ap.add_argument("--new-folder", action="store_true",
                    help="if the output folder holds records of another setup or design, use the first of "
                         "<output>-2, <output>-3, ... that is new or whose records fit this config")
    ap.add_argument("--ray", metavar="ADDRESS", default=None,
                    help="run the DEM batches on a Ray cluster: 'auto' (a running cluster), 'local' (start one "
                         "here) or ray://host:port (overrides the config's executor)")
    args = ap.parse_args(argv)
    if args.only is not None and args.max_samples is None:
        ap.error("--only needs --max-samples (the analysis uses every response)")
    try:
        cfg = load_config(args.config)
        unknown = sorted(set(args.only or ()) - {r.name for r in cfg.responses})
        if unknown:
            raise ConfigError(f"--only: unknown response(s) {unknown}; this campaign has "
                              f"{[r.name for r in cfg.responses]}")
    except ConfigError as exc:
        print(f"warpdem calibrate: configuration error: {exc}", file=sys.stderr)
        return 2
    try:
        cfg.device = check_device(args.device or cfg.device, "--device" if args.device else f"{args.config}: device")
        if args.ray:
            cfg.executor = RayExecutor(address=args.ray)
        out = Path(args.out or cfg.output)
        if args.new_folder:
            out = first_fitting_folder(cfg, out)
        check_output_folder(out, "--out" if args.out else "output")
        campaign = Campaign(cfg, out, retry_failed=args.retry_failed)
        if args.max_samples is not None:
            t0 = time.perf_counter()
            done = campaign.run_design(progress=not args.no_progress, max_samples=args.max_samples,
                                       retry_failed=args.retry_failed, responses=args.only)
            for resp in cfg.responses:
                recs = [r for (i, name), r in done.items() if name == resp.name]
                ok = sum(r["status"] == "ok" for r in recs)
                campaign.log(f"{resp.name}: {len(recs)} of {cfg.samples} samples done ({ok} ok)")
            campaign.log(f"part finished in {time.perf_counter() - t0:.1f} s; run again to continue")
            return 0
        res = campaign.run(progress=not args.no_progress)
        from .report_campaign import campaign_verdict

        verdict, _ = campaign_verdict(_jsonable(res))
        print(verdict.headline)  # the verdict first, then where the numbers and plots are
        for line in verdict.details:
            print(f"  - {line}")
        print(f"report: {campaign.out / 'report.html'}  (summary: {campaign.out / 'summary.md'})")
        return 0
    except ConfigError as exc:  # e.g. records of another design in the output folder
        print(f"warpdem calibrate: {exc}", file=sys.stderr)
        return 2
