"""A world's result does not depend on the worlds it shares a batch with (issue 30: the main job's
verdict must not change with the machine's core count). The time step follows the material's
smallest possible sphere (``BulkMaterial.smallest_sphere``), not the smallest one a batch's fills
drew; the walls' height and the motion start follow the tallest loose column the fill mass can
form (``Experiment.loose_top_bound``); the hollow cylinder's settling starts when its own pile is
cleared, not the tallest of its batch; a world's settling ends at its own time limit. So one
process or two give bitwise-identical observables for every world.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import warpdem as wd
from warpdem import geometry
from calibration.experiments import make_experiment
from calibration.materials import BulkMaterial
from tests.test_batch_checkpoint import SETS, SMALL_DRUM, TINY_CYL

SETS3 = SETS + [dict(mu_s_pp=0.45, mu_s_pw=0.4)]


def test_smallest_sphere_of_spheres_and_of_clumps():
    m = BulkMaterial.spheres(0.024, 0.030)
    r, mass = m.smallest_sphere
    assert r == 0.012 and mass == pytest.approx(m.particle.density * 4 / 3 * math.pi * 0.012 ** 3)
    exp = make_experiment("baffle", "paper")
    gravel = exp.bulk_material()
    if not gravel.is_spheres:
        r, mass = gravel.smallest_sphere
        assert 0 < r <= min(float(min(t.radii)) for t, _ in gravel.clumps)
        assert 0 < mass < min(t.mass for t, _ in gravel.clumps)


def test_the_time_step_follows_the_material_not_the_drawn_fill():
    m = BulkMaterial.spheres(0.014, 0.018)
    lim = wd.time_step_limits_for([(m.particle, *m.smallest_sphere)])
    # a fill that happened to draw nothing below 16 mm would allow a longer step; the material's does not
    big = BulkMaterial.spheres(0.016, 0.018)
    assert lim.recommended < wd.time_step_limits_for([(big.particle, *big.smallest_sphere)]).recommended


def test_one_process_or_two_give_the_same_worlds():
    """Three drum worlds, each with its own fill: in one process, or split 2 + 1. With the step of
    the drawn fills the lone third world ran at another step (26.05 against 25.98 deg)."""
    exp = make_experiment("drum", "quick", **SMALL_DRUM)
    one = exp.run(SETS3, device="cpu", processes=1)
    two = exp.run(SETS3, device="cpu", processes=2)
    assert [r.observables for r in one] == [r.observables for r in two]
    assert len({r.timing["dt_s"] for r in one + two}) == 1


def test_a_cylinder_world_does_not_wait_for_the_tallest_pile_of_its_batch():
    """Three hollow-cylinder worlds, each with its own fill: in one process, or split 2 + 1. Before,
    the lift of every world lasted until the tallest pile of its batch was cleared, and the shell's
    height and the motion start followed the batch's tallest loose column (a cylinder 80 mm high:
    the loose columns, about 120 mm, stand above it)."""
    exp = make_experiment("cylinder", "quick", **TINY_CYL, height=0.08)
    one = exp.run(SETS3, device="cpu", processes=1)
    two = exp.run(SETS3, device="cpu", processes=2)
    assert all(r.ok for r in one + two)
    assert [r.observables for r in one] == [r.observables for r in two]
    lift = [r.diagnostics["lift_time_s"] for r in one]
    assert len(set(lift)) == 3  # each world lifts until its own pile is cleared
    assert [r.diagnostics["lift_time_s"] for r in two] == lift
    assert one[0].protocol["fill"]["above_region"]
    assert one[0].protocol["t_motion_start_s"] == two[2].protocol["t_motion_start_s"] > exp.fill_settle_max_time


def test_a_world_settles_to_its_own_time_limit_whatever_the_batch():
    """Simulation.settle with a time limit per world: a world that reaches its limit between two
    checks stops there, and the other worlds see no extra check; a world ends as it ends alone."""
    def model(worlds):
        b = wd.ModelBuilder(num_worlds=len(worlds))
        b.add_material(wd.GRAVEL)
        for w, z in enumerate(worlds):
            b.add_spheres([[0.0, 0.0, z], [0.0, 0.0, z + 0.025]], [0.01, 0.01], "gravel", world=w)
        b.add_wall(geometry.plane((0.0, 0.0, 0.0), 0.2, 0.2), "gravel", name="floor")
        return wd.Simulation(b.finalize("cpu"), 2e-5)

    heights, limits = [0.02, 0.05, 0.03], [0.0105, 0.031, 0.0203]   # limits off the 0.01 s checks
    batch = model(heights)
    batch.settle(1e-12, np.array(limits), check_interval=0.01)
    x = batch.state.body_q.numpy().reshape(3, 2, 3)
    for w, (z, t) in enumerate(zip(heights, limits)):
        alone = model([z])
        alone.settle(1e-12, t, check_interval=0.01)
        np.testing.assert_array_equal(alone.state.body_q.numpy(), x[w])
