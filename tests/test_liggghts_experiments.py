"""LIGGGHTS decks written from the project's experiments (validation.reference.liggghts_experiments):
walls, motion, material, fill and protocol in the deck; tiny runs read back through
calibration.measurement. Runs skip when LIGGGHTS is absent (install it with
scripts/install_liggghts.sh)."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

import warpdem as wd
from calibration.experiments import BaffleBox, HollowCylinder, RotatingDrum
from validation.reference.liggghts import liggghts_executable, read_dump
from validation.reference.liggghts_experiments import (capture_walls, contact_parameter_table,
                                                       fill_for_index, liggghts_model_keywords, stl_text,
                                                       warpdem_time_step, write_deck)
from validation.reference.liggghts_readback import run_and_measure

needs_liggghts = pytest.mark.skipif(liggghts_executable() is None,
                                    reason="LIGGGHTS not installed (scripts/install_liggghts.sh)")
FRICTION = {"mu_s_pp": 0.45, "mu_s_pw": 0.35}


def _stl_triangles(text: str) -> np.ndarray:
    v = [[float(x) for x in ln.split()[1:4]] for ln in text.splitlines() if ln.strip().startswith("vertex")]
    return np.array(v).reshape(-1, 3, 3)


def _tiny_baffle(**kw) -> BaffleBox:
    """A 200 x 100 mm box with ~90 spheres of 24-30 mm: a few layers, a lift of 0.12 m."""
    settings = dict(box_length=0.2, box_width=0.1, floor_length=0.5, floor_side_margin=0.05, fill_mass=2.4,
                    lift_to=0.12, lift_speed=0.2, max_time_after_lift=1.0, fill_settle_max_time=0.4,
                    measure_y=(0.0, 0.1), min_bins=2, density_margin=0.0, density_top_margin=0.03,
                    contact_law=wd.ContactLaw(rolling="epsd2"), fill_per_world=True)
    settings.update(kw)
    return BaffleBox.from_config("quick", **settings)


@pytest.mark.parametrize("make", [lambda: BaffleBox.from_config("quick"), lambda: RotatingDrum.from_config("quick"),
                                  lambda: HollowCylinder.from_config("quick")])
def test_walls_are_the_builders_meshes_and_the_stl_holds_their_triangles(make):
    exp = make()
    walls = capture_walls(exp, fill_top=0.35)
    builder = wd.ModelBuilder(1, contact_law=exp.contact_law)
    builder.add_material(exp.bulk_material().particle)
    builder.add_material(exp.wall_material)
    exp.add_walls(builder, 0.35, 0.0, exp.bulk_material())
    assert [w.name for w in walls] == [w.name for w in builder.walls]
    for cap, real in zip(walls, builder.walls):
        np.testing.assert_array_equal(cap.vertices, real.vertices)
        np.testing.assert_array_equal(cap.faces, real.faces)
        assert (cap.motion is None) == real.motion.is_static
        np.testing.assert_allclose(_stl_triangles(stl_text(cap)), real.vertices[real.faces], rtol=0, atol=1e-12)


def test_law_keywords_and_parameter_table():
    assert liggghts_model_keywords(wd.ContactLaw(rolling="none")) == "model hertz tangential history"
    assert liggghts_model_keywords(wd.ContactLaw(rolling="epsd2", cohesion="sjkr")) == \
        "model hertz tangential history cohesion sjkr rolling_friction epsd2 tangential_reduce off"
    assert liggghts_model_keywords(wd.ContactLaw(rolling="epsd2", cohesion="sjkr"), tangential_reduce=True).endswith(
        "tangential_reduce on")
    assert liggghts_model_keywords(wd.ContactLaw(rolling="cdt", cohesion="sjkr2")).endswith("cohesion sjkr2 rolling_friction cdt tangential_reduce off")
    assert liggghts_model_keywords(wd.ContactLaw(rolling="cdt", cohesion="sjkr2_reduced")).endswith(
        "cohesion sjkr2 rolling_friction cdt tangential_reduce on")
    exp = BaffleBox.from_config("quick", contact_law=wd.ContactLaw(rolling="epsd2", cohesion="sjkr"))
    table = contact_parameter_table(exp, {**FRICTION, "mu_r_pp": 0.2, "cohesion_energy_density_pw": 1e5})
    assert table["restitution_pp"] == table["restitution_pw"] == 0.6  # the experiment's contact_defaults
    assert table["mu_s_pp"] == 0.45 and table["mu_r_pp"] == 0.2 and table["cohesion_energy_density_pw"] == 1e5
    assert table["mu_r_pw"] == exp.contact_law.specs["mu_r"].default
    deck = write_deck(exp, {**FRICTION, "mu_r_pp": 0.2, "mu_r_pw": 0.1, "cohesion_energy_density_pp": 1e5})
    assert "coefficientRollingFriction peratomtypepair 2 0.2 0.1 0.1 0.1" in deck.deck
    assert "cohesionEnergyDensity peratomtypepair 2 100000 0 0 0" in deck.deck
    assert f"youngsModulus peratomtype {wd.GRAVEL.youngs_modulus:.10g} {wd.PLEXIGLAS.youngs_modulus:.10g}" in deck.deck


def test_baffle_deck_fill_motion_and_protocol_times():
    exp = _tiny_baffle()
    fill = fill_for_index(exp, 3)
    deck = write_deck(exp, FRICTION, fill_mode="identical", fill_index=3)
    assert deck.dt == pytest.approx(warpdem_time_step(exp, fill))
    # the fill: every sphere of warpdem's fill 3, same centres and radii
    rows = [ln.split() for ln in deck.files["fill.data"].split("Atoms")[1].strip().splitlines()]
    assert len(rows) == fill.sample.n == deck.n_particles
    np.testing.assert_allclose([float(r[2]) for r in rows], 2.0 * fill.sample.radius, rtol=1e-14)
    np.testing.assert_allclose([[float(x) for x in r[4:7]] for r in rows], fill.positions, rtol=1e-14)
    # the baffle's lift: linear at lift_speed for round(lift_duration / dt) steps, then removed
    lift_steps = int(round(exp.lift_duration / deck.dt))
    assert re.search(r"fix lift all move/mesh mesh wall_baffle linear 0 0 0\.2\n(.*\n){2}run %d post no\n.*\nunfix lift"
                     % lift_steps, deck.deck)
    # the settle loop: KE criterion in chunks of settle_check_interval, at most fill_settle_max_time
    t_min, t_max = exp.fill_settle_times([fill])
    assert deck.settings["phases"]["fill_settle"]["max_steps"] == int(round(t_max / deck.dt))
    assert deck.settings["phases"]["fill_settle"]["chunk_steps"] == int(round(exp.settle_check_interval / deck.dt))
    assert "${ke_per_particle} < 1e-06" in deck.deck
    assert deck.settings["phases"]["after_lift_settle"]["max_steps"] == \
        int(round((exp.max_time_after_lift - exp.lift_duration) / deck.dt))
    assert sorted(deck.files) == ["fill.data"] + sorted(w.stl_name for w in capture_walls(exp, fill.top))


def test_drum_deck_rotation_and_snapshots():
    exp = RotatingDrum.from_config("quick")
    deck = write_deck(exp, {**FRICTION, "rpm": 45.0}, fill_mode="poured", dt=2e-4)
    assert "rotate origin 0 0 0 axis 0 1 0 period %.12g" % (60.0 / 45.0) in deck.deck
    n_frames = exp.record * exp.frames_per_revolution
    assert len(deck.settings["snapshot_files"]) == n_frames
    assert len(set(deck.settings["snapshot_files"])) == n_frames - (exp.record - 1)  # shared revolution ends
    assert "insert/rate/region" in deck.deck and "particledistribution/discrete/numberbased" in deck.deck


@needs_liggghts
def test_tiny_baffle_runs_and_reads_back(tmp_path):
    exp = _tiny_baffle()
    fill = fill_for_index(exp, 0)
    deck = write_deck(exp, {"mu_s_pp": 0.45, "mu_s_pw": 0.2, "mu_r_pp": 0.1, "mu_r_pw": 0.1}, fill_mode="identical",
                      fill=fill)
    m, run = run_and_measure(exp, deck, tmp_path / "run", timeout_s=120)
    before = read_dump(tmp_path / "run" / "after_fill.dump")[-1]
    assert len(before["id"]) == fill.sample.n  # nothing lost while settling in the box
    np.testing.assert_allclose(np.sort(before["radius"]), np.sort(fill.sample.radius), rtol=1e-12)
    np.testing.assert_allclose(before["mass"].sum(), fill.sample.total_mass, rtol=1e-9)
    assert m.status == "ok", m.error
    assert 0.0 < m.observables["static_angle"] < 60.0
    assert 1000.0 < m.observables["bulk_density"] < 2661.0
    assert m.diagnostics["phases"]["lift"]["end_step"] - m.diagnostics["phases"]["lift"]["start_step"] == \
        int(round(exp.lift_duration / deck.dt))


@needs_liggghts
def test_tiny_poured_cylinder_and_drum_run_and_read_back(tmp_path):
    cyl = HollowCylinder.from_config("quick", diameter=0.1, fill_mass=0.6, lift_speed=0.2, max_time_after_lift=0.4,
                                     fill_settle_max_time=0.3, plate_size=0.4, bin_width=0.01, min_bins=2,
                                     contact_law=wd.ContactLaw(rolling="epsd2", cohesion="sjkr"))
    deck = write_deck(cyl, {**FRICTION, "mu_r_pp": 0.3, "mu_r_pw": 0.3, "cohesion_energy_density_pp": 5e4},
                      fill_mode="poured", dt=2e-4)
    m, _ = run_and_measure(cyl, deck, tmp_path / "cyl", timeout_s=120)
    assert m.status == "ok", m.error
    assert m.observables["pile_height"] is not None and m.observables["pile_height"] >= 0.0
    assert m.diagnostics["particles_after_fill"] == pytest.approx(deck.n_particles, rel=0.1)
    assert "lift_plan" in m.diagnostics["phases"]

    drum = RotatingDrum.from_config("quick", diameter=0.16, length=0.08, crop_side=0.08, measure_y=(0.01, 0.07),
                                    bin_width=0.02, min_bins=2, discard=0, record=1, frames_per_revolution=3,
                                    max_skipped_snapshots=2, fill_settle_max_time=0.3,
                                    contact_law=wd.ContactLaw(rolling="epsd2"))
    deck = write_deck(drum, {**FRICTION, "mu_r_pp": 0.2, "mu_r_pw": 0.2, "rpm": 60.0}, fill_mode="identical", dt=2e-4)
    m, _ = run_and_measure(drum, deck, tmp_path / "drum", timeout_s=120)
    assert m.status == "ok", m.error
    assert math.isfinite(m.observables["dynamic_angle"])
    assert m.diagnostics["particles_final"] == deck.n_particles  # a closed drum loses nothing
