"""The recalibration's history-matching waves (validation.study.refine_study) on analytic models.

Two base parameters a, b in [0, 1] and one effect parameter c in [0, 1] ("bump"); every run adds
Gaussian noise (sd 0.2) seeded by the world itself (parameters, replicate, key), so a world run
twice gives the same value, as the DEM cache does:

    t/one = 10 a,   t/two = 10 b,   t/three = 10 c + 6 exp(-|(a, b) - (0.4, 0.6)|^2 / (2 0.1^2))

The lab is the model at a = 0.4, b = 0.6, c = 0.3.  The narrow bump sits exactly where t/one and
t/two pin (a, b), and a small design (15 sets) never lands in it: the first surrogate of t/three
is 10 c, its best fit puts c near 0.6-0.9, and the DEM there is 6 higher.  Only DEM runs near the
optimum teach the surrogate the bump.  ``DriftingModel`` adds 5 to t/three at every call: no
surrogate predicts its next run, so the waves must stop at their limit.
"""
from __future__ import annotations

import hashlib
import json
import math
import threading
from pathlib import Path

import numpy as np
import pytest

from calibration.designs import Parameter, ParameterSpace
from validation import CandidateEffect, DiagnosisSettings, EffectParameter, ForwardModel, ForwardRunner, Observable
from validation import diagnose, write_diagnosis
from validation.design import evaluate_sets
from validation.pooled import PooledForward, run_as_workers
from validation.study import _maximin_subset, study_model

KEYS = ("t/one", "t/two", "t/three")
SPACE = ParameterSpace((Parameter("a", 0.0, 1.0), Parameter("b", 0.0, 1.0)))
BUMP = CandidateEffect("bump", (EffectParameter("c", "-", 0.0, 1.0, 0.0),), "the bump effect")
TRUTH = {"a": 0.4, "b": 0.6, "c": 0.3}
SETTINGS = dict(design_points_per_parameter=5, min_design_points=8, replicates=2, scan_points=4096,
                evidence_samples=2048, refine_points=4, gp_restarts=1, add=("bump",), model_discrepancy="none")


class BumpModel(ForwardModel):
    """The model of the module docstring (bump centre and width as arguments)."""

    def __init__(self, centre=(0.4, 0.6), width: float = 0.1, height: float = 6.0):
        self.centre, self.width, self.height = centre, width, height
        self.calls = 0
        self.threads: set[str] = set()

    def mean(self, key: str, p: dict, effects: tuple) -> float:
        a, b = p["a"], p["b"]
        c = p["c"] if "bump" in effects else 0.0
        if key == "t/one":
            return 10 * a
        if key == "t/two":
            return 10 * b
        d2 = (a - self.centre[0]) ** 2 + (b - self.centre[1]) ** 2
        return 10 * c + self.height * math.exp(-d2 / (2 * self.width ** 2))

    def evaluate(self, effects, parameter_sets, replicates, keys):
        self.calls += 1
        self.threads.add(threading.current_thread().name)
        out = np.empty((len(parameter_sets), replicates, len(keys)))
        for i, p in enumerate(parameter_sets):
            world = sorted((n, round(float(v), 12)) for n, v in p.items())
            for r in range(replicates):
                for j, k in enumerate(keys):
                    h = hashlib.sha1(json.dumps([world, r, k]).encode()).hexdigest()
                    noise = np.random.default_rng(int(h[:8], 16)).normal(0.0, 0.2)
                    out[i, r, j] = self.mean(k, p, tuple(effects)) + noise
        return out


class DriftingModel(BumpModel):
    """t/three rises by 5 at every call: the DEM at a best fit never matches what the design showed."""

    def mean(self, key, p, effects):
        return super().mean(key, p, effects) + (5.0 * self.calls if key == "t/three" else 0.0)


def lab(model: BumpModel, truth: dict = TRUTH) -> list[Observable]:
    """Three repeats per observable at ``truth`` (mean exact, spread 0.2)."""
    out = []
    for k in KEYS:
        m = model.mean(k, truth, ("bump",))
        out.append(Observable(k, "t", k[2:], "-", (m - 0.2, m, m + 0.2)))
    return out


def run(max_refine_waves: int, model: BumpModel | None = None, **extra):
    model = model or BumpModel()
    settings = DiagnosisSettings(**{**SETTINGS, **extra}, max_refine_waves=max_refine_waves)
    return diagnose(lab(BumpModel()), SPACE, [BUMP], model, settings)


@pytest.fixture(scope="module")
def one_wave():
    return run(1)


@pytest.fixture(scope="module")
def looped():
    return run(3)


def test_the_loop_brings_every_observable_within_2_sigma_where_one_wave_leaves_one_far_off(one_wave, looped):
    # one wave (the diagnosis before the loop): the surrogate misses the bump at its best fit
    old = one_wave.history.versions[-1]
    assert old.max_abs_z > 5.0 and old.n_within < old.n_observables
    assert [w.check.disagreeing for w in one_wave.final.refinement] == [("t/three",)]
    # the loop: another wave with the confirmations joined, and the DEM agrees with the surrogate
    new = looped.history.versions[-1]
    assert new.n_within == new.n_observables == 3 and new.max_abs_z <= 2.0 and looped.met
    waves = looped.final.refinement
    assert len(waves) >= 2 and not waves[0].check.agrees and waves[-1].check.agrees
    assert looped.final.waves == 1 + len(waves)
    assert abs(looped.final.best_parameters["c"] - TRUTH["c"]) < 0.1
    assert "still disagrees" not in looped.headline and "every observable lies within 2 sigma" in looped.headline
    # every wave is in the JSON
    d = looped.to_dict()
    rec = d["versions"][-1]["refinement"]
    assert [w["wave"] for w in rec] == [w.wave for w in waves] and rec[0]["disagreeing"] == ["t/three"]
    assert rec[-1]["agrees"] and rec[-1]["max_abs_z_dem"] <= 2.0 and rec[1]["confirmation_sets"] == 2
    assert d["versions"][-1]["surrogate_check"]["agrees"]


def test_confirmation_runs_join_the_design(looped):
    final, cand = looped.final, looped.rounds[0].candidates[0].study
    X, Y = final.design.X, final.design.Y
    # the candidate's confirmation and the first wave's (at its best fit) are design sets of the last wave
    first_wave_best = np.array([looped.final.refinement[0].best_parameters[n]
                                for n in final.version.space.names])
    runner = ForwardRunner(BumpModel())
    for x in (cand.confirmation.x, first_wave_best):
        rows = np.flatnonzero(np.all(np.isclose(X, x, rtol=0, atol=1e-12), axis=1))
        assert len(rows) == 1, x
        fresh = runner(final.version.effect_names, [final.version.space.as_dict(x)], 3, KEYS)[0]
        np.testing.assert_allclose(Y[rows[0], :3], fresh, rtol=0, atol=1e-12)
        assert np.all(np.isnan(Y[rows[0], 3:]))
    assert len(X) == len(cand.design.X) + sum(w.new_sets + w.confirmation_sets for w in final.refinement)


def test_one_wave_reproduces_the_single_recalibration_wave(one_wave):
    """max_refine_waves = 1: exactly the wave of the diagnosis before the loop (written out here)."""
    settings = one_wave.settings
    cand = one_wave.rounds[0].candidates[0].study
    runner = ForwardRunner(BumpModel())
    mi = cand.scan.max_implausibility
    pool = cand.scan.U[mi <= settings.cutoff]
    if len(pool) < settings.refine_points:
        pool = cand.scan.U[np.argsort(mi)[:max(settings.refine_points * 4, len(mi) // 50)]]
    U_new = _maximin_subset(pool, settings.refine_points, cand.version.space.to_unit(cand.design.X))
    new = evaluate_sets(cand.version, runner, KEYS, cand.version.space.from_unit(U_new), settings.replicates)
    base = one_wave.base
    want = study_model(cand.version, one_wave.observations, runner, settings, settings.seed + 1500,
                       cand.design.extended(new), waves=2, noise=(base.noise_sd, base.noise_dof))
    got = one_wave.final
    assert got.waves == 2 and len(got.refinement) == 1
    np.testing.assert_array_equal(got.design.X, want.design.X)
    np.testing.assert_array_equal(got.design.Y, want.design.Y)
    np.testing.assert_allclose(got.best.x, want.best.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.confirmation.mean, want.confirmation.mean, rtol=0, atol=1e-12)
    # max_refine_waves = 0 is the same single wave
    zero = run(0)
    np.testing.assert_array_equal(zero.final.design.X, got.design.X)
    assert _without_seconds(zero.to_dict()["versions"]) == _without_seconds(one_wave.to_dict()["versions"])


def _without_seconds(x):
    """Every number but wall times, floats to 10 significant digits: studies that run beside each
    other in threads may sum in another order in BLAS (differences of 1e-16, seen in the implausibility)."""
    if isinstance(x, dict):
        return {k: _without_seconds(v) for k, v in x.items() if k != "seconds"}
    if isinstance(x, list):
        return [_without_seconds(v) for v in x]
    if isinstance(x, float) and x == x:  # NaN stays the same object (containers compare it by identity)
        return float(f"{x:.10g}")
    return x


def test_waves_stop_at_the_limit_and_the_verdict_says_the_surrogate_still_disagrees():
    r = run(2, DriftingModel())
    waves = r.final.refinement
    assert len(waves) == 2 and [w.wave for w in waves] == [2, 3]
    assert all(not w.check.agrees and "t/three" in w.check.disagreeing for w in waves)
    assert not r.met
    assert ("the surrogate still disagrees with the DEM at that best fit for t/three after 2 refinement waves"
            in r.headline) and "not yet a failure of the bump effect" in r.headline
    step = next(s for s in r.next_steps if "still disagrees" in s)
    assert "t/three" in step and "add design points" in step
    # the misfit left there is not blamed on the effect
    assert not any(s.startswith("Still beyond") and "t/three" in s for s in r.next_steps)
    d = r.to_dict()
    assert d["versions"][-1]["surrogate_check"]["disagreeing"] == ["t/three"]
    assert d["verdict"]["surrogate_disagrees"] == ["t/three"] and d["verdict"]["refinement_waves"] == 2


def test_report_lists_the_waves(looped, tmp_path):
    html = write_diagnosis(looped, tmp_path / "diag")["report"].read_text()
    assert "History-matching waves" in html and "confirmation sets joined" in html
    assert json.loads((tmp_path / "diag" / "diagnosis.json").read_text())["verdict"]["surrogate_disagrees"] == []


def test_settings_validate_max_refine_waves():
    assert DiagnosisSettings().max_refine_waves == 5
    for bad in (-1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="max_refine_waves must be an integer >= 0"):
            DiagnosisSettings(max_refine_waves=bad)


def test_pooled_diagnoses_run_their_waves_through_the_pool(looped, one_wave):
    """Two diagnoses in one pool (one needs several waves, one stops after one): same numbers as alone."""
    inner = BumpModel()
    pool = PooledForward(inner)
    s3 = DiagnosisSettings(**SETTINGS, max_refine_waves=3)
    s1 = DiagnosisSettings(**SETTINGS, max_refine_waves=1)
    obs = lab(BumpModel())
    together = run_as_workers(pool, [lambda: diagnose(obs, SPACE, [BUMP], pool, s3),
                                     lambda: diagnose(obs, SPACE, [BUMP], pool, s1)])
    assert _without_seconds(together[0].to_dict()["versions"]) == _without_seconds(looped.to_dict()["versions"])
    assert _without_seconds(together[1].to_dict()["versions"]) == _without_seconds(one_wave.to_dict()["versions"])
    assert inner.threads - {threading.main_thread().name}  # the waves' requests came from the pool's workers


def test_max_refine_waves_is_read_from_the_config_and_checked(tmp_path):
    """The YAML key reaches the settings; a negative count is refused naming the key."""
    import yaml

    from validation.config import load_diagnosis_config
    from warpdem import ConfigError

    root = Path(__file__).resolve().parents[1] / "validation" / "configs"
    doc = yaml.safe_load((root / "tiny_diagnosis.yaml").read_text())
    (tmp_path / "tiny_lab.yaml").write_text((root / "tiny_lab.yaml").read_text())
    doc["diagnosis"]["max_refine_waves"] = 2
    (tmp_path / "d.yaml").write_text(yaml.safe_dump(doc))
    cfg, _ = load_diagnosis_config(tmp_path / "d.yaml")
    assert cfg.diagnosis.max_refine_waves == 2
    doc["diagnosis"]["max_refine_waves"] = -1
    (tmp_path / "d.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match="max_refine_waves"):
        load_diagnosis_config(tmp_path / "d.yaml")


def test_waves_stop_when_a_wave_stalls_before_the_limit():
    """A drifting model: the second wave's disagreement is no smaller than the first's, so no
    third wave runs although max_refine_waves allows five; the wave is marked stalled."""
    r = run(5, DriftingModel())
    waves = r.final.refinement
    assert len(waves) == 2 and [w.wave for w in waves] == [2, 3]
    assert waves[-1].check.max_disagreement > 0.9 * waves[0].check.max_disagreement
    assert [w.stalled for w in waves] == [False, True]
    assert r.to_dict()["versions"][-1]["refinement"][-1]["stalled"] is True
    assert not r.met


def test_a_falling_disagreement_is_not_a_stall(looped):
    assert not any(w.stalled for w in looped.final.refinement)


def test_the_wave_with_the_best_dem_confirmation_is_kept():
    """Drifting model: every wave's DEM lands further off, so the first wave's fit (the smallest
    largest |z| of the DEM confirmations) is returned, and marked kept."""
    r = run(5, DriftingModel())
    waves = r.final.refinement
    zs = [w.check.max_abs_z_dem for w in waves]
    kept = [w.kept for w in waves]
    assert kept.count(True) == 1 and zs[kept.index(True)] == min(zs)
    assert r.final.check.max_abs_z_dem == min(zs) and r.final.waves == waves[kept.index(True)].wave


def test_an_agreeing_last_wave_is_kept(looped):
    assert looped.final.refinement[-1].kept and looped.final.check.agrees
