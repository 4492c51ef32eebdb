"""A diagnosis never shows green over data that cannot tell (issue 30): an adequate base model whose
plausible set fills most of its box reads amber "the data cannot tell", with the share; a plausible
set the data narrowed keeps "No effect is needed" in green. Synthetic results, no forward model."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from calibration.reporting import Report
from validation.adequacy import Adequacy
from validation.diagnose import CANNOT_TELL_PLAUSIBLE_SHARE, _summarise, data_cannot_tell
from validation.observables import Observable, Observations
from validation.report import _verdict

OBS = Observations([Observable("baffle/static_angle", "baffle", "static_angle", "deg", (30.0, 33.0, 27.0),
                               label="static angle A"),
                    Observable("baffle/bulk_density", "baffle", "bulk_density", "kg/m3", (1600.0, 1610.0, 1590.0),
                               label="bulk density")])


def adequacy(share: float, adequate: bool = True) -> Adequacy:
    """An adequacy verdict over two friction coefficients with ``share`` of the box plausible."""
    n = 512
    return Adequacy(adequate, 3.0, 0.4 if adequate else 4.2, {"mu_s_pp": 0.5, "mu_s_pw": 0.5}, n,
                    int(round(share * n)) if adequate else 0, share if adequate else 0.0,
                    {"mu_s_pp": (0.1, 0.9), "mu_s_pw": (0.1, 0.9)} if adequate else {}, (), (), 1.2, 2, 2,
                    "The model is adequate." if adequate else "This model cannot reproduce these measurements.")


def base_study(share: float, adequate: bool = True) -> SimpleNamespace:
    """The parts of a :class:`validation.study.ModelStudy` the verdict reads."""
    return SimpleNamespace(
        name="base", adequacy=adequacy(share, adequate), check=SimpleNamespace(disagreeing=(), agrees=True),
        refinement=(), confirmation=None, version=SimpleNamespace(effects=(), effect_names=()),
        surrogates=SimpleNamespace(quality=[SimpleNamespace(key="baffle/static_angle", r2=0.12),
                                            SimpleNamespace(key="baffle/bulk_density", r2=0.8)]))


def history(max_abs_z: float = 0.8) -> SimpleNamespace:
    errors = SimpleNamespace(n_observables=2, n_within=2, max_abs_z=max_abs_z, chi2_per_observable=0.4,
                             z={"baffle/static_angle": 0.8, "baffle/bulk_density": -0.3})
    return SimpleNamespace(versions=[errors])


def result(share: float) -> SimpleNamespace:
    """A finished diagnosis whose base model is adequate with ``share`` of its box plausible."""
    base = base_study(share)
    settings = SimpleNamespace(within_sigma=2.0)
    met, headline, details, steps = _summarise([base], [], history(), settings)
    why = data_cannot_tell(base.adequacy)
    return SimpleNamespace(observations=OBS, versions=[base], base=base, final=base, history=history(), met=met,
                           headline=headline, details=details, next_steps=steps, caveats=[why] if why else [],
                           forward={"runs": 20}, seconds={"total": 120.0}, none_of_candidates=False)


@pytest.mark.parametrize("share, cannot_tell", [(1.0, True), (CANNOT_TELL_PLAUSIBLE_SHARE, True),
                                                (CANNOT_TELL_PLAUSIBLE_SHARE - 0.01, False), (0.3, False)])
def test_the_data_cannot_tell_when_the_plausible_set_fills_the_box(share, cannot_tell):
    why = data_cannot_tell(adequacy(share))
    assert (why is not None) is cannot_tell
    if cannot_tell:
        assert f"plausible over {share:.0%} of its parameter box" in why
    assert data_cannot_tell(adequacy(share, adequate=False)) is None  # an inadequate model: the data did tell


def test_a_box_full_of_plausible_sets_reads_amber_cannot_tell():
    r = result(1.0)
    assert r.headline.startswith("The data cannot tell: the base model is plausible over 100% of its parameter box")
    assert "No effect is needed" not in r.headline
    assert any(s.startswith("Measure more") for s in r.next_steps)
    verdict = _verdict(r)
    assert verdict.tone == "weak" and verdict.status_text == "Cannot tell" and verdict.caveats == r.caveats
    numbers = dict(verdict.numbers)
    assert numbers["plausible share of the box (base)"] == "100%"
    assert numbers["lowest surrogate CV R² (base)"] == "0.12 (static angle A)"
    html = Report("diagnosis", verdict).to_html()
    assert 'class="verdict weak"' in html and ">Cannot tell<" in html and "Weak basis:" in html
    assert 'class="verdict met"' not in html


def test_a_narrowed_plausible_set_keeps_no_effect_is_needed_in_green():
    r = result(0.3)
    assert r.headline.startswith("No effect is needed") and r.caveats == []
    verdict = _verdict(r)
    assert verdict.tone == "met" and verdict.status_text == "Met"
    assert dict(verdict.numbers)["plausible share of the box (base)"] == "30%"
    assert 'class="verdict met"' in Report("diagnosis", verdict).to_html()


def candidate(name: str, log_bayes: float, r2: float) -> SimpleNamespace:
    """The parts of a :class:`validation.ranking.CandidateResult` a weak choice reads."""
    quality = [SimpleNamespace(key="cylinder/pile_angle", r2=0.9), SimpleNamespace(key="baffle/static_angle", r2=r2)]
    return SimpleNamespace(name=name, log_bayes=log_bayes, effect=SimpleNamespace(words=name.replace("_", " ")),
                           study=SimpleNamespace(surrogates=SimpleNamespace(quality=quality)))


@pytest.mark.parametrize("margin, r2, weak", [(1.1, -1.07, True), (2.4, 0.3, True), (3.5, -1.07, False),
                                              (1.1, 0.6, False)])
def test_a_choice_on_a_thin_margin_from_poor_surrogates_is_weak(margin, r2, weak):
    """The README's main job chose rolling resistance over cohesion by ln B 1.1 with a static-angle
    surrogate of CV R^2 -1.07: that choice is a caveat (amber), while a strong margin or good
    surrogates are not."""
    from validation.diagnose import RankingRound, weak_choice

    top, runner = candidate("rolling_resistance", 14.6, r2), candidate("cohesion", 14.6 - margin, r2)
    rnd = RankingRound(current=None, candidates=(top, runner), tied=(), discrimination=None,
                       chosen="rolling_resistance", reason="highest evidence")
    why = weak_choice(rnd)
    assert (why is not None) == weak
    if weak:
        assert "rolling resistance over cohesion" in why and f"{margin:.1f}" in why and f"{r2:.2f}" in why
    # a tie settled by a proposed measurement, or no choice at all, is not a weak choice of the data
    assert weak_choice(RankingRound(None, (top, runner), (), SimpleNamespace(), "rolling_resistance", "")) is None
    assert weak_choice(RankingRound(None, (top, runner), (), None, None, "")) is None


def test_an_effect_added_on_a_weak_choice_reads_met_on_a_weak_basis():
    """Two versions (base + the added effect), all within 2 sigma, a weak-choice caveat: amber, "Met on
    a weak basis" (not "Cannot tell", which is for data that cannot show whether an effect is missing)."""
    r = result(0.3)
    added = SimpleNamespace(**{**vars(r.base), "name": "base + rolling resistance"})
    why = "The choice of rolling resistance over cohesion rests on a margin of ln B 1.1"
    r = SimpleNamespace(**{**vars(r), "versions": [r.base, added], "final": added, "met": True, "caveats": [why]})
    verdict = _verdict(r)
    assert verdict.tone == "weak" and verdict.status_text == "Met on a weak basis" and verdict.caveats == [why]
    assert ">Met on a weak basis<" in Report("diagnosis", verdict).to_html()
