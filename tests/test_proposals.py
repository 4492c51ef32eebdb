"""Proposals over the whole space a lab can reach (validation.proposals) and their ranking by
separation per lab hour (validation.discrimination); no DEM: an analytic forward model."""
from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from calibration.designs import Parameter, ParameterSpace
from calibration.experiments import EXPERIMENTS
from validation import CandidateEffect, EffectParameter, ForwardModel, ForwardRunner, Observable, ProposedMeasurement
from validation.config import DiagnosisConfig
from validation.discrimination import Forecast, discriminate, rank_forecasts
from validation.effects import ModelVersion
from validation.proposals import DEFAULT_MAX_PROPOSED_CONDITIONS, enumerate_proposals, lab_effort, lab_hours
from warpdem import ConfigError

ALL = 1000  # a cap that keeps every condition


def _obs(key: str, condition: dict, value: float = 1.0) -> Observable:
    experiment, _, quantity = key.split("/")
    unit = EXPERIMENTS[experiment].OBSERVABLES[quantity]
    return Observable(key, experiment, quantity, unit, (value, value * 1.01, value * 0.99), condition)


#: a baffle test (static angle only) and the drum at 15 and 30 rpm; no cylinder
MEASURED = [_obs("baffle/9kg/static_angle", {"fill_mass": 9.0}, 30.0),
            _obs("drum/15rpm/dynamic_angle", {"rpm": 15.0}, 35.0),
            _obs("drum/30rpm/dynamic_angle", {"rpm": 30.0}, 37.0)]


def _same(frame_a: dict, frame_b: dict, experiment: str) -> bool:
    """Two conditions of ``experiment`` simulate the same settings (quick scale)."""
    base = EXPERIMENTS[experiment].from_config("quick")
    keys = set(frame_a) | set(frame_b)
    return all(frame_a.get(k, getattr(base, k)) == frame_b.get(k, getattr(base, k)) for k in keys)


# ----------------------------------------------------------------------------- declarations
def test_every_experiment_declares_what_a_lab_can_change_and_its_effort():
    for name, cls in EXPERIMENTS.items():
        effort = lab_effort(name)
        assert effort is cls.LAB_EFFORT and effort.repeat_hours > 0 and effort.setup_hours > effort.repeat_hours
        assert cls.LAB_SETTINGS, name
        fields = set(cls.field_names())
        for s in cls.LAB_SETTINGS:
            assert s.name in fields and set(s.also_scaled) <= fields, (name, s.name)
            assert s.why and s.words and s.unit
            assert isinstance(getattr(cls.from_config("paper"), s.name), float)
    # the order the issue asks for: a speed change on a filled drum is cheap, a new size is not
    drum = {s.name: s for s in EXPERIMENTS["drum"].LAB_SETTINGS}
    cyl = {s.name: s for s in EXPERIMENTS["cylinder"].LAB_SETTINGS}
    assert drum["rpm"].hours(3) < drum["fill_fraction"].hours(3) < drum["diameter"].hours(3)
    assert cyl["fill_mass"].hours(3) < cyl["diameter"].hours(3)


def test_config_default_cap_is_the_module_default():
    cfg = DiagnosisConfig.model_validate({"measurements": "m.yaml", "parameters": {"mu_s_pp": [0.1, 0.9]}})
    assert cfg.max_proposed_conditions == DEFAULT_MAX_PROPOSED_CONDITIONS


# ----------------------------------------------------------------------------- enumeration
def test_enumeration_covers_every_setting_and_observable_and_skips_what_was_measured():
    plan = enumerate_proposals(MEASURED, scale="quick", max_conditions=ALL)
    assert not plan.dropped, plan.not_forecast()
    props = plan.proposals
    keys = [p.key for p in props]
    assert len(set(keys)) == len(keys) and not set(keys) & {o.key for o in MEASURED}
    for p in props:  # names fit the measurement format (experiment/condition/quantity, no white space)
        exp, cond, qty = p.key.split("/")
        assert exp == p.experiment and qty == p.quantity and not any(ch.isspace() for ch in cond)
        assert p.unit == EXPERIMENTS[p.experiment].OBSERVABLES[p.quantity] and p.lab_hours > 0
    # nothing measured is proposed again
    for o in MEASURED:
        assert not any(p.experiment == o.experiment and p.quantity == o.quantity
                       and _same(dict(p.condition), dict(o.condition), o.experiment) for p in props), o.key
    # the unmeasured observable at a measured condition: no new DEM worlds
    bulk = [c for c in plan.conditions if c.experiment == "baffle" and not c.new]
    assert len(bulk) == 1 and bulk[0].quantities == ("bulk_density",) and dict(bulk[0].settings) == {"fill_mass": 9.0}
    # every declared setting at every declared value from every measured condition, with every observable
    measured = {"baffle": [{"fill_mass": 9.0}], "drum": [{"rpm": 15.0}, {"rpm": 30.0}]}
    for experiment, conditions in measured.items():
        cls = EXPERIMENTS[experiment]
        base = cls.from_config("quick")
        for cond in conditions:
            for s in cls.LAB_SETTINGS:
                for _, value in s.values(float(cond.get(s.name, getattr(base, s.name)))):
                    want = {**cond, s.name: value}
                    if any(_same(want, m, experiment) for m in conditions):
                        continue  # e.g. twice 15 rpm: measured
                    core = {k: v for k, v in want.items() if k not in s.also_scaled}
                    hits = [p for p in props if p.experiment == experiment
                            and {k: v for k, v in p.condition.items() if k not in s.also_scaled} == core]
                    assert sorted(p.quantity for p in hits) == sorted(cls.OBSERVABLES), (experiment, want)
    # twice 15 rpm is 30 rpm, measured: not proposed; a third of 15 rpm is
    drum_rpms = {p.condition.get("rpm") for p in props if p.experiment == "drum" and set(p.condition) == {"rpm"}}
    assert drum_rpms == {5.0, 60.0, 10.0}
    # the wider box carries its measured slab along, and a fill of the same height
    wide = [p for p in props if p.experiment == "baffle" and "box_width" in p.condition]
    assert wide and all(p.condition["measure_y"] == pytest.approx((0.045, 0.255)) and p.condition["fill_mass"] == 13.5
                        for p in wide)
    # the unmeasured experiment at its standard set-up, every observable, the set-up in its effort
    cyl = [p for p in props if p.experiment == "cylinder"]
    assert sorted(p.quantity for p in cyl) == sorted(EXPERIMENTS["cylinder"].OBSERVABLES)
    assert all(dict(p.condition) == {} and p.lab_hours == pytest.approx(2.0 + 3 * 0.4) for p in cyl)
    # several measured drum conditions: the words say which one a change starts from
    assert any("at rpm 15" in p.label for p in props if p.experiment == "drum")


def test_cap_bounds_the_new_conditions_and_names_the_ones_left_out():
    everything = enumerate_proposals(MEASURED, scale="quick", max_conditions=ALL)
    n_all = everything.new_conditions
    assert n_all > 4
    plan = enumerate_proposals(MEASURED, scale="quick", max_conditions=4)
    kept = [c for c in plan.conditions if c.new]
    assert len(kept) == 4 == plan.new_conditions
    assert len(plan.dropped) == n_all - 4
    assert all("max_proposed_conditions" in d.reason for d in plan.dropped)
    # every condition reached is either forecast or named as left out
    kept_or_dropped = {(c.experiment, c.words) for c in kept} | {(d.experiment, d.words) for d in plan.dropped}
    assert kept_or_dropped == {(c.experiment, c.words) for c in everything.conditions if c.new}
    assert len(plan.not_forecast()) == len(plan.dropped) and all("lab hours" in s for s in plan.not_forecast())
    # settings in turns, cheapest first: four different settings, none dearer than a dropped untried one
    assert len({(c.experiment, c.change) for c in kept}) == 4
    tried = {(c.experiment, c.change) for c in kept}
    untried = [c for c in everything.conditions if c.new and (c.experiment, c.change) not in tried]
    assert max(c.lab_hours for c in kept) <= min(c.lab_hours for c in untried)
    assert ("drum", "rpm") in tried  # the cheapest of all: a speed change on a filled drum
    # the free proposals (measured conditions' unmeasured observables) are never capped
    none_new = enumerate_proposals(MEASURED, scale="quick", max_conditions=0)
    assert none_new.new_conditions == 0 and [p.quantity for p in none_new.proposals] == ["bulk_density"]


def test_a_condition_the_machine_cannot_run_is_left_out_with_the_reason():
    def check(experiment, settings):
        if experiment == "drum" and "diameter" in settings:
            raise ConfigError("drum: fill of 9e6 particles exceeds the limit")

    plan = enumerate_proposals(MEASURED, scale="quick", max_conditions=ALL, check=check)
    assert not any("diameter" in p.condition for p in plan.proposals if p.experiment == "drum")
    refused = [d for d in plan.dropped if "diameter" in d.settings]
    assert refused and all("exceeds the limit" in d.reason for d in refused)
    # a value the experiment itself refuses (fill fraction >= 1) is left out too
    full = enumerate_proposals([_obs("drum/a/dynamic_angle", {"fill_fraction": 0.7}, 35.0)], scale="quick",
                               max_conditions=ALL)
    assert any("fill_fraction" in d.reason for d in full.dropped)
    assert not any(p.condition.get("fill_fraction", 0) >= 1 for p in full.proposals)


def test_lab_hours_of_a_condition():
    drum = [{"rpm": 30.0}]
    assert lab_hours("drum", {"rpm": 60.0}, drum, 3, "quick") == pytest.approx(0.3)  # speed on a filled drum
    assert lab_hours("drum", {"rpm": 30.0, "diameter": 0.45}, drum, 3, "quick") == pytest.approx(8.0 + 1.5)
    assert lab_hours("drum", {"rpm": 30.0}, drum, 3, "quick") == pytest.approx(1.5)  # the measured condition again
    assert lab_hours("drum", {"rpm": 30.0, "record": 4}, drum, 2, "quick") == pytest.approx(1.0)  # undeclared: repeats
    assert lab_hours("cylinder", {}, [], 3, "quick") == pytest.approx(2.0 + 1.2)  # not measured: set up first
    # a wider box with the fill that keeps its height: the box is the change, the fill comes with it
    wide = {"fill_mass": 42.0, "box_width": 0.3, "measure_y": (0.045, 0.255)}
    assert lab_hours("baffle", wide, [{}], 3, "quick") == pytest.approx(4.0 + 1.5)
    # the cheapest route from any measured condition counts
    assert lab_hours("drum", {"rpm": 60.0}, [{"rpm": 30.0, "fill_fraction": 0.25}, {"rpm": 30.0}], 3,
                     "quick") == pytest.approx(0.3)


def test_config_proposals_keep_working_and_bad_settings_are_config_errors():
    from validation.cli import _proposals

    def cfg(proposals, **kw):
        return DiagnosisConfig.model_validate({"measurements": "m.yaml", "parameters": {"mu_s_pp": [0.1, 0.9]},
                                               "scale": "quick", "proposals": proposals, **kw})

    listed = _proposals(cfg([{"experiment": "drum", "quantity": "dynamic_angle", "settings": {"rpm": 60},
                              "label": "drum at 60 rpm"},
                             {"experiment": "drum", "quantity": "dynamic_angle", "settings": {"rpm": 60},
                              "lab_hours": 7.5}]), MEASURED)
    assert [p.key for p in listed.proposals] == ["drum/proposed0/dynamic_angle", "drum/proposed1/dynamic_angle"]
    assert listed.proposals[0].lab_hours == pytest.approx(0.3) and listed.proposals[1].lab_hours == 7.5
    with pytest.raises(ConfigError, match=r"proposals\[0\]\.settings: .*'speed'"):
        _proposals(cfg([{"experiment": "drum", "quantity": "dynamic_angle", "settings": {"speed": 60}}]), MEASURED)
    with pytest.raises(ConfigError, match=r"proposals\[0\]: the drum experiment does not report 'height'"):
        _proposals(cfg([{"experiment": "drum", "quantity": "height"}]), MEASURED)
    with pytest.raises(ConfigError, match=r"proposals\[0\]\.settings: drum: fill_fraction must be < 1"):
        _proposals(cfg([{"experiment": "drum", "quantity": "dynamic_angle", "settings": {"fill_fraction": 1.2}}]),
                   MEASURED)
    assert _proposals(cfg("none"), MEASURED).proposals == ()
    auto = _proposals(cfg("auto", max_proposed_conditions=3), MEASURED)
    assert auto.new_conditions == 3 and auto.dropped


# ----------------------------------------------------------------------------- ranking by effort
BASE = ParameterSpace((Parameter("a", 0.0, 1.0),))
EFFECT_A = CandidateEffect("effect_a", (EffectParameter("ka", "-", 0.0, 1.0, 0.0),), "effect A")
EFFECT_B = CandidateEffect("effect_b", (EffectParameter("kb", "-", 0.0, 1.0, 0.0),), "effect B")
WORDS = {"effect_a": "effect A", "effect_b": "effect B"}


class _TwoEffects(ForwardModel):
    """Each key ``x/<name>/q`` reads 10 + a under effect A and 10 + a + gap[name] under effect B,
    with a small deterministic fill-to-fill scatter; keys in ``failing`` are never measured (NaN)."""

    def __init__(self, gap: dict[str, float], failing=(), not_forecast=()):
        self.gap, self.failing = gap, set(failing)
        self.proposals_not_forecast = tuple(not_forecast)

    def evaluate(self, effects, parameter_sets, replicates, keys):
        out = np.empty((len(parameter_sets), replicates, len(keys)))
        for i, p in enumerate(parameter_sets):
            for r in range(replicates):
                for j, k in enumerate(keys):
                    shift = self.gap[k.split("/")[1]] if "effect_b" in effects else 0.0
                    out[i, r, j] = np.nan if k in self.failing else 10 + p["a"] + shift + 0.05 * math.sin(7 * i + 3 * r)
        return out


def _studies():
    X = np.column_stack([np.linspace(0, 1, 8), np.linspace(0, 1, 8)[::-1]])
    U = np.random.default_rng(0).random((400, 2))
    out = {}
    for e in (EFFECT_A, EFFECT_B):
        out[e.name] = SimpleNamespace(version=ModelVersion(BASE, (e,)), design=SimpleNamespace(X=X),
                                      evidence=SimpleNamespace(posterior_sample=lambda n, seed, U=U: U[:n]))
    return out


def _proposal(name: str, hours: float | None) -> ProposedMeasurement:
    return ProposedMeasurement(f"x/{name}/q", "drum", "dynamic_angle", "deg", {}, f"angle {name}", n_repeats=3,
                               lab_hours=hours)


def test_effort_ranking_picks_the_cheaper_of_two_proposals_that_separate_about_equally():
    # 'dear' separates slightly more than 'cheap', at five times the lab hours; 'far' most, dearest
    model = _TwoEffects({"dear": 3.1, "cheap": 3.0, "far": 6.0, "close": 0.1})
    props = [_proposal("dear", 5.0), _proposal("cheap", 1.0), _proposal("far", 20.0), _proposal("close", 0.2)]
    d = discriminate(_studies(), WORDS, props, ForwardRunner(model), n_posterior=300)
    sep = {f.proposal.key: f.separation for f in d.forecasts}
    assert sep["x/dear/q"] > sep["x/cheap/q"] >= 2.0 and sep["x/far/q"] > sep["x/dear/q"]
    assert sep["x/close/q"] < 2.0  # cheapest of all, but it does not separate: never recommended
    assert d.recommended == "x/cheap/q" and d.forecasts[0].proposal.key == "x/cheap/q"
    assert [f.proposal.key for f in d.forecasts] == ["x/cheap/q", "x/dear/q", "x/far/q", "x/close/q"]
    assert "about 1 lab hours" in d.sentence and "most separation per lab hour" in d.sentence
    assert "angle far separates them more" in d.sentence
    doc = d.to_dict()
    first = doc["forecasts"][0]
    assert first["lab_hours"] == 1.0 and first["separation_sigma_per_lab_hour"] == pytest.approx(sep["x/cheap/q"])
    assert doc["forecasts"][1]["separation_sigma_per_lab_hour"] == pytest.approx(sep["x/dear/q"] / 5.0)
    assert doc["separating"] == 3 and doc["not_forecast"] == []


def test_rank_forecasts_by_separation_per_hour_among_those_that_separate():
    def fc(name, sep, hours):
        return Forecast(_proposal(name, hours), {"a": 0.0, "b": 1.0}, {"a": 0.1, "b": 0.1}, 0.1, sep, ("a", "b"))

    equal = rank_forecasts([fc("dear", 3.0, 4.0), fc("cheap", 3.0, 1.0)], 2.0)
    assert [f.proposal.key for f in equal] == ["x/cheap/q", "x/dear/q"]
    below = rank_forecasts([fc("cheap", 1.9, 0.1), fc("dear", 2.5, 10.0), fc("nan", float("nan"), 0.1),
                            fc("weak", 0.5, 0.1)], 2.0)
    assert [f.proposal.key for f in below] == ["x/dear/q", "x/cheap/q", "x/weak/q", "x/nan/q"]
    unknown = rank_forecasts([fc("known", 3.0, 2.0), fc("unknown", 2.5, None)], 2.0)  # None counts as 1 hour
    assert unknown[0].proposal.key == "x/unknown/q"


def test_indistinguishable_says_so_and_lists_what_each_predicts():
    model = _TwoEffects({"one": 0.0, "two": 0.05, "three": 0.1, "four": 0.0},
                        not_forecast=("drum at drum diameter 0.45 m: beyond the 6 new conditions",))
    props = [_proposal(n, 1.0) for n in ("one", "two", "three", "four")]
    d = discriminate(_studies(), WORDS, props, ForwardRunner(model), n_posterior=300)
    assert d.recommended is None
    assert "these effects are indistinguishable with these experiments" in d.sentence
    assert "cannot separate" in d.sentence and "both remain possible" in d.sentence.lower()
    for f in d.forecasts[:3]:  # the closest three, with each candidate's prediction and unit
        assert f"at the {f.proposal.name}" in d.sentence
        for n in ("effect_a", "effect_b"):
            assert f"{WORDS[n]} predicts {f.means[n]:.3g} ± {f.sds[n]:.2g} deg" in d.sentence
    assert f"at the {d.forecasts[3].proposal.name}," not in d.sentence
    assert "1 more proposal was not forecast" in d.sentence
    assert d.to_dict()["not_forecast"] == list(model.proposals_not_forecast)


def test_a_proposal_too_few_runs_measured_is_left_out_not_fatal():
    model = _TwoEffects({"good": 4.0, "bad": 4.0}, failing={"x/bad/q"})
    d = discriminate(_studies(), WORDS, [_proposal("bad", 0.5), _proposal("good", 1.0)], ForwardRunner(model),
                     n_posterior=300)
    assert [f.proposal.key for f in d.forecasts] == ["x/good/q"] and d.recommended == "x/good/q"
    assert len(d.not_forecast) == 1 and d.not_forecast[0].startswith("angle bad: no forecast")
    none = discriminate(_studies(), WORDS, [_proposal("bad", 0.5)], ForwardRunner(model), n_posterior=300)
    assert none.recommended is None and "could be forecast" in none.sentence


def test_proposed_measurement_lab_hours_are_checked():
    with pytest.raises(ValueError, match="lab_hours must be > 0"):
        _proposal("x", 0.0)
    assert dataclasses.replace(_proposal("x", 2), lab_hours=None).to_dict()["lab_hours"] is None


def test_an_unknown_proposal_setting_is_one_line_and_exit_code_2(tmp_path, capsys):
    import yaml
    from pathlib import Path

    from validation.cli import diagnose_main

    configs = Path(__file__).parent.parent / "validation" / "configs"
    doc = yaml.safe_load((configs / "tiny_diagnosis.yaml").read_text())
    doc.update(measurements=str(configs / "tiny_lab.yaml"), output=str(tmp_path / "out"),
               proposals=[{"experiment": "cylinder", "quantity": "pile_height", "settings": {"fill_kg": 4}}])
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(yaml.safe_dump(doc))
    assert diagnose_main([str(cfg), "--device", "cpu"]) == 2
    err = capsys.readouterr().err
    assert "proposals[0].settings" in err and "'fill_kg'" in err and "fill_mass" in err and "Traceback" not in err
