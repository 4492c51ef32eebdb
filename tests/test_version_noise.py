"""Which fill-to-fill noise a model version is judged with (validation.study.version_noise): the
base model's, unless the version's own replicates reject it by a two-sided F test. Cohesive gravel
scatters far more than the frictional base model; holding it to the base's scatter called its
confirmations "beyond 2 sigma" for noise it really has."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from validation import ForwardRunner, Misfit, diagnose, write_diagnosis
from validation.effects import ModelVersion
from validation.observables import Observations
from validation.study import NOISE_TEST_ALPHA, study_model, version_noise

sys.path.insert(0, str(Path(__file__).parent))
from test_diagnosis_logic import BASE, COHESION, FAST, KEYS, NOISE_SD, TRUTHS, AnalyticGranularModel, lab_observables  # noqa: E402,E501


def test_the_f_test_keeps_the_base_noise_unless_the_replicates_reject_it():
    # the paper-scale cohesion case (docs/results/lone_set_cohesion_pooled_h100_2026-11-27): own vs base
    sd, dof, source = version_noise([5.663, 18.36, 1.697, 3.834, 3.610, 5.925, 0.003], [5, 5, 9, 9, 9, 2, 3],
                                    [0.702, 19.29, 1.125, 0.808, 1.168, 0.0, 0.006], [5, 5, 5, 5, 5, 0, 5])
    assert source == ("own", "base", "base", "own", "base", "own", "base")
    np.testing.assert_allclose(sd, [5.663, 19.29, 1.125, 3.834, 1.168, 5.925, 0.006])
    np.testing.assert_allclose(dof, [5, 5, 5, 9, 5, 2, 5])
    # right at the edges of the acceptance region
    hi = np.sqrt(stats.f.isf(NOISE_TEST_ALPHA / 2, 6, 8))
    lo = np.sqrt(stats.f.ppf(NOISE_TEST_ALPHA / 2, 6, 8))
    _, _, source = version_noise([0.99 * hi, 1.01 * hi, 1.01 * lo, 0.99 * lo], [6] * 4, [1.0] * 4, [8] * 4)
    assert source == ("base", "own", "base", "own")
    # nothing to test against: the version's own replicates never varied, or the base's did not
    _, _, source = version_noise([2.0, 0.0], [0, 0], [0.0, 1.0], [0, 4])
    assert source == ("own", "base")


class ScatteringCohesion(AnalyticGranularModel):
    """The analytic model, but cohesion multiplies the static angle's fill-to-fill noise by 6."""

    def evaluate(self, effects, parameter_sets, replicates, keys):
        out = super().evaluate(effects, parameter_sets, replicates, keys)
        if "cohesion" in effects:
            j = keys.index("baffle/static_angle")
            out[:, :, j] += self.rng.normal(0.0, NOISE_SD["static_angle"] * np.sqrt(35.0), out[:, :, j].shape)
        return out


def test_a_version_that_scatters_more_is_judged_with_its_own_noise():
    obs = Observations(lab_observables(TRUTHS["cohesion"], ("cohesion",)))
    runner = ForwardRunner(ScatteringCohesion(5))
    base = study_model(ModelVersion(BASE), obs, runner, FAST, seed=1)
    assert set(base.noise_source) == {"own"}
    study = study_model(ModelVersion(BASE).with_effect(COHESION), obs, runner, FAST, seed=2,
                        noise=(base.noise_sd, base.noise_dof))
    j = KEYS.index("baffle/static_angle")
    assert study.noise_source[j] == "own" and study.noise_sd[j] > 3 * base.noise_sd[j]
    pile = KEYS.index("cylinder/pile_angle")  # the base model forms no pile: its replicates never varied
    assert base.noise_dof[pile] == 0 and study.noise_source[pile] == "own"
    assert all(s == "base" for k, s in zip(KEYS, study.noise_source) if k not in (KEYS[j], KEYS[pile]))
    assert study.to_dict()["dem_noise_source"] == list(study.noise_source)
    # the confirmation's z uses that noise (or, where its own fills scatter beyond it, their spread:
    # validation.study.local_noise; with this seed the static angle's first three fills did, 7.9 deg)
    c = study.confirmation
    assert study.misfit.dem_noise_sd[j] == study.noise_sd[j]
    local = np.array([s == "local" for s in c.noise_source])
    np.testing.assert_array_equal(c.noise_sd, np.where(local, c.spread, study.noise_sd))
    sim_sd = c.noise_sd / np.sqrt(c.n_ok)
    np.testing.assert_allclose(c.z, study.misfit.z(c.mean, sim_sd), rtol=1e-12)
    held_to_base = Misfit.build(obs, np.where(np.arange(len(KEYS)) == j, base.noise_sd, c.noise_sd))
    z_base = held_to_base.z(c.mean, held_to_base.dem_noise_sd / np.sqrt(c.n_ok))[j]
    assert abs(z_base) > 2 * abs(c.z[j]) > 0  # the base's noise would have called the same runs far off


def test_the_verdict_and_the_report_say_where_a_version_keeps_its_own_noise(tmp_path):
    obs = lab_observables(TRUTHS["cohesion"], ("cohesion",))
    result = diagnose(obs, BASE, [COHESION], ScatteringCohesion(1), FAST)
    said = [d for d in result.details if "scatters differently" in d]
    assert len(said) == 1 and "static angle A" in said[0] and "base + cohesion" in said[0]
    assert "pile angle" not in said[0]  # the base model formed no pile: nothing to differ from
    html = write_diagnosis(result, tmp_path / "diag")["report"].read_text()
    assert html.count("scatters differently from fill to fill") == 1  # in the surrogates and DEM noise section
