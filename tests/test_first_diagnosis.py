"""The README's main job, `warpdem diagnose validation/configs/first_diagnosis.yaml`: its files load
and say nothing of the hidden effect (fast), and on the 2-core CPU it finds rolling resistance
(slow: about 8-11 min; docs/notes/diagnosis_hidden_effects.md, "The README's first diagnosis")."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import yaml

from validation.config import load_diagnosis_config
from validation.measurements import load_observations

CONFIGS = Path(__file__).resolve().parents[1] / "validation" / "configs"


def test_first_diagnosis_config_and_lab_file_load():
    cfg, base = load_diagnosis_config(CONFIGS / "first_diagnosis.yaml")
    assert cfg.candidates == ["rolling_resistance", "cohesion"]
    obs = load_observations(CONFIGS / "first_lab.yaml")
    assert len(obs.keys) == 4 and list(obs.n) == [3, 3, 3, 3]


def test_the_lab_file_does_not_name_the_hidden_effect():
    """The measurement file is all the diagnosis reads; it must not give the answer away."""
    text = (CONFIGS / "first_lab.yaml").read_text().lower()
    for word in ("rolling", "cohesion", "mu_r", "epsd", "sjkr"):
        assert word not in text, word


@pytest.mark.slow
def test_first_diagnosis_finds_the_hidden_rolling_resistance(tmp_path):
    from validation.cli import diagnose_main

    for name in ("first_diagnosis.yaml", "first_lab.yaml"):
        shutil.copy(CONFIGS / name, tmp_path / name)
    doc = yaml.safe_load((tmp_path / "first_diagnosis.yaml").read_text())
    doc["output"] = str(tmp_path / "out")
    (tmp_path / "first_diagnosis.yaml").write_text(yaml.safe_dump(doc))
    assert diagnose_main([str(tmp_path / "first_diagnosis.yaml"), "--device", "cpu"]) == 0
    d = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert not d["versions"][0]["adequacy"]["adequate"]
    assert d["versions"][-1]["effects"] == ["rolling_resistance"]
    assert d["verdict"]["met"]
