"""The DEM as the diagnosis's forward model: every design of one experiment in one launch.

:class:`DEMForwardModel` answers ``evaluate(effects, parameter_sets, replicates, keys)`` by running
the standard experiments (:mod:`calibration.experiments`) with the model description of the base
plus the effects switched on. Observables of one experiment that differ only in the drum speed
share one run (the speed is a per-world setting); each (parameter set, replicate) is a world with
its own loose fill. World results are cached in a JSONL file keyed by a fingerprint of the model,
the experiment settings, the parameters and the replicate index, so an interrupted or repeated
diagnosis (or a second measurement set against the same designs) never repeats a DEM run. The
cache holds simulations only, never measurements.
"""
from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from calibration.campaign_records import code_version
from calibration.experiments import EXPERIMENTS, make_experiment
from calibration.experiments.checkpoints import BatchCheckpoints
from calibration.materials import BulkMaterial
from calibration.model_description import ModelDescription
from warpdem import ConfigError
from warpdem.provenance import json_digest
from warpdem.record_files import RecordFile

from .dem_effects import DEMEffect, apply_effects
from .forward import ForwardModel, ProposedMeasurement, replicate_counts

__all__ = ["ObservableSpec", "DEMForwardModel"]

#: fill index blocks: design worlds draw fills from here upwards (a lab-data generator uses others)
DESIGN_FILLS = 10_000_000


@dataclass(frozen=True)
class ObservableSpec:
    """What the DEM must simulate for one observable key: experiment, quantity, settings."""

    key: str
    experiment: str
    quantity: str
    settings: Mapping[str, Any] = field(default_factory=dict)


#: the DEM cache's format name (its header line, :mod:`warpdem.record_files`)
CACHE_FORMAT = "warpdem-dem-cache"
#: keys every DEM-cache record has (a file whose JSON lines lack them is not a DEM cache)
CACHE_RECORD_KEYS = frozenset({"id", "experiment", "status", "parameters"})


def is_cache_record(rec: Mapping[str, Any]) -> bool:
    """True for a DEM-cache record (a world's result, :meth:`DEMForwardModel._store`)."""
    return CACHE_RECORD_KEYS <= set(rec) and isinstance(rec["id"], str)


#: Parameter sets equal within this relative difference are the same DEM world (float round-off
#: of a best fit found again on another machine; :meth:`DEMForwardModel._adopt_near_record`).
NEAR_PARAMETER_RTOL = 1e-9


def _fingerprint(obj: Any) -> str:
    """A world's or a setup's id in the DEM cache (:func:`warpdem.provenance.json_digest`, unknown
    objects by ``str``): the ids of the caches already written depend on it."""
    return json_digest(obj, default=str)


class DEMForwardModel(ForwardModel):
    """Runs the standard experiments for the diagnosis.

    Args:
        base: the base model description (contact law, material or None, plugins).
        base_material: the material when ``base.material`` is None (e.g. the measurement file's);
            None: each experiment's scale preset material.
        effects: the candidate effects by name (switched on by name in :meth:`evaluate`).
        observables: every key the diagnosis may ask for (measured and proposed).
        scale: experiment preset ("paper", "quick"; drum also "short"), per experiment in
            ``experiment_settings[exp]["scale"]`` if given.
        experiment_settings: per experiment, settings applied to every condition (e.g. shorter
            protocol), overridden by the condition's own settings.
        fixed: contact parameters applied to every world (e.g. restitution).
        cache: JSONL file of world results (None: no cache).
        superset: run every model version as the base plus ALL candidate effects, the ones not
            switched on held at their "off" value (rolling friction 0, cohesion 0, aspect ratio 1).
            The physics is the same (an effect at its off value adds exactly nothing), but every
            version then shares one contact law and material, so the designs of all versions run
            in one launch per experiment and share one cache. Needs at most one candidate per
            kind; ``"auto"``: on when that holds.
        checkpoint_every_s: wall seconds [s] between batch checkpoints of a DEM launch, kept in
            ``<cache stem>_checkpoints/`` beside the cache (:class:`calibration.experiments.BatchCheckpoints`),
            so a launch cut short (a time-limited GPU call, Ctrl-C) continues where it stopped when
            the same request comes again (the cache has not grown, so the launch draws the same
            fills and matches its checkpoint); None, or no cache: no checkpoints.
        proposals_not_forecast: one line per condition the proposal search reached but left out
            (:meth:`validation.proposals.ProposalPlan.not_forecast`), for the discrimination to name.
    """

    def __init__(self, base: ModelDescription, base_material: BulkMaterial | None, effects: Sequence[DEMEffect],
                 observables: Sequence[ObservableSpec], scale: str = "paper",
                 experiment_settings: Mapping[str, Mapping[str, Any]] | None = None,
                 fixed: Mapping[str, float] | None = None, device: str | None = None,
                 processes: int | str | None = "auto", cache: str | Path | None = None,
                 progress: bool = False, proposals: Sequence[ProposedMeasurement] = (),
                 superset: bool | str = "auto", checkpoint_every_s: float | None = 120.0,
                 executor: Any = None, proposals_not_forecast: Sequence[str] = (),
                 cache_code_version: str = "match") -> None:
        self.base = base
        self.base_material = base_material
        self.effects = {e.name: e for e in effects}
        self.observables = {o.key: o for o in observables}
        for o in observables:
            if o.experiment not in EXPERIMENTS:
                raise ConfigError(f"observable {o.key}: unknown experiment {o.experiment!r}; valid: {sorted(EXPERIMENTS)}")
            if o.quantity not in EXPERIMENTS[o.experiment].OBSERVABLES:
                raise ConfigError(f"observable {o.key}: the {o.experiment} experiment does not report "
                                  f"{o.quantity!r}; it reports {list(EXPERIMENTS[o.experiment].OBSERVABLES)}")
        self.scale = scale
        self.experiment_settings = {k: dict(v) for k, v in (experiment_settings or {}).items()}
        self.fixed = dict(fixed or {})
        self.device = device
        self.processes = processes
        # where the batches run (calibration.executor: local processes or a Ray cluster); None: local
        self.executor = executor
        self.progress = progress
        self._proposals = tuple(proposals)
        self.proposals_not_forecast = tuple(proposals_not_forecast)
        self.cache_path = Path(cache) if cache is not None else None
        self.checkpoints = None if self.cache_path is None or checkpoint_every_s is None else BatchCheckpoints(
            self.cache_path.parent / f"{self.cache_path.stem}_checkpoints", float(checkpoint_every_s))
        self._cache: dict[str, dict[str, Any]] = {}
        if cache_code_version not in ("match", "any"):
            raise ConfigError(f"cache_code_version must be 'match' or 'any', got {cache_code_version!r}")
        # the engine and experiment sources that made a world (calibration.campaign_records.code_version):
        # every cache record carries it, and a record made by other code is not served (see _load_cache)
        self.code = code_version()["source_sha256"]
        self.cache_code_version = cache_code_version
        self.cache_other_code = 0
        kinds = [e.kind for e in effects]
        mergeable = len(set(kinds)) == len(kinds)
        if superset == "auto":
            superset = mergeable
        elif superset and not mergeable:
            raise ConfigError(f"superset: candidates of the same kind cannot be merged into one model: {kinds}")
        self.superset = bool(superset)
        self.dem_seconds = 0.0
        self.dem_worlds = 0
        # worlds run whose measurement failed, per experiment, with the first error seen (each failed
        # world's error is in its cache record)
        self.dem_failures: dict[str, dict[str, Any]] = {}
        self.log: list[dict[str, Any]] = []
        self._cache_file = None if self.cache_path is None else RecordFile(
            self.cache_path, CACHE_FORMAT, is_cache_record, key="cache", what="DEM cache")
        if self._cache_file is not None:
            self._load_cache()

    def _load_cache(self) -> None:
        """Read the cache. It must prove it is one (:mod:`warpdem.record_files`: a DEM-cache header,
        or a file of DEM-cache records written before headers existed); any other file named in
        ``cache:`` is refused and left untouched. A torn line (a write cut by an interruption) is
        reported, cut from the file (kept in ``<cache>.torn``; rewritten atomically, so later appends
        start on a fresh line) and its world is run again."""
        assert self._cache_file is not None
        contents = self._cache_file.read()
        other: dict[str, int] = {}
        for _, rec in contents.records:
            made_by = rec.get("code")
            if made_by == self.code or self.cache_code_version == "any":
                if made_by == self.code or rec["id"] not in self._cache:
                    self._cache[rec["id"]] = rec
            else:
                key = made_by or "unrecorded"
                other[key] = other.get(key, 0) + 1
        self.cache_other_code = sum(other.values())
        if other:
            versions = ", ".join(f"{n} by {v}" for v, n in sorted(other.items()))
            print(f"DEM cache {self.cache_path}: {sum(other.values())} cached world(s) were made by other engine or "
                  f"experiment code ({versions}; this code is {self.code}); they are not used and run again if "
                  f"needed (cache_code_version: any reuses them on purpose)", file=sys.stderr, flush=True)
        if contents.torn:
            print(f"DEM cache {self.cache_path}: {len(contents.torn)} torn line(s) dropped (a write cut by an "
                  f"interruption, kept in {self.cache_path.name}.torn); those worlds will be run again",
                  file=sys.stderr, flush=True)
            self._cache_file.repair(contents, contents.torn)

    # ------------------------------------------------------------------ helpers
    def material_for(self, experiment: str) -> BulkMaterial:
        """The base material of one experiment: the description's, the given one, or the preset's."""
        if self.base.material is not None:
            return self.base.material
        if self.base_material is not None:
            return self.base_material
        extra = dict(self.experiment_settings.get(experiment, {}))
        return make_experiment(experiment, extra.pop("scale", self.scale), **extra).bulk_material()

    def description(self, effects: Sequence[str], experiment: str) -> ModelDescription:
        """The base plus ``effects`` (every candidate in superset mode) for one experiment, with
        that experiment's material."""
        unknown = [e for e in effects if e not in self.effects]
        if unknown:
            raise ConfigError(f"unknown effect(s) {unknown}; this forward model knows {sorted(self.effects)}")
        base = ModelDescription(self.base.contact_law, self.material_for(experiment), self.base.plugins)
        on = list(self.effects) if self.superset else list(effects)
        return apply_effects(base, [self.effects[e] for e in on], base.material)

    def padded(self, effects: Sequence[str], parameter_set: Mapping[str, float]) -> dict[str, float]:
        """In superset mode, ``parameter_set`` with every effect not switched on at its off value."""
        out = {k: float(v) for k, v in parameter_set.items()}
        if self.superset:
            for name, eff in self.effects.items():
                if name not in effects:
                    for p in eff.candidate.parameters:
                        out.setdefault(p.name, float(p.reference))
        return out

    def proposals(self) -> Sequence[ProposedMeasurement]:
        return self._proposals

    def setup(self) -> dict[str, Any]:
        """What decides a world's result apart from its parameters and fill: the model of every
        version per experiment, scale, settings, fixed parameters, cache and device. Two forward
        models with equal setups may share worlds (:meth:`adopt`)."""
        every = tuple(self.effects)
        return {"models": {e: self.description(every, e).describe() for e in sorted(EXPERIMENTS)},
                "effects": sorted(self.effects), "superset": self.superset, "scale": self.scale,
                "experiment_settings": self.experiment_settings, "fixed": self.fixed,
                "cache": str(self.cache_path.resolve()) if self.cache_path else None, "device": self.device,
                "cache_code_version": self.cache_code_version}

    def adopt(self, other: "DEMForwardModel", where: str = "") -> None:
        """Serve ``other``'s observables and proposals too (one forward model, one cache, pooled
        launches for several measurement sets). Refuses a different setup, naming what differs."""
        mine, theirs = self.setup(), other.setup()
        differ = [k for k in mine if _fingerprint(mine[k]) != _fingerprint(theirs[k])]
        if differ:
            raise ConfigError(f"{where or 'forward model'}: cannot share DEM runs with the first config: "
                              f"{', '.join(differ)} differ (one process diagnoses several measurement sets only "
                              "when they simulate the same model the same way)")
        for key, spec in other.observables.items():
            known = self.observables.get(key)
            if known is not None and known != spec:
                raise ConfigError(f"{where}: observable {key} has other settings than in the first config: "
                                  f"{spec.settings} vs {known.settings}")
            self.observables[key] = spec
        names = {p.key for p in self._proposals}
        self._proposals += tuple(p for p in other.proposals() if p.key not in names)
        self.proposals_not_forecast += tuple(d for d in other.proposals_not_forecast
                                             if d not in self.proposals_not_forecast)

    def check_experiments(self) -> None:
        """Build the experiment of every observable's condition once, without running it: a setting
        the experiment refuses (``fill_mass: true``) or a fill larger than the machine can hold
        (:meth:`calibration.experiments.common.Experiment.check_size`) is a ConfigError naming the
        observable, before any DEM runs."""
        seen: set[tuple[str, str]] = set()
        for key, o in self.observables.items():
            settings = {k: v for k, v in o.settings.items() if k != "rpm"}
            group = (o.experiment, json.dumps(settings, sort_keys=True, default=str))
            if group in seen:
                continue
            seen.add(group)
            try:
                self._experiment(o.experiment, settings, self.description((), o.experiment), DESIGN_FILLS).check_size()
            except ConfigError as exc:
                raise ConfigError(f"observable {key}: {exc}") from None

    def _experiment(self, name: str, settings: Mapping[str, Any], desc: ModelDescription, first_fill: int):
        extra = dict(self.experiment_settings.get(name, {}))
        scale = extra.pop("scale", self.scale)
        kw = {**extra, **{k: v for k, v in settings.items() if k != "rpm"}}
        material = desc.material
        return make_experiment(name, scale, contact_law=desc.contact_law, plugins=desc.plugins, material=material,
                               fill_per_world=True, first_fill_index=first_fill, **kw)

    def _world_id(self, model_fp: str, exp_fp: str, params: Mapping[str, float], rep: int, rpm: float | None) -> str:
        return _fingerprint([model_fp, exp_fp, {k: round(float(v), 12) for k, v in sorted(params.items())}, rep, rpm])

    def _adopt_near_record(self, wid: str, model_fp: str, exp_fp: str, experiment: str,
                           params: Mapping[str, float], rep: int, rpm: float | None) -> bool:
        """Serve a world from a cached record whose parameters differ from ``params`` by float
        round-off only (relative ``NEAR_PARAMETER_RTOL``). A best fit found again on another
        machine differs in its last digits (another BLAS under the surrogates' optimiser), which
        would otherwise re-run a world already simulated. The record must recompute to its own id
        under this model and setup (``model_fp``, ``exp_fp``), so it is the same world up to the
        parameter round-off; it is then known under ``wid`` too (in memory, not written again)."""
        for rec in self._cache.values():
            if rec.get("experiment") != experiment or rec.get("replicate") != rep or rec.get("rpm") != rpm:
                continue
            got = rec.get("parameters") or {}
            if set(got) != set(params):
                continue
            if all(abs(float(got[k]) - float(v)) <= NEAR_PARAMETER_RTOL * max(abs(float(v)), abs(float(got[k])))
                   for k, v in params.items()) and self._world_id(model_fp, exp_fp, got, rep, rpm) == rec["id"]:
                self._cache[wid] = rec
                return True
        return False

    def _store(self, rec: dict[str, Any]) -> None:
        rec = {**rec, "code": self.code}
        self._cache[rec["id"]] = rec
        if self._cache_file is not None:
            self._cache_file.append([rec])

    # ------------------------------------------------------------------ evaluate
    def _groups(self, keys: Sequence[str]) -> dict[tuple[str, str], list[int]]:
        """Key indices by (experiment, settings without rpm): one run each, the rpm per world."""
        groups: dict[tuple[str, str], list[int]] = {}
        for k_i, key in enumerate(keys):
            if key not in self.observables:
                raise ConfigError(f"the DEM forward model has no observable '{key}'")
            o = self.observables[key]
            settings = {k: v for k, v in o.settings.items() if k != "rpm"}
            groups.setdefault((o.experiment, json.dumps(settings, sort_keys=True, default=str)), []).append(k_i)
        return groups

    def _rpms(self, keys: Sequence[str], k_idx: Sequence[int]) -> list:
        return sorted({self.observables[keys[k]].settings.get("rpm") for k in k_idx},
                      key=lambda v: -1 if v is None else float(v))

    def worlds_per_run(self, keys: Sequence[str]) -> int:
        """DEM worlds one (parameter set, fill) of ``keys`` takes: one per experiment condition and
        drum speed (e.g. 5 for a baffle test, the drum at 3 speeds and a cylinder lift)."""
        return sum(len(self._rpms(keys, k_idx)) for k_idx in self._groups(keys).values())

    @property
    def on_cuda(self) -> bool:
        """True when the worlds run on a CUDA device (the given one, else Warp's preferred one)."""
        dev = self.device
        if dev is None:
            import warp as wp

            dev = wp.get_preferred_device()
        return str(dev).startswith("cuda")

    per_set_replicates = True  # evaluate takes one fill count per set (validation.forward)

    def evaluate(self, effects: tuple[str, ...], parameter_sets: Sequence[Mapping[str, float]],
                 replicates: int | Sequence[int], keys: Sequence[str]) -> np.ndarray:
        counts = replicate_counts(replicates, len(parameter_sets))
        out = np.full((len(parameter_sets), int(counts.max()), len(keys)), np.nan)
        parameter_sets = [self.padded(effects, ps) for ps in parameter_sets]
        for (exp_name, settings_json), k_idx in self._groups(keys).items():
            settings = json.loads(settings_json)
            desc = self.description(effects, exp_name)
            model_fp = _fingerprint(desc.describe())
            rpms = self._rpms(keys, k_idx)
            exp_fp = _fingerprint([exp_name, self.scale, self.experiment_settings.get(exp_name, {}), settings,
                                   self.fixed])
            todo: list[tuple[int, int, Any, str]] = []
            for i, ps in enumerate(parameter_sets):
                for r in range(counts[i]):
                    for rpm in rpms:
                        wid = self._world_id(model_fp, exp_fp, ps, r, rpm)
                        if wid not in self._cache and not self._adopt_near_record(wid, model_fp, exp_fp, exp_name,
                                                                                  ps, r, rpm):
                            todo.append((i, r, rpm, wid))
            if todo:
                self._run_worlds(exp_name, settings, desc, parameter_sets, todo)
            for i, ps in enumerate(parameter_sets):
                for r in range(counts[i]):
                    for k in k_idx:
                        o = self.observables[keys[k]]
                        rec = self._cache[self._world_id(model_fp, exp_fp, ps, r, o.settings.get("rpm"))]
                        v = (rec.get("observables") or {}).get(o.quantity)
                        # a failed world is left out whole, even where it measured something before the
                        # failure (A's bulk density when no angle could be measured; kept in its record):
                        # the angles a failure hides are the steep ones, and fitting the density of those
                        # runs alone moved the best fit of the README's first diagnosis to where no
                        # angle could be measured (2026-11-27)
                        out[i, r, k] = np.nan if v is None or rec.get("status") != "ok" else float(v)
        return out

    def _run_worlds(self, exp_name: str, settings: Mapping[str, Any], desc: ModelDescription,
                    parameter_sets: Sequence[Mapping[str, float]], todo: list) -> None:
        """Run the missing worlds of one experiment in one launch and cache their observables."""
        # every world ever run is one cache record, so fills numbered after them are new ones, also
        # across resumed sessions (processes sharing one cache at once may draw the same fills)
        first_fill = DESIGN_FILLS + len(self._cache)
        exp = self._experiment(exp_name, settings, desc, first_fill)
        sets = []
        for i, r, rpm, _ in todo:
            s = {**self.fixed, **{k: float(v) for k, v in parameter_sets[i].items()}}
            if rpm is not None:
                s["rpm"] = float(rpm)
            sets.append(s)
        t0 = time.perf_counter()
        print(f"DEM: {exp_name} {dict(settings) or ''}, {len(sets)} world(s) of {desc.contact_law.describe()}, "
              f"{desc.material.name} ...", file=sys.stderr, flush=True)
        results = exp.run(sets, device=self.device, progress=self.progress, processes=self.processes,
                          checkpoints=self.checkpoints, executor=self.executor)
        wall = time.perf_counter() - t0
        print(f"DEM: {exp_name}: {len(sets)} world(s) in {wall:.1f} s", file=sys.stderr, flush=True)
        self.dem_seconds += wall
        self.dem_worlds += len(sets)
        self.log.append({"experiment": exp_name, "settings": dict(settings), "worlds": len(sets),
                         "wall_s": round(wall, 2), "model": desc.contact_law.describe(),
                         "material": desc.material.name})
        for res in results:
            if not res.ok:
                f = self.dem_failures.setdefault(exp_name, {"worlds": 0, "first_error": res.error})
                f["worlds"] += 1
        for (i, r, rpm, wid), res in zip(todo, results):
            self._store({"id": wid, "experiment": exp_name, "status": res.status, "error": res.error,
                         "parameters": dict(parameter_sets[i]), "replicate": r, "rpm": rpm,
                         "observables": res.observables, "fill_index": first_fill + res.world})


def condition_settings(experiment: str, condition: Mapping[str, Any]) -> dict[str, Any]:
    """The settings of a measured condition that the experiment knows (rpm for the drum is a
    per-world setting); unknown names are an error naming them."""
    cls = EXPERIMENTS.get(experiment)
    if cls is None:
        raise ConfigError(f"unknown experiment {experiment!r}; the DEM can run {sorted(EXPERIMENTS)}")
    known = set(cls.field_names()) | ({"rpm"} if experiment == "drum" else set())
    bad = sorted(set(condition) - known)
    if bad:
        raise ConfigError(f"{experiment}: condition setting(s) {bad} are not settings of the experiment; "
                          f"valid: {sorted(known)}")
    out = {}
    for k, v in condition.items():
        if isinstance(v, float) and not math.isfinite(v):
            raise ConfigError(f"{experiment}: condition setting {k} must be finite, got {v}")
        out[k] = v
    return out
