"""The strict schemas of every file type, and every command's options, refuse a bad input at load
(issue 29): exit code 2, a message naming the key (or option), no traceback, no DEM.

The cases run ``warpdem COMMAND ...`` through :func:`warpdem.cli.main` with the helpers and the
``no_dem`` fixture of tests/test_bad_inputs_total.py (building a simulation, running an
experiment or building the pump model fails a case); with that file's cases they make the
table of docs/bad_inputs.md. The shipped configs still load (a schema that refuses good files
would pass every case here).
"""
from __future__ import annotations

import sys
import time
import traceback
from pathlib import Path
from typing import Any, Callable

import pytest
import yaml

sys.path.insert(0, str(Path(__file__).parent))
from test_bad_inputs_total import CASES as TOTAL_CASES  # noqa: E402
from test_bad_inputs_total import (CAMPAIGN, EXPERIMENT, LAB_TEXT, PUMP, _case_id, a_file, camp, diag,  # noqa: E402
                                   diag_with_lab, edited, exp, lab, no_dem, pump, put)

from warpdem.cli import main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEM_AT = {"mu_s_pp": 0.45, "mu_s_pw": 0.35}
_ = no_dem  # a fixture of the total file: any DEM started fails a case here too


def target(value: Any) -> list[str]:
    """``calibrate --max-samples 1`` of the quick campaign whose first response has ``value`` as target."""
    return camp(edited(CAMPAIGN, "responses.0.target", value))


def setting(index: int, settings: dict) -> list[str]:
    """The quick campaign with ``settings`` for response ``index``."""
    return camp(edited(CAMPAIGN, f"responses.{index}.settings", settings))


def image() -> str:
    """A synthetic photograph of a 35 deg slope in the case's folder."""
    import cv2

    from calibration.measurement.render import synthetic_slope_image

    cv2.imwrite("pile.png", synthetic_slope_image(35.0))
    return "pile.png"


def measure(*options: str) -> list[str]:
    return ["measure", image(), *options, "--no-diagnostic"]


CASES: list[tuple[str, Callable[[], list[str]], list[str]]] = [
    # ---------------------------------------------------------------- campaign: targets (--max-samples never read them)
    ("cal-target-text", lambda: target("high"), ["responses[0].target", "angle in deg"]),
    ("cal-target-true", lambda: target(True), ["responses[0].target", "True"]),
    ("cal-target-negative", lambda: target(-5.0), ["responses[0].target", "> 0"]),
    ("cal-target-above-90", lambda: target(95.0), ["responses[0].target", "< 90"]),
    ("cal-target-missing", lambda: camp({**CAMPAIGN, "responses": [
        {k: v for k, v in CAMPAIGN["responses"][0].items() if k != "target"}, CAMPAIGN["responses"][1]]}),
     ["responses[0].target", "missing"]),
    ("cal-target-empty-mapping", lambda: target({}), ["responses[0].target", "dem_at"]),
    ("cal-target-file-missing", lambda: target({"file": "nope.yaml", "experiment": "baffle", "condition": "9kg"}),
     ["alpha_static", "nope.yaml"]),
    ("cal-target-file-without-condition", lambda: target({"file": "tiny_lab.yaml", "experiment": "baffle"}),
     ["responses[0].target.condition", "missing"]),
    ("cal-target-file-unknown-condition", lambda: target({"file": "tiny_lab.yaml", "experiment": "baffle",
                                                          "condition": "10kg"}), ["alpha_static", "10kg", "9kg"]),
    ("cal-target-file-unknown-experiment", lambda: target({"file": "tiny_lab.yaml", "experiment": "drum",
                                                           "condition": "9kg"}), ["alpha_static", "drum"]),
    ("cal-target-runs-zero", lambda: target({"dem_at": DEM_AT, "runs": 0}), ["responses[0].target.runs", ">= 1"]),
    ("cal-target-runs-text", lambda: target({"dem_at": DEM_AT, "runs": "five"}), ["target.runs", "whole number"]),
    ("cal-target-unknown-key", lambda: target({"dem_at": DEM_AT, "run": 2}), ["target.run", "unknown key", "runs"]),
    ("cal-dem-at-text", lambda: target({"dem_at": {**DEM_AT, "mu_s_pp": "high"}}), ["dem_at.mu_s_pp", "number"]),
    ("cal-dem-at-true", lambda: target({"dem_at": {**DEM_AT, "mu_s_pp": True}}), ["dem_at.mu_s_pp", "True"]),
    ("cal-dem-at-out-of-range", lambda: target({"dem_at": {**DEM_AT, "mu_s_pp": 50.0}}),
     ["dem_at", "mu_s_pp", "admissible range"]),
    ("cal-dem-at-unknown-parameter", lambda: target({"dem_at": {**DEM_AT, "mu_x_pp": 0.3}}), ["dem_at", "mu_x_pp"]),
    ("cal-validation-target-text", lambda: camp(edited(CAMPAIGN, "validation.target", "high")),
     ["validation.target"]),
    # ---------------------------------------------------------------- campaign: types and sections
    ("cal-bound-true", lambda: camp(edited(CAMPAIGN, "parameters.mu_s_pp", [True, 0.5])), ["parameters.mu_s_pp[0]"]),
    ("cal-bound-quoted", lambda: camp(edited(CAMPAIGN, "parameters.mu_s_pp", ["0.1", 0.5])),
     ["parameters.mu_s_pp[0]", "without quotes"]),
    ("cal-bound-three-values", lambda: camp(edited(CAMPAIGN, "parameters.mu_s_pp", [0.1, 0.3, 0.5])),
     ["parameters.mu_s_pp", "[low, high]"]),
    ("cal-parameters-empty", lambda: camp({**CAMPAIGN, "parameters": {}}), ["parameters", "at least 1"]),
    ("cal-parameter-unknown", lambda: camp(edited(CAMPAIGN, "parameters.mu_x", [0.1, 0.2])), ["mu_x", "valid"]),
    ("cal-parameter-both-fixed", lambda: camp(edited(CAMPAIGN, "fixed.mu_s_pp", 0.3)), ["mu_s_pp", "fixed"]),
    ("cal-fixed-true", lambda: camp(edited(CAMPAIGN, "fixed.mu_r_pp", True)), ["fixed.mu_r_pp", "number"]),
    ("cal-fixed-quoted", lambda: camp(edited(CAMPAIGN, "fixed.mu_r_pp", "0.1")), ["fixed.mu_r_pp", "without quotes"]),
    ("cal-design-samples-text", lambda: camp(edited(CAMPAIGN, "design.samples", "many")), ["design.samples"]),
    ("cal-design-samples-fraction", lambda: camp(edited(CAMPAIGN, "design.samples", 14.5)),
     ["design.samples", "whole number"]),
    ("cal-design-seed-true", lambda: camp(edited(CAMPAIGN, "design.seed", True)), ["design.seed"]),
    ("cal-design-held-out-too-many", lambda: camp(edited(CAMPAIGN, "design.held_out", 13)),
     ["design.held_out", "training samples"]),
    ("cal-design-unknown-key", lambda: camp(edited(CAMPAIGN, "design.sample", 10)), ["design.sample", "unknown key"]),
    ("cal-name-list", lambda: camp({**CAMPAIGN, "name": [1, 2]}), ["name", "text"]),
    ("cal-output-number", lambda: camp({**CAMPAIGN, "output": 5}), ["output", "text"]),
    ("cal-fills-typo", lambda: camp({**CAMPAIGN, "fills": "independant"}), ["fills", "independent"]),
    ("cal-processes-text", lambda: camp({**CAMPAIGN, "processes": "many"}), ["processes", "auto"]),
    ("cal-responses-empty", lambda: camp({**CAMPAIGN, "responses": []}), ["responses", "at least 1"]),
    ("cal-responses-mapping", lambda: camp({**CAMPAIGN, "responses": {"a": 1}}), ["responses", "list"]),
    ("cal-response-name-number", lambda: camp(edited(CAMPAIGN, "responses.0.name", 5)), ["responses[0].name"]),
    ("cal-response-name-empty", lambda: camp(edited(CAMPAIGN, "responses.0.name", "")),
     ["responses[0].name", "empty"]),
    ("cal-response-unknown-key", lambda: camp(edited(CAMPAIGN, "responses.0.replicate", 2)),
     ["responses[0].replicate", "unknown key"]),
    ("cal-response-scale-typo", lambda: camp(edited(CAMPAIGN, "responses.0.scale", "quik")), ["quik", "alpha_static"]),
    ("cal-response-replicates-zero", lambda: camp(edited(CAMPAIGN, "responses.0.replicates", 0)),
     ["responses[0].replicates", ">= 1"]),
    ("cal-response-settings-list", lambda: setting(0, [1]), ["responses[0].settings", "mapping"]),
    ("cal-response-setting-seed-text", lambda: setting(0, {"seed": "abc"}), ["alpha_static", "seed", "whole number"]),
    ("cal-response-setting-max-contacts-text", lambda: setting(0, {"max_contacts": "many"}), ["max_contacts"]),
    ("cal-response-setting-lift-speed-true", lambda: setting(0, {"lift_speed": True}), ["lift_speed"]),
    ("cal-response-setting-fill-per-world-text", lambda: setting(0, {"fill_per_world": "yes"}),
     ["fill_per_world", "true or false"]),
    ("cal-response-setting-dt-negative", lambda: setting(0, {"dt": -1e-5}), ["alpha_static", "dt"]),
    ("cal-response-setting-rpm-text", lambda: setting(1, {"rpm": "fast"}), ["beta_dynamic", "rpm"]),
    ("cal-response-setting-measure-y-reversed", lambda: setting(0, {"measure_y": [0.2, 0.1]}), ["measure_y"]),
    ("cal-response-setting-measure-y-text", lambda: setting(0, {"measure_y": "wide"}), ["measure_y", "[low, high]"]),
    ("cal-response-setting-vtk", lambda: setting(0, {"vtk_every": 0.1}), ["responses[0].settings", "'vtk' section"]),
    ("cal-validation-list", lambda: camp({**CAMPAIGN, "validation": [1]}), ["validation", "mapping"]),
    ("cal-optimisation-pop-text", lambda: camp(edited(CAMPAIGN, "optimisation.pop_size", "many")),
     ["optimisation.pop_size"]),
    ("cal-optimisation-pop-fraction", lambda: camp(edited(CAMPAIGN, "optimisation.pop_size", 100.5)),
     ["optimisation.pop_size", "whole number"]),
    ("cal-optimisation-pop-true", lambda: camp(edited(CAMPAIGN, "optimisation.pop_size", True)),
     ["optimisation.pop_size"]),
    ("cal-tolerance-text", lambda: camp(edited(CAMPAIGN, "optimisation.tolerance_deg", "tight")), ["tolerance_deg"]),
    ("cal-tolerance-list-with-text", lambda: camp(edited(CAMPAIGN, "optimisation.tolerance_deg", [1.0, "x"])),
     ["tolerance_deg"]),
    ("cal-tolerance-nan", lambda: camp(edited(CAMPAIGN, "optimisation.tolerance_deg", float("nan"))),
     ["tolerance_deg", "finite"]),
    ("cal-tolerance-inf", lambda: camp(edited(CAMPAIGN, "optimisation.tolerance_deg", float("inf"))),
     ["tolerance_deg", "finite"]),
    ("cal-tolerance-quoted", lambda: camp(edited(CAMPAIGN, "optimisation.tolerance_deg", "1.5")), ["tolerance_deg"]),
    ("cal-confirmation-runs-quoted", lambda: camp(edited(CAMPAIGN, "confirmation.runs", "5")),
     ["confirmation.runs", "without quotes"]),
    ("cal-sensitivity-n-fraction", lambda: camp(edited(CAMPAIGN, "sensitivity.n", 1024.5)), ["sensitivity.n"]),
    ("cal-surrogate-splits-true", lambda: camp({**CAMPAIGN, "surrogate": {"n_splits": True}}),
     ["surrogate.n_splits"]),
    ("cal-checkpoints-enabled-text", lambda: camp({**CAMPAIGN, "checkpoints": {"enabled": "yes"}}),
     ["checkpoints.enabled", "true or false"]),
    ("cal-checkpoints-every-negative", lambda: camp({**CAMPAIGN, "checkpoints": {"every_s": -1}}),
     ["checkpoints.every_s", ">= 0"]),
    ("cal-vtk-every-text", lambda: camp({**CAMPAIGN, "vtk": {"every": "often"}}), ["vtk.every", "number"]),
    ("cal-vtk-replicate-beyond-fills", lambda: camp({**CAMPAIGN, "vtk": {"every": 0.05, "replicate": 2}}),
     ["vtk.replicate", "alpha_static"]),
    ("cal-contact-law-typo", lambda: camp({**CAMPAIGN, "contact_law": {"rolling": "epsd3"}}),
     ["contact_law", "epsd3"]),
    ("cal-contact-law-list", lambda: camp({**CAMPAIGN, "contact_law": ["epsd"]}), ["contact_law", "mapping"]),
    ("cal-material-reversed-diameters", lambda: camp({**CAMPAIGN, "material": {"type": "spheres",
                                                                              "diameter": [0.03, 0.02]}}),
     ["material", "diameter"]),
    ("cal-executor-unknown-kind", lambda: camp({**CAMPAIGN, "executor": {"kind": "slurm"}}), ["executor.kind"]),
    ("cal-plugin-missing", lambda: camp({**CAMPAIGN, "plugins": ["nope.py"]}), ["plugins", "nope.py"]),
    ("cal-batch-worlds-zero", lambda: camp({**CAMPAIGN, "batch_worlds": 0}), ["batch_worlds", ">= 1"]),
    ("cal-top-level-list", lambda: ["calibrate", put("c.yaml", "- 1\n- 2\n")], ["c.yaml", "mapping"]),
    ("cal-empty-file", lambda: ["calibrate", put("c.yaml", "")], ["c.yaml", "mapping"]),
    ("cal-max-samples-zero", lambda: camp(CAMPAIGN)[:-1] + ["0"], ["--max-samples", ">= 1"]),
    ("cal-max-samples-text", lambda: camp(CAMPAIGN)[:-1] + ["all"], ["--max-samples", "all"]),
    ("cal-only-unknown-response", lambda: camp(CAMPAIGN, "--only", "gamma"), ["--only", "gamma"]),
    # ---------------------------------------------------------------- pump
    ("pump-worlds-option-negative", lambda: pump(PUMP, "--worlds", "-1"), ["run.worlds", ">= 1", "-1"]),
    ("pump-worlds-negative", lambda: pump(edited(PUMP, "run.worlds", -1)), ["run.worlds", ">= 1"]),
    ("pump-revolutions-option-negative", lambda: pump(PUMP, "--revolutions", "-2"), ["run.revolutions", "> 0"]),
    ("pump-design-unknown-key", lambda: pump(edited(PUMP, "design.inlet_lenght", 0.1)),
     ["design.inlet_lenght", "unknown key", "inlet_length"]),
    ("pump-design-text", lambda: pump(edited(PUMP, "design.speed_rpm", "fast")), ["design.speed_rpm", "number"]),
    ("pump-design-true", lambda: pump(edited(PUMP, "design.speed_rpm", True)), ["design.speed_rpm"]),
    ("pump-design-blades-fraction", lambda: pump(edited(PUMP, "design.blades", 3.5)), ["design.blades"]),
    ("pump-design-efficiency", lambda: pump(edited(PUMP, "design.hydraulic_efficiency", 1.5)),
     ["design", "hydraulic_efficiency"]),
    ("pump-design-leading-edge", lambda: pump(edited(PUMP, "design.leading_edge_radius", 0.5)),
     ["design", "leading_edge_radius"]),
    ("pump-design-list", lambda: pump({**PUMP, "design": [1]}), ["design", "mapping"]),
    ("pump-geometry-resolution-text", lambda: pump(edited(PUMP, "geometry.resolution", "fine")),
     ["geometry.resolution"]),
    ("pump-geometry-mesh-unknown-component", lambda: pump(edited(PUMP, "geometry.meshes", {"rotor": "r.stl"})),
     ["geometry.meshes.rotor", "blade"]),
    ("pump-geometry-mesh-missing", lambda: pump(edited(PUMP, "geometry.meshes", {"blade": "nope.stl"})),
     ["geometry.meshes.blade", "nope.stl"]),
    ("pump-fluid-density-text", lambda: pump(edited(PUMP, "fluid.density", "heavy")), ["fluid.density"]),
    ("pump-fluid-density-negative", lambda: pump(edited(PUMP, "fluid.density", -1000)), ["fluid.density", "> 0"]),
    ("pump-fluid-viscosity-zero", lambda: pump(edited(PUMP, "fluid.viscosity", 0)), ["fluid.viscosity"]),
    ("pump-fluid-grid-zero", lambda: pump(edited(PUMP, "fluid.grid_spacing", 0)), ["fluid.grid_spacing"]),
    ("pump-fluid-grid-tiny", lambda: pump(edited(PUMP, "fluid.grid_spacing", 1e-6)),
     ["fluid.grid_spacing", "MAX_GRID_POINTS"]),
    ("pump-fluid-drag-typo", lambda: pump(edited(PUMP, "fluid.drag", "stokes")), ["fluid.drag", "di_felice"]),
    ("pump-fluid-added-mass-true", lambda: pump(edited(PUMP, "fluid.added_mass", True)), ["fluid.added_mass"]),
    ("pump-fluid-voidage-negative", lambda: pump(edited(PUMP, "fluid.voidage_cell", -0.1)),
     ["fluid.voidage_cell", "admissible range"]),
    ("pump-coupling-relaxation-text", lambda: pump(edited(PUMP, "coupling.relaxation", "x")),
     ["coupling.relaxation"]),
    ("pump-volume-fraction-true", lambda: pump(edited(PUMP, "particles.volume_fraction", True)),
     ["particles.volume_fraction"]),
    ("pump-volume-fraction-above", lambda: pump(edited(PUMP, "particles.volume_fraction", 1.5)),
     ["particles.volume_fraction", "< 0.6"]),
    ("pump-rate-negative", lambda: pump(edited(PUMP, "particles.rate", -5)), ["particles.rate", "> 0"]),
    ("pump-rate-too-low", lambda: pump(edited(PUMP, "particles.rate", 0.01)),
     ["injects no particle", "particles.rate"]),
    ("pump-inject-after-the-run", lambda: pump(edited(PUMP, "particles.inject_from", 5.0)),
     ["particles.inject_from", "after the run's end"]),
    ("pump-inject-until-before-from", lambda: pump(edited(edited(PUMP, "particles.inject_from", 0.2),
                                                          "particles.inject_until", 0.1)),
     ["particles.inject_until", "after particles.inject_from"]),
    ("pump-injects-too-many", lambda: pump(edited(PUMP, "particles.rate", 1e9)),
     ["particles.rate", "MAX_PARTICLES_PER_WORLD"]),
    ("pump-material-reversed", lambda: pump(edited(PUMP, "particles.material", {"type": "spheres",
                                                                              "diameter": [0.02, 0.01]})),
     ["particles.material", "diameter"]),
    ("pump-material-type", lambda: pump(edited(PUMP, "particles.material", {"type": "sand"})),
     ["particles.material", "sand"]),
    ("pump-contact-unknown", lambda: pump(edited(PUMP, "contact.mu_x_pp", 0.3)), ["contact", "mu_x_pp"]),
    ("pump-contact-text", lambda: pump(edited(PUMP, "contact.mu_s_pp", "high")), ["contact.mu_s_pp", "number"]),
    ("pump-contact-negative", lambda: pump(edited(PUMP, "contact.mu_s_pp", -0.3)),
     ["contact", "mu_s_pp", "admissible range"]),
    ("pump-contact-rolling-typo", lambda: pump(edited(PUMP, "contact.rolling", "epsd3")),
     ["contact.rolling", "epsd3"]),
    ("pump-wall-modulus-text", lambda: pump(edited(PUMP, "wall.youngs_modulus", "steel")),
     ["wall.youngs_modulus"]),
    ("pump-wall-poisson-above", lambda: pump(edited(PUMP, "wall.poisson_ratio", 0.7)), ["wall.poisson_ratio"]),
    ("pump-wall-unknown-key", lambda: pump(edited(PUMP, "wall.hardness", 1)), ["wall.hardness", "unknown key"]),
    ("pump-max-contacts-zero", lambda: pump(edited(PUMP, "run.max_contacts", 0)), ["run.max_contacts"]),
    ("pump-steps-per-graph-zero", lambda: pump(edited(PUMP, "run.steps_per_graph", 0)), ["run.steps_per_graph"]),
    ("pump-trajectory-world-beyond", lambda: pump(edited(PUMP, "run.trajectory_world", 5)),
     ["run.trajectory_world", "1 world"]),
    ("pump-worlds-fraction", lambda: pump(edited(PUMP, "run.worlds", 2.5)), ["run.worlds", "whole number"]),
    ("pump-record-every-beyond-the-run", lambda: pump(edited(PUMP, "run.record_every", 100.0)),
     ["run.record_every", "longer than the run"]),
    ("pump-spin-up-beyond-the-run", lambda: pump(edited(PUMP, "wear.spin_up_revolutions", 50)),
     ["wear.spin_up_revolutions", "no wear sample"]),
    ("pump-wear-text", lambda: pump(edited(PUMP, "wear.dnv_K", "x")), ["wear.dnv_K"]),
    ("pump-seed-text", lambda: pump({**PUMP, "seed": "abc"}), ["seed", "whole number"]),
    ("pump-seed-fraction", lambda: pump({**PUMP, "seed": 1.5}), ["seed", "whole number"]),
    ("pump-seed-true", lambda: pump({**PUMP, "seed": True}), ["seed"]),
    ("pump-name-list", lambda: pump({**PUMP, "name": [1]}), ["name", "text"]),
    ("pump-gravity-two-values", lambda: pump({**PUMP, "gravity": [0, -9.81]}), ["gravity"]),
    ("pump-gravity-text", lambda: pump({**PUMP, "gravity": "down"}), ["gravity"]),
    ("pump-output-number", lambda: pump({**PUMP, "output": 5}), ["output", "text"]),
    ("pump-notes-list", lambda: pump({**PUMP, "notes": [1]}), ["notes"]),
    ("pump-empty-file", lambda: ["pump", put("p.yaml", "")], ["p.yaml", "empty"]),
    ("pump-top-level-list", lambda: ["pump", put("p.yaml", "- 1\n")], ["p.yaml", "mapping"]),
    # ---------------------------------------------------------------- experiment configs
    ("exp-progress-text", lambda: exp({**EXPERIMENT, "progress": "yes"}), ["progress", "true or false"]),
    ("exp-description-list", lambda: exp({**EXPERIMENT, "description": [1]}), ["description"]),
    ("exp-output-number", lambda: exp({**EXPERIMENT, "output": 5}), ["output", "text"]),
    ("exp-scale-number", lambda: exp({**EXPERIMENT, "scale": 5}), ["scale"]),
    ("exp-experiment-list", lambda: exp({**EXPERIMENT, "experiment": ["baffle"]}), ["experiment", "text"]),
    ("exp-parameters-text", lambda: exp({**EXPERIMENT, "parameters": "all"}), ["parameters", "list of mappings"]),
    ("exp-parameter-true", lambda: exp(edited(EXPERIMENT, "parameters.0.mu_s_pp", True)), ["mu_s_pp", "number"]),
    ("exp-parameter-lists-unequal", lambda: exp({**EXPERIMENT, "parameters": {"mu_s_pp": [0.3, 0.4],
                                                                               "mu_s_pw": [0.3]}}),
     ["parameters", "differ in length"]),
    ("exp-parameter-nan", lambda: exp(edited(EXPERIMENT, "parameters.0.mu_s_pp", float("nan"))),
     ["mu_s_pp", "finite"]),
    ("exp-plugins-number", lambda: exp({**EXPERIMENT, "plugins": 5}), ["plugins"]),
    ("exp-material-list", lambda: exp({**EXPERIMENT, "material": [1]}), ["material", "mapping"]),
    ("exp-setting-seed-text", lambda: exp({**EXPERIMENT, "settings": {"seed": "x"}}), ["seed", "whole number"]),
    ("exp-settings-list", lambda: exp({**EXPERIMENT, "settings": [1]}), ["settings", "mapping"]),
    ("exp-top-level-list", lambda: ["experiment", put("e.yaml", "- 1\n")], ["e.yaml", "mapping"]),
    ("exp-empty-file", lambda: ["experiment", put("e.yaml", "")], ["e.yaml", "empty file"]),
    # ---------------------------------------------------------------- measurement files and diagnosis experiments
    ("lab-min-bins-fraction", lambda: ["measure", "--file", lab("min_bins: 2", "min_bins: 2.5")],
     ["lab.yaml", "min_bins", "whole number"]),
    ("lab-simulation-setting", lambda: ["measure", "--file", lab("min_bins: 2", "seed: 3")],
     ["settings.seed", "simulation"]),
    ("lab-lift-to-text", lambda: ["measure", "--file", lab("lift_to: 0.25", "lift_to: high")], ["lift_to"]),
    ("lab-unit-typo", lambda: ["measure", "--file", lab("unit: deg", "unit: degree")], ["static_angle.unit", "deg"]),
    ("lab-format-typo", lambda: ["measure", "--file", lab("warpdem-measurements/2", "warpdem-measurements/3")],
     ["format", "warpdem-measurements/3"]),
    ("lab-resolution-negative", lambda: ["measure", "--file", lab("resolution: 0.5", "resolution: -0.5")],
     ["static_angle.resolution"]),
    ("lab-repeat-above-90", lambda: ["measure", "--file", lab("- 17.60261", "- 95.0")], ["repeats[0]", "90"]),
    ("lab-repeat-text", lambda: ["measure", "--file", lab("- 17.60261", "- high")], ["repeats[0]", "not a number"]),
    ("lab-density-negative", lambda: ["measure", "--file", lab("- 1339.206656", "- -1339.2")],
     ["bulk_density.repeats[0]"]),
    ("diag-lab-fill-mass-exponent-is-a-number", lambda: diag_with_lab("fill_mass: 9.0", "fill_mass: 1.0e6"),
     ["fill_mass = 1e+06 kg", "MAX_PARTICLES_PER_WORLD"]),
    ("diag-lab-min-bins-fraction", lambda: diag_with_lab("min_bins: 2", "min_bins: 2.5"), ["min_bins", "whole"]),
    ("diag-lab-lift-to-text", lambda: diag_with_lab("lift_to: 0.25", "lift_to: high"), ["lift_to", "number"]),
    ("diag-experiments-setting-text", lambda: diag(experiments={"baffle": {"lift_speed": "fast"}}),
     ["lift_speed", "number"]),
    ("diag-experiments-setting-typo", lambda: diag(experiments={"baffle": {"lift_sped": 0.2}}), ["lift_sped"]),
    # ---------------------------------------------------------------- warpdem measure (options)
    ("measure-zero-width-window-px", lambda: measure("--window-px", "10", "10", "0", "50"),
     ["--window-px", "0 px wide"]),
    ("measure-zero-height-window", lambda: measure("--scale", "1", "--window", "0", "50", "5", "5"),
     ["--window", "0 mm high"]),
    ("measure-reversed-window", lambda: measure("--window-px", "50", "10", "0", "50"), ["--window-px", "-40 px"]),
    ("measure-one-px-window", lambda: measure("--window-px", "10", "11", "0", "50"), ["--window-px", "at least 2 px"]),
    ("measure-window-and-window-px", lambda: measure("--window", "0", "1", "0", "1", "--window-px", "0", "9", "0", "9"),
     ["--window", "--window-px"]),
    ("measure-rpm-negative", lambda: measure("--video", "--rpm", "-30"), ["--rpm", "> 0"]),
    ("measure-fps-zero", lambda: measure("--video", "--fps", "0"), ["--fps", "> 0"]),
    ("measure-discard-negative", lambda: measure("--video", "--discard", "-1"), ["--discard", ">= 0"]),
    ("measure-record-zero", lambda: measure("--video", "--record", "0"), ["--record", ">= 1"]),
    ("measure-threshold-above-255", lambda: measure("--threshold", "300"), ["--threshold", "0-255"]),
    ("measure-threshold-nan", lambda: measure("--threshold", "nan"), ["--threshold", "finite"]),
    ("measure-band-reversed", lambda: measure("--band", "5", "1"), ["--band", "LO < HI"]),
    ("measure-open-negative", lambda: measure("--open-px", "-1"), ["--open-px", ">= 0"]),
    ("measure-min-angle-negative", lambda: measure("--min-angle", "-5"), ["--min-angle", "0 <= a < 90"]),
    ("measure-min-angle-above-90", lambda: measure("--min-angle", "100"), ["--min-angle"]),
    ("measure-scale-nan", lambda: measure("--scale", "nan"), ["--scale"]),
    ("measure-h-ref-zero", lambda: measure("--h-ref", "0"), ["--h-ref", "> 0"]),
    ("measure-unknown-experiment", lambda: ["measure", "--file", "tiny_lab.yaml", "--experiment", "drum"],
     ["--experiment", "drum"]),
    ("measure-unknown-condition", lambda: ["measure", "--file", "tiny_lab.yaml", "--experiment", "baffle",
                                           "--condition", "5kg"], ["--condition", "5kg", "9kg"]),
    ("measure-experiment-without-file", lambda: measure("--experiment", "baffle"), ["--experiment", "--file"]),
    ("measure-source-and-file", lambda: measure("--file", "tiny_lab.yaml"), ["--file", "not both"]),
    ("measure-nothing", lambda: ["measure"], ["nothing to measure"]),
    ("measure-source-not-an-image", lambda: ["measure", put("x.png", "not an image")], ["x.png", "not an image"]),
    ("measure-diagnostic-under-a-file", lambda: ["measure", image(), "--diagnostic", a_file() + "/x.png"],
     ["--diagnostic", "afile"]),
    ("measure-diagnostic-dir-is-a-file", lambda: ["measure", image(), "--diagnostic-dir", a_file()],
     ["--diagnostic-dir", "afile"]),
    # ---------------------------------------------------------------- warpdem pour / bench
    ("pour-mu-negative", lambda: ["pour", "--mu", "-1"], ["--mu", ">= 0"]),
    ("pour-mu-nan", lambda: ["pour", "--mu", "nan"], ["--mu", "finite"]),
    ("pour-mu-r-text", lambda: ["pour", "--mu-r", "high"], ["--mu-r", "high"]),
    ("pour-rolling-friction-above-range", lambda: ["pour", "--mu-r", "50"], ["mu_r_pp", "admissible range"]),
    ("pour-frames-zero", lambda: ["pour", "--frames", "0"], ["--frames", ">= 1"]),
    ("pour-spheres-beyond-memory", lambda: ["pour", "--spheres", "100000000000"], ["--spheres", "GB"]),
    ("bench-warmup-negative", lambda: ["bench", "--warmup", "-5"], ["--warmup", ">= 0"]),
    ("bench-settle-time-negative", lambda: ["bench", "--settle-time", "-1"], ["--settle-time", "> 0"]),
    ("bench-settle-time-nan", lambda: ["bench", "--settle-time", "nan"], ["--settle-time", "finite"]),
    ("bench-max-contacts-zero", lambda: ["bench", "--max-contacts", "0"], ["--max-contacts", ">= 1"]),
    ("bench-wall-candidates-negative", lambda: ["bench", "--wall-candidates", "-1"], ["--wall-candidates", ">= 0"]),
    ("bench-spheres-beyond-memory", lambda: ["bench", "--spheres", "1000000", "--worlds", "100000"],
     ["--spheres x --worlds", "GB"]),
    ("bench-load-state-missing", lambda: ["bench", "--load-state", "nope.npz"], ["--load-state", "nope.npz"]),
    ("bench-save-state-under-a-file", lambda: ["bench", "--save-state", a_file() + "/s.npz"],
     ["--save-state", "afile"]),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_a_bad_input_is_refused_at_load_by_its_schema(case, tmp_path, monkeypatch, capsys, no_dem):
    name, argv_of, words = case
    monkeypatch.chdir(tmp_path)
    put("tiny_lab.yaml", LAB_TEXT)
    t0 = time.perf_counter()
    try:
        rc = main(argv_of())
    except BaseException:  # noqa: BLE001 - the boundary must catch everything
        pytest.fail(f"{name}: an exception left warpdem.cli.main:\n{traceback.format_exc()}")
    out, err = capsys.readouterr()
    assert rc == 2, f"{name}: exit code {rc}\n{err}"
    assert "Traceback" not in err + out, err
    for word in words:
        assert word in err, f"{name}: the message does not name {word!r}:\n{err}"
    assert time.perf_counter() - t0 < 30, f"{name}: {time.perf_counter() - t0:.0f} s to refuse it"


def test_at_least_150_distinct_bad_inputs_with_the_total_file():
    ids = [c[0] for c in CASES] + [_case_id(c) for c in TOTAL_CASES]
    assert len(set(ids)) == len(ids), sorted({i for i in ids if ids.count(i) > 1})
    assert len(ids) >= 150


# ------------------------------------------------------------------------ the shipped files still load
@pytest.mark.parametrize("config", ["quick_calibration", "quick_effects", "gpu_spheres", "paper_gravel"])
def test_shipped_campaign_configs_load(config):
    import calibration.campaign as cp

    cfg = cp.load_config(ROOT / "calibration/configs" / f"{config}.yaml")
    assert cfg.responses and cfg.space.parameters


def test_shipped_pump_config_loads():
    """(paper_pump.yaml: tests/test_pump_run.py; its gravel clumps take seconds to build.)"""
    from pump.run import load_config

    cfg = load_config(ROOT / "pump/configs/quick_pump.yaml")
    assert cfg["run"]["revolutions"] > cfg["wear"]["spin_up_revolutions"]


@pytest.mark.parametrize("config", ["quick_baffle", "quick_drum", "quick_cylinder"])
def test_shipped_experiment_configs_load(config):
    from calibration.experiments.cli import load_config

    assert load_config(ROOT / "calibration/configs" / f"{config}.yaml")["experiment"] in config


def test_a_campaign_target_file_is_read_at_load(tmp_path):
    """A target from a measurement file (relative to the config) loads, and a wrong condition is
    named before any DEM: what --max-samples never resolved is checked by parse_config."""
    import calibration.campaign as cp
    from warpdem import ConfigError

    (tmp_path / "lab.yaml").write_text(LAB_TEXT)
    doc = edited(CAMPAIGN, "responses.0.target", {"file": "lab.yaml", "experiment": "baffle", "condition": "9kg"})
    cfg = cp.parse_config(doc, base_dir=tmp_path, source="c.yaml")
    assert cfg.responses[0].target["condition"] == "9kg"
    with pytest.raises(ConfigError, match=r"c.yaml: response 'alpha_static' target: .*no condition '8kg'"):
        cp.parse_config(edited(doc, "responses.0.target.condition", "8kg"), base_dir=tmp_path, source="c.yaml")


def test_every_problem_of_a_campaign_is_listed_at_once():
    import calibration.campaign as cp
    from warpdem import ConfigError

    doc = edited(edited(CAMPAIGN, "responses.0.replicates", "two"), "design.seed", True)
    with pytest.raises(ConfigError) as exc:
        cp.parse_config({**doc, "bogus": 1}, source="c.yaml")
    message = str(exc.value)
    assert "3 problems" in message
    for key in ("responses[0].replicates", "design.seed", "bogus: unknown key"):
        assert key in message, message


def test_exponents_are_numbers_and_quoted_numbers_get_a_hint():
    """PyYAML (YAML 1.1) reads 6.0e4 and 1e-5 as text; the loader reads them as numbers, as YAML 1.2
    does; a quoted number stays text and is refused with a hint."""
    from warpdem.config_io import parse_yaml
    from warpdem.config_schema import yaml_number_hint

    assert yaml.safe_load("a: 6.0e4")["a"] == "6.0e4"
    assert parse_yaml("a: 6.0e4\nb: 1e-5\nc: -3E2\nd: '1e5'\ne: 1e5x\n", "f.yaml") == \
        {"a": 6.0e4, "b": 1e-5, "c": -300.0, "d": "1e5", "e": "1e5x"}
    assert "1.0e+6" in yaml_number_hint("1.0e6") and "without quotes" in yaml_number_hint("0.3")
    assert yaml_number_hint("high") == "" and yaml_number_hint(0.3) == ""
