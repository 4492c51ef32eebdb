"""Slot sizing of a batch: many-member clumps start with a capped number of slots (more only after
an overflow), and a neighbour list past Warp's 2^31 array limit is refused with a clear message
instead of Warp's ValueError deep in the solver (the paper-gravel reproduction at 37 worlds)."""

from __future__ import annotations

import pytest

import warpdem as wd
from calibration.experiments import make_experiment
from calibration.experiments.common import MAX_START_CONTACT_SLOTS, _contact_slots
from calibration.materials import BulkMaterial


def test_many_member_clumps_start_with_a_capped_slot_count():
    gravel = make_experiment("baffle", "paper").bulk_material()
    assert max(len(t.radii) for t, _ in gravel.clumps) >= 20
    assert _contact_slots([gravel]) == MAX_START_CONTACT_SLOTS == 64  # 16 + 8 * 24 = 208 before
    rods = BulkMaterial.shaped("elongated", 0.024, 0.030, aspect_ratio=2.2, size_classes=2)
    n = max(len(t.radii) for t, _ in rods.clumps)
    assert _contact_slots([rods]) == 16 + 8 * (n - 1) < 64
    assert _contact_slots([BulkMaterial.spheres(0.01, 0.012)]) == 16


def test_a_neighbour_list_past_the_array_limit_is_refused_before_allocation():
    b = wd.ModelBuilder(num_worlds=1, contact_law=wd.ContactLaw(), max_contacts=16)
    b.add_material(wd.GRAVEL)
    for i in range(4):
        b.add_sphere((0.1 * i, 0.0, 0.1), 0.02, wd.GRAVEL.name)
    model = b.finalize("cpu")
    with pytest.raises(wd.ConfigError, match=r"2\^31.*fewer worlds per launch"):
        wd.Simulation(model, 1e-5, max_neighbours=2 ** 30)
