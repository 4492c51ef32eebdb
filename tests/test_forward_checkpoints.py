"""A diagnosis's DEM launch cut short (a time-limited GPU call, Ctrl-C) continues from its batch
checkpoint when the same request comes again: the cache has not grown, so the launch draws the
same fills and matches its checkpoint, and the observables equal those of an uncut launch. CPU,
a tiny quick-scale hollow-cylinder batch of 2 worlds (a few seconds)."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_batch_checkpoint import SETS, TINY_CYL, Killed, count_steps, kill_after_save  # noqa: E402

from calibration.model_description import ModelDescription  # noqa: E402
from validation.dem_forward import DEMForwardModel, ObservableSpec  # noqa: E402

KEYS = ("pile",)
SETTINGS = {k: v for k, v in TINY_CYL.items() if k != "fill_per_world"}  # the forward model sets it


def forward(cache, every_s=0.3):
    spec = ObservableSpec("pile", "cylinder", "pile_angle", SETTINGS)
    return DEMForwardModel(ModelDescription.from_config({"contact_law": {"rolling": "none"}}), None, [], [spec],
                           scale="quick", device="cpu", processes=1, cache=cache, checkpoint_every_s=every_s)


def test_cut_launch_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    full = count_steps(monkeypatch)
    reference = forward(tmp_path / "ref" / "dem_runs.jsonl").evaluate((), SETS, 1, KEYS)
    monkeypatch.undo()
    cache = tmp_path / "cut" / "dem_runs.jsonl"
    fm = forward(cache)
    assert fm.checkpoints.folder == tmp_path / "cut" / "dem_runs_checkpoints"
    saves = kill_after_save(monkeypatch, 2)
    with pytest.raises(Killed):
        fm.evaluate((), SETS, 1, KEYS)
    monkeypatch.undo()
    assert not cache.exists() or cache.read_text() == ""  # nothing recorded: the launch was cut
    assert any(fm.checkpoints.folder.iterdir())
    again = forward(cache)
    steps = count_steps(monkeypatch)
    got = again.evaluate((), SETS, 1, KEYS)
    np.testing.assert_array_equal(got, reference)  # bitwise on the CPU
    assert steps[0] == full[0] - saves[-1][1] > 0  # continued from the checkpoint, not started over
    assert list(again.checkpoints.folder.iterdir()) == []


def test_no_checkpoints_without_a_cache_or_when_switched_off(tmp_path):
    assert forward(None).checkpoints is None
    assert forward(tmp_path / "c.jsonl", every_s=None).checkpoints is None
