"""Measurement files: the seed paper's Tables 1 and 10, validation errors,
image entries."""

import copy
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from calibration.measurement import (
    MeasurementError,
    MeasurementFileError,
    load_measurements,
    parse_measurements,
    synthetic_slope_image,
)
from calibration.measurement.cli import measure_main

TABLE = Path(__file__).resolve().parents[1] / "calibration" / "data" / "zhang2023_table1.yaml"


def slope_rounding_tol(slope, decimals=4):
    """Angle uncertainty (deg) of a slope given to `decimals` decimals."""
    return 0.5 * 10.0**-decimals * math.degrees(1.0 / (1.0 + slope**2)) + 1e-9


@pytest.fixture(scope="module")
def table():
    return load_measurements(TABLE)


def test_table1_static(table):
    c = table.condition("baffle_static", "lab")
    assert c.kind == "baffle_static" and c.data == "slopes" and c.origin == "lab"
    st = c.stats()
    assert st.n == 5
    # slope 0.6515 -> 33.0834 deg (Table 1), up to the rounding of the 4-decimal slope
    assert abs(st.values_deg[0] - 33.0834) <= slope_rounding_tol(0.6515)
    for slope, ang, ref in zip(c.repeats, st.values_deg, c.reported["angles_deg"]):
        assert abs(ang - ref) <= slope_rounding_tol(slope)
    assert st.mean_deg == pytest.approx(32.534, abs=5e-4)
    assert st.std_deg == pytest.approx(0.4217, abs=1e-4)  # sample std, ddof = 1
    assert st.sem_deg == pytest.approx(st.std_deg / math.sqrt(5))
    assert st.mean_slope == pytest.approx(0.63794)


def test_table1_dynamic(table):
    st = table.condition("drum_dynamic").stats()
    assert st.average == "slope" and st.n == 1
    assert abs(st.mean_deg - 49.0579) <= slope_rounding_tol(1.1527)
    assert round(st.mean_deg, 2) == 49.06
    assert math.isnan(st.std_deg) and math.isnan(st.sem_deg)


def test_table10_hollow_cylinder(table):
    c = table.condition("hollow_cylinder", "lab")
    st = c.stats()
    assert st.n == 5 and len(st.views_deg) == 5 and all(len(v) == 4 for v in st.views_deg)
    np.testing.assert_allclose(st.values_deg, c.reported["gamma_s_deg"], atol=0.0101)
    assert st.mean_deg == pytest.approx(32.53, abs=0.005)
    assert st.std_deg == pytest.approx(1.3866, abs=1e-4)
    sim = table.condition("hollow_cylinder", "dem_optimum")
    assert sim.origin == "simulation"
    assert sim.stats().mean_deg == pytest.approx(31.47, abs=0.005)
    rel = (st.mean_deg - sim.stats().mean_deg) / st.mean_deg * 100
    assert rel == pytest.approx(sim.reported["relative_error_pct"], abs=0.01)


def test_summary_and_json_equivalent(tmp_path, table):
    s = table.summary()
    assert s["baffle_static"]["conditions"]["lab"]["mean_deg"] == pytest.approx(32.534, abs=5e-4)
    assert s["drum_dynamic"]["conditions"]["rpm30"]["std_deg"] is None
    json.dumps(s)  # JSON-ready
    raw = yaml.safe_load(TABLE.read_text())
    p = tmp_path / "t.json"
    p.write_text(json.dumps(raw))
    js = load_measurements(p)
    assert js.condition("hollow_cylinder", "lab").stats().mean_deg == pytest.approx(32.532)


@pytest.fixture()
def raw():
    return yaml.safe_load(TABLE.read_text())


def _write(tmp_path, data, name="bad.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data))
    return p


def _expect_error(tmp_path, data, *fragments):
    p = _write(tmp_path, data)
    with pytest.raises(MeasurementFileError) as ei:
        load_measurements(p)
    msg = str(ei.value)
    assert str(p) in msg
    for f in fragments:
        assert f in msg, msg
    return ei.value


def test_unknown_key(tmp_path, raw):
    raw["experiments"]["baffle_static"]["conditions"]["lab"]["slope"] = [0.6]
    e = _expect_error(tmp_path, raw, "experiments.baffle_static.conditions.lab.slope", "unknown key 'slope'")
    assert e.key == "experiments.baffle_static.conditions.lab.slope"
    bad = copy.deepcopy(raw)
    bad["experimnets"] = {}
    _expect_error(tmp_path, bad, "experimnets", "unknown key")


def test_missing_fields(tmp_path, raw):
    d = copy.deepcopy(raw)
    del d["experiments"]["drum_dynamic"]["kind"]
    _expect_error(tmp_path, d, "experiments.drum_dynamic.kind", "missing")
    d = copy.deepcopy(raw)
    del d["experiments"]["drum_dynamic"]["conditions"]["rpm30"]["slopes"]
    _expect_error(tmp_path, d, "experiments.drum_dynamic.conditions.rpm30", "missing field")
    _expect_error(tmp_path, {"format": "warpdem-measurements/1"}, "experiments", "missing")


def test_non_numeric_and_out_of_range(tmp_path, raw):
    d = copy.deepcopy(raw)
    d["experiments"]["baffle_static"]["conditions"]["lab"]["slopes"][1] = "0.63x"
    _expect_error(tmp_path, d, "slopes[1]", "not a number")
    d = copy.deepcopy(raw)
    d["experiments"]["hollow_cylinder"]["conditions"]["lab"]["angles_deg"][2][1] = True
    _expect_error(tmp_path, d, "angles_deg[2][1]", "not a number")
    d = copy.deepcopy(raw)
    d["experiments"]["hollow_cylinder"]["conditions"]["lab"]["angles_deg"][0][0] = 95.0
    _expect_error(tmp_path, d, "angles_deg[0][0]", "out of range")
    d = copy.deepcopy(raw)
    d["experiments"]["drum_dynamic"]["kind"] = "drum"
    _expect_error(tmp_path, d, "experiments.drum_dynamic.kind", "not one of")


def test_slope_and_angle_both_and_empty_repeats(tmp_path, raw):
    d = copy.deepcopy(raw)
    d["experiments"]["baffle_static"]["conditions"]["lab"]["angles_deg"] = [33.0]
    _expect_error(tmp_path, d, "conditions.lab", "angles_deg and slopes")
    d = copy.deepcopy(raw)
    d["experiments"]["baffle_static"]["conditions"]["lab"]["slopes"] = []
    _expect_error(tmp_path, d, "conditions.lab.slopes", "empty repeats")


def test_other_malformations(tmp_path, raw):
    d = copy.deepcopy(raw)
    d["format"] = "something/2"
    _expect_error(tmp_path, d, "format", "unsupported")
    p = tmp_path / "broken.yaml"
    p.write_text("experiments: [unclosed\n")
    with pytest.raises(MeasurementFileError, match="not valid YAML"):
        load_measurements(p)
    with pytest.raises(MeasurementFileError, match="cannot read"):
        load_measurements(tmp_path / "missing.yaml")
    img = {"experiments": {"e": {"kind": "baffle_static", "conditions": {"c": {
        "images": ["a.png"], "image_settings": {"window_mm": [0, 300, 0, 200]}}}}}}
    _expect_error(tmp_path, img, "image_settings.window_mm", "needs scale_px_per_mm")
    with pytest.raises(MeasurementFileError, match="<mapping>"):
        parse_measurements({"experiments": {}})
    with pytest.raises(MeasurementError, match="no experiment"):
        load_measurements(TABLE).condition("nope")


def test_image_entries_measured(tmp_path):
    angles = [30.0, 32.0, 34.0]
    scale, crest, top, floor = 2.0, 120.0, 120.0, 420.0
    names = []
    for i, a in enumerate(angles):
        img = synthetic_slope_image(a, crest_col=crest, top_row=top, floor_row=floor,
                                    noise_std=10.0, gradient=0.4, texture=20.0, rng=i)
        names.append(f"img/pile_{i}.png")
        (tmp_path / "img").mkdir(exist_ok=True)
        cv2.imwrite(str(tmp_path / names[-1]), img)
    h_mm = (floor - top) / scale
    data = {
        "format": "warpdem-measurements/1",
        "experiments": {"baffle_static": {"kind": "baffle_static", "conditions": {"photos": {
            "images": names[:2] + [{"path": names[2], "material": "dark"}],
            "image_settings": {"scale_px_per_mm": scale, "origin_px": [crest, floor],
                               "window_mm": [-20, 255, -5, h_mm + 30], "fit_band": [0.15, 0.85],
                               "h_ref": h_mm},
        }}}},
    }
    p = tmp_path / "lab.yaml"
    p.write_text(yaml.safe_dump(data))
    mf = load_measurements(p)
    c = mf.condition("baffle_static")
    assert c.images[0][0] == str(tmp_path / names[0])  # relative to the file
    st = c.stats(diagnostic_dir=tmp_path / "diag")
    np.testing.assert_allclose(st.values_deg, angles, atol=0.5)
    assert st.mean_deg == pytest.approx(np.mean(angles), abs=0.5)
    assert len(list((tmp_path / "diag").glob("*.png"))) == 3
    assert mf.summary()["baffle_static"]["conditions"]["photos"]["measured"] is False
    # the CLI on the same entry
    rc = measure_main(["--file", str(p), "--experiment", "baffle_static",
                       "--diagnostic-dir", str(tmp_path / "cli_diag")])
    assert rc == 0
    assert len(list((tmp_path / "cli_diag").glob("*.png"))) == 3


def test_cli_file_summary(capsys):
    assert measure_main(["--file", str(TABLE)]) == 0
    out = json.loads(capsys.readouterr().out)
    lab = out["experiments"]["baffle_static"]["conditions"]["lab"]
    assert lab["mean_deg"] == pytest.approx(32.534, abs=5e-4)
