"""Measurement files, version 2: several observables per experiment and condition with units,
protocol settings, censored "no pile formed"; version-1 files as observations; the writer's
round trip; conversion to the diagnosis's Observables."""

import copy
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from calibration.experiments import EXPERIMENTS
from calibration.measurement import (
    FORMAT_V2,
    NO_PILE_LIMIT_DEG,
    MeasurementError,
    MeasurementFileError,
    ObservationRecord,
    check_settings,
    load_measurements,
    parse_measurements,
    synthetic_slope_image,
    unreported_observables,
    write_measurements_v2,
)
from calibration.measurement.cli import measure_main
from validation.measurements import (
    load_observations,
    observations_from_records,
    record_from_observable,
    write_observations,
)
from validation.observables import Observable

DATA = Path(__file__).resolve().parents[1] / "calibration" / "data"
EXAMPLE = DATA / "example_v2.yaml"
TABLE_V1 = DATA / "zhang2023_table1.yaml"

EXPECTED_KEYS = [
    "drum/15rpm/dynamic_angle", "drum/30rpm/dynamic_angle", "drum/45rpm/dynamic_angle",
    "baffle/lab/static_angle", "baffle/lab/bulk_density", "baffle/lab/mass_left_in_box",
    "cylinder/lab/pile_angle", "cylinder/lab/pile_height", "cylinder/2kg/pile_angle", "cylinder/2kg/pile_height",
]


@pytest.fixture(scope="module")
def example():
    return load_measurements(EXAMPLE)


@pytest.fixture()
def raw():
    return yaml.safe_load(EXAMPLE.read_text())


def _write(tmp_path, data, name="bad.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data, sort_keys=False))
    return p


def _by_key(records):
    return {r.key: r for r in records}


# --------------------------------------------------------------------------- the example
def test_example_loads_with_every_observable(example):
    assert example.version == 2
    assert example.material == {"type": "spheres", "diameter": [0.016, 0.020], "density": 2661}
    recs = example.observations()
    assert [r.key for r in recs] == EXPECTED_KEYS
    r = _by_key(recs)
    d15 = r["drum/15rpm/dynamic_angle"]
    assert (d15.experiment, d15.condition, d15.quantity, d15.unit) == ("drum", "15rpm", "dynamic_angle", "deg")
    assert d15.repeats == (35.1, 35.9, 34.8) and d15.resolution == 0.1 and d15.label == "drum angle at 15 rpm"
    assert d15.settings == {"rpm": 15, "diameter": 0.300, "length": 0.150, "fill_fraction": 0.40}
    assert [r[f"drum/{s}rpm/dynamic_angle"].settings["rpm"] for s in (15, 30, 45)] == [15, 30, 45]
    # slopes -> one angle per repeat, atan(|slope|)
    np.testing.assert_allclose(r["drum/45rpm/dynamic_angle"].repeats,
                               np.degrees(np.arctan([0.8541, 0.8662, 0.8421])))
    assert r["baffle/lab/bulk_density"].unit == "kg/m^3"
    assert r["baffle/lab/bulk_density"].repeats == (1562.0, 1571.0, 1555.0)
    assert r["baffle/lab/mass_left_in_box"].unit == "kg"
    assert r["baffle/lab/mass_left_in_box"].description.startswith("weighed after the lift")
    assert r["baffle/lab/static_angle"].settings["fill_mass"] == 16.0
    # views: a repeat's value is the mean of theta_1..4
    assert r["cylinder/lab/pile_angle"].repeats[0] == pytest.approx(np.mean([27.9, 28.6, 28.1, 27.4]))
    # pile height written in mm, stored in m (the unit the cylinder reports)
    ph = r["cylinder/lab/pile_height"]
    assert ph.unit == "m"
    np.testing.assert_allclose(ph.repeats, [0.118, 0.124, 0.121])
    assert ph.resolution == pytest.approx(0.001)
    assert all(x.origin == "lab" for x in recs)


def test_example_fits_the_registered_experiments(example):
    check_settings(example, EXPERIMENTS)         # names only
    check_settings(example, EXPERIMENTS, build=True)  # every condition builds its experiment
    load_measurements(EXAMPLE, experiments=EXPERIMENTS)
    assert unreported_observables(example, EXPERIMENTS) == ["baffle/lab/mass_left_in_box"]


def test_v2_condition_stats_and_summary(example):
    st = example.condition("drum", "15rpm").stats()   # what campaign targets read
    assert st.n == 3 and st.mean_deg == pytest.approx(np.mean([35.1, 35.9, 34.8]))
    assert st.std_deg == pytest.approx(np.std([35.1, 35.9, 34.8], ddof=1))
    assert example.condition("drum", "45rpm").stats().average == "slope"
    assert example.condition("baffle", "lab").settings["lift_speed"] == 0.1
    assert set(example.condition("baffle", "lab").observables) == {"static_angle", "bulk_density", "mass_left_in_box"}
    with pytest.raises(MeasurementError, match="below the detection limit in all 3 repeats"):
        example.condition("cylinder", "2kg").stats()
    s = example.summary()
    json.dumps(s)
    bd = s["baffle"]["conditions"]["lab"]["observables"]["bulk_density"]
    assert bd["n"] == 3 and bd["mean"] == pytest.approx(1562.6667, abs=1e-3)
    assert bd["sem"] == pytest.approx(np.std([1562, 1571, 1555], ddof=1) / math.sqrt(3))
    npf = s["cylinder"]["conditions"]["2kg"]["observables"]["pile_angle"]
    assert npf["n"] == 0 and npf["mean"] is None and npf["n_censored"] == 3 and npf["censor_limit"] == NO_PILE_LIMIT_DEG


def test_v2_condition_without_angle(tmp_path):
    data = {"format": FORMAT_V2, "experiments": {"baffle": {"conditions": {"lab": {
        "settings": {}, "observables": {"bulk_density": {"unit": "g/cm^3", "repeats": [1.56, 1.57]}}}}}}}
    mf = parse_measurements(data)
    (rec,) = mf.observations()
    assert rec.unit == "kg/m^3"
    np.testing.assert_allclose(rec.repeats, [1560.0, 1570.0])
    with pytest.raises(MeasurementError, match="no angle measured here"):
        mf.condition("baffle", "lab").stats()


def test_cli_summary_of_v2(capsys):
    assert measure_main(["--file", str(EXAMPLE)]) == 0
    out = json.loads(capsys.readouterr().out)
    obs = out["experiments"]["drum"]["conditions"]["30rpm"]["observables"]["dynamic_angle"]
    assert obs["mean"] == pytest.approx(np.mean([38.2, 37.6, 38.9]))


def test_v2_json_same_as_yaml(tmp_path, raw):
    p = tmp_path / "example.json"
    p.write_text(json.dumps(raw))
    assert load_measurements(p).observations() == load_measurements(EXAMPLE).observations()


# --------------------------------------------------------------------------- errors
def _set(path, value):
    """A mutation that sets raw[path...] = value (path: keys separated by '|')."""
    def f(d):
        keys = path.split("|")
        for k in keys[:-1]:
            d = d[k]
        d[keys[-1]] = value
    return f


def _delete(path):
    def f(d):
        keys = path.split("|")
        for k in keys[:-1]:
            d = d[k]
        del d[keys[-1]]
    return f


def _rename(path, new):
    def f(d):
        keys = path.split("|")
        for k in keys[:-1]:
            d = d[k]
        d[new] = d.pop(keys[-1])
    return f


D15 = "experiments|drum|conditions|15rpm"
DA = f"{D15}|observables|dynamic_angle"
BL = "experiments|baffle|conditions|lab"
CL = "experiments|cylinder|conditions|lab"
C2 = "experiments|cylinder|conditions|2kg"
K15 = "experiments.drum.conditions.15rpm"
KDA = f"{K15}.observables.dynamic_angle"
KBL = "experiments.baffle.conditions.lab"
KCL = "experiments.cylinder.conditions.lab"
KC2 = "experiments.cylinder.conditions.2kg"

BAD_INPUTS = [
    # (id, mutation, key path in the message and in .key, message fragment)
    ("typo_in_observable", _rename(f"{DA}|repeats", "repets"), f"{KDA}.repets", "unknown key 'repets'"),
    ("unknown_top_key", _set("titel", "x"), "titel", "unknown key 'titel'"),
    ("v1_kind_in_v2", _set("experiments|drum|kind", "drum_dynamic"), "experiments.drum.kind", "unknown key 'kind'"),
    ("v1_parameters_in_v2", _set(f"{D15}|parameters", {"rpm": 15}), f"{K15}.parameters", "unknown key 'parameters'"),
    ("missing_unit", _delete(f"{DA}|unit"), f"{KDA}.unit", "missing required field"),
    ("angle_not_in_deg", _set(f"{BL}|observables|static_angle|unit", "rad"),
     f"{KBL}.observables.static_angle.unit", "does not fit static_angle"),
    ("density_in_metres", _set(f"{BL}|observables|bulk_density|unit", "m"),
     f"{KBL}.observables.bulk_density.unit", "use kg/m^3"),
    ("empty_unit", _set(f"{BL}|observables|mass_left_in_box|unit", " "),
     f"{KBL}.observables.mass_left_in_box.unit", "empty unit"),
    ("angle_out_of_range", _set(f"{DA}|repeats", [35.0, 95.0]), f"{KDA}.repeats[1]", "out of range"),
    ("angle_view_out_of_range", _set(f"{CL}|observables|pile_angle|repeats", [[30.0, -1.0]]),
     f"{KCL}.observables.pile_angle.repeats[0][1]", "out of range"),
    ("not_a_number", _set(f"{DA}|repeats", [35.1, "35.9x"]), f"{KDA}.repeats[1]", "not a number"),
    ("boolean_repeat", _set(f"{BL}|observables|mass_left_in_box|repeats", [9.4, True]),
     f"{KBL}.observables.mass_left_in_box.repeats[1]", "not a number"),
    ("negative_density", _set(f"{BL}|observables|bulk_density|repeats", [1560.0, -3.0]),
     f"{KBL}.observables.bulk_density.repeats[1]", "out of range"),
    ("empty_repeats", _set(f"{DA}|repeats", []), f"{KDA}.repeats", "empty repeats"),
    ("repeats_and_slopes", _set(f"{DA}|slopes", [0.7, 0.71]), KDA, "found repeats and slopes"),
    ("no_data", _delete(f"{DA}|repeats"), KDA, "missing field: one of repeats"),
    ("no_pile_on_height", _set(f"{C2}|observables|pile_height|no_pile", 3),
     f"{KC2}.observables.pile_height.no_pile", "only for pile_angle"),
    ("no_pile_and_below_detection", _set(f"{C2}|observables|pile_angle|below_detection", {"n": 3, "limit": 2.0}),
     f"{KC2}.observables.pile_angle", "not both"),
    ("no_pile_zero", _set(f"{C2}|observables|pile_angle|no_pile", 0), f"{KC2}.observables.pile_angle.no_pile",
     "out of range"),
    ("no_pile_not_integer", _set(f"{C2}|observables|pile_angle|no_pile", 2.5),
     f"{KC2}.observables.pile_angle.no_pile", "not an integer"),
    ("below_detection_without_limit", _set(f"{BL}|observables|mass_left_in_box",
                                          {"unit": "kg", "below_detection": {"n": 3}}),
     f"{KBL}.observables.mass_left_in_box.below_detection.limit", "missing required field"),
    ("below_detection_typo", _set(f"{BL}|observables|mass_left_in_box",
                                  {"unit": "kg", "below_detection": {"n": 3, "limt": 0.1}}),
     f"{KBL}.observables.mass_left_in_box.below_detection.limt", "unknown key 'limt'"),
    ("images_for_density", _set(f"{BL}|observables|bulk_density|images", ["a.png"]),
     f"{KBL}.observables.bulk_density.images", "only for angles"),
    ("average_with_repeats", _set(f"{DA}|average", "slope"), f"{KDA}.average", "not to repeats"),
    ("image_settings_with_repeats", _set(f"{DA}|image_settings", {"threshold": 100}), f"{KDA}.image_settings",
     "only allowed with images or video"),
    ("negative_resolution", _set(f"{DA}|resolution", -0.1), f"{KDA}.resolution", "out of range"),
    ("pile_formed_two", _set(f"{CL}|observables|pile_formed", {"unit": "1/0", "repeats": [1, 2]}),
     f"{KCL}.observables.pile_formed.repeats[1]", "is 1 (yes) or 0 (no)"),
    ("missing_settings", _delete(f"{D15}|settings"), f"{K15}.settings", "missing required field"),
    ("material_in_settings", _set(f"{D15}|settings|material", {"type": "spheres"}), f"{K15}.settings.material",
     "stated once for the whole file"),
    ("mapping_setting", _set(f"{D15}|settings|rpm", {"value": 15}), f"{K15}.settings.rpm",
     "expected a number, string, boolean, null or a list of numbers"),
    ("nan_setting", _set(f"{D15}|settings|rpm", float("nan")), f"{K15}.settings.rpm", "not a finite number"),
    ("no_observables", _set(f"{D15}|observables", {}), f"{K15}.observables", "no observables"),
    ("no_conditions", _set("experiments|drum|conditions", {}), "experiments.drum.conditions", "no conditions"),
    ("bad_quantity_name", _rename(f"{DA}", "dynamic angle"), f"{K15}.observables.dynamic angle",
     "quantity name 'dynamic angle' is not allowed"),
    ("bad_condition_name", _rename(D15, "15/rpm"), "experiments.drum.conditions.15/rpm",
     "condition name '15/rpm' is not allowed"),
    ("bad_origin", _set(f"{D15}|origin", "guess"), f"{K15}.origin", "not one of lab, simulation"),
    ("material_sizes_reversed", _set("material|diameter", [0.020, 0.016]), "material.diameter", "d_min <= d_max"),
    ("material_nested", _set("material|shape", {"name": "x"}), "material.shape", "expected a number, string"),
]


@pytest.mark.parametrize("mutate,key,fragment", [b[1:] for b in BAD_INPUTS], ids=[b[0] for b in BAD_INPUTS])
def test_bad_input_names_file_and_key(tmp_path, raw, mutate, key, fragment):
    d = copy.deepcopy(raw)
    mutate(d)
    p = _write(tmp_path, d)
    with pytest.raises(MeasurementFileError) as ei:
        load_measurements(p)
    msg = str(ei.value)
    assert msg.startswith(f"{p}: {key}: "), msg
    assert fragment in msg, msg
    assert ei.value.key == key and ei.value.file == str(p)


def test_unsupported_format_names_both_versions(tmp_path, raw):
    raw["format"] = "warpdem-measurements/3"
    p = _write(tmp_path, raw)
    with pytest.raises(MeasurementFileError, match=r"format: unsupported format .*/1.*/2"):
        load_measurements(p)


def test_settings_checked_against_experiments(tmp_path, raw):
    def expect(d, key, fragment, **kw):
        p = _write(tmp_path, d)
        with pytest.raises(MeasurementFileError) as ei:
            load_measurements(p, **kw)
        assert str(p) in str(ei.value) and ei.value.key == key and fragment in str(ei.value), str(ei.value)

    d = copy.deepcopy(raw)
    d["experiments"]["drums"] = d["experiments"].pop("drum")
    load_measurements(_write(tmp_path, d))      # names unchecked without a registry
    expect(d, "experiments.drums", "unknown experiment 'drums' (registered: baffle, cylinder, drum)",
           experiments=EXPERIMENTS)
    d = copy.deepcopy(raw)
    d["experiments"]["drum"]["conditions"]["15rpm"]["settings"]["rmp"] = 15
    expect(d, f"{K15}.settings.rmp", "unknown setting 'rmp' of experiment 'drum'", experiments=EXPERIMENTS)
    d = copy.deepcopy(raw)
    d["experiments"]["drum"]["conditions"]["15rpm"]["settings"]["dt"] = 1e-5
    expect(d, f"{K15}.settings.dt", "sets up the simulation", experiments=EXPERIMENTS)
    d = copy.deepcopy(raw)
    d["experiments"]["cylinder"]["conditions"]["lab"]["settings"]["sections"] = 32
    expect(d, f"{KCL}.settings.sections", "sets up the simulation", experiments=EXPERIMENTS)
    # a plain mapping of setting names
    expect(raw, f"{K15}.settings.diameter", "unknown setting 'diameter'",
           experiments={"drum": {"rpm"}, "baffle": set(), "cylinder": set()})
    # build: the experiment itself refuses a value
    d = copy.deepcopy(raw)
    d["experiments"]["drum"]["conditions"]["30rpm"]["settings"]["length"] = -0.15
    load_measurements(_write(tmp_path, d), experiments=EXPERIMENTS)   # the names are fine
    expect(d, "experiments.drum.conditions.30rpm.settings", "refuses these settings", experiments=EXPERIMENTS,
           build=True)
    d = copy.deepcopy(raw)
    d["material"]["colour"] = "grey"
    expect(d, "material", "cannot build this material", experiments=EXPERIMENTS, build=True)


def test_unit_checked_against_what_the_experiment_reports():
    class FlowTest:
        OBSERVABLES = {"flow_rate": "kg/s"}

        @classmethod
        def field_names(cls):
            return ["scale", "orifice"]

    data = {"format": FORMAT_V2, "experiments": {"hopper": {"conditions": {"lab": {
        "settings": {"orifice": 0.05}, "observables": {"flow_rate": {"unit": "g/s", "repeats": [810, 790]}}}}}}}
    mf = parse_measurements(data)   # an unknown quantity keeps any unit
    with pytest.raises(MeasurementFileError) as ei:
        check_settings(mf, {"hopper": FlowTest})
    assert ei.value.key == "experiments.hopper.conditions.lab.observables.flow_rate.unit"
    assert "hopper reports flow_rate in kg/s, not g/s" in str(ei.value)
    data["experiments"]["hopper"]["conditions"]["lab"]["observables"]["flow_rate"]["unit"] = "kg/s"
    check_settings(parse_measurements(data), {"hopper": FlowTest})
    assert unreported_observables(parse_measurements(data), {"hopper": FlowTest}) == []


# --------------------------------------------------------------------------- version 1
def test_v1_still_loads_and_gives_observations():
    mf = load_measurements(TABLE_V1)
    assert mf.version == 1 and mf.material == {}
    check_settings(mf, EXPERIMENTS)   # version 1: parameters are free notes, nothing to check
    recs = _by_key(mf.observations())
    assert list(recs) == ["baffle/lab/static_angle", "drum/rpm30/dynamic_angle", "cylinder/lab/pile_angle",
                          "cylinder/dem_optimum/pile_angle"]
    st = mf.condition("baffle_static", "lab").stats()
    np.testing.assert_allclose(recs["baffle/lab/static_angle"].repeats, st.values_deg)
    assert recs["baffle/lab/static_angle"].settings == {"lift_speed_m_s": 0.1}
    assert recs["drum/rpm30/dynamic_angle"].repeats == pytest.approx((49.0579,), abs=2e-3)
    assert recs["cylinder/lab/pile_angle"].repeats == pytest.approx((31.13, 32.29, 34.70, 32.92, 31.61), abs=0.0101)
    assert recs["cylinder/dem_optimum/pile_angle"].origin == "simulation"
    assert all(r.unit == "deg" and r.n_censored == 0 for r in recs.values())
    assert unreported_observables(mf, EXPERIMENTS) == []


def test_v1_two_experiments_of_one_kind_get_distinct_keys():
    data = {"experiments": {
        "box_a": {"kind": "baffle_static", "conditions": {"lab": {"angles_deg": [30.0, 31.0]}}},
        "box_b": {"kind": "baffle_static", "conditions": {"lab": {"angles_deg": [32.0, 33.0]}}},
        "wedge": {"kind": "other", "conditions": {"lab": {"angles_deg": [20.0, 21.0]}}},
    }}
    keys = [r.key for r in parse_measurements(data).observations()]
    assert keys == ["baffle/lab/static_angle", "baffle/box_b.lab/static_angle", "wedge/lab/angle"]


def test_v1_as_observables():
    with pytest.raises(MeasurementFileError) as ei:   # the drum's single repeat has no standard error
        load_observations(TABLE_V1)
    assert ei.value.key == "drum/rpm30/dynamic_angle" and str(TABLE_V1) in str(ei.value)
    assert "resolution" in str(ei.value)
    obs = load_observations(TABLE_V1, default_resolution={"deg": 0.01})
    assert obs.keys == ("baffle/lab/static_angle", "drum/rpm30/dynamic_angle", "cylinder/lab/pile_angle")
    drum = obs[obs.index("drum/rpm30/dynamic_angle")]
    assert drum.n == 1 and drum.standard_error == 0.01 and drum.condition["rpm"] == 30
    cyl = obs[obs.index("cylinder/lab/pile_angle")]
    assert cyl.mean == pytest.approx(32.53, abs=0.005)
    assert cyl.standard_error == pytest.approx(1.3866 / math.sqrt(5), abs=1e-4)
    every = load_observations(TABLE_V1, default_resolution=0.01, origins=None)
    assert "cylinder/dem_optimum/pile_angle" in every.keys


# --------------------------------------------------------------------------- censored
def test_no_pile_is_censored(example):
    rec = _by_key(example.observations())["cylinder/2kg/pile_angle"]
    assert rec.repeats == () and rec.n_censored == 3 and rec.censor_limit == NO_PILE_LIMIT_DEG == 3.0
    assert rec.n == 3
    obs = load_observations(EXAMPLE)
    o = obs[obs.index("cylinder/2kg/pile_angle")]
    assert o.is_censored and o.n == 3 and o.detection_limit == 3.0 and o.mean == 3.0
    assert o.label == "pile angle of 2 kg" and o.condition["fill_mass"] == 2.0
    assert list(obs.censored) == [k == "cylinder/2kg/pile_angle" for k in EXPECTED_KEYS]


def test_below_detection_in_another_unit_and_mixed_repeats(tmp_path):
    data = {"format": FORMAT_V2, "experiments": {"baffle": {"conditions": {"lab": {
        "settings": {"fill_mass": 16.0},
        "observables": {"mass_left_in_box": {"unit": "g", "below_detection": {"n": 2, "limit": 5.0}}}}}},
        "cylinder": {"conditions": {"lab": {
            "settings": {"fill_mass": 10.0},
            "observables": {"pile_angle": {"unit": "deg", "repeats": [12.0, 14.0], "no_pile": 1}}}}}}}
    p = _write(tmp_path, data, "mixed.yaml")
    recs = _by_key(load_measurements(p).observations())
    m = recs["baffle/lab/mass_left_in_box"]
    assert m.unit == "kg" and m.n_censored == 2 and m.censor_limit == pytest.approx(0.005)
    mixed = recs["cylinder/lab/pile_angle"]
    assert mixed.repeats == (12.0, 14.0) and mixed.n_censored == 1 and mixed.n == 3
    # the file holds what the lab saw; the diagnosis refuses a pile that formed only sometimes
    with pytest.raises(MeasurementFileError) as ei:
        load_observations(p)
    assert ei.value.key == "experiments.cylinder.conditions.lab.observables.pile_angle"
    assert str(p) in str(ei.value) and "neither a mean nor a limit" in str(ei.value)


# --------------------------------------------------------------------------- writer
def test_writer_round_trip(tmp_path, example):
    recs = example.observations()
    for name in ("back.yaml", "back.json"):
        p = tmp_path / name
        written = write_measurements_v2(p, recs, title="synthetic lab", source="generator",
                                        material=example.material,
                                        descriptions={"drum": "rotating drum", "cylinder/2kg": "small fill"})
        back = load_measurements(p)
        assert back.observations() == recs == written.observations()
        assert back.version == 2 and back.title == "synthetic lab" and back.material == example.material
        assert back.experiments["drum"].description == "rotating drum"
        assert back.condition("cylinder", "2kg").description == "small fill"
    text = (tmp_path / "back.yaml").read_text()
    assert "no_pile: 3" in text and text.splitlines()[1] == f"format: {FORMAT_V2}"


def test_writer_records_from_a_generator(tmp_path):
    """What a synthetic-lab generator writes: numpy numbers, simulated origin, censored limits."""
    rng = np.random.default_rng(0)
    recs = [ObservationRecord("drum", f"{rpm}rpm", "dynamic_angle", "deg", rng.normal(36 + rpm / 10, 0.5, 3),
                              {"rpm": np.int64(rpm)}, origin="simulation") for rpm in (15, 30, 45)]
    recs += [ObservationRecord("cylinder", "lab", "pile_angle", "deg", (), {"fill_mass": 10.0}, 3, 2.0),
             ObservationRecord("cylinder", "lab", "pile_height", "m", (0.01, 0.012, 0.011), {"fill_mass": 10.0}),
             ObservationRecord("hopper", "lab", "flow_rate", "kg/s", (0.81, 0.79), {"orifice": 0.05}, resolution=0.01)]
    p = tmp_path / "gen.yaml"
    write_measurements_v2(p, recs)
    assert load_measurements(p).observations() == recs
    assert "below_detection: {n: 3, limit: 2.0}" in p.read_text()


@pytest.mark.parametrize("records,fragment", [
    ([ObservationRecord("cylinder", "lab", "pile_height", "mm", (118.0,), {})], "would not load back identically"),
    ([ObservationRecord("drum", "a", "dynamic_angle", "deg", (35.0,), {"rpm": 15}),
      ObservationRecord("drum", "a", "dynamic_angle", "deg", (36.0,), {"rpm": 15})], "duplicated observation"),
    ([ObservationRecord("drum", "a", "dynamic_angle", "deg", (35.0,), {"rpm": 15}),
      ObservationRecord("drum", "a", "power", "W", (3.0,), {"rpm": 30})], "disagree on the settings"),
    ([ObservationRecord("drum", "a", "dynamic_angle", "deg", (135.0,), {})], "out of range"),
    ([ObservationRecord("drum", "a/b", "dynamic_angle", "deg", (35.0,), {})], "is not allowed"),
])
def test_writer_refuses_what_would_not_load_back(tmp_path, records, fragment):
    p = tmp_path / "w.yaml"
    with pytest.raises(ValueError, match=fragment):
        write_measurements_v2(p, records)
    assert not p.exists()


# --------------------------------------------------------------------------- validation Observables
def test_conversion_to_observables(example):
    obs = load_observations(EXAMPLE)
    assert obs.keys == tuple(EXPECTED_KEYS)
    d15 = obs[0]
    assert isinstance(d15, Observable) and d15.experiment == "drum" and d15.quantity == "dynamic_angle"
    assert d15.unit == "deg" and dict(d15.condition)["rpm"] == 15 and d15.label == "drum angle at 15 rpm"
    assert d15.mean == pytest.approx(np.mean([35.1, 35.9, 34.8]))
    assert d15.standard_error == pytest.approx(np.std([35.1, 35.9, 34.8], ddof=1) / math.sqrt(3))
    bd = obs[obs.index("baffle/lab/bulk_density")]
    assert bd.unit == "kg/m^3" and bd.mean == pytest.approx(1562.6667, abs=1e-3)
    assert bd.standard_error == pytest.approx(np.std([1562, 1571, 1555], ddof=1) / math.sqrt(3))
    ph = obs[obs.index("cylinder/lab/pile_height")]
    assert ph.mean == pytest.approx(0.121) and ph.resolution == pytest.approx(0.001)
    assert obs[obs.index("baffle/lab/mass_left_in_box")].label == "mass left in box, baffle lab"  # no label given
    np.testing.assert_allclose(obs.means[:3], [np.mean(r.repeats) for r in example.observations()[:3]])
    # the resolution floors the standard error
    tight = ObservationRecord("drum", "a", "dynamic_angle", "deg", (35.0, 35.01, 35.02), {"rpm": 15}, resolution=0.5)
    (o,) = observations_from_records([tight])
    assert o.standard_error == 0.5


def test_observables_written_and_read_back(tmp_path):
    obs = load_observations(EXAMPLE)
    p = tmp_path / "obs.yaml"
    write_observations(p, obs, title="from observables", material={"type": "spheres", "diameter": [0.016, 0.02]})
    back = load_observations(p)
    assert back.items == obs.items
    with pytest.raises(ValueError, match="experiment/condition/quantity"):
        record_from_observable(Observable("drum_15", "drum", "dynamic_angle", "deg", (35.0, 36.0)))


def test_v2_images_measured(tmp_path):
    angles = [30.0, 34.0]
    scale, crest, top, floor = 2.0, 120.0, 120.0, 420.0
    (tmp_path / "img").mkdir()
    names = []
    for i, a in enumerate(angles):
        img = synthetic_slope_image(a, crest_col=crest, top_row=top, floor_row=floor, noise_std=10.0,
                                    gradient=0.4, texture=20.0, rng=i)
        names.append(f"img/pile_{i}.png")
        cv2.imwrite(str(tmp_path / names[-1]), img)
    h_mm = (floor - top) / scale
    data = {"format": FORMAT_V2, "experiments": {"baffle": {"conditions": {"photos": {
        "settings": {"fill_mass": 16.0},
        "observables": {
            "static_angle": {"unit": "deg", "images": names, "image_settings": {
                "scale_px_per_mm": scale, "origin_px": [crest, floor], "window_mm": [-20, 255, -5, h_mm + 30],
                "fit_band": [0.15, 0.85], "h_ref": h_mm}},
            "bulk_density": {"unit": "kg/m^3", "repeats": [1560.0, 1570.0]}}}}}}}
    p = _write(tmp_path, data, "photos.yaml")
    mf = load_measurements(p)
    c = mf.condition("baffle", "photos")
    assert c.data == "images" and c.images[0][0] == str(tmp_path / names[0])   # relative to the file
    assert mf.summary()["baffle"]["conditions"]["photos"]["observables"]["static_angle"]["measured"] is False
    (angle, density) = mf.observations(diagnostic_dir=tmp_path / "diag")
    np.testing.assert_allclose(angle.repeats, angles, atol=0.5)
    assert density.repeats == (1560.0, 1570.0)
    assert len(list((tmp_path / "diag").glob("*.png"))) == 2


def test_docs_example_matches_the_example_file():
    text = (Path(__file__).resolve().parents[1] / "docs" / "measurement_format.md").read_text()
    blocks = [b.split("```", 1)[0] for b in text.split("```yaml\n")[1:]]
    (doc,) = [b for b in blocks if b.startswith(f"format: {FORMAT_V2}\ntitle:")]
    def numbers(mf):
        return [(r.key, r.unit, r.repeats, r.settings, r.n_censored, r.censor_limit) for r in mf.observations()]

    assert numbers(parse_measurements(yaml.safe_load(doc))) == numbers(load_measurements(EXAMPLE))
