"""Model error (issue 28, item 4): the fidelity suite's residuals as a model-discrepancy sd.

The table (validation/reference/model_discrepancy.json) is rebuilt from the committed
warpdem-vs-LIGGGHTS results and must match; the estimator is checked on cases of known answer;
the sd enters every sigma; the report splits each z's variance; and on an analytic lab whose
"other code" differs from the model by a fixed bias, the simulator treated as exact invents a
missing effect while the model error keeps the verdict "no effect is needed".
"""

from __future__ import annotations

import glob
import json
import math

import numpy as np
import pytest

from tests.test_diagnosis_logic import (BASE, COHESION, FAST, KEYS, ROLLING, SHAPE, AnalyticGranularModel,
                                        lab_observables)
from validation import DiagnosisSettings, Misfit, Observable, Observations, diagnose, write_diagnosis
from validation.model_error import (FIDELITY_TABLE, build_table, collect_fidelity_cases, fidelity_table,
                                    resolve_model_discrepancy)

FOLDERS = sorted(glob.glob("docs/results/liggghts_experiments/*/"))


def test_shipped_table_is_rebuilt_from_the_committed_fidelity_results():
    cases = collect_fidelity_cases(FOLDERS)
    rebuilt = build_table(cases, [f.rstrip("/").rsplit("/", 1)[1] for f in FOLDERS])
    shipped = fidelity_table()
    assert set(rebuilt["quantities"]) == set(shipped["quantities"]) >= {"static_angle", "dynamic_angle",
                                                                          "bulk_density", "pile_angle"}
    for q, row in rebuilt["quantities"].items():
        assert row["sd"] == pytest.approx(shipped["quantities"][q]["sd"], rel=1e-9), q
    # only same-law rows: the forced tangential_reduce rows (different physics, 4-7 deg) are left out
    assert all(abs(c["difference"]) < 4.0 for c in cases if c["observable"].endswith("angle"))
    # one set of runs summarised in two folders counts once
    keys = [(c["observable"], c["group"], c["law"], round(c["difference"], 12)) for c in cases]
    assert len(keys) == len(set(keys))
    assert 0.3 < shipped["quantities"]["static_angle"]["sd"] < 3.0  # deg: "1-2 deg between codes"
    assert shipped["quantities"]["bulk_density"]["relative"] and shipped["quantities"]["bulk_density"]["sd"] < 0.03


def _case(d: float, se: float, q: str = "static_angle") -> dict:
    return {"observable": q, "difference": d, "standard_error": se, "group": None, "relative": False}


def test_moment_estimator_removes_the_fill_noise_and_pools_thin_quantities():
    # biases +-1 deg measured exactly: sd 1; the same with se 1 each: the noise explains it all
    assert build_table([_case(1, 0), _case(-1, 0), _case(1, 0)], [])["quantities"]["static_angle"]["sd"] == 1.0
    assert build_table([_case(1, 1), _case(-1, 1), _case(1, 1)], [])["quantities"]["static_angle"]["sd"] == 0.0
    # a quantity with one case takes its family's pooled estimate
    t = build_table([_case(2, 0), _case(-2, 0), _case(2, 0), _case(0.1, 0, "pile_angle")], [])
    row = t["quantities"]["pile_angle"]
    assert row["cases"] == 1 and row["sd"] == pytest.approx(math.sqrt((12 + 0.01) / 4)) and "pooled" in row["estimate"]


def _obs() -> Observations:
    return Observations((Observable("baffle/static_angle", "baffle", "static_angle", "deg", (30.0, 31.0, 29.0)),
                         Observable("baffle/bulk_density", "baffle", "bulk_density", "kg/m^3", (1500.0, 1510.0, 1490.0)),
                         Observable("x/other", "x", "curvature", "1/m", (1.0, 1.1, 0.9))))


def test_resolution_by_quantity_relative_density_and_unknown_quantity():
    table = fidelity_table()["quantities"]
    sds, terms = resolve_model_discrepancy("fidelity", _obs())
    assert sds["baffle/static_angle"] == table["static_angle"]["sd"]
    assert sds["baffle/bulk_density"] == pytest.approx(table["bulk_density"]["sd"] * 1500.0)
    assert "x/other" not in sds and "no fidelity case" in terms[2].source
    assert resolve_model_discrepancy("none", _obs())[0] == {}
    assert resolve_model_discrepancy({"x/other": 0.2}, _obs())[0] == {"x/other": 0.2}
    with pytest.raises(ValueError, match="fidelity"):
        resolve_model_discrepancy("liggghts", _obs())


def test_model_error_enters_sigma_and_the_shares_sum_to_one():
    noise = np.array([1.0, 10.0, 0.1])
    exact = Misfit.build(_obs(), noise, "none")
    fid = Misfit.build(_obs(), noise, "fidelity")
    sds = resolve_model_discrepancy("fidelity", _obs())[0]
    extra = np.array([sds.get(k, 0.0) ** 2 for k in _obs().keys])
    assert np.allclose(fid.fixed_variance - exact.fixed_variance, extra) and extra[0] > 0
    shares = fid.variance_shares(np.array([0.5, 5.0, 0.05]))
    total = sum(shares.values())
    assert np.allclose(total, 1.0)
    assert shares["model_error"][0] == pytest.approx(extra[0] / fid.variance(np.array([0.5, 5.0, 0.05]))[0])
    assert shares["model_error"][2] == 0.0


def test_settings_refuse_a_bad_model_discrepancy():
    assert DiagnosisSettings().model_discrepancy == "fidelity"
    for bad in ("liggghts", {"a": -1.0}, {"a": float("nan")}, {"a": True}):
        with pytest.raises(ValueError, match="model_discrepancy"):
            DiagnosisSettings(model_discrepancy=bad)
    with pytest.raises(ValueError, match="unknown observables"):
        diagnose(lab_observables({"mu_s_pp": 0.5, "mu_s_pw": 0.4}, ()), BASE, [ROLLING], AnalyticGranularModel(1),
                 DiagnosisSettings(model_discrepancy={"drum/99rpm/dynamic_angle": 1.0}))


#: the "other code" that made the lab data: the analytic model plus fixed biases of the size the
#: fidelity suite measured between two codes (static angle up, drum angles down: no friction pair
#: moves them that way together)
CODE_BIAS = {"baffle/static_angle": +2.0, "drum/15rpm/dynamic_angle": -1.0, "drum/30rpm/dynamic_angle": -1.0,
             "drum/45rpm/dynamic_angle": -1.0}


@pytest.fixture(scope="module")
def biased_lab():
    obs = lab_observables({"mu_s_pp": 0.5, "mu_s_pw": 0.4}, ())
    return [Observable(o.key, o.experiment, o.quantity, o.unit, tuple(np.add(o.repeats, CODE_BIAS.get(o.key, 0.0))),
                       o.condition, o.label, o.resolution, o.n_below_detection, o.detection_limit) for o in obs]


def test_model_error_keeps_a_code_bias_from_being_read_as_a_missing_effect(biased_lab, tmp_path):
    exact = diagnose(biased_lab, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1), FAST)
    assert not exact.base_adequate  # treated as exact, the simulator cannot reach a 2-deg code bias
    sd = {k: 1.5 * abs(v) for k, v in CODE_BIAS.items()}
    with_error = diagnose(biased_lab, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1),
                          DiagnosisSettings(**{**FAST.to_dict(), "model_discrepancy": sd}))
    assert with_error.base_adequate and with_error.added_effects == ()
    row = with_error.final.comparison_rows()[KEYS.index("baffle/static_angle")]
    assert row["model_error_sd"] == 3.0 and row["dem_sigma_shares"]["model_error"] > 0.5
    terms = {t.key: t for t in with_error.model_error}
    assert terms["baffle/static_angle"].sd == 3.0 and terms["baffle/static_angle"].source == "set by the user"
    paths = write_diagnosis(with_error, tmp_path)
    html = paths["report"].read_text(encoding="utf-8")
    assert "What each z is made of" in html and "set in the config" in html
    doc = json.loads(paths["json"].read_text(encoding="utf-8"))
    assert doc["model_error"][0]["key"] == KEYS[0]


@pytest.mark.parametrize("value, named", [({"drum/99rpm/dynamic_angle": 1.0}, "drum/99rpm/dynamic_angle"),
                                          ("liggghts", "model_discrepancy"), ({"baffle/9kg/static_angle": -1}, "model_discrepancy")])
def test_a_bad_model_discrepancy_in_the_config_is_refused_at_load(value, named, tmp_path, monkeypatch, capsys):
    import calibration.experiments.common as common
    import warpdem as wd
    from tests.test_bad_inputs_total import DIAGNOSIS, LAB_TEXT
    from warpdem.cli import main

    def dem(*args, **kwargs):
        raise AssertionError("DEM work started: the input was not refused at load")

    monkeypatch.setattr(wd.Simulation, "__init__", dem)
    monkeypatch.setattr(common.Experiment, "run", dem)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "lab.yaml").write_text(LAB_TEXT)
    doc = {**DIAGNOSIS, "measurements": "lab.yaml", "output": "out",
           "diagnosis": {**DIAGNOSIS.get("diagnosis", {}), "model_discrepancy": value}}
    import yaml

    (tmp_path / "d.yaml").write_text(yaml.safe_dump(doc))
    assert main(["diagnose", "d.yaml", "--prefetch"]) == 2
    err = capsys.readouterr().err
    assert named in err and "Traceback" not in err
