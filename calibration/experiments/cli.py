"""``warpdem experiment CONFIG``: run one standard experiment from a YAML/JSON config, print
and save the results (JSON) and one picture of the fitted profile per world.

Config (SI units; see calibration/configs/quick_*.yaml)::

    experiment: baffle            # baffle | drum | cylinder
    scale: quick                  # paper | quick (drum also: short)
    device: cpu                   # optional (default: Warp's default device)
    output: results/quick_baffle  # optional (default: experiment_<name>_<scale>)
    material: {type: spheres, diameter: [0.024, 0.030]}   # optional
    contact_law: {rolling: epsd2, cohesion: sjkr}         # optional (default Hertz-Mindlin + epsd)
    plugins: [my_effects.py]      # optional: files (relative to the config) of extra sub-models
    settings: {lift_speed: 0.2}   # optional: any setting of the experiment
    parameters:                   # one world per entry (or a mapping of equal-length lists)
      - {mu_s_pp: 0.3, mu_s_pw: 0.3, mu_r_pp: 0.05, mu_r_pw: 0.05}
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any, Mapping, Sequence

from pydantic import Field, ValidationError, field_validator

from warpdem import ConfigError
from warpdem.config_io import (check_device, check_output_folder, device_arg, load_config_file, parse_processes,
                               processes_arg, write_atomic)
from warpdem.config_schema import Flag, Section, Text, problem_lines, raise_problems

from . import EXPERIMENTS, ExperimentResult, make_experiment

__all__ = ["experiment_main", "load_config", "run_config", "plot_result", "ExperimentFile"]



def load_config(path: str | os.PathLike) -> dict[str, Any]:
    """Read a YAML or JSON experiment config and check it whole (:func:`check_config`,
    :func:`deeper_problems`) before any DEM runs."""
    p = Path(path)
    cfg = check_config(load_config_file(p, "experiment config"), str(p))
    cfg["_base_dir"] = str(p.parent)
    raise_problems(str(p), deeper_problems(cfg))
    return cfg


def deeper_problems(cfg: Mapping[str, Any]) -> list[str]:
    """Every problem below the top level, before any DEM runs: the model (material, contact law,
    plugins), the experiment's scale and settings, and each parameter set (names, numbers, the
    sub-models' admissible bounds). Each stage is checked even when another failed, so one
    message can list them all."""
    from ..model_description import ModelDescription
    from .common import normalize_parameter_sets

    problems: list[str] = []
    model = None
    try:
        model = ModelDescription.from_config(cfg, base_dir=cfg.get("_base_dir", "."))
    except (ConfigError, ValueError, TypeError) as exc:
        problems.append(f"model (material, contact_law, plugins): {exc}")
    settings = dict(cfg.get("settings") or {})
    if model is not None:
        if model.material is not None:
            settings["material"] = model.material
        settings.update(contact_law=model.contact_law, plugins=model.plugins)
    exp = None
    try:
        exp = make_experiment(cfg["experiment"], cfg.get("scale", "paper"), **settings)
    except (ConfigError, ValueError, TypeError) as exc:
        problems.append(f"experiment {cfg['experiment']!r} (scale, settings): {exc}")
        try:  # the parameter sets are still checked, against the experiment without the user's settings
            model_only = {k: settings[k] for k in ("material", "contact_law", "plugins") if k in settings}
            exp = make_experiment(cfg["experiment"], cfg.get("scale", "paper"), **model_only)
        except (ConfigError, ValueError, TypeError):
            exp = None
    if exp is not None and model is not None:
        try:
            sets = normalize_parameter_sets(cfg["parameters"], exp.parameter_names)
        except ConfigError as exc:
            problems.append(f"parameters: {exc}")
        else:
            try:  # the fill's size against the machine, for every world of the run
                exp.check_size(len(sets))
            except ConfigError as exc:
                problems.append(str(exc))
            specs = model.parameter_specs(exp.bulk_material())  # per pair type (mu_s_pp, ...) and shape
            for w, ps in enumerate(sets):
                for name, value in ps.items():
                    spec = specs.get(name)
                    if spec is not None and not spec.bounds[0] <= value <= spec.bounds[1]:
                        problems.append(f"parameters[{w}].{name} = {value} [{spec.unit}] is outside its admissible "
                                        f"range [{spec.bounds[0]}, {spec.bounds[1]}]")
    return problems


class ExperimentFile(Section):
    """The experiment config's schema (module docstring): every key, its type; an unknown key is
    refused. What depends on the experiment (its settings, the parameter names, the model) is
    :func:`deeper_problems`."""

    experiment: Text
    scale: Text = "paper"
    device: Text | None = None
    processes: Any = None
    output: Text | None = Field(None, min_length=1)
    material: Any = None
    contact_law: Any = None
    plugins: Any = None
    settings: dict[Text, Any] | None = None
    parameters: Any
    progress: Flag = False
    description: Text = ""

    @field_validator("experiment")
    @classmethod
    def _registered(cls, v: str) -> str:
        if v not in EXPERIMENTS:
            raise ValueError(f"unknown experiment {v!r}; valid: {sorted(EXPERIMENTS)}")
        return v

    @field_validator("processes")
    @classmethod
    def _processes(cls, v: Any) -> Any:
        try:
            return parse_processes(v, "processes")
        except ConfigError:
            raise ValueError("must be a whole number >= 1 or 'auto'") from None


def check_config(cfg: Any, source: str = "<mapping>") -> dict[str, Any]:
    """Validate the top level of a config mapping (:class:`ExperimentFile`, then where the model
    and scale belong); every problem found is listed in one ConfigError."""
    if not isinstance(cfg, Mapping):
        raise ConfigError(f"{source}: an experiment config must be a mapping of keys, got "
                          f"{'an empty file' if cfg is None else type(cfg).__name__}")
    problems: list[str] = []
    try:
        ExperimentFile.model_validate(dict(cfg))
    except ValidationError as exc:
        problems += problem_lines(exc, ExperimentFile)
    settings = cfg.get("settings") or {}
    if not isinstance(settings, Mapping):
        settings = {}
    if "material" in settings and "material" in cfg:
        problems.append("give 'material' either at the top level or in 'settings', not both")
    if "scale" in settings:
        problems.append("put 'scale' at the top level, not in 'settings'")
    for k in ("contact_law", "plugins"):
        if k in settings:
            problems.append(f"put '{k}' at the top level, not in 'settings'")
    try:
        check_device(cfg.get("device"), "device", present=False)  # present: checked at the run
    except ConfigError as exc:
        problems.append(str(exc))
    raise_problems(source, problems)
    return dict(cfg)


def run_config(cfg: Mapping[str, Any], device: str | None = None, progress: bool | None = None,
               processes: int | str | None = None) -> tuple[list[ExperimentResult], Any]:
    """Build the experiment of a checked config and run it; returns (results, experiment)."""
    from ..model_description import ModelDescription

    settings = dict(cfg.get("settings") or {})
    model = ModelDescription.from_config(cfg, base_dir=cfg.get("_base_dir", "."))
    if model.material is not None:
        settings["material"] = model.material
    settings["contact_law"] = model.contact_law
    settings["plugins"] = model.plugins
    exp = make_experiment(cfg["experiment"], cfg.get("scale", "paper"), **settings)
    results = exp.run(cfg["parameters"], device=device or cfg.get("device"),
                      progress=bool(cfg.get("progress", False) if progress is None else progress),
                      processes=processes if processes is not None else cfg.get("processes", "auto"))
    return results, exp


# --------------------------------------------------------------------------- pictures
def _draw_particles(ax, x, r, h_axis: int, keep) -> None:
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle

    patches = [Circle((p[h_axis], p[2]), q) for p, q in zip(x[keep], r[keep])]
    ax.add_collection(PatchCollection(patches, facecolor="0.7", edgecolor="0.3", linewidths=0.3))


def _draw_fit(ax, fit, label: str, color: str = "tab:red", sign: float = 1.0, h0: float = 0.0) -> None:
    import numpy as np

    p = fit.profile
    ok = p.counts > 0
    ax.plot(h0 + sign * p.centres[ok], p.heights[ok], ".", color="tab:blue", ms=4, label="bin heights")
    xs = np.array([fit.x_fit.min(), fit.x_fit.max()])
    ax.plot(h0 + sign * xs, fit.slope * xs + fit.intercept, "-", color=color, lw=2,
            label=f"{label}: {fit.angle_deg:.1f} deg, {fit.n_bins} bins")
    if fit.z_band is not None:
        for z in fit.z_band:
            ax.axhline(z, color="0.5", lw=0.6, ls=":")


def plot_result(result: ExperimentResult, path: str | os.PathLike) -> None:
    """Side view of the world's particles with the surface bins and fitted line(s) (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    s = result.protocol.get("settings", {})
    title = (f"{result.experiment} ({result.scale}) world {result.world}: "
             + (f"{result.angle_name} = {result.angle_deg:.2f} deg" if result.ok else f"FAILED: {result.error}"))
    params = ", ".join(f"{k}={v:g}" for k, v in result.parameters.items())
    if result.experiment == "cylinder":
        fig, axs = plt.subplots(1, 2, figsize=(12, 4.5))
    else:
        fig, axs = plt.subplots(1, 1, figsize=(10, 5))
        axs = [axs]
    if result.particles is not None:
        x, r = (np.asarray(a, dtype=float) for a in result.particles)
    else:
        x, r = np.zeros((0, 3)), np.zeros(0)
    if result.experiment == "baffle":
        ax = axs[0]
        y0, y1 = s.get("measure_y", (0.03, 0.17))
        _draw_particles(ax, x, r, 0, (x[:, 1] >= y0) & (x[:, 1] <= y1))
        if result.fit is not None:
            _draw_fit(ax, result.fit, "alpha")
        ax.axvline(s.get("box_length", 0.3), color="k", lw=1, ls="--")
        ax.set_xlim(-0.01, s.get("floor_length", 0.7))
    elif result.experiment == "drum":
        ax = axs[0]
        y0, y1 = s.get("measure_y", (0.03, 0.12))
        _draw_particles(ax, x, r, 0, (x[:, 1] >= y0) & (x[:, 1] <= y1))
        R = 0.5 * s.get("diameter", 0.3)
        t = np.linspace(0, 2 * np.pi, 200)
        ax.plot(R * np.cos(t), R * np.sin(t), "k-", lw=1)
        c = 0.5 * s.get("crop_side", 0.15)
        ax.plot([-c, c, c, -c, -c], [-c, -c, c, c, -c], "k--", lw=0.8)
        if result.fit is not None:
            _draw_fit(ax, result.fit.fits[-1], "last snapshot")
            d = result.diagnostics
            ax.text(0.02, 0.02, f"beta = atan|mean slope| = {result.fit.angle_deg:.2f} deg; snapshots "
                    f"{d.get('snapshot_mean_deg', float('nan')):.2f} +- {d.get('snapshot_std_deg', float('nan')):.2f} deg",
                    transform=ax.transAxes, fontsize=8)
        ax.set_xlim(-R - 0.01, R + 0.01)
        ax.set_ylim(-R - 0.01, R + 0.01)
    elif result.experiment == "cylinder":
        d_mean = result.diagnostics.get("mean_diameter_m", float(2 * r.mean()) if r.size else 0.02)
        for k, (ax, plane) in enumerate(zip(axs, ("xz", "yz"))):
            other = 1 if plane == "xz" else 0
            h_axis = 0 if plane == "xz" else 1
            _draw_particles(ax, x, r, h_axis, np.abs(x[:, other]) < d_mean)
            if result.fit is not None:
                _draw_fit(ax, result.fit.fits[2 * k], f"+{plane[0]}", "tab:red", 1.0)
                _draw_fit(ax, result.fit.fits[2 * k + 1], f"-{plane[0]}", "tab:orange", -1.0)
            ax.set_title(f"{plane} plane")
            ax.set_xlim(-0.5 * s.get("plate_size", 1.0), 0.5 * s.get("plate_size", 1.0))
    for ax in axs:
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("horizontal [m]")
        ax.set_ylabel("z [m]")
        handles, labels = ax.get_legend_handles_labels()
        uniq = dict(zip(labels, handles))
        if uniq:
            ax.legend(uniq.values(), uniq.keys(), fontsize=7, loc="upper right")
    fig.suptitle(f"{title}\n{params}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- main
def experiment_main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``warpdem experiment``; returns the exit status (0: every world measured,
    1: some world failed, 2: configuration error)."""
    ap = argparse.ArgumentParser(prog="warpdem experiment", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config", help="YAML or JSON experiment config")
    ap.add_argument("--device", type=device_arg, help="override the config's device (cpu, cuda, cuda:0)")
    ap.add_argument("--output", help="override the config's output directory")
    ap.add_argument("--progress", action="store_true", help="print protocol phases to stderr")
    ap.add_argument("--processes", default=None, type=processes_arg,
                    help="CPU only: split the worlds over N processes ('auto': one per core; default: the "
                         "config's 'processes', else auto)")
    ap.add_argument("--no-plots", action="store_true", help="do not write the per-world pictures")
    args = ap.parse_args(argv)
    try:
        cfg = load_config(args.config)
        out_dir = args.output or cfg.get("output") or f"experiment_{cfg['experiment']}_{cfg.get('scale', 'paper')}"
        settings = dict(cfg.get("settings") or {})
        if settings.get("vtk_every") is not None and settings.get("vtk_folder") is None:
            settings["vtk_folder"] = str(Path(out_dir) / "vtk")  # the VTK series follows --output
            cfg["settings"] = settings
        check_device(args.device or cfg.get("device"), "--device" if args.device else f"{args.config}: device")
        check_output_folder(out_dir, "--output" if args.output else "output")
        results, exp = run_config(cfg, device=args.device, progress=args.progress or None, processes=args.processes)
    except ConfigError as exc:
        print(f"warpdem experiment: configuration error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.output or cfg.get("output") or f"experiment_{cfg['experiment']}_{cfg.get('scale', 'paper')}")
    out.mkdir(parents=True, exist_ok=True)
    doc = {"config": cfg, "config_file": str(args.config), "experiment": exp.name, "scale": exp.scale,
           "results": [r.to_dict() for r in results]}
    write_atomic(out / "results.json", json.dumps(doc, indent=1))
    if not args.no_plots:
        for r in results:
            plot_result(r, out / f"world_{r.world:03d}.png")
    from .report import write_experiment_report

    report = write_experiment_report(results, exp, out)
    for r in results:
        line = {"experiment": r.experiment, "scale": r.scale, "world": r.world, "status": r.status,
                r.angle_name: None if r.angle_deg is None else round(r.angle_deg, 3), "parameters": r.parameters}
        if r.bulk_density is not None:
            line["bulk_density"] = round(r.bulk_density, 1)
        if r.experiment == "drum" and r.ok:
            line["snapshot_std_deg"] = round(r.diagnostics["snapshot_std_deg"], 3)
        if r.experiment == "cylinder" and r.ok:
            if r.diagnostics.get("no_pile"):
                line["no_pile"] = r.diagnostics.get("no_pile_reason", True)
            else:
                line["thetas_deg"] = [round(t, 3) for t in r.diagnostics["thetas_deg"]]
        if r.observables:
            line["observables"] = {k: (None if v is None else round(v, 4)) for k, v in r.observables.items()}
        if not r.ok:
            line["error"] = r.error
        print(json.dumps(line))
    t = results[0].timing
    print(json.dumps({"output": str(out), "report": str(report), "wall_s": t["wall_s"], "steps": t["steps"], "simulated_s": t["simulated_s"],
                      "spheres": t["spheres"], "worlds": t["worlds"], "device": t["device"]}))
    return 0 if all(r.ok for r in results) else 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(experiment_main())
