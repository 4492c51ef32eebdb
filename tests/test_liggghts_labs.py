"""LIGGGHTS as the lab of the hidden-effects proof (validation.reference.liggghts_labs) and the
scoring of its truths (benchmarks/score_hidden_effects.py): cases, decks, the three files, the lab
file not leaking the truth, and the rules for two hidden effects and an effect outside the
candidates. One tiny real run skips when LIGGGHTS is absent (install it with
scripts/install_liggghts.sh)."""
from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest
import yaml

from calibration.measurement.records import load_measurements
from validation.config import load_diagnosis_config
from warpdem.config_io import load_config_file
from validation.hidden_effects import TRUE_FRICTION
from validation.reference.liggghts import liggghts_executable
from validation.reference.liggghts_labs import (CANDIDATES, LAB_CASES, LabRun, canonical_case, case_material,
                                                generate_labs, lab_deck, lab_diagnosis_config, lab_document,
                                                plan_runs, poured_amount, truth_document, _max_fill_index,
                                                _stated_material)

ROOT = Path(__file__).parent.parent
needs_liggghts = pytest.mark.skipif(liggghts_executable() is None,
                                    reason="LIGGGHTS not installed (scripts/install_liggghts.sh)")
OBSERVABLES = {"baffle": {"static_angle": "deg", "bulk_density": "kg/m^3"}, "drum": {"dynamic_angle": "deg"},
               "cylinder": {"pile_angle": "deg", "pile_height": "m", "pile_formed": "1/0"}}


def _scorer():
    spec = importlib.util.spec_from_file_location("score_hidden_effects", ROOT / "benchmarks" / "score_hidden_effects.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_cases_hide_what_they_say_and_accept_the_plus_spelling():
    assert canonical_case("rolling+cohesion") == "rolling_cohesion"
    with pytest.raises(ValueError, match="unknown lab case 'shape'"):
        canonical_case("shape")
    both = LAB_CASES["rolling_cohesion"]
    assert both.law == {"rolling": "epsd2", "cohesion": "sjkr"}
    assert both.contact_parameters() == {**TRUE_FRICTION, "mu_r_pp": 0.15, "mu_r_pw": 0.15,
                                         "cohesion_energy_density_pp": 1e5, "cohesion_energy_density_pw": 1e5}
    assert set(both.hidden_effects) == {"rolling_resistance", "cohesion"} <= set(CANDIDATES)
    wide = LAB_CASES["wide_psd"]
    assert wide.hidden_effects == () and wide.outside and wide.law == {"rolling": "none"}
    assert LAB_CASES["base"].contact_parameters() == TRUE_FRICTION and not LAB_CASES["base"].outside


def test_the_wide_size_distribution_keeps_the_stated_mean_particle_and_packing():
    stated = _stated_material("baffle", "quick")
    assert case_material(LAB_CASES["base"], stated) is stated
    wide = case_material(LAB_CASES["wide_psd"], stated)
    assert sum(wide.diameter) == pytest.approx(sum(stated.diameter))  # same number-mean diameter
    assert wide.diameter[1] - wide.diameter[0] > 3.5 * (stated.diameter[1] - stated.diameter[0])
    assert wide.particle == stated.particle and wide.solids_fraction == stated.solids_fraction


def test_plan_shares_fill_indices_between_cases_and_keeps_seeds_in_range(tmp_path):
    runs = plan_runs(["base", "wide_psd"], "quick", 3, tmp_path)
    per_case = {c: [r for r in runs if r.case == c] for c in ("base", "wide_psd")}
    assert len(per_case["base"]) == 15  # baffle 3 + drum 3 x 3 speeds + cylinder 3
    idx = [r.fill_index for r in per_case["base"]]
    assert len(set(idx)) == 15 and idx == [r.fill_index for r in per_case["wide_psd"]]
    assert max(idx) <= _max_fill_index(LAB_CASES["wide_psd"].size_classes)
    assert per_case["base"][0].experiment == "drum"  # the longest runs first
    assert len({r.folder for r in runs}) == len(runs)
    with pytest.raises(ValueError, match="fills must lie in"):
        plan_runs(["base"], "quick", 1, tmp_path)


def _run(case: str, exp: str, cond: str, settings: dict, tmp_path: Path) -> LabRun:
    return LabRun(case, exp, cond, settings, 8100, tmp_path / case)


def test_decks_write_the_hidden_law_and_pour_the_hidden_sizes(tmp_path):
    protocol, deck = lab_deck(_run("rolling_cohesion", "drum", "30rpm", {"rpm": 30.0}, tmp_path), "quick", dt=1e-4)
    assert "pair_style gran model hertz tangential history cohesion sjkr rolling_friction epsd2 tangential_reduce off" \
        in deck.deck
    assert re.search(r"coefficientRollingFriction peratomtypepair 2 0.15 0.15 0.15 0.15", deck.deck)
    assert re.search(r"cohesionEnergyDensity peratomtypepair 2 100000 100000", deck.deck)
    assert deck.fill_mode == "poured" and "insert/rate/region" in deck.deck and deck.settings["rpm"] == 30.0
    _, base = lab_deck(_run("base", "baffle", "quick", {}, tmp_path), "quick", dt=1e-4)
    assert "pair_style gran model hertz tangential history\n" in base.deck and "cohesionEnergyDensity" not in base.deck
    assert re.search(r"coefficientFriction peratomtypepair 2 0.45 0.35 0.35 0.35", base.deck)
    protocol, wide = lab_deck(_run("wide_psd", "cylinder", "quick", {}, tmp_path), "quick", dt=1e-4)
    radii = [float(r) for r in re.findall(r"radius constant (\S+)", wide.deck)]
    stated = protocol.bulk_material()
    assert len(radii) == 12 and min(radii) < 0.7 * stated.diameter[0] / 2 and max(radii) > 1.2 * stated.diameter[1] / 2
    assert wide.settings["lift_clearance_m"] == pytest.approx(stated.diameter[1])  # the stated protocol
    assert protocol.lift_clearance is None  # the protocol measures with the stated material


def test_the_poured_mass_is_read_from_the_log():
    log = ("INFO: Particle insertion pour: inserted 91 particle templates (mass 2.521766e+00) at step 1\n"
           " - a total of 91 particle templates (mass 2.521766e+00) inserted so far.\n"
           "WARNING: Particle insertion: Less insertions than requested (./src/fix_insert.cpp:814)\n"
           " - a total of 959 particle templates (mass 2.698556e+01) inserted so far.\n")
    assert poured_amount(log) == {"particles": 959, "mass_kg": 26.98556, "short_insertions": 1}
    assert poured_amount("no insertion") == {}


def _record(exp: str, cond: str, fill: int, obs: dict, status: str = "ok", error: str | None = None) -> dict:
    return {"experiment": exp, "condition": cond, "fill_index": fill, "status": status, "error": error,
            "observables": obs, "wall_s": 10.0}


def test_the_lab_file_holds_the_repeats_and_nothing_of_the_truth(tmp_path):
    recs = [_record("baffle", "quick", 7000 + k, {"static_angle": 20.0 + k, "bulk_density": 1450.0 + k})
            for k in range(3)]
    recs += [_record("drum", "15rpm", 8000 + k, {"dynamic_angle": 40.0 + k}) for k in range(2)]
    recs += [_record("drum", "15rpm", 8002, {"dynamic_angle": None}, "failed",
                     "LIGGGHTS run failed: LiggghtsFailed: LIGGGHTS failed in /x/runs/rolling_cohesion/drum (rc 1)")]
    recs += [_record("drum", "30rpm", 8100, {"dynamic_angle": 41.0}),
             _record("drum", "30rpm", 8101, {"dynamic_angle": None}, "failed", "drum_dynamic_angle: too few bins")]
    recs += [_record("cylinder", "quick", 9000 + k, {"pile_angle": 0.0, "pile_height": 0.017, "pile_formed": 0.0})
             for k in range(3)]
    doc = lab_document(recs, "quick", OBSERVABLES)
    conds = {e: v["conditions"] for e, v in doc["experiments"].items()}
    assert conds["baffle"]["quick"]["observables"]["bulk_density"] == {"unit": "kg/m^3", "repeats": [1450.0, 1451.0, 1452.0],
                                                                       "resolution": 1.0}
    assert conds["drum"]["15rpm"]["observables"]["dynamic_angle"]["repeats"] == [40.0, 41.0]
    assert conds["drum"]["15rpm"]["settings"] == {"rpm": 15.0}
    assert "30rpm" not in conds["drum"]  # one measured repeat is no standard error
    assert conds["cylinder"]["quick"]["observables"]["pile_angle"] == {"unit": "deg", "no_pile": 3, "resolution": 0.5}
    assert "drum/15rpm: 1 of 3 repeat(s) not measurable: the run failed" in doc["notes"]
    text = yaml.safe_dump(doc)
    for leak in [*LAB_CASES, "rolling", "cohesion", "epsd2", "sjkr", "psd", "runs/", "0.15", "300000", "100000", "3e5", "1e5", "3.0e+05"]:
        assert leak not in text, leak
    path = tmp_path / "lab.yaml"
    path.write_text(text)
    assert load_measurements(path) is not None


def test_truth_and_diagnosis_configs(tmp_path):
    recs = [_record("baffle", "quick", 7000, {"static_angle": 20.0, "bulk_density": 1450.0})]
    truth = truth_document("wide_psd", recs, "quick", 3, "poured", tmp_path / "runs", 123.4, "LIGGGHTS-PUBLIC 3.8.0")
    assert truth["hidden_effects"] == [] and truth["outside_candidates"] and truth["liggghts_version"].endswith("3.8.0")
    assert truth["deck_folder"].endswith("runs/wide_psd") and truth["wall_s"] == 123.4 and truth["runs"] == recs
    assert truth["materials"]["cylinder"]["stated_diameter_m"] == [0.014, 0.018]
    cfgs = {c: lab_diagnosis_config(c, "quick", tmp_path) for c in LAB_CASES}
    keyed = {c: {k: v for k, v in cfg.items() if k not in ("name", "measurements", "output")} for c, cfg in cfgs.items()}
    assert all(k == keyed["base"] for k in keyed.values())  # the diagnosis cannot tell the cases apart
    assert keyed["base"]["diagnosis"]["max_added_effects"] == 2 and keyed["base"]["candidates"] == list(CANDIDATES)
    # the lab poured its fills, so the diagnosis pours too where warpdem can; a lab of warpdem's fills does not
    assert keyed["base"]["experiments"] == {"baffle": {"fill_mode": "poured"}, "cylinder": {"fill_mode": "poured"}}
    assert "experiments" not in lab_diagnosis_config("base", "quick", tmp_path, fill_mode="identical")
    (tmp_path / "diagnose_rolling_cohesion.yaml").write_text(yaml.safe_dump(cfgs["rolling_cohesion"]))
    cfg, _ = load_diagnosis_config(tmp_path / "diagnose_rolling_cohesion.yaml")
    assert cfg.measurements == "lab_rolling_cohesion.yaml"


def test_the_first_scale_is_the_readme_first_diagnosis(tmp_path):
    """--scale first: the 9 kg baffle test and the 3 kg hollow cylinder of validation.hidden_effects'
    "first", and diagnosis configs with first_diagnosis.yaml's small settings and cohesion range."""
    runs = plan_runs(["base", "wide_psd"], "first", 3, tmp_path)
    base = [r for r in runs if r.case == "base"]
    assert len(base) == 6 and {(r.experiment, r.condition) for r in base} == {("baffle", "9kg"), ("cylinder", "3kg")}
    assert next(r for r in base if r.experiment == "baffle").settings == {
        "fill_mass": 9.0, "lift_to": 0.25, "max_time_after_lift": 1.5, "min_bins": 2}
    protocol, deck = lab_deck(next(r for r in base if r.experiment == "cylinder"), "first", dt=1e-4)
    assert protocol.fill_mass == 3.0 and deck.settings["fill_mass_kg"] == pytest.approx(3.0)
    first = load_config_file(ROOT / "validation" / "configs" / "first_diagnosis.yaml", "diagnosis config")
    cfgs = {c: lab_diagnosis_config(c, "first", tmp_path) for c in LAB_CASES}
    keyed = {c: {k: v for k, v in cfg.items() if k not in ("name", "measurements", "output")} for c, cfg in cfgs.items()}
    assert all(k == keyed["base"] for k in keyed.values())
    cfg = cfgs["base"]
    assert cfg["diagnosis"] == {**first["diagnosis"], "max_added_effects": 2}
    assert cfg["effect_ranges"] == first["effect_ranges"] and cfg["scale"] == first["scale"] == "quick"
    assert cfg["parameters"] == first["parameters"] and cfg["fixed"] == first["fixed"]
    assert cfg["candidates"] == list(CANDIDATES) and cfg["cache"] == "dem_cache.jsonl"
    (tmp_path / "diagnose_base.yaml").write_text(yaml.safe_dump(cfg))
    loaded, _ = load_diagnosis_config(tmp_path / "diagnose_base.yaml")
    assert loaded.measurements == "lab_base.yaml"


# --------------------------------------------------------------------------- scoring
def _diagnosis(added: list[str], base_adequate: bool, headline: str, ranked: list[str], **verdict) -> dict:
    rounds = []
    if ranked:
        rounds = [{"candidates": [{"rank": i + 1, "effect": {"name": n}, "log_bayes_vs_current": 5.0 - i,
                                   "max_abs_z": 1.0} for i, n in enumerate(ranked)],
                   "tied": [], "chosen": added[0] if added else None, "reason": "..."}]
    version = {"version": "v", "chi2_per_dof": 1.0, "max_abs_z": 1.5, "n_within": 7, "n_observables": 7}
    return {"verdict": {"headline": headline, "base_adequate": base_adequate, "added_effects": added, **verdict},
            "error_history": {"versions": [version] * (1 + len(added))},
            "forward_model": {"seconds": 1.0, "runs": 10}, "rounds": rounds, "observables": [],
            "versions": [{"confirmation": None, "best_fit": {"mu_s_pp": 0.4}}]}


def _score(tmp_path: Path, case: str, diag: dict) -> dict:
    truth = truth_document(case, [], "quick", 3, "poured", tmp_path / "runs", 1.0, "LIGGGHTS-PUBLIC 3.8.0")
    (tmp_path / f"truth_{case}.json").write_text(json.dumps(truth))
    (tmp_path / f"diagnosis_{case}").mkdir(exist_ok=True)
    (tmp_path / f"diagnosis_{case}" / "diagnosis.json").write_text(json.dumps(diag))
    return _scorer().score_case(tmp_path, case)


NONE_HEADLINE = "This model cannot reproduce these measurements, and none of the candidate effects explains why"
BOTH = ["rolling_resistance", "cohesion", "shape"]


def test_two_hidden_effects_are_right_only_when_both_are_added_in_either_order(tmp_path):
    for added in (["rolling_resistance", "cohesion"], ["cohesion", "rolling_resistance"]):
        row = _score(tmp_path, "rolling_cohesion", _diagnosis(added, False, "with ... added", BOTH))
        assert row["found"] and row["rule"] == "added" and row["hidden"] == "cohesion+rolling_resistance"
    for added in (["rolling_resistance"], ["rolling_resistance", "shape"], []):
        assert not _score(tmp_path, "rolling_cohesion", _diagnosis(added, False, "...", BOTH))["found"]
    # the right effects added but disowned ("none of the candidates explains these measurements") is wrong
    assert not _score(tmp_path, "rolling_cohesion", _diagnosis(["rolling_resistance", "cohesion"], False, "None of ...",
                                                               BOTH, none_of_candidates=True))["found"]
    # one hidden effect: that effect added and nothing else
    assert _score(tmp_path, "rolling", _diagnosis(["rolling_resistance"], False, "...", BOTH))["found"]
    assert not _score(tmp_path, "rolling", _diagnosis(["rolling_resistance", "cohesion"], False, "...", BOTH))["found"]
    assert _score(tmp_path, "base", _diagnosis([], True, "No effect is needed: ...", []))["found"]


def test_an_effect_outside_the_candidates_is_right_only_when_the_diagnosis_names_none(tmp_path):
    row = _score(tmp_path, "wide_psd", _diagnosis([], False, NONE_HEADLINE, BOTH))
    assert row["found"] and row["none_of_candidates"] == "headline" and row["hidden"] == "outside the candidates"
    row = _score(tmp_path, "wide_psd", _diagnosis([], False, "The base model ...", BOTH, none_of_candidates=True))
    assert row["found"] and row["none_of_candidates"] == "verdict field"
    # studied and disowned: an effect added, then "none of the candidates explains these measurements"
    row = _score(tmp_path, "wide_psd", _diagnosis(["shape"], False, "None of the candidate effects explains these "
                                                  "measurements: ...", BOTH, none_of_candidates=True))
    assert row["found"]
    table = _scorer().markdown([row])
    assert "shape (none of the candidates explains it)" in table and "outside the candidates" in table
    # the explicit field decides over the words; an effect offered as the explanation or an adequate base is wrong
    assert not _score(tmp_path, "wide_psd", _diagnosis([], False, NONE_HEADLINE, BOTH, none_of_candidates=False))["found"]
    assert not _score(tmp_path, "wide_psd", _diagnosis(["shape"], False, "With shape added ...", BOTH))["found"]
    assert not _score(tmp_path, "wide_psd", _diagnosis([], True, "No effect is needed: ...", []))["found"]


# --------------------------------------------------------------------------- a real run
@needs_liggghts
def test_tiny_lab_runs_liggghts_and_writes_the_three_files(tmp_path):
    res = generate_labs(["base"], tmp_path, scale="tiny", fills=2, jobs=2, progress=False)
    assert res["liggghts_version"].startswith("LIGGGHTS")
    lab = yaml.safe_load((tmp_path / "lab_base.yaml").read_text())
    reps = lab["experiments"]["baffle"]["conditions"]["9kg"]["observables"]["static_angle"]["repeats"]
    assert len(reps) == 2 and all(0.0 < a < 45.0 for a in reps)
    truth = json.loads((tmp_path / "truth_base.json").read_text())
    assert truth["case"] == "base" and len(truth["runs"]) == 2 and truth["fill_mode"] == "poured"
    assert not list((tmp_path / "runs").rglob("*.dump"))  # measured, then deleted
    assert (tmp_path / "decks" / "base" / "baffle_9kg_fill7000.deck").exists()
    poured = truth["materials"]["baffle"]
    assert poured["fill_mass_kg"] == pytest.approx(9.0) and poured["poured_mass_kg"][0] > 0.99 * 9.0  # all poured
    cfg, _ = load_diagnosis_config(tmp_path / "diagnose_base.yaml")
    assert load_measurements(tmp_path / cfg.measurements) is not None
