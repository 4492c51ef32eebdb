"""The diagnosis logic (validation/) on a cheap analytic forward model of known structure.

The model imitates the granular experiments with two sliding frictions (x = mu_s_pp, w = mu_s_pw)
and three candidate effects of distinct signature (r = mu_r / 0.2, c = cohesion / 5 kJ/m3,
s = aspect_ratio - 1, each in [0, 1]); sat(x) = 1 - exp(-3x):

    static angle A (deg)       = 18 + 8 sat + 2 w + 14 r + 8 c + 10 s
    drum angle at w rpm (deg)  = 26 + 5 sat + 1.5 w + 0.08 w_rpm + 10 r + 6 c (15 / w_rpm) + s (4 + 0.15 w_rpm)
    pile angle C (deg)         = max(0, 30 r + 18 c + 24 s - 5 + 8 x (r + c + s))   (0: no pile formed)
    bulk density (kg/m3)       = 1650 - 40 sat - 15 w - 60 r - 150 c + 40 s

Rolling resistance shifts the drum angle evenly, cohesion most at low speed, shape most at high
speed; cohesion and rolling lower the density, shape raises it; without any effect no pile forms.
Every run adds Gaussian fill-to-fill noise (0.5 deg angles, 0.8 deg pile, 6 kg/m3 density).  The
"lab" is the same model with a hidden effect and its own noise seed; the diagnosis sees only the
measured repeats.  In the tie variant "shape" acts exactly like rolling resistance at 15-45 rpm
and differs only above 45 rpm (drum at 60 rpm).
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from calibration.designs import Parameter, ParameterSpace
from validation import (CandidateEffect, DiagnosisSettings, EffectParameter, ErrorHistory, ForwardModel,
                        ForwardRunner, Misfit, Observable, Observations, ProposedMeasurement, diagnose, discriminate,
                        estimate_log_evidence, minimal_conflicts, pooled_noise_sd, write_diagnosis)
from validation.diagnose import RankingRound, _break_tie
from validation.ranking import CandidateResult
from validation.search import evaluate_points

NOISE_SD = {"static_angle": 0.5, "dynamic_angle": 0.5, "pile_angle": 0.8, "bulk_density": 6.0}
KEYS = ("baffle/static_angle", "drum/15rpm/dynamic_angle", "drum/30rpm/dynamic_angle", "drum/45rpm/dynamic_angle",
        "cylinder/pile_angle", "baffle/bulk_density")
LABELS = {"baffle/static_angle": "static angle A", "baffle/bulk_density": "bulk density",
          "cylinder/pile_angle": "pile angle C"}


class AnalyticGranularModel(ForwardModel):
    """The analytic model of the module docstring (``shape_like_rolling``: the tie variant)."""

    def __init__(self, seed: int = 0, shape_like_rolling: bool = False, proposals=()):
        self.rng = np.random.default_rng(seed)
        self.shape_like_rolling = shape_like_rolling
        self._proposals = tuple(proposals)

    def proposals(self):
        return self._proposals

    def mean(self, key: str, p: dict, effects: tuple) -> float:
        x, w = p["mu_s_pp"], p["mu_s_pw"]
        r = p["mu_r"] / 0.2 if "rolling_resistance" in effects else 0.0
        c = p["cohesion_energy_density"] / 5.0 if "cohesion" in effects else 0.0
        s = p["aspect_ratio"] - 1.0 if "shape" in effects else 0.0
        m = re.match(r"drum/(\d+)rpm/dynamic_angle$", key)
        rpm = float(m.group(1)) if m else 0.0
        extra = 0.0
        if self.shape_like_rolling:  # shape == rolling below 45 rpm, plus 0.5 deg/rpm above
            r, extra, s, c = r + s, 0.5 * s * max(0.0, rpm - 45.0), 0.0, 0.0
        sat = 1.0 - math.exp(-3.0 * x)
        if key == "baffle/static_angle":
            return 18 + 8 * sat + 2 * w + 14 * r + 8 * c + 10 * s
        if key == "baffle/bulk_density":
            return 1650 - 40 * sat - 15 * w - 60 * r - 150 * c + 40 * s
        if key == "cylinder/pile_angle":
            return 30 * r + 18 * c + 24 * s - 5 + 8 * x * (r + c + s)
        if m:
            return 26 + 5 * sat + 1.5 * w + 0.08 * rpm + 10 * r + 6 * c * (15 / rpm) + s * (4 + 0.15 * rpm) + extra
        raise KeyError(f"analytic model cannot simulate {key!r}")

    def evaluate(self, effects, parameter_sets, replicates, keys):
        out = np.empty((len(parameter_sets), replicates, len(keys)))
        for i, p in enumerate(parameter_sets):
            for j, k in enumerate(keys):
                q = k.rsplit("/", 1)[1]
                v = self.mean(k, p, effects) + self.rng.normal(0.0, NOISE_SD[q], replicates)
                out[i, :, j] = np.maximum(v, 0.0) if q == "pile_angle" else v
        return out


BASE = ParameterSpace((Parameter("mu_s_pp", 0.1, 0.9), Parameter("mu_s_pw", 0.1, 0.9)))
ROLLING = CandidateEffect("rolling_resistance", (EffectParameter("mu_r", "-", 0.0, 0.2, 0.0),), "rolling resistance")
COHESION = CandidateEffect("cohesion", (EffectParameter("cohesion_energy_density", "kJ/m3", 0.0, 5.0, 0.0),),
                           "cohesion")
SHAPE = CandidateEffect("shape", (EffectParameter("aspect_ratio", "-", 1.0, 2.0, 1.0),), "particle shape")
# the analytic "lab" below is the model itself (no model error): model_discrepancy "none"
FAST = DiagnosisSettings(design_points_per_parameter=8, min_design_points=12, replicates=2, scan_points=4096,
                         evidence_samples=4096, refine_points=6, gp_restarts=1, model_discrepancy="none")
DRUM_60 = ProposedMeasurement("drum/60rpm/dynamic_angle", "drum", "dynamic_angle", "deg", {"rpm": 60},
                              "drum angle at 60 rpm")
DRUM_10 = ProposedMeasurement("drum/10rpm/dynamic_angle", "drum", "dynamic_angle", "deg", {"rpm": 10},
                              "drum angle at 10 rpm")


def lab_observables(truth: dict, effects: tuple, seed: int = 123, repeats: int = 3, **model_kwargs) -> list[Observable]:
    """Measured repeats from the model with hidden ``effects`` at ``truth``; piles below 3 deg are "no pile"."""
    Y = AnalyticGranularModel(seed, **model_kwargs).evaluate(tuple(effects), [truth], repeats, KEYS)[0]
    obs = []
    for j, key in enumerate(KEYS):
        experiment, *rest = key.split("/")
        quantity = rest[-1]
        unit = "kg/m3" if quantity == "bulk_density" else "deg"
        condition = {"rpm": float(rest[0][:-3])} if experiment == "drum" else {}
        label = LABELS.get(key, f"drum angle at {rest[0][:-3]} rpm")
        if quantity == "pile_angle" and np.all(Y[:, j] < 3.0):
            obs.append(Observable.below_detection(key, experiment, quantity, unit, repeats, 3.0, condition, label,
                                                  resolution=0.5))
        else:
            obs.append(Observable(key, experiment, quantity, unit, tuple(Y[:, j]), condition, label))
    return obs


TRUTHS = {
    "rolling_resistance": {"mu_s_pp": 0.45, "mu_s_pw": 0.5, "mu_r": 0.12},
    "cohesion": {"mu_s_pp": 0.5, "mu_s_pw": 0.4, "cohesion_energy_density": 2.0},
    "shape": {"mu_s_pp": 0.5, "mu_s_pw": 0.4, "aspect_ratio": 1.5},
}
HIDDEN_VALUE = {"rolling_resistance": ("mu_r", 0.12, 0.02), "cohesion": ("cohesion_energy_density", 2.0, 0.4),
                "shape": ("aspect_ratio", 1.5, 0.1)}


@pytest.fixture(scope="module")
def base_truth():
    obs = lab_observables({"mu_s_pp": 0.5, "mu_s_pw": 0.4}, ())
    return diagnose(obs, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1), FAST)


@pytest.fixture(scope="module")
def hidden():
    """Diagnoses of the three hidden-effect labs, by effect name."""
    return {name: diagnose(lab_observables(truth, (name,)), BASE, [ROLLING, COHESION, SHAPE],
                           AnalyticGranularModel(1), FAST) for name, truth in TRUTHS.items()}


@pytest.fixture(scope="module")
def tie():
    obs = lab_observables(TRUTHS["rolling_resistance"], ("rolling_resistance",), shape_like_rolling=True)
    model = AnalyticGranularModel(1, shape_like_rolling=True, proposals=(DRUM_10, DRUM_60))
    return diagnose(obs, BASE, [ROLLING, SHAPE], model, FAST)


# ----------------------------------------------------------------------------- statistics by hand
def test_misfit_combines_the_three_variances_and_censoring_is_one_sided():
    obs = Observations([Observable("a", "drum", "angle", "deg", (40.0, 41.0, 42.0)),
                        Observable.below_detection("p", "cylinder", "pile_angle", "deg", 3, 3.0, resolution=0.5)])
    m = Misfit.build(obs, np.array([0.6, 0.4]))
    se2 = (1.0 / math.sqrt(3)) ** 2
    var_a = se2 + 0.6 ** 2 / 3 + 0.2 ** 2
    z = m.z(np.array([39.0, 2.0]), np.array([0.2, 0.1]))
    assert z[0] == pytest.approx((41.0 - 39.0) / math.sqrt(var_a), rel=1e-12)
    assert z[1] == 0.0  # predicted 2 deg < limit 3 deg: consistent with "no pile"
    z = m.z(np.array([41.0, 7.0]), np.array([0.0, 0.1]))
    assert z[1] == pytest.approx(-(7.0 - 3.0) / math.sqrt(0.5 ** 2 + 0.4 ** 2 / 3 + 0.1 ** 2), rel=1e-12)
    # Student t with Welch-Satterthwaite dof for the estimated SE (2 dof; DEM noise known here), normal for the
    # censored one (its sigma is a resolution: known)
    nu = (se2 + 0.6 ** 2 / 3) ** 2 / (se2 ** 2 / 2)
    assert m.dof[0] == pytest.approx(nu) and m.dof[1] == np.inf
    ll = m.log_likelihood(np.array([41.0, 7.0]), np.array([0.0, 0.1]))
    sd = np.sqrt(m.variance(np.array([0.0, 0.1])))
    want = stats.t.logpdf(0.0, nu, scale=sd[0]) + stats.norm.logpdf(3.0 - 7.0, scale=sd[1])
    assert ll == pytest.approx(want, rel=1e-10)


def test_pooled_noise_is_the_pooled_standard_deviation():
    Y = np.array([[[1.0], [3.0]], [[10.0], [14.0]], [[5.0], [np.nan]]])  # third set: one run failed
    sd, dof = pooled_noise_sd(Y, ["k"])
    assert dof[0] == 2 and sd[0] == pytest.approx(math.sqrt((2.0 + 8.0) / 2.0))
    with pytest.raises(ValueError, match="replicates >= 2"):
        pooled_noise_sd(np.ones((4, 1, 1)), ["k"])


def test_evidence_of_a_normalised_gaussian_is_one():
    mu, sd = np.array([0.4, 0.6, 0.5]), np.array([0.03, 0.05, 0.02])

    def log_l(U):
        return -0.5 * np.sum(((U - mu) / sd) ** 2 + np.log(2 * np.pi * sd ** 2), axis=1)

    ev = estimate_log_evidence(log_l, mu + 0.01, 4096, seed=3)
    assert abs(ev.log_evidence) < 3 * ev.standard_error + 0.02  # integral over the cube = 1
    flat = estimate_log_evidence(lambda U: np.zeros(len(U)), mu, 1024, seed=3)
    assert flat.log_evidence == pytest.approx(0.0, abs=0.02)


def test_minimal_conflicts_finds_pairs_and_unreachable_observables():
    P = np.array([[1, 0, 1, 0], [0, 1, 1, 0], [1, 0, 0, 0]], bool)  # col 3 never plausible; 0 and 1 never together
    assert minimal_conflicts(P, 3) == [(3,), (0, 1)]


# ----------------------------------------------------------------------------- the branches
def test_adequate_base_truth_needs_no_effect_and_its_plausible_set_holds_the_truth(base_truth):
    r = base_truth
    assert r.base_adequate and r.met and r.rounds == [] and len(r.versions) == 1
    assert r.headline.startswith("No effect is needed")
    a = r.base.adequacy
    for name, value in (("mu_s_pp", 0.5), ("mu_s_pw", 0.4)):
        lo, hi = a.plausible_ranges[name]
        assert lo <= value <= hi, (name, lo, hi)
    # the truth itself is non-implausible on the surrogates, and the data rule out part of the box
    u = BASE.to_unit(np.array([0.5, 0.4]))
    p = evaluate_points(u[None], r.base.surrogates, r.base.misfit)
    assert p.max_implausibility[0] <= 3.0
    assert a.plausible_fraction < 0.9
    # the DEM confirmation at the best fit agrees with every measurement
    assert np.nanmax(np.abs(r.base.confirmation.z)) <= 2.0


@pytest.mark.parametrize("effect", ["rolling_resistance", "cohesion", "shape"])
def test_hidden_effect_is_flagged_ranked_first_and_fixes_every_observable(hidden, effect):
    r = hidden[effect]
    assert not r.base_adequate and "cannot reproduce" in r.headline
    a = r.base.adequacy
    named = {k for c in a.unreachable + a.conflicts for k in c.keys}
    assert named, "the conflicting observables must be named"
    assert a.min_max_implausibility > 3.0 and a.chi2_per_dof > 5.0
    rnd = r.rounds[0]
    assert rnd.top.name == effect, [(c.name, c.log_evidence) for c in rnd.candidates]
    assert rnd.candidates[0].log_evidence - rnd.candidates[1].log_evidence > math.log(20.0)  # "strong" or more
    assert rnd.chosen == effect and r.added_effects == (effect,)
    # after adding it, every observable is within 2 sigma (DEM confirmation at the recalibrated fit)
    final = r.history.versions[-1]
    assert final.n_within == final.n_observables == 6 and final.max_abs_z <= 2.0
    assert r.met
    assert f"brings all 6 observables within 2 sigma" in rnd.top.sentence
    name, value, tol = HIDDEN_VALUE[effect]
    assert abs(r.final.best_parameters[name] - value) <= tol


def test_conflict_names_the_pile_and_signatures_point_at_the_data(hidden):
    r = hidden["rolling_resistance"]
    a = r.base.adequacy
    assert "cylinder/pile_angle" in {k for c in a.unreachable for k in c.keys}
    assert "pile angle C" in a.sentence
    by_name = {c.name: c for c in r.rounds[0].candidates}
    # rolling resistance moves every observable the way the base model misses it
    assert by_name["rolling_resistance"].signature.alignment > 0.9
    j = r.observations.index("baffle/bulk_density")
    resid = r.base.confirmation.z[j]
    assert resid < 0  # base model's bed too dense
    assert by_name["shape"].signature.full[j] > 0 and by_name["rolling_resistance"].signature.full[j] < 0
    assert "bulk density" in by_name["shape"].sentence and "sigma off" in by_name["shape"].sentence


def test_error_history_falls_and_round_trips(hidden, tmp_path):
    h = hidden["rolling_resistance"].history
    assert [v.version for v in h.versions] == ["base", "base + rolling resistance"]
    before, after = h.versions
    assert before.chi2_per_observable > 100 * after.chi2_per_observable
    assert after.max_abs_z < 2.0 < before.max_abs_z
    assert before.chi2_per_dof is not None and after.dof == 3
    back = ErrorHistory.read(h.write(tmp_path / "h.json"))
    assert back.to_dict() == h.to_dict()


def test_tie_names_the_condition_that_separates(tie):
    rnd = tie.rounds[0]
    assert set(rnd.tied) == {"rolling_resistance", "shape"}
    gap = abs(rnd.candidates[0].log_evidence - rnd.candidates[1].log_evidence)
    assert gap < math.log(3.0)
    d = rnd.discrimination
    assert d is not None and d.recommended == "drum/60rpm/dynamic_angle"
    by_key = {f.proposal.key: f for f in d.forecasts}
    assert by_key["drum/60rpm/dynamic_angle"].separation > 3.0
    assert by_key["drum/10rpm/dynamic_angle"].separation < 1.0
    # shape predicts the steeper drum at 60 rpm (0.5 deg/rpm above 45 rpm times its strength)
    f = by_key["drum/60rpm/dynamic_angle"]
    assert f.means["shape"] - f.means["rolling_resistance"] > 2.0
    assert "drum angle at 60 rpm" in tie.next_steps[0] and "provisionally" in rnd.reason
    assert "provisional: particle shape fits as well" in tie.headline and "drum angle at 60 rpm" in tie.headline


def _tied_candidate(name: str, log_bayes: float, z_dem) -> SimpleNamespace:
    """What the tie-break reads of a CandidateResult: name, words, evidence and DEM residuals."""
    dem_chi2 = CandidateResult.dem_chi2.fget(SimpleNamespace(z=np.asarray(z_dem, dtype=float)))  # the real rule
    return SimpleNamespace(name=name, effect=SimpleNamespace(words=name.replace("_", " ")), log_bayes=log_bayes,
                           log_evidence=log_bayes, dem_chi2=dem_chi2)


@pytest.mark.parametrize("dem_gap, expected", [(45.0, "cohesion"), (1.5, "rolling_resistance")])
def test_a_tie_is_broken_by_the_dem_at_the_best_fits_only_when_it_separates(dem_gap, expected):
    """The paper-scale cohesion lab at the 20-minute settings (2026-11-27, H100): rolling resistance
    ln B +16.7 and cohesion +16.4 tie, but the DEM at the best fits gives chi^2 53.2 and 8.4. A DEM
    gap above 2 ln 3 picks the closer candidate; a smaller one leaves the evidence's order."""
    top = _tied_candidate("rolling_resistance", 16.7, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, math.sqrt(8.4 + dem_gap)])
    closer = _tied_candidate("cohesion", 16.4, [0.0, 0.0, 0.0, 0.0, 0.0, math.sqrt(8.4), np.nan])
    rnd = RankingRound(None, (top, closer), ("rolling_resistance", "cohesion"), None, None, "")
    chosen, reason = _break_tie(rnd, math.log(3.0))
    assert chosen == expected
    assert "provisionally" in reason and "DEM chi2 8.4" in reason
    if expected == "cohesion":
        assert "clearly closest" in reason
    else:
        assert "highest evidence" in reason


def test_data_cannot_separate_is_said_not_guessed(tie):
    rnd = tie.rounds[0]
    studies = {c.name: c.study for c in rnd.candidates}
    words = {c.name: c.effect.words for c in rnd.candidates}
    runner = ForwardRunner(AnalyticGranularModel(7, shape_like_rolling=True))
    static = ProposedMeasurement("baffle/static_angle", "baffle", "static_angle", "deg", label="static angle A again")
    d = discriminate(studies, words, [DRUM_10, static], runner, threshold=2.0)
    assert d.recommended is None and "cannot separate" in d.sentence
    assert max(f.separation for f in d.forecasts) < 2.0
    d0 = discriminate(studies, words, [], runner)
    assert d0.recommended is None and "no further condition" in d0.sentence


class _TwoTargets(ForwardModel):
    """One parameter a in [0, 1]; observables 'first' and 'second' both equal 10 a; 'third' is 5.
    An optional do-nothing effect adds a parameter that changes nothing."""

    def __init__(self):
        self.rng = np.random.default_rng(0)

    def evaluate(self, effects, parameter_sets, replicates, keys):
        out = np.empty((len(parameter_sets), replicates, len(keys)))
        for i, p in enumerate(parameter_sets):
            mean = {"t/first": 10 * p["a"], "t/second": 10 * p["a"], "t/third": 5.0}
            for j, k in enumerate(keys):
                out[i, :, j] = mean[k] + self.rng.normal(0, 0.1, replicates)
        return out


def test_pair_conflict_and_no_candidate_helps():
    obs = [Observable("t/first", "t", "first", "-", (2.0, 2.1, 1.9)),
           Observable("t/second", "t", "second", "-", (8.0, 8.1, 7.9)),
           Observable("t/third", "t", "third", "-", (5.0, 5.1, 4.9))]
    useless = CandidateEffect("useless", (EffectParameter("b", "-", 0.0, 1.0, 0.0),))
    r = diagnose(obs, ParameterSpace((Parameter("a", 0.0, 1.0),)), [useless], _TwoTargets(),
                 DiagnosisSettings(min_design_points=10, scan_points=1024, evidence_samples=2048, gp_restarts=0))
    a = r.base.adequacy
    assert not a.adequate and a.unreachable == ()
    assert [c.keys for c in a.conflicts] == [("t/first", "t/second")]
    assert "gives both the t/first and t/second" in a.conflicts[0].sentence
    assert r.rounds[0].chosen is None and "not among the candidates" in r.rounds[0].reason
    assert len(r.versions) == 1 and not r.met and "none of the candidate effects" in r.headline
    assert abs(r.rounds[0].top.log_bayes) < math.log(3.0)  # a parameter that does nothing costs nothing


# ----------------------------------------------------------------------------- bad input
def test_bad_input_names_the_problem():
    with pytest.raises(ValueError, match="pile formed only sometimes"):
        Observable("c/pile", "c", "pile_angle", "deg", (20.0,), n_below_detection=2, detection_limit=3.0)
    with pytest.raises(ValueError, match="one repeat gives no standard error"):
        Observable("a", "b", "c", "deg", (20.0,))
    with pytest.raises(ValueError, match="finite"):
        Observable("a", "b", "c", "deg", (20.0, float("nan")))
    with pytest.raises(ValueError, match="duplicated"):
        Observations([Observable("a", "b", "c", "deg", (1.0, 2.0))] * 2)
    with pytest.raises(ValueError, match="reference"):
        EffectParameter("mu_r", "-", 0.0, 0.2, 0.5)
    with pytest.raises(ValueError, match="already a parameter of the base model"):
        diagnose(lab_observables({"mu_s_pp": 0.5, "mu_s_pw": 0.4}, ()), BASE,
                 [CandidateEffect("bad", (EffectParameter("mu_s_pp", "-", 0, 1, 0),))], AnalyticGranularModel(), FAST)
    with pytest.raises(ValueError, match="not candidates"):
        diagnose(lab_observables({"mu_s_pp": 0.5, "mu_s_pw": 0.4}, ()), BASE, [ROLLING], AnalyticGranularModel(),
                 DiagnosisSettings(add=("cohesion",)))
    with pytest.raises(ValueError, match="replicates must be an integer >= 2"):
        DiagnosisSettings(replicates=1)

    class WrongShape(AnalyticGranularModel):
        def evaluate(self, effects, parameter_sets, replicates, keys):
            return np.zeros((len(parameter_sets), len(keys)))

    with pytest.raises(ValueError, match=r"returned shape .* expected \(n_sets, replicates, n_keys\)"):
        ForwardRunner(WrongShape())((), [{"mu_s_pp": 0.5, "mu_s_pw": 0.5}], 2, KEYS)
    zero = [Observable.below_detection("cylinder/pile_angle", "cylinder", "pile_angle", "deg", 3, 3.0)]
    with pytest.raises(ValueError, match="zero measurement error and zero DEM noise"):
        Misfit.build(Observations(zero), np.zeros(1))


# ----------------------------------------------------------------------------- output
def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome"):
        if shutil.which(name):
            return shutil.which(name)
    return None


def test_write_json_figures_and_report(tie, tmp_path):
    paths = write_diagnosis(tie, tmp_path / "diag")
    for name in ("json", "error_history_json", "comparison", "residuals", "signatures", "discrimination",
                 "error_history", "report"):
        assert paths[name].is_file() and paths[name].stat().st_size > 0, name
    data = json.loads(paths["json"].read_text())  # strict JSON: no NaN
    assert data["verdict"]["added_effects"] == ["rolling_resistance"]
    assert data["rounds"][0]["discrimination"]["recommended"] == "drum/60rpm/dynamic_angle"
    assert len(data["versions"][0]["design"]["parameter_sets"]) == 16
    html = paths["report"].read_text()
    assert "noise of</th>" in html and html.count("<td>base model&#x27;s</td>") + html.count("<td>base model's</td>") > 0
    assert data["versions"][1]["dem_noise_source"].count("base") > 0  # the added version kept the base's noise
    n_png = sum(1 for k in paths if k not in ("json", "error_history_json", "report"))
    assert html.count('src="data:image/png;base64,') == n_png
    assert html.index('id="verdict"') < html.index("Comparison at the best fit") < html.index("What to measure next") \
        < html.index("Error history") < html.index('id="next"')
    binary = _chromium()
    if binary is None:
        pytest.skip("no Chromium/Chrome binary on PATH (apt-get install chromium): report not rendered")
    shot = tmp_path / "report.png"
    cmd = [binary, "--headless", "--disable-gpu", "--hide-scrollbars", f"--screenshot={shot}",
           "--window-size=1200,2000", paths["report"].resolve().as_uri()]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        cmd.insert(1, "--no-sandbox")
    subprocess.run(cmd, capture_output=True, timeout=120)
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)[..., :3]
    assert float(img.std()) > 0.05, "report screenshot is blank"
    keep = os.environ.get("WARPDEM_KEEP_SCREENSHOTS")
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
        shutil.copy(shot, Path(keep) / "diagnosis_report_screenshot.png")
