"""Designs that measure the DEM noise on a share of their sets (``diagnosis.replicated_fraction``):
which sets get the fills, how the forward runner serves per-set fill counts (one call for a model
that takes them, one per count otherwise), that the DEM forward model asks for exactly those
worlds, and that the diagnosis on the analytic model reaches the same verdicts with a third of the
sets replicated while running about a third fewer simulations."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_diagnosis_logic import BASE, COHESION, FAST, ROLLING, SHAPE, TRUTHS, AnalyticGranularModel, lab_observables  # noqa: E402

from validation.design import NoiseNotMeasurable, design_replicates, pooled_noise_sd  # noqa: E402
from validation.diagnose import diagnose  # noqa: E402
from validation.forward import ForwardRunner, replicate_counts  # noqa: E402
from validation.settings import DiagnosisSettings  # noqa: E402


def test_design_replicates_spreads_the_replicated_sets_and_keeps_a_minimum():
    assert design_replicates(12, 2) == (2,) * 12
    third = design_replicates(12, 2, 1 / 3)
    assert sum(c == 2 for c in third) == 4 and set(third) == {1, 2}
    assert third[0] == third[-1] == 2  # spread from the first set to the last
    assert sum(c == 2 for c in design_replicates(6, 2, 0.1)) == 3  # at least 3 sets measure the noise
    assert design_replicates(2, 3, 0.1) == (3, 3)  # fewer sets than the minimum: all
    assert sum(c == 2 for c in design_replicates(6, 2, 1 / 3, minimum=0)) == 2  # a refinement wave
    # evenly spread and fixed (the up-front call and the study must ask for the same worlds)
    assert design_replicates(24, 2, 0.25) == (2, 1, 1, 1, 1, 2, 1, 1, 1, 2, 1, 1, 1, 1, 2, 1, 1, 1, 2, 1, 1, 1, 1, 2)


def test_noise_without_replicated_sets_names_the_settings_to_change():
    Y = np.arange(12.0).reshape(6, 2, 1)
    Y[:, 1, :] = np.nan  # every set's second fill failed (or was never asked for)
    with pytest.raises(NoiseNotMeasurable, match="replicated_fraction"):
        pooled_noise_sd(Y, ("pile",))


def test_settings_and_counts_refuse_what_is_not_a_fraction_or_a_count():
    for bad in (0.0, 1.5, float("nan"), True):
        with pytest.raises(ValueError, match="replicated_fraction must be in"):
            DiagnosisSettings(replicated_fraction=bad)
    with pytest.raises(ValueError, match="replicates per set must be 3 integers >= 1"):
        replicate_counts([1, 0, 2], 3)
    with pytest.raises(ValueError, match="replicates per set must be 3 integers"):
        replicate_counts([1, 2], 3)
    assert replicate_counts(2, 3).tolist() == [2, 2, 2]


class _Recorder:
    """A forward model that answers set index + replicate / 10 and records its calls."""

    def __init__(self, per_set: bool):
        self.per_set_replicates = per_set
        self.calls = []

    def evaluate(self, effects, parameter_sets, replicates, keys):
        counts = replicate_counts(replicates, len(parameter_sets))
        self.calls.append(replicates)
        out = np.full((len(parameter_sets), int(counts.max()), len(keys)), np.nan)
        for i, (p, c) in enumerate(zip(parameter_sets, counts)):
            for r in range(c):
                out[i, r, :] = p["i"] + r / 10
        return out


@pytest.mark.parametrize("per_set", [True, False])
def test_runner_serves_per_set_counts_in_one_call_or_one_per_count(per_set):
    model = _Recorder(per_set)
    runner = ForwardRunner(model)
    sets = [{"i": float(i)} for i in range(4)]
    Y = runner((), sets, [2, 1, 1, 2], ("a",))
    assert Y.shape == (4, 2, 1)
    np.testing.assert_array_equal(Y[:, 0, 0], [0, 1, 2, 3])
    np.testing.assert_array_equal(Y[:, 1, 0], [0.1, np.nan, np.nan, 3.1])
    assert model.calls == ([(2, 1, 1, 2)] if per_set else [1, 2])
    assert runner.runs == 6 and runner.failed_runs == 0  # the empty second fills are not failures
    sd, dof = pooled_noise_sd(Y)
    assert dof.tolist() == [2.0]  # only the replicated sets measure the noise


def test_dem_forward_asks_for_exactly_the_worlds_of_each_count(tmp_path, monkeypatch):
    import warpdem as wd
    from calibration.model_description import ModelDescription
    from validation.dem_forward import DEMForwardModel, ObservableSpec

    spec = ObservableSpec("pile", "cylinder", "pile_angle", {})
    fm = DEMForwardModel(ModelDescription(wd.ContactLaw()), None, [], [spec], scale="quick", device="cpu",
                         cache=tmp_path / "c.jsonl")
    asked = []

    def fake_run(exp_name, settings, desc, parameter_sets, todo):
        for i, r, rpm, wid in todo:
            asked.append((i, r))
            fm._store({"id": wid, "experiment": exp_name, "status": "ok", "error": None,
                       "parameters": dict(parameter_sets[i]), "replicate": r, "rpm": rpm,
                       "observables": {"pile_angle": 10.0 * i + r}, "fill_index": len(asked)})

    monkeypatch.setattr(fm, "_run_worlds", fake_run)
    sets = [{"mu_s_pp": 0.2 + 0.1 * i, "mu_s_pw": 0.3} for i in range(3)]
    Y = fm.evaluate((), sets, (2, 1, 2), ("pile",))
    assert sorted(asked) == [(0, 0), (0, 1), (1, 0), (2, 0), (2, 1)]
    np.testing.assert_array_equal(Y[:, :, 0], [[0, 1], [10, np.nan], [20, 21]])
    asked.clear()
    np.testing.assert_array_equal(fm.evaluate((), sets, 2, ("pile",))[1], [[10], [11]])  # only (1, 1) is new
    assert asked == [(1, 1)]


@pytest.fixture(scope="module")
def third_replicated():
    """The hidden-rolling analytic lab diagnosed with every set replicated and with a third of them."""
    obs = lab_observables(TRUTHS["rolling_resistance"], ("rolling_resistance",))
    out = {}
    for fraction in (1.0, 1 / 3):
        settings = DiagnosisSettings(**{**FAST.to_dict(), "replicated_fraction": fraction})
        out[fraction] = diagnose(obs, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1), settings)
    return out


def test_a_third_replicated_reaches_the_same_verdict_with_fewer_runs(third_replicated):
    full, third = third_replicated[1.0], third_replicated[1 / 3]
    for r in (full, third):
        assert not r.base_adequate and "cannot reproduce" in r.headline
        assert r.rounds[0].top.name == "rolling_resistance" and r.added_effects == ("rolling_resistance",)
        final = r.history.versions[-1]
        assert final.n_within == final.n_observables and r.met
    runs = {f: r.forward["runs"] for f, r in third_replicated.items()}
    assert runs[1 / 3] < 0.8 * runs[1.0], runs
    # the noise is measured on fewer degrees of freedom (the base model's pile angle, "no pile" in most
    # of the box, may have none: it then counts as a clipped, one-sided observable, as it does here with
    # every set replicated too)
    assert np.all(third.base.noise_dof <= full.base.noise_dof) and third.base.noise_dof.sum() < full.base.noise_dof.sum()
    assert np.count_nonzero(third.base.noise_dof) >= len(third.base.noise_dof) - 1


@pytest.mark.parametrize("case", ["base", "rolling_resistance", "cohesion", "shape"])
def test_the_twenty_minute_settings_keep_every_verdict(case):
    """The settings of the H100 lone-set timing (``design_points_per_parameter`` 4, a third of the
    sets replicated): on the analytic model every hidden-effect case is still found and fitted,
    and the base truth still needs nothing, with at most two thirds of the runs."""
    truth, effects = ({"mu_s_pp": 0.5, "mu_s_pw": 0.4}, ()) if case == "base" else (TRUTHS[case], (case,))
    obs = lab_observables(truth, effects)
    fast = DiagnosisSettings(**{**FAST.to_dict(), "design_points_per_parameter": 4, "replicated_fraction": 0.34})
    full = DiagnosisSettings(**{**FAST.to_dict(), "design_points_per_parameter": 6})
    r = diagnose(obs, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1), fast)
    if case == "base":
        assert r.base_adequate and r.added_effects == () and r.met
        return
    assert not r.base_adequate and r.rounds[0].top.name == case and r.added_effects == (case,)
    final = r.history.versions[-1]
    assert final.n_within == final.n_observables and r.met
    reference = diagnose(obs, BASE, [ROLLING, COHESION, SHAPE], AnalyticGranularModel(1), full)
    assert r.forward["runs"] <= 2 / 3 * reference.forward["runs"], (r.forward["runs"], reference.forward["runs"])
