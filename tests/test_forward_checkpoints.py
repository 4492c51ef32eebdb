"""A diagnosis's DEM launch cut short (a time-limited GPU call, Ctrl-C) continues from its batch
checkpoint when the same request comes again: the cache has not grown, so the launch draws the
same fills and matches its checkpoint, and the observables equal those of an uncut launch. CPU,
a tiny quick-scale hollow-cylinder batch of 2 worlds (a few seconds)."""
import numpy as np
import pytest

import warpdem as wd
from calibration.experiments import checkpoints
from calibration.model_description import ModelDescription
from validation.dem_forward import DEMForwardModel, ObservableSpec

TINY_CYL = dict(fill_mass=1.5, lift_speed=0.5, max_time_after_lift=0.2, min_pile_layers=0.0)
SETS = [dict(mu_s_pp=0.3, mu_s_pw=0.3), dict(mu_s_pp=0.6, mu_s_pw=0.5)]
KEYS = ("pile",)


def count_steps(monkeypatch) -> list:
    """Count the steps every ``Simulation.run`` advances."""
    steps = [0]
    plain_run = wd.Simulation.run

    def run(self, n, *args, **kwargs):
        steps[0] += int(n)
        return plain_run(self, n, *args, **kwargs)

    monkeypatch.setattr(wd.Simulation, "run", run)
    return steps


class Killed(BaseException):
    """Stands for a kill right after a checkpoint was written."""


def forward(cache, every_s=0.3):
    spec = ObservableSpec("pile", "cylinder", "pile_angle", TINY_CYL)
    return DEMForwardModel(ModelDescription.from_config({"contact_law": {"rolling": "none"}}), None, [], [spec],
                           scale="quick", device="cpu", processes=1, cache=cache, checkpoint_every_s=every_s)


def test_cut_launch_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    full = count_steps(monkeypatch)
    reference = forward(tmp_path / "ref" / "dem_runs.jsonl").evaluate((), SETS, 1, KEYS)
    monkeypatch.undo()
    cache = tmp_path / "cut" / "dem_runs.jsonl"
    fm = forward(cache)
    assert fm.checkpoints.folder == tmp_path / "cut" / "dem_runs_checkpoints"
    plain_save = checkpoints.BatchCheckpoint.save
    saves = []

    def save(self, ctx, inner):
        plain_save(self, ctx, inner)
        saves.append(ctx.sim.steps)
        if len(saves) == 2:
            raise Killed()

    monkeypatch.setattr(checkpoints.BatchCheckpoint, "save", save)
    with pytest.raises(Killed):
        fm.evaluate((), SETS, 1, KEYS)
    monkeypatch.undo()
    assert not cache.exists() or cache.read_text() == ""  # nothing recorded: the launch was cut
    assert any(fm.checkpoints.folder.iterdir())
    again = forward(cache)
    steps = count_steps(monkeypatch)
    got = again.evaluate((), SETS, 1, KEYS)
    np.testing.assert_array_equal(got, reference)  # bitwise on the CPU
    assert steps[0] == full[0] - saves[-1] > 0  # continued from the checkpoint, not started over
    assert list(again.checkpoints.folder.iterdir()) == []


def test_no_checkpoints_without_a_cache_or_when_switched_off(tmp_path):
    assert forward(None).checkpoints is None
    assert forward(tmp_path / "c.jsonl", every_s=None).checkpoints is None
