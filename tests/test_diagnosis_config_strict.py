"""The diagnosis config takes numbers as numbers and flags as flags (issue 29): text that looks like a
number, a flag written as text, a boolean where a number belongs and a fraction where a count belongs
are refused at load, rc 2, with the key named, before any DEM."""

from __future__ import annotations

import pytest
import yaml

from tests.test_bad_inputs_total import DIAGNOSIS, LAB_TEXT


@pytest.mark.parametrize("change, key", [
    ({"diagnosis": {"replicates": "2"}}, "diagnosis.replicates"),
    ({"diagnosis": {"replicates": 2.5}}, "diagnosis.replicates"),
    ({"diagnosis": {"rank_when_adequate": "yes"}}, "diagnosis.rank_when_adequate"),
    ({"diagnosis": {"cutoff": True}}, "diagnosis.cutoff"),
    ({"progress": "yes"}, "progress"),
    ({"fixed": {"restitution_pp": True}}, "fixed.restitution_pp"),
    ({"parameters": {"mu_s_pp": ["0.1", 0.9], "mu_s_pw": [0.1, 0.9]}}, "parameters.mu_s_pp"),
    ({"effect_ranges": {"mu_r_pp": [0.0, "0.3"]}}, "effect_ranges.mu_r_pp"),
    ({"max_proposed_conditions": "two"}, "max_proposed_conditions"),
    ({"diagnosis": {"model_discrepancy": {"baffle/9kg/static_angle": "1"}}}, "model_discrepancy"),
])
def test_wrong_types_in_the_diagnosis_config_are_refused_at_load(change, key, tmp_path, monkeypatch, capsys):
    import calibration.experiments.common as common
    import warpdem as wd
    from warpdem.cli import main

    def dem(*args, **kwargs):
        raise AssertionError("DEM work started: the input was not refused at load")

    monkeypatch.setattr(wd.Simulation, "__init__", dem)
    monkeypatch.setattr(common.Experiment, "run", dem)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "lab.yaml").write_text(LAB_TEXT)
    doc = {**DIAGNOSIS, "measurements": "lab.yaml", "output": "out"}
    for k, v in change.items():
        doc[k] = {**doc.get(k, {}), **v} if isinstance(v, dict) and k == "diagnosis" else v
    (tmp_path / "d.yaml").write_text(yaml.safe_dump(doc))
    assert main(["diagnose", "d.yaml", "--prefetch"]) == 2
    err = capsys.readouterr().err
    assert key in err and "Traceback" not in err
