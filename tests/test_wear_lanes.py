"""Copies ("lanes") of the wall wear accumulators (warpdem.solver.WallStats): on a GPU thousands of
spheres resting on one floor triangle would otherwise queue their atomic adds on one address. The
forces never read the accumulators, so bodies and contacts are bit for bit the same with any number
of lanes; the accumulated wear is the same sum in another order (float rounding). A checkpoint keeps
every lane, so a restart continues bit for bit; older checkpoints (one array per field) still load."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import warpdem as wd
from warpdem.io import load_checkpoint, save_checkpoint
from warpdem.solver import WEAR_LANE_BUDGET, WEAR_LANES, wear_lane_count

sys.path.insert(0, str(Path(__file__).parent))
from test_contact_stages import SCENES  # noqa: E402
from test_layout_levers import RUNS, run_with  # noqa: E402


def test_lanes_change_no_force_and_wear_only_to_rounding(monkeypatch):
    one = run_with(RUNS["wear"], {"wear_lanes": 1}, "cpu", monkeypatch)
    eight = run_with(RUNS["wear"], {"wear_lanes": 8}, "cpu", monkeypatch)
    assert one["wear_energy_n"].sum() > 0 and one["wear_impulse_t"].sum() > 0
    for key, want in one.items():
        if key.startswith("wear_"):
            np.testing.assert_allclose(eight[key], want, rtol=1e-5, atol=1e-12, err_msg=key)
        else:
            assert np.array_equal(eight[key], want), key


def test_the_lanes_are_really_used():
    sim = SCENES["wear"]()
    sim = wd.Simulation(sim.model, sim.dt, wear_lanes=8)
    sim.run(400)
    lanes = sim.solver.wall_stats.export_lanes()["impulse_n"]
    assert lanes.shape == (8, sim.solver.wall_stats.entries)
    assert np.count_nonzero(lanes.sum(axis=1)) > 1  # several spheres' lanes took contacts
    np.testing.assert_allclose(sim.solver.wall_stats.impulse_n.numpy(), lanes.sum(axis=0), rtol=1e-6)


def test_checkpoint_keeps_every_lane(tmp_path):
    model = SCENES["wear"]().model
    ref = wd.Simulation(model, 2e-5, wear_lanes=8)
    ref.run(400)
    sim = wd.Simulation(model, 2e-5, wear_lanes=8)
    sim.run(200)
    again = load_checkpoint(save_checkpoint(tmp_path / "ck.npz", sim), "cpu", wear_lanes=8)
    again.run(200)
    for f in again.solver.wall_stats.FIELDS:
        np.testing.assert_array_equal(getattr(again.solver.wall_stats, f).numpy(),
                                      getattr(ref.solver.wall_stats, f).numpy(), err_msg=f)
    one_lane = load_checkpoint(tmp_path / "ck.npz", "cpu", wear_lanes=1)  # lanes summed into one
    np.testing.assert_allclose(one_lane.solver.wall_stats.energy_n.numpy(), sim.solver.wall_stats.energy_n.numpy(),
                               rtol=1e-6)


def test_lane_count_auto_and_checks():
    assert wear_lane_count("auto", 10, on_gpu=False) == 1
    assert wear_lane_count("auto", 10, on_gpu=True) == WEAR_LANES == 32
    big = WEAR_LANE_BUDGET // 4  # the pump's meshes times many worlds: fewer copies, within the budget
    assert wear_lane_count("auto", big, on_gpu=True) == 4
    assert wear_lane_count("auto", 10 * WEAR_LANE_BUDGET, on_gpu=True) == 1
    assert wear_lane_count(16, 10, on_gpu=False) == 16
    for bad in (0, 3, 128, 2.0, True, "many"):
        with pytest.raises(wd.ConfigError, match="wear_lanes"):
            wear_lane_count(bad, 10, on_gpu=True)
