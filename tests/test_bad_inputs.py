"""A corpus of user mistakes against every `warpdem` subcommand (issue 12, "fail loudly").

Each case is one mistake a user makes (a typo, a missing file, a value out of range, a broken
YAML file). The subcommand must refuse it before any DEM runs: exit code 2, a message that names
the problem (the key, the value or the file), no traceback. Adding a case is one line in a table.
"""
from __future__ import annotations

import copy
import traceback
from pathlib import Path
from typing import Any, Callable

import pytest
import yaml

from calibration.campaign import calibrate_main
from calibration.experiments.cli import experiment_main
from calibration.measurement.cli import measure_main
from pump.run import pump_main
from validation.cli import diagnose_main

ROOT = Path(__file__).resolve().parents[1]

EXPERIMENT = {"experiment": "baffle", "scale": "quick", "device": "cpu",
              "parameters": [{"mu_s_pp": 0.3, "mu_s_pw": 0.3, "mu_r_pp": 0.05, "mu_r_pw": 0.05}]}
CAMPAIGN = yaml.safe_load((ROOT / "calibration/configs/quick_calibration.yaml").read_text())
DIAGNOSIS = yaml.safe_load((ROOT / "validation/configs/tiny_diagnosis.yaml").read_text())
PUMP = yaml.safe_load((ROOT / "pump/configs/quick_pump.yaml").read_text())


def edited(base: dict, path: str, value: Any) -> dict:
    """``base`` with the dotted ``path`` set to ``value`` (``...`` deletes it)."""
    doc = copy.deepcopy(base)
    *parents, last = path.split(".")
    node = doc
    for key in parents:
        node = node[int(key)] if isinstance(node, list) else node[key]
    if value is ...:
        del node[last]
    elif isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return doc


# (id, command, config document or raw text or None for "no file", extra argv, words the message must hold)
CASES: list[tuple[str, Callable, Any, list[str], list[str]]] = [
    # warpdem experiment
    ("exp-missing-file", experiment_main, None, [], ["nope.yaml"]),
    ("exp-broken-yaml", experiment_main, "experiment: baffle\nparameters: [{mu_s_pp: 0.3\n", [], ["bad.yaml"]),
    ("exp-unknown-experiment", experiment_main, edited(EXPERIMENT, "experiment", "baffel"), [], ["baffel"]),
    ("exp-unknown-scale", experiment_main, edited(EXPERIMENT, "scale", "huge"), [], ["huge"]),
    ("exp-unknown-key", experiment_main, {**EXPERIMENT, "paramters": []}, [], ["paramters"]),
    ("exp-negative-friction", experiment_main, edited(EXPERIMENT, "parameters.0.mu_s_pp", -0.3), [], ["mu_s_pp"]),
    ("exp-unknown-parameter", experiment_main, edited(EXPERIMENT, "parameters.0.mu_x", 0.3), [], ["mu_x"]),
    ("exp-text-for-number", experiment_main, edited(EXPERIMENT, "parameters.0.mu_s_pw", "high"), [], ["mu_s_pw"]),
    ("exp-unknown-rolling-model", experiment_main, {**EXPERIMENT, "contact_law": {"rolling": "epsd3"}}, [],
     ["epsd3"]),
    ("exp-reversed-diameters", experiment_main,
     {**EXPERIMENT, "material": {"type": "spheres", "diameter": [0.030, 0.024]}}, [], ["diameter"]),
    ("exp-unknown-setting", experiment_main, {**EXPERIMENT, "settings": {"lift_sped": 0.2}}, [], ["lift_sped"]),
    ("exp-no-parameters", experiment_main, edited(EXPERIMENT, "parameters", []), [], ["parameters"]),
    ("exp-processes-zero", experiment_main, EXPERIMENT, ["--processes", "0"], ["processes"]),
    # warpdem measure
    ("measure-missing-image", measure_main, None, ["--scale", "3"], ["nope.png"]),
    ("measure-zero-scale", measure_main, None, ["--scale", "0"], ["scale"]),
    ("measure-missing-file", measure_main, None, ["--file", "nope.yaml"], ["nope.yaml"]),
    # warpdem calibrate
    ("cal-missing-file", calibrate_main, None, [], ["nope.yaml"]),
    ("cal-broken-yaml", calibrate_main, "name: x\nparameters: {mu_s_pp: [0.1, \n", [], ["bad.yaml"]),
    ("cal-bound-outside-admissible", calibrate_main, edited(CAMPAIGN, "parameters.mu_s_pp", [-0.5, 0.75]), [],
     ["mu_s_pp"]),
    ("cal-reversed-bounds", calibrate_main, edited(CAMPAIGN, "parameters.mu_s_pw", [0.75, 0.15]), [], ["mu_s_pw"]),
    ("cal-optimisation-typo", calibrate_main, edited(CAMPAIGN, "optimisation.pop_sise", 50), [], ["pop_sise"]),
    ("cal-confirmation-typo", calibrate_main, edited(CAMPAIGN, "confirmation.run", 5), [], ["run"]),
    ("cal-unknown-response-experiment", calibrate_main, edited(CAMPAIGN, "responses.0.experiment", "shear_cell"),
     [], ["shear_cell"]),
    ("cal-negative-tolerance", calibrate_main, edited(CAMPAIGN, "optimisation.tolerance_deg", -1.0), [],
     ["tolerance_deg"]),
    ("cal-bad-fixed", calibrate_main, edited(CAMPAIGN, "fixed.mu_r_pp", -0.1), [], ["mu_r_pp"]),
    # warpdem diagnose
    ("diag-missing-file", diagnose_main, None, [], ["nope.yaml"]),
    ("diag-missing-measurements", diagnose_main, edited(DIAGNOSIS, "measurements", "nowhere.yaml"), [],
     ["nowhere.yaml"]),
    ("diag-unknown-candidate", diagnose_main, edited(DIAGNOSIS, "candidates", ["magnetism"]), [], ["magnetism"]),
    ("diag-reversed-bounds", diagnose_main, edited(DIAGNOSIS, "parameters.mu_s_pp", [0.9, 0.1]), [], ["mu_s_pp"]),
    ("diag-settings-typo", diagnose_main, edited(DIAGNOSIS, "diagnosis.replicate", 2), [], ["replicate"]),
    ("diag-unknown-add", diagnose_main, DIAGNOSIS, ["--add", "magnetism"], ["magnetism"]),
    ("diag-bad-designs-up-front", diagnose_main, edited(DIAGNOSIS, "diagnosis.designs_up_front", "sometimes"), [],
     ["diagnosis.designs_up_front", "auto, true or false"]),
    # warpdem pump
    ("pump-missing-file", pump_main, None, [], ["nope.yaml"]),
    ("pump-unknown-key", pump_main, {**PUMP, "fluidd": {}}, [], ["fluidd"]),
    ("pump-negative-fraction", pump_main, edited(PUMP, "particles.volume_fraction", -0.04), [],
     ["volume_fraction"]),
    ("pump-zero-dt", pump_main, edited(PUMP, "run.dt", 0.0), [], ["dt"]),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_a_user_mistake_is_refused_with_a_message_that_names_it(case, tmp_path, capsys, monkeypatch):
    name, command, doc, extra, words = case
    monkeypatch.chdir(tmp_path)
    if name.startswith("diag-"):  # the diagnosis config names its measurement file relative to itself
        (tmp_path / "tiny_lab.yaml").write_text((ROOT / "validation/configs/tiny_lab.yaml").read_text())
    if doc is None:
        argv = ["nope.yaml"]
    else:
        path = tmp_path / ("bad.yaml" if isinstance(doc, str) else "config.yaml")
        path.write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc))
        argv = [str(path)]
    if command is measure_main:
        argv = extra if "--file" in extra else ["nope.png", *extra]
    else:
        argv = argv + extra
    try:
        code = command(argv)
    except SystemExit as exc:  # argparse refuses its own arguments this way
        code = exc.code
    except Exception:  # noqa: BLE001 - the point of the test
        pytest.fail(f"{name}: a traceback instead of a message:\n{traceback.format_exc()}")
    err = capsys.readouterr().err
    assert code == 2, f"{name}: exit code {code}, stderr:\n{err}"
    assert "Traceback" not in err, err
    for word in words:
        assert word in err, f"{name}: the message does not name {word!r}:\n{err}"


def test_every_problem_of_an_experiment_config_is_listed_in_one_message(tmp_path, capsys):
    """Two mistakes at the top level, or in the settings and the parameters, are named together
    (fixing one at a time would cost a run each), before any DEM runs."""
    top = tmp_path / "top.yaml"
    top.write_text(yaml.safe_dump({**EXPERIMENT, "experiment": "baffel", "paramters": []}))
    assert experiment_main([str(top)]) == 2
    err = capsys.readouterr().err
    assert "2 problems" in err and "baffel" in err and "paramters" in err
    deep = tmp_path / "deep.yaml"
    deep.write_text(yaml.safe_dump({**EXPERIMENT, "settings": {"lift_sped": 0.2},
                                    "parameters": [{"mu_s_pp": 0.3}, {"mu_s_pw": -0.5}]}))
    assert experiment_main([str(deep)]) == 2
    err = capsys.readouterr().err
    assert "lift_sped" in err and "parameters[1].mu_s_pw = -0.5" in err, err


def test_every_problem_of_a_pump_config_is_listed_in_one_message(tmp_path, capsys):
    path = tmp_path / "pump.yaml"
    path.write_text(yaml.safe_dump({**edited(edited(PUMP, "run.dt", 0.0), "coupling.two_way", "yes"), "fluidd": {}}))
    assert pump_main([str(path)]) == 2
    err = capsys.readouterr().err
    assert "3 problems" in err and "fluidd" in err and "run.dt" in err and "coupling.two_way" in err, err
