"""designs_up_front: every planned design in ONE forward-model call, and not one number changes.

The forward model is the cached analytic superset model of test_pooled_forward (noise seeded by
the world, not by call order, as the DEM cache serves a world the same whenever it is asked for),
wrapped to record every call: its effects, its parameter sets and whether it simulated anything."""
from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_diagnosis_logic import BASE, FAST, AnalyticGranularModel, lab_observables  # noqa: E402
from test_pooled_forward import CANDS, TRUTHS, CachedAnalyticModel  # noqa: E402

from validation import diagnose  # noqa: E402
from validation.diagnose import _up_front_choice, design_size, planned_designs  # noqa: E402
from validation.pooled import PooledForward, run_as_workers  # noqa: E402

ON = dataclasses.replace(FAST, designs_up_front=True)
AUTO = dataclasses.replace(FAST, designs_up_front="auto")
N_DESIGN_SETS = sum(n for _, n, _ in planned_designs(BASE, CANDS, FAST))  # 16 + 3 x 24 = 88


class RecordingModel(CachedAnalyticModel):
    """Records (effects, padded parameter sets, replicates, simulated anything) of every call."""

    def __init__(self, on_cuda: bool | None = None):
        super().__init__()
        self.calls: list[tuple[tuple[str, ...], list[tuple], int, bool]] = []
        if on_cuda is not None:
            self.on_cuda = on_cuda

    def evaluate(self, effects, parameter_sets, replicates, keys):
        launches = self.launches
        out = super().evaluate(effects, parameter_sets, replicates, keys)
        sets = [tuple(sorted(self.padded(effects, p).items())) for p in parameter_sets]
        self.calls.append((tuple(effects), sets, replicates, self.launches > launches))
        return out

    def design_calls(self) -> list[int]:
        """Sizes of the calls that hold a design (at least one version's Latin hypercube)."""
        smallest = min(design_size(v, FAST) for v, _, _ in planned_designs(BASE, CANDS, FAST))
        return [len(sets) for _, sets, _, _ in self.calls if len(sets) >= smallest]


def _numbers(result) -> dict:
    """Every entry of the result's to_dict except wall times, the forward-model call counts and the
    setting itself (the only places the two runs may differ)."""
    def strip(x):
        if isinstance(x, dict):
            return {k: strip(v) for k, v in x.items() if k != "seconds"}
        if isinstance(x, list):
            return [strip(v) for v in x]
        return x
    d = result.to_dict()
    d.pop("forward_model")
    d["settings"].pop("designs_up_front")
    return strip(d)


def _close(a, b, rel: float = 1e-9) -> bool:
    """``a == b`` with floats equal within ``rel`` (everything else exactly)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_close(a[k], b[k], rel) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_close(x, y, rel) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float):
        return a == pytest.approx(b, rel=rel, abs=1e-12, nan_ok=True)
    return a == b


@pytest.fixture(scope="module")
def rolling_lab():
    return lab_observables(TRUTHS["rolling_resistance"], ("rolling_resistance",), seed=7)


@pytest.mark.parametrize("pooled", [False, True], ids=["alone", "pooled"])
def test_every_design_goes_into_one_call_and_no_number_changes(rolling_lab, pooled):
    off_model, on_model = RecordingModel(), RecordingModel()
    wrap = (lambda m: PooledForward(m)) if pooled else (lambda m: m)
    r_off = diagnose(rolling_lab, BASE, CANDS, wrap(off_model), AUTO)  # auto on a CPU model: off
    r_on = diagnose(rolling_lab, BASE, CANDS, wrap(on_model), ON)
    assert _numbers(r_on) == _numbers(r_off)
    assert r_on.headline == r_off.headline and r_on.added_effects == ("rolling_resistance",)
    # off: the base design, then the candidates' (pooled: one merged launch; alone: one call each)
    assert off_model.design_calls() == ([16, 16, 72, 24, 24, 24] if pooled else [16, 24, 24, 24])
    # on: ONE call holds every design, with every effect switched on (the absent ones at their off value);
    # (pooled: the pool's merged call, then the request's own answer read back from the cache)
    first_effects, first_sets, reps, simulated = on_model.calls[0]
    assert first_effects == tuple(on_model.effects) and reps == FAST.replicates and simulated
    assert len(first_sets) == N_DESIGN_SETS == 88
    assert on_model.design_calls() == ([88, 88] if pooled else [88])
    if pooled:
        assert not on_model.calls[1][3]  # the request's own answer comes from the cache
    # ... and they are exactly the sets the studies asked for one by one when it was off
    off_design_sets = {s for _, sets, _, _ in off_model.calls if len(sets) >= 16 for s in sets}
    assert off_design_sets == set(first_sets)
    # the same worlds simulated, in fewer launches
    assert on_model.worlds == off_model.worlds
    assert on_model.launches < off_model.launches
    up = r_on.forward["designs_up_front"]
    assert up["on"] and up["calls"] == 1 and up["unused_versions"] == []
    assert up["worlds_run"] == up["worlds_used"] == 2 * N_DESIGN_SETS
    assert r_off.forward["designs_up_front"] == {"setting": "auto", "on": False,
                                                 "reason": "auto: the forward model does not run on a CUDA device"}
    assert r_on.forward["calls"] < r_off.forward["calls"] and r_on.forward["runs"] == r_off.forward["runs"]
    json.dumps(r_on.to_dict(), allow_nan=False)  # the record is plain JSON


def test_unused_up_front_designs_of_an_adequate_base_model_are_said_and_counted(capsys):
    obs = lab_observables({"mu_s_pp": 0.5, "mu_s_pw": 0.4}, (), seed=7)
    r_off = diagnose(obs, BASE, CANDS, RecordingModel(), FAST)
    model = RecordingModel()
    r_on = diagnose(obs, BASE, CANDS, model, ON)
    assert r_on.base_adequate and not r_on.rounds
    assert _numbers(r_on) == _numbers(r_off)
    assert model.design_calls() == [N_DESIGN_SETS]
    up = r_on.forward["designs_up_front"]
    assert up["unused_versions"] == ["rolling_resistance", "cohesion", "shape"]
    assert up["worlds_run"] == 2 * N_DESIGN_SETS and up["worlds_used"] == 2 * 16
    err = capsys.readouterr().err
    assert "144 design world(s) of rolling_resistance, cohesion, shape asked for up front were not used" in err


def test_auto_is_off_on_the_cpu_and_on_on_a_cuda_superset_model():
    import warpdem as wd
    from calibration.model_description import ModelDescription
    from validation.dem_forward import DEMForwardModel

    assert _up_front_choice(AUTO, RecordingModel()) == (False, "auto: the forward model does not run on a CUDA device")
    assert _up_front_choice(AUTO, RecordingModel(on_cuda=True))[0]
    assert _up_front_choice(AUTO, PooledForward(RecordingModel(on_cuda=True)))[0]  # the pool asks its model
    assert not _up_front_choice(dataclasses.replace(FAST, designs_up_front=False), RecordingModel(on_cuda=True))[0]
    # a model that cannot answer every version in one call does not take part, whatever the setting
    on, why = _up_front_choice(ON, AnalyticGranularModel(0))
    assert not on and "no superset model" in why
    # the DEM forward model says where it runs (no DEM is run here)
    desc = ModelDescription(wd.ContactLaw())
    assert not DEMForwardModel(desc, None, (), (), device="cpu").on_cuda
    assert DEMForwardModel(desc, None, (), (), device="cuda:0").on_cuda


def test_prefetch_runs_the_same_single_call_as_the_up_front_step(rolling_lab, capsys):
    from validation.cli import _prefetch

    model = RecordingModel()
    keys = tuple(o.key for o in rolling_lab)
    assert _prefetch(keys, BASE, CANDS, model, FAST, []) == 0
    up_front = RecordingModel()
    diagnose(rolling_lab, BASE, CANDS, up_front, ON)
    assert len(model.calls) == 1 and model.calls[0] == up_front.calls[0]
    line = json.loads(capsys.readouterr().out.strip())
    assert line["prefetched"] == ["base", "rolling_resistance", "cohesion", "shape"] and line["sets"] == 88
    assert _prefetch(keys, BASE, CANDS, model, FAST, ["base", "magnetism"]) == 2
    assert "magnetism" in capsys.readouterr().err



def test_several_measurement_sets_share_one_up_front_launch():
    """Several diagnoses in one process (the CLI's pool): their up-front requests merge into one
    call, the common designs run once, and every number equals that of the runs with it off."""
    labs = {n: lab_observables(t, (n,), seed=7) for n, t in TRUTHS.items()}
    results = {}
    for settings in (FAST, ON):
        inner = RecordingModel()
        pool = PooledForward(inner)
        results[settings.designs_up_front] = (run_as_workers(
            pool, [lambda n=n: diagnose(labs[n], BASE, CANDS, pool, settings) for n in labs]), inner, pool)
    (off, off_model, _), (on, on_model, on_pool) = results["auto"], results[True]
    for a, b in zip(on, off):
        # equal up to float round-off: diagnoses side by side in threads share the process-wide
        # BLAS thread setting, which each restores when it ends (diagnose's threadpool_limits), so
        # the last digits of the late stages can depend on which finished first, with the setting
        # off too; one diagnosis (the tests above) is bit for bit the same
        assert _close(_numbers(a), _numbers(b))
        assert a.headline == b.headline and a.added_effects == b.added_effects
    assert on_pool.merges[0] == {"requests": 3, "sets": N_DESIGN_SETS, "replicates": 2, "keys": 6}
    assert on_model.worlds == off_model.worlds
    # the first launch ran every design of the three sets, none came later (how the later, small
    # requests merge depends on the threads' timing: see validation.pooled.run_as_workers)
    launched = [sets for _, sets, _, simulated in on_model.calls if simulated]
    assert len(launched[0]) == N_DESIGN_SETS
    assert not set(launched[0]) & {s for sets in launched[1:] for s in sets}
