"""validation.pooled: concurrent studies share forward-model calls and get the same answers.

The forward model here is the analytic granular model of test_diagnosis_logic with noise that is
a function of (parameters, replicate, key) -- not of call order -- and a world cache, as the DEM
forward model has; it counts its "launches" (calls that had to simulate something)."""
from __future__ import annotations

import hashlib
import json
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_diagnosis_logic import (BASE, COHESION, FAST, KEYS, NOISE_SD, ROLLING, SHAPE, TRUTHS,  # noqa: E402
                                  AnalyticGranularModel, lab_observables)

from validation import ForwardModel, diagnose  # noqa: E402
from validation.pooled import PooledForward, run_as_workers  # noqa: E402

CANDS = [ROLLING, COHESION, SHAPE]
OFF = {"mu_r": 0.0, "cohesion_energy_density": 0.0, "aspect_ratio": 1.0}


class CachedAnalyticModel(ForwardModel):
    """Superset-style analytic model: every version is the model with all effects, the absent
    ones at their off value; world results cached; noise seeded by the world itself."""

    superset = True
    effects = {"rolling_resistance": None, "cohesion": None, "shape": None}

    def __init__(self, fail_after: int | None = None):
        self.analytic = AnalyticGranularModel(0)
        self.cache: dict[str, float] = {}
        self.launches = 0
        self.worlds = 0
        self.fail_after = fail_after
        self.threads: set[str] = set()

    def padded(self, effects, p):
        return {**{k: v for k, v in OFF.items()}, **{k: float(v) for k, v in p.items()}}

    def _world(self, p, rep, key):
        return hashlib.sha1(json.dumps([sorted(p.items()), rep, key]).encode()).hexdigest()

    def evaluate(self, effects, parameter_sets, replicates, keys):
        self.threads.add(threading.current_thread().name)
        sets = [self.padded(effects, p) for p in parameter_sets]
        todo = [(p, r, k) for p in sets for r in range(replicates) for k in keys
                if self._world(p, r, k) not in self.cache]
        if todo:
            self.launches += 1
            if self.fail_after is not None and self.launches > self.fail_after:
                raise RuntimeError("the simulator broke")
            for p, r, k in todo:
                seed = int(self._world(p, r, k)[:8], 16)
                q = k.rsplit("/", 1)[1]
                v = self.analytic.mean(k, p, tuple(self.effects)) + np.random.default_rng(seed).normal(0, NOISE_SD[q])
                self.cache[self._world(p, r, k)] = max(v, 0.0) if q == "pile_angle" else v
            self.worlds += len(todo)
        return np.array([[[self.cache[self._world(p, r, k)] for k in keys] for r in range(replicates)] for p in sets])


def _numbers(result):
    """Every number of a diagnosis except wall times, floats to 10 significant digits (studies running
    beside each other in threads may sum in another order in BLAS: differences of 1e-16)."""
    def strip(x):
        if isinstance(x, dict):
            return {k: strip(v) for k, v in x.items() if k != "seconds"}
        if isinstance(x, list):
            return [strip(v) for v in x]
        if isinstance(x, float) and x == x:  # NaN stays the same object (containers compare it by identity)
            return float(f"{x:.10g}")
        return x
    d = result.to_dict()
    return strip({k: d[k] for k in ("verdict", "versions", "rounds", "error_history", "next_steps")}), result.headline


@pytest.fixture(scope="module")
def labs():
    return {name: lab_observables(truth, (name,), seed=7) for name, truth in TRUTHS.items()}


def test_candidates_share_launches_and_get_the_same_answers(labs):
    obs = labs["rolling_resistance"]
    alone = CachedAnalyticModel()
    r_alone = diagnose(obs, BASE, CANDS, alone, FAST)
    inner = CachedAnalyticModel()
    pooled = PooledForward(inner)
    r_pooled = diagnose(obs, BASE, CANDS, pooled, FAST)
    assert _numbers(r_pooled) == _numbers(r_alone)
    assert inner.worlds == alone.worlds  # the same worlds, no more
    assert inner.launches < alone.launches  # the three candidates' studies ran together
    # the three candidates' studies and the (inadequate) base model's confirmation ran together
    assert len(inner.threads) > 1 and pooled.merges and max(m["requests"] for m in pooled.merges) == 1 + len(CANDS)


def test_several_diagnoses_in_one_process_share_launches(labs):
    alone = {}
    launches_alone = 0
    for name, obs in labs.items():
        m = CachedAnalyticModel()
        alone[name] = diagnose(obs, BASE, CANDS, m, FAST)
        launches_alone += m.launches
    inner = CachedAnalyticModel()
    pool = PooledForward(inner)
    names = list(labs)
    together = run_as_workers(pool, [lambda n=n: diagnose(labs[n], BASE, CANDS, pool, FAST) for n in names])
    for n, r in zip(names, together):
        assert _numbers(r) == _numbers(alone[n]), n
    assert inner.launches < launches_alone / 2


def test_a_failing_simulator_reaches_every_waiting_study_without_hanging(labs):
    inner = CachedAnalyticModel(fail_after=1)  # the base design runs, the candidates' first batch fails
    pool = PooledForward(inner)
    done = []

    def run():
        with pytest.raises(RuntimeError, match="simulator broke"):
            diagnose(labs["cohesion"], BASE, CANDS, pool, FAST)
        done.append(True)

    th = threading.Thread(target=run)
    th.start()
    th.join(timeout=120)
    assert not th.is_alive() and done


def test_an_unregistered_caller_is_served_alone():
    inner = CachedAnalyticModel()
    pool = PooledForward(inner)
    y = pool.evaluate((), [{"mu_s_pp": 0.3, "mu_s_pw": 0.4}], 2, KEYS[:2])
    assert y.shape == (1, 2, 2) and inner.launches == 1


def _tiny_configs(tmp_path, **second):
    import shutil

    import yaml

    src = Path(__file__).resolve().parents[1] / "validation" / "configs"
    shutil.copy(src / "tiny_lab.yaml", tmp_path / "tiny_lab.yaml")
    cfg = yaml.safe_load((src / "tiny_diagnosis.yaml").read_text())
    paths = []
    for i, extra in enumerate(({}, second)):
        c = {**cfg, "output": str(tmp_path / f"out{i}"), "cache": str(tmp_path / "cache.jsonl"), **extra}
        p = tmp_path / f"cfg{i}.yaml"
        p.write_text(yaml.safe_dump(c))
        paths.append(str(p))
    return paths


def test_cli_refuses_to_pool_configs_that_simulate_differently(tmp_path, capsys):
    from validation.cli import diagnose_main

    paths = _tiny_configs(tmp_path, fixed={"restitution_pp": 0.5, "restitution_pw": 0.6})
    assert diagnose_main([*paths, "--device", "cpu"]) == 2
    err = capsys.readouterr().err
    assert "cannot share DEM runs" in err and "fixed" in err and paths[1] in err


def test_cli_refuses_two_configs_writing_one_folder(tmp_path, capsys):
    from validation.cli import diagnose_main

    paths = _tiny_configs(tmp_path, output=str(tmp_path / "out0"))
    assert diagnose_main([*paths, "--device", "cpu"]) == 2
    assert "same output folder" in capsys.readouterr().err


def test_a_torn_dem_cache_line_is_reported_dropped_and_later_appends_stay_readable(tmp_path, capsys):
    """A write cut by an interruption leaves half a line; loading reports it, rewrites the file
    without it, and the next record starts on its own line (it would otherwise be glued to the
    fragment and lost at the following load)."""
    import json

    import warpdem as wd
    from calibration.model_description import ModelDescription
    from validation.dem_forward import DEMForwardModel

    def record(wid: str) -> dict:
        return {"id": wid, "experiment": "baffle", "status": "ok", "parameters": {"mu_s_pp": 0.5}, "replicate": 0,
                "rpm": None, "observables": {"static_angle": 30.0}}

    cache = tmp_path / "dem_cache.jsonl"
    DEMForwardModel(ModelDescription(wd.ContactLaw()), None, (), (), cache=cache)._store(record("a"))
    DEMForwardModel(ModelDescription(wd.ContactLaw()), None, (), (), cache=cache)._store(record("b"))
    assert json.loads(cache.read_text().splitlines()[0])["warpdem_records"] == "warpdem-dem-cache"  # the header
    with open(cache, "a") as fh:
        fh.write(json.dumps(record("c"))[:20])
    forward = DEMForwardModel(ModelDescription(wd.ContactLaw()), None, (), (), cache=cache)
    assert set(forward._cache) == {"a", "b"}
    assert "1 torn line(s) dropped" in capsys.readouterr().err
    assert (tmp_path / "dem_cache.jsonl.torn").read_text() == json.dumps(record("c"))[:20] + "\n"  # kept aside
    forward._store(record("d"))
    again = DEMForwardModel(ModelDescription(wd.ContactLaw()), None, (), (), cache=cache)
    assert set(again._cache) == {"a", "b", "d"}
    assert "torn" not in capsys.readouterr().err


def test_a_dem_cache_written_before_headers_still_loads_and_its_torn_line_is_cut(tmp_path, capsys):
    """A cache without the header line is recognised by its records (every JSON line a world's
    record), so caches written before the header existed keep serving their worlds."""
    import json

    import warpdem as wd
    from calibration.model_description import ModelDescription
    from validation.dem_forward import DEMForwardModel

    recs = [{"id": w, "experiment": "drum", "status": "ok", "parameters": {}, "observables": {}} for w in "ab"]
    cache = tmp_path / "old.jsonl"
    cache.write_text("".join(json.dumps(r) + "\n" for r in recs) + '{"id": "c", "exp')
    forward = DEMForwardModel(ModelDescription(wd.ContactLaw()), None, (), (), cache=cache,
                              cache_code_version="any")  # such records name no code version
    assert set(forward._cache) == {"a", "b"} and "1 torn line(s) dropped" in capsys.readouterr().err
    assert cache.read_text() == "".join(json.dumps(r) + "\n" for r in recs)


def test_a_world_found_again_with_round_off_parameters_is_served_from_the_cache(tmp_path):
    """A best fit found again on another machine differs in its last digits; the cached world with
    (relatively) 1e-12 different parameters is reused, one 1e-6 away or of another model is not."""
    import warpdem as wd
    from calibration.model_description import ModelDescription
    from validation.dem_forward import DEMForwardModel

    forward = DEMForwardModel(ModelDescription(wd.ContactLaw()), None, (), (), cache=tmp_path / "c.jsonl")
    params = {"mu_s_pp": 0.47429896119979187, "mu_s_pw": 0.36016236828610326}
    wid = forward._world_id("model", "setup", params, 0, None)
    forward._store({"id": wid, "experiment": "baffle", "status": "ok", "parameters": params, "replicate": 0,
                    "rpm": None, "observables": {"static_angle": 21.0}})

    def near(rel: float, model: str = "model") -> bool:
        moved = {k: v * (1 + rel) for k, v in params.items()}
        return forward._adopt_near_record(forward._world_id(model, "setup", moved, 0, None), model, "setup",
                                          "baffle", moved, 0, None)

    assert near(2e-11)
    assert not near(1e-6)
    assert not near(2e-11, model="another model")
    assert len((tmp_path / "c.jsonl").read_text().splitlines()) == 2  # header and record: an alias is not written again


class CachedTieModel(CachedAnalyticModel):
    """The cached superset model with shape built to mimic rolling resistance below 45 rpm (the tie
    of test_diagnosis_logic) and the drum at 10 and 60 rpm to forecast."""

    def __init__(self):
        super().__init__()
        from test_diagnosis_logic import DRUM_10, DRUM_60

        self.analytic = AnalyticGranularModel(0, shape_like_rolling=True, proposals=(DRUM_10, DRUM_60))

    def proposals(self):
        return self.analytic.proposals()


def test_the_tied_candidates_forecasts_share_one_launch():
    """When candidates tie, their runs at the proposed conditions are requests of one merged call
    (one launch per experiment on the GPU), not one launch per candidate; the chosen candidate's
    recalibration, which does not wait for them, joins that call."""
    from test_diagnosis_logic import TRUTHS as T

    obs = lab_observables(T["rolling_resistance"], ("rolling_resistance",), shape_like_rolling=True)
    inner = CachedTieModel()
    pool = PooledForward(inner)
    result = diagnose(obs, BASE, [ROLLING, SHAPE], pool, FAST)
    disc = result.rounds[0].discrimination
    assert disc is not None and len(disc.candidates) == 2 and disc.forecasts
    forecast_keys = {p.key for p in inner.proposals()}
    # both candidates' forecasts (the proposed conditions' keys) and the recalibration's first wave
    # (the measured observables' keys) in one call
    merged = [m for m in pool.merges if m["keys"] == len(obs) + len(forecast_keys) and m["requests"] == 3]
    assert merged, pool.merges
    assert _numbers(result) == _numbers(diagnose(obs, BASE, [ROLLING, SHAPE], CachedTieModel(), FAST))  # as alone
