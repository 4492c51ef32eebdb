"""Two effects at once and "none of my candidates" (issue 28, items 2 and 3), on the analytic model.

The labs are the analytic granular model of ``tests/test_diagnosis_logic.py`` with hidden effects:
rolling resistance AND cohesion at once (the pair must be added, effect by effect), and a bulk
density 80 kg/m^3 above what any candidate can give (as a denser particle-size distribution would:
shape, the only candidate that raises the density, gives at most +40 and then also a pile and steeper
angles), which must end in "none of the candidate effects explains these measurements".
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.test_diagnosis_logic import (BASE, COHESION, FAST, KEYS, ROLLING, SHAPE, AnalyticGranularModel,
                                        lab_observables)
from validation import DiagnosisSettings, Observable, diagnose, write_diagnosis

PAIR_TRUTH = {"mu_s_pp": 0.45, "mu_s_pw": 0.4, "mu_r": 0.1, "cohesion_energy_density": 2.0}


@pytest.fixture(scope="module")
def pair():
    obs = lab_observables(PAIR_TRUTH, ("rolling_resistance", "cohesion"))
    return diagnose(obs, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1), FAST)


def test_two_hidden_effects_are_both_added_effect_by_effect(pair, tmp_path):
    assert set(pair.added_effects) == {"rolling_resistance", "cohesion"}, pair.headline
    assert pair.met and not pair.none_of_candidates
    # the error history goes base -> +A -> +A+B and falls at each step
    h = pair.history.versions
    assert [len(v.effects) for v in h] == [0, 1, 2]
    assert h[0].chi2 > h[1].chi2 > h[2].chi2
    assert len(pair.rounds) == 2 and pair.rounds[1].current.version.effect_names == (pair.added_effects[0],)
    doc = json.loads(write_diagnosis(pair, tmp_path)["json"].read_text(encoding="utf-8"))
    assert doc["verdict"]["added_effects"] == list(pair.added_effects) and not doc["verdict"]["none_of_candidates"]


def test_one_hidden_effect_gets_no_second_one():
    obs = lab_observables({"mu_s_pp": 0.45, "mu_s_pw": 0.5, "mu_r": 0.12}, ("rolling_resistance",))
    r = diagnose(obs, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1), FAST)
    assert r.added_effects == ("rolling_resistance",) and r.met and not r.none_of_candidates
    # a second round runs only when needed (observables beyond 2 sigma, or a tie)
    assert len(r.rounds) == 1 or r.rounds[1].chosen is None


def test_max_added_effects_one_keeps_the_single_effect_behaviour():
    obs = lab_observables(PAIR_TRUTH, ("rolling_resistance", "cohesion"))
    r = diagnose(obs, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1),
                 DiagnosisSettings(**{**FAST.to_dict(), "max_added_effects": 1}))
    assert len(r.added_effects) == 1 and len(r.rounds) == 1


@pytest.fixture(scope="module")
def outside():
    obs = lab_observables({"mu_s_pp": 0.5, "mu_s_pw": 0.4}, ())
    dense = [Observable(o.key, o.experiment, o.quantity, o.unit, tuple(np.add(o.repeats, 80.0)), o.condition, o.label,
                        o.resolution, o.n_below_detection, o.detection_limit) if o.quantity == "bulk_density" else o
             for o in obs]
    return diagnose(dense, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1), FAST)


def test_an_effect_outside_the_candidates_is_called_so(outside, tmp_path):
    r = outside
    assert not r.base_adequate and not r.met
    assert r.none_of_candidates, r.headline
    assert "none of the candidate effects explains" in r.headline.lower()
    keys = [u.key for u in r.unreached]
    assert "baffle/bulk_density" in keys
    u = r.unreached[keys.index("baffle/bulk_density")]
    assert u.best_abs_z > FAST.cutoff and "bulk density" in r.headline
    # it is not offered as the explanation
    assert not any(step.startswith("Enable ") for step in r.next_steps)
    assert any("beyond the candidates" in step for step in r.next_steps)
    paths = write_diagnosis(r, tmp_path)
    doc = json.loads(paths["json"].read_text(encoding="utf-8"))
    assert doc["verdict"]["none_of_candidates"] and doc["verdict"]["unreached"][0]["key"] in KEYS
    html = paths["report"].read_text(encoding="utf-8")
    assert "no candidate reaches" in html.lower()


def test_a_choice_short_of_strong_evidence_is_provisional_and_names_what_would_decide():
    """Every candidate within ``strong_log_bayes`` of the top (here made huge) is a contender: the
    choice stands, provisionally, and the proposals are forecast under the contenders."""
    from tests.test_diagnosis_logic import DRUM_10, DRUM_60

    obs = lab_observables({"mu_s_pp": 0.45, "mu_s_pw": 0.5, "mu_r": 0.12}, ("rolling_resistance",))
    model = AnalyticGranularModel(1, proposals=(DRUM_10, DRUM_60))
    r = diagnose(obs, BASE, [ROLLING, COHESION, SHAPE], model,
                 DiagnosisSettings(**{**FAST.to_dict(), "strong_log_bayes": 1e6}))
    rnd = r.rounds[0]
    assert rnd.chosen == "rolling_resistance" and len(rnd.tied) == 1
    assert set(rnd.contenders) == {"rolling_resistance", "cohesion", "shape"} == set(rnd.discriminated)
    assert rnd.discrimination is not None and set(rnd.discrimination.candidates) == set(rnd.contenders)
    assert "provisional" in r.headline and "fits nearly as well" in r.headline
    # a provisional choice never reads green: the verdict carries why
    assert any("is provisional" in c for c in r.caveats)
    # the default (ln B 3) leaves a clear winner alone: no forecasts
    plain = diagnose(obs, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1, proposals=(DRUM_10, DRUM_60)), FAST)
    assert plain.rounds[0].contenders == () and plain.rounds[0].discrimination is None
    assert not any("is provisional" in c for c in plain.caveats)
