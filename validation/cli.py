"""``warpdem diagnose CONFIG``: model versus measurements, the missing effect, the error falling.

Reads the config (:mod:`validation.config`) and the measurement file it names, checks both
against the engine's declarations before any DEM runs, builds the DEM forward model
(:mod:`validation.dem_forward`) and the candidate effects (:mod:`validation.dem_effects`), runs
:func:`validation.diagnose.diagnose` and writes ``diagnosis.json``, the figures and
``report.html`` to the output folder. DEM runs are cached in ``dem_runs.jsonl`` there: an
interrupted diagnosis resumes where it stopped. With ``diagnosis: {designs_up_front: auto}`` (the
default) a run on a CUDA device first runs every design that does not depend on the data in one
launch per experiment (``--prefetch`` makes that same call and stops); ``dem_timing.json``
records it.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any, Sequence

from warpdem import ConfigError
from warpdem.config_io import check_device, check_output_folder, device_arg, processes_arg, write_atomic

__all__ = ["diagnose_main", "build_diagnosis"]


def _material_of_measurements(path: Path):
    """The material a measurement file declares (None when it declares none)."""
    from calibration.materials import BulkMaterial
    from calibration.measurement.records import load_measurements

    mf = load_measurements(path)
    mat = getattr(mf, "material", None) or None
    if mat is None or isinstance(mat, BulkMaterial):
        return mat
    return BulkMaterial.from_config(dict(mat))


def _relative(p: Path, base_dir: Path) -> Path:
    return p if p.is_absolute() else base_dir / p


def _preset_material(cfg):
    from calibration.experiments import make_experiment

    return make_experiment("baffle", cfg.scale).bulk_material()


def _proposals(cfg, observables, material=None):
    """Conditions worth forecasting when candidates tie, as a :class:`validation.proposals.ProposalPlan`:
    the config's list (each one's lab effort from the experiments' tables unless it gives
    ``lab_hours``), or (auto) every setting a lab can change and every observable, at most
    ``max_proposed_conditions`` new conditions (:func:`validation.proposals.enumerate_proposals`).
    ``material``: the material the DEM will run (None: the presets'), to refuse a fill too large."""
    from calibration.experiments import EXPERIMENTS, make_experiment

    from .dem_forward import condition_settings
    from .forward import ProposedMeasurement
    from .proposals import ProposalPlan, enumerate_proposals, lab_hours

    def experiment_at(exp: str, settings) -> None:
        """Build (not run) ``exp`` at ``settings`` as the DEM will: a ConfigError says why it cannot run."""
        extra = dict(cfg.experiments.get(exp, {}))
        scale = extra.pop("scale", cfg.scale)
        kw = {**extra, **settings}
        if material is not None:
            kw["material"] = material
        make_experiment(exp, scale, **kw).check_size()

    if cfg.proposals == "none":
        return ProposalPlan((), (), (), cfg.max_proposed_conditions)
    if cfg.proposals == "auto":
        return enumerate_proposals(observables, cfg.scale, cfg.experiments, cfg.max_proposed_conditions,
                                   check=experiment_at)
    out = []
    for i, p in enumerate(cfg.proposals):
        if p.experiment not in EXPERIMENTS:
            raise ConfigError(f"proposals[{i}]: unknown experiment {p.experiment!r}; valid: {sorted(EXPERIMENTS)}")
        units = EXPERIMENTS[p.experiment].OBSERVABLES
        if p.quantity not in units:
            raise ConfigError(f"proposals[{i}]: the {p.experiment} experiment does not report {p.quantity!r}; "
                              f"it reports {list(units)}")
        try:
            settings = condition_settings(p.experiment, dict(p.settings))
            experiment_at(p.experiment, settings)
        except ConfigError as exc:
            raise ConfigError(f"proposals[{i}].settings: {exc}") from None
        measured = [dict(o.condition) for o in observables if o.experiment == p.experiment]
        hours = p.lab_hours if p.lab_hours is not None else lab_hours(
            p.experiment, settings, measured, p.n_repeats, cfg.scale, cfg.experiments.get(p.experiment, {}))
        key = f"{p.experiment}/proposed{i}/{p.quantity}"
        out.append(ProposedMeasurement(key, p.experiment, p.quantity, units[p.quantity], settings, p.label or key,
                                       p.expected_standard_error, p.n_repeats, lab_hours=hours))
    return ProposalPlan(tuple(out), (), (), cfg.max_proposed_conditions)


def build_diagnosis(cfg, base_dir: Path, device: str | None = None, output: Path | None = None,
                    add: Sequence[str] = (), processes: Any = None, ray_address: str | None = None):
    """Everything :func:`validation.diagnose.diagnose` needs, checked: (observations, base space,
    candidates, forward model, settings, dem effects)."""
    from calibration.designs import Parameter, ParameterSpace
    from calibration.model_description import ModelDescription

    from .dem_effects import default_effects, resolve_effect
    from .dem_forward import DEMForwardModel, ObservableSpec, condition_settings
    from .measurements import load_observations
    from .settings import DiagnosisSettings

    check_device(device or cfg.device, "--device" if device else "device")
    mpath = Path(cfg.measurements)
    if not mpath.is_absolute():
        mpath = base_dir / mpath
    if not mpath.is_file():
        raise ConfigError(f"measurements: file not found: {mpath}")
    observations = load_observations(mpath)
    desc = ModelDescription.from_config(cfg.model.model_dump(), base_dir=base_dir, where="model")
    # None: each experiment's scale preset material (quick-scale checks)
    material = desc.material or _material_of_measurements(mpath)
    plist = []
    for name, bounds in cfg.parameters.items():
        lo, hi = desc.check_bounds(name, list(bounds), "parameters")
        spec = desc.parameter_specs()[name]
        plist.append(Parameter(name, lo, hi, spec.unit, spec.description))
    fixed = {k: desc.check_value(k, v, "fixed") for k, v in cfg.fixed.items()}
    both = sorted(set(fixed) & set(cfg.parameters))
    if both:
        raise ConfigError(f"parameters and fixed both name {both}")
    ranges = {k: list(v) for k, v in cfg.effect_ranges.items()}
    if cfg.candidates == "default":
        effects = default_effects(desc, material or _preset_material(cfg), ranges)
    else:
        effects = [resolve_effect(t, ranges) for t in cfg.candidates]
    effect_parameters = {p.name for e in effects for p in e.candidate.parameters}
    unknown = sorted(set(ranges) - effect_parameters)
    if unknown:
        raise ConfigError(f"effect_ranges: {unknown} {'is not a parameter' if len(unknown) == 1 else 'are not parameters'}"
                          f" of the candidate effects; valid: {sorted(effect_parameters)}")
    names = [e.name for e in effects]
    if len(set(names)) != len(names):
        raise ConfigError(f"candidates: an effect is listed twice: {names}")
    for e in effects:
        if e.kind != "shape" and getattr(desc.contact_law, e.kind) != "none":
            raise ConfigError(f"candidates: the base law already has {e.kind} '{getattr(desc.contact_law, e.kind)}'; "
                              f"'{e.name}' cannot be added")
        clash = sorted(set(e.candidate.parameter_names) & (set(cfg.parameters) | set(fixed)))
        if clash:
            raise ConfigError(f"candidates: effect '{e.name}' brings {clash}, which the base already calibrates or fixes")
    added = list(cfg.add) + list(add)
    for a in added:
        if a not in names:
            raise ConfigError(f"add: '{a}' is not among the candidate effects {names}")
    specs = []
    for o in observations:
        try:
            settings = condition_settings(o.experiment, dict(o.condition))
        except ConfigError as exc:
            raise ConfigError(f"measurements: {mpath}: experiments.{o.experiment}: {exc}") from None
        specs.append(ObservableSpec(o.key, o.experiment, o.quantity, settings))
    plan = _proposals(cfg, list(observations), material)
    proposals = list(plan.proposals)
    specs += [ObservableSpec(p.key, p.experiment, p.quantity, condition_settings(p.experiment, dict(p.condition)))
              for p in proposals]
    # measurements and cache are relative to the config's folder; the output folder (as in
    # `warpdem calibrate`) and --output to the working directory
    out = check_output_folder(output or Path(cfg.output or f"results/diagnosis_{cfg.name}"),
                              "--output" if output else "output")
    cache = _relative(Path(cfg.cache), base_dir) if cfg.cache else out / "dem_runs.jsonl"
    if not cache.is_dir():  # a folder named as the cache is refused by the cache itself
        check_output_folder(cache.parent, "cache", "the DEM cache's folder")
    from calibration.executor import executor_from_config

    procs = processes if processes is not None else cfg.processes
    executor = executor_from_config({"kind": "ray", "address": ray_address} if ray_address else cfg.executor,
                                    procs, "executor")
    forward = DEMForwardModel(desc, material, effects, specs, scale=cfg.scale, experiment_settings=cfg.experiments,
                              fixed=fixed, device=device or cfg.device, processes=procs, cache=cache,
                              progress=False, proposals=proposals, executor=executor,
                              proposals_not_forecast=plan.not_forecast(),
                              cache_code_version=cfg.cache_code_version)
    try:  # every condition's experiment is built now (settings, fill size), not when its DEM starts
        forward.check_experiments()
    except ConfigError as exc:
        raise ConfigError(f"measurements: {mpath}: {exc}") from None
    disc = cfg.diagnosis.model_discrepancy
    unknown = sorted(set(disc) - set(observations.keys)) if isinstance(disc, dict) else []
    if unknown:
        raise ConfigError(f"diagnosis.model_discrepancy: unknown observable(s) {unknown}; the measurement file "
                          f"has {list(observations.keys)}")
    settings = DiagnosisSettings(**{**cfg.diagnosis.model_dump(), "add": tuple(dict.fromkeys(added))})
    return observations, ParameterSpace(tuple(plist)), [e.candidate for e in effects], forward, settings, out


def _prefetch(keys: Sequence[str], space, cands, forward, settings, which: Sequence[str]) -> int:
    """Run (into the cache) the designs :func:`validation.diagnose.planned_designs` lists, with
    :func:`validation.diagnose.run_planned_designs` (the diagnosis's ``designs_up_front`` step):
    one call for every version with a superset model, else one call per version. One JSON line per call."""
    from .diagnose import planned_designs, run_planned_designs, version_name
    from .forward import ForwardRunner, merges_versions

    valid = [version_name(v) for v, _, _ in planned_designs(space, cands, settings)]
    unknown = sorted(set(which) - set(valid))
    if unknown:
        print(f"warpdem diagnose: --prefetch: unknown version(s) {unknown}; valid: {sorted(valid)}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    merged = merges_versions(forward)

    def line(call: dict) -> None:
        if merged:  # one model holds every version: all designs in one launch per experiment
            doc = {"prefetched": call["versions"], "sets": call["sets"], "replicates": call["replicates"],
                   "superset": True, "wall_s": round(time.perf_counter() - t0, 1),
                   "dem_worlds_run": getattr(forward, "dem_worlds", None), "launches": getattr(forward, "log", None)}
        else:
            doc = {"prefetched": call["versions"][0], "sets": call["sets"], "replicates": call["replicates"],
                   "wall_s": round(call["seconds"], 1), "dem_worlds_run": getattr(forward, "dem_worlds", None)}
        print(json.dumps(doc), flush=True)

    run_planned_designs(ForwardRunner(forward), keys, space, cands, settings, list(which) or None, line)
    return 0


def _quiet_surrogate_fits() -> None:
    """Silence scikit-learn's Gaussian-process convergence warnings for this process. A length scale at
    its bound (a flat response) is expected and the surrogates' cross-validated quality is reported
    instead; ``validation.surrogates`` filters them per fit, but ``warnings.catch_warnings`` is not
    thread-safe and the pooled studies fit in threads, so some leaked onto the user's screen."""
    import warnings

    from sklearn.exceptions import ConvergenceWarning

    warnings.filterwarnings("ignore", category=ConvergenceWarning, module=r"sklearn\.")


def diagnose_main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="warpdem diagnose", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config", nargs="+", help="diagnosis config(s) (YAML), see validation/configs/; several configs "
                    "of the same model (e.g. one per measurement set) run in one process and share DEM launches")
    ap.add_argument("--output", help="output folder (default: the config's 'output')")
    ap.add_argument("--device", type=device_arg, help="cpu or cuda (default: the config's, else cuda if present)")
    ap.add_argument("--processes", type=processes_arg, help="CPU worker processes ('auto' = one per core)")
    ap.add_argument("--ray", metavar="ADDRESS", help="run the DEM batches on a Ray cluster: 'auto' (a running "
                    "cluster), 'local' (start one here) or ray://host:port (overrides the config's executor)")
    ap.add_argument("--add", action="append", default=[], metavar="EFFECT",
                    help="add this effect whatever the ranking (repeatable)")
    ap.add_argument("--prefetch", nargs="*", metavar="VERSION",
                    help="only run the designs the diagnosis needs before it sees the data (the base model and "
                         "each candidate; name some, e.g. 'base rolling_resistance', to split them over processes) "
                         "into the DEM cache, then stop: the same merged call as the diagnosis's designs_up_front "
                         "step")
    ap.add_argument("--experiments", nargs="+", metavar="EXPERIMENT",
                    help="with --prefetch: only these experiments' observables (one launch each), e.g. to keep "
                         "each call of a time-limited GPU machine to one experiment")
    args = ap.parse_args(list(argv) if argv is not None else None)
    _quiet_surrogate_fits()
    from .config import load_diagnosis_config
    from .diagnose import diagnose
    from .report import write_diagnosis

    t0 = time.perf_counter()
    if args.prefetch is not None and len(args.config) > 1:
        print("warpdem diagnose: --prefetch takes one config", file=sys.stderr)
        return 2
    procs = args.processes
    jobs = []
    try:
        for path in args.config:
            cfg, base_dir = load_diagnosis_config(path)
            output = Path(args.output) if args.output and len(args.config) == 1 else None
            jobs.append((path, *build_diagnosis(cfg, base_dir, args.device, output, args.add, procs, args.ray)))
        forward = jobs[0][4]
        for job in jobs[1:]:
            forward.adopt(job[4], where=job[0])
        outs = [job[6] for job in jobs]
        if len(set(map(str, outs))) != len(outs):
            raise ConfigError(f"the configs write to the same output folder: {[str(o) for o in outs]}")
    except (ConfigError, ValueError) as exc:
        print(f"warpdem diagnose: {exc}", file=sys.stderr)
        return 2
    if args.prefetch is not None:
        _, obs, space, cands, forward, settings, _ = jobs[0]
        keys = [o.key for o in obs if not args.experiments or o.experiment in args.experiments]
        if not keys:
            print(f"warpdem diagnose: --experiments {args.experiments}: no measured observable of these experiments",
                  file=sys.stderr)
            return 2
        return _prefetch(keys, space, cands, forward, settings, args.prefetch)
    from .design import NoiseNotMeasurable
    from .pooled import PooledForward, run_as_workers

    # one forward model for every config; requests made at the same time (candidates of a ranking
    # round, the diagnoses of several measurement sets) share DEM launches
    pool = PooledForward(forward)
    for path, obs, space, cands, _, settings, out in jobs:
        print(f"warpdem diagnose: {path}: {len(list(obs))} observables, base parameters {space.names}, candidates "
              f"{[c.name for c in cands]}; output {out}", file=sys.stderr, flush=True)
    try:
        results = run_as_workers(pool, [(lambda j=j: diagnose(j[1], j[2], j[3], pool, j[5])) for j in jobs],
                                 names=[Path(j[0]).stem for j in jobs])
    except KeyboardInterrupt:
        cache = getattr(forward, "cache_path", None)
        kept = (f"{forward.dem_worlds} DEM world(s) run in this sitting are kept in {cache}; run the same command "
                "again to resume from there" if cache else "no DEM cache is configured ('cache:' in the config), so "
                "the DEM worlds run so far are lost")
        print(f"warpdem diagnose: interrupted after {time.perf_counter() - t0:.0f} s; {kept}", file=sys.stderr)
        return 130
    except NoiseNotMeasurable as exc:
        print(f"warpdem diagnose: {exc}", file=sys.stderr)
        return 2
    wall = round(time.perf_counter() - t0, 1)
    for (path, *_, out), result in zip(jobs, results):
        paths = write_diagnosis(result, out)
        timing = {"wall_s": wall, "dem_s": round(forward.dem_seconds, 1), "dem_worlds_run": forward.dem_worlds,
                  "dem_launches": forward.log, "merged_requests": pool.merges,
                  "diagnoses_in_this_process": [str(j[0]) for j in jobs], "device": str(forward.device or "default"),
                  "designs_up_front": result.forward.get("designs_up_front"),
                  "failed_worlds": getattr(forward, "dem_failures", {})}
        write_atomic(out / "dem_timing.json", json.dumps(timing, indent=1))
        if len(jobs) > 1:
            print(f"{path}:")
        print(result.headline)
        print(f"report: {paths.get('report', out / 'report.html')}  (wall {timing['wall_s']} s, DEM {timing['dem_s']} s, "
              f"{timing['dem_worlds_run']} worlds run{' for all configs' if len(jobs) > 1 else ''})")
        for exp_name, f in timing["failed_worlds"].items():
            print(f"  {f['worlds']} {exp_name} world(s) failed a measurement (left out of the fits; each one's error "
                  f"is in the DEM records), e.g. {f['first_error']}")
    return 0

if __name__ == "__main__":
    sys.exit(diagnose_main())
