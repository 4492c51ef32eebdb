"""Standard experiments (docs/experiments.md): materials, fills, levelling,
configs and quick-scale runs of A (baffle), B (drum) and C (hollow cylinder).

The quick runs take 20-40 s each on 2 CPU cores."""
import json
import math

import numpy as np
import pytest

import warpdem as wd
from calibration.experiments import BaffleBox, HollowCylinder, RotatingDrum, make_experiment
from calibration.experiments.cli import check_config, experiment_main
from calibration.experiments.common import normalize_parameter_sets
from calibration.filling import (Box, FillError, HorizontalCylinder, VerticalCylinder, check_no_overlap, level,
                                 member_positions, random_fill)
from calibration.materials import BulkMaterial, sample_particles

LOW = dict(mu_s_pp=0.3, mu_s_pw=0.3, mu_r_pp=0.05, mu_r_pw=0.05)
HIGH = dict(mu_s_pp=0.6, mu_s_pw=0.6, mu_r_pp=0.15, mu_r_pw=0.15)


def dumbbell_material(size_scale=1.0):
    cg = pytest.importorskip("warpdem.clump_geometry")
    t1 = cg.make_template([[-0.006, 0, 0], [0.006, 0, 0]], [0.008, 0.008], 2661.0, name="dumbbell")
    t2 = cg.make_template([[0, 0, 0]], [0.009], 2661.0, name="ball")
    return BulkMaterial.clump_mix([(t1, 0.75), (t2, 0.25)], size_scale=size_scale)


# --------------------------------------------------------------------------- materials
def test_sample_spheres_by_mass_and_count():
    m = BulkMaterial.spheres(0.016, 0.020)
    s = sample_particles(m, mass=2.0, rng=1)
    assert abs(s.total_mass - 2.0) <= s.mass.max()
    d = 2 * s.radius
    assert d.min() >= 0.016 and d.max() <= 0.020 and d.std() > 0.0005  # uniform, not fixed
    assert sample_particles(BulkMaterial.spheres(0.018), n=7, rng=0).radius.tolist() == [0.009] * 7


def test_sample_clump_mix_follows_number_fractions():
    mat = dumbbell_material()
    s = sample_particles(mat, n=40, rng=0)
    assert np.count_nonzero(s.template == 0) == 30 and np.count_nonzero(s.template == 1) == 10
    s = sample_particles(mat, mass=1.0, rng=0)
    assert abs(s.total_mass - 1.0) < max(t.mass for t, _ in mat.clumps)


def test_material_validation():
    with pytest.raises(wd.ConfigError, match="exactly one"):
        BulkMaterial()
    with pytest.raises(wd.ConfigError, match="millimetres"):
        BulkMaterial.spheres(16, 20)
    with pytest.raises(wd.ConfigError, match="d_min <= d_max"):
        BulkMaterial.spheres(0.02, 0.01)
    with pytest.raises(wd.ConfigError, match="unknown key"):
        BulkMaterial.from_config({"type": "spheres", "diameter": 0.02, "colour": "grey"})
    with pytest.raises(wd.ConfigError, match="exactly one of n"):
        sample_particles(BulkMaterial.spheres(0.02), rng=0)
    m = BulkMaterial.from_config({"type": "spheres", "diameter": [0.016, 0.02], "density": 2500})
    assert m.particle.density == 2500 and m.diameter == (0.016, 0.02)


# --------------------------------------------------------------------------- fill
@pytest.mark.parametrize("region", [Box((0, 0, 0), (0.15, 0.1, 0.1)), VerticalCylinder((0, 0), 0.07, 0, 0.1),
                                    HorizontalCylinder((0, 0), 0.1, 0, 0.08)])
def test_fill_has_no_overlaps_and_stays_inside(region):
    s = sample_particles(BulkMaterial.spheres(0.016, 0.020), mass=1.5, rng=3)
    f = random_fill(region, s, rng=3)
    x, r, _ = member_positions(f)
    # independent overlap check: all pairs
    d = np.linalg.norm(x[:, None] - x[None], axis=2) - (r[:, None] + r[None])
    np.fill_diagonal(d, 1.0)
    assert d.min() > 0
    assert np.all(region.contains(x, r, 0.0))
    assert check_no_overlap(f) == 0.0


def test_fill_rises_above_open_region_and_refuses_closed_one():
    s = sample_particles(BulkMaterial.spheres(0.02), n=60, rng=0)
    f = random_fill(Box((0, 0, 0), (0.1, 0.1, 0.05)), s, rng=0)
    assert f.above_region and f.top > 0.05
    with pytest.raises(FillError, match="fit"):
        random_fill(Box((0, 0, 0), (0.1, 0.1, 0.05), open_top=False), s, rng=0)


def test_pour_fill_fills_a_closed_drum_beyond_one_loose_pass():
    from calibration.experiments.drum import drum_mesh
    from calibration.filling import pour_fill

    R, L = 0.08, 0.06
    region = HorizontalCylinder((0, 0), R, 0, L)
    s = sample_particles(BulkMaterial.spheres(0.016, 0.020), mass=0.45 * math.pi * R * R * L * 0.6 * 2661, rng=0)
    assert not random_fill(region, s, 0, allow_partial=True).complete  # one loose pass is not enough
    f = pour_fill(region, s, lambda b: b.add_wall(drum_mesh(R, L, 48), wd.PLEXIGLAS), rng=0, device="cpu")
    assert f.complete and f.settled and f.pours >= 1
    x, r, _ = member_positions(f)
    assert np.all(np.hypot(x[:, 0], x[:, 2]) + r < R + 0.05 * r)
    assert check_no_overlap(f, tol=0.1 * r.min()) < 0.1 * r.min()  # only small settled contact overlaps


def test_clump_fill_no_member_overlaps():
    mat = dumbbell_material()
    s = sample_particles(mat, n=80, rng=2)
    f = random_fill(Box((0, 0, 0), (0.12, 0.12, 0.1)), s, rng=2)
    assert check_no_overlap(f) == 0.0
    x, r, owner = member_positions(f)
    assert len(x) == 2 * 60 + 20
    # the model builder's own overlap check agrees
    b = wd.ModelBuilder()
    b.add_material(wd.GRAVEL)
    from calibration.filling import add_fill

    add_fill(b, f, "gravel", 0)
    m = b.finalize("cpu", overlap_tolerance=0.0)
    assert m.num_bodies == 80 and m.num_spheres == 140


def test_level_deactivates_bodies_above_height():
    b = wd.ModelBuilder(num_worlds=2)
    b.add_material(wd.GRAVEL)
    z = np.array([0.01, 0.031, 0.052])
    pos = np.stack([np.zeros(3), np.zeros(3), z], 1)
    for w in range(2):
        b.add_spheres(pos, 0.01, "gravel", world=w)
    sim = wd.Simulation(b.finalize("cpu"), 1e-5)
    removed = level(sim, 0.045)  # tops at 0.02, 0.041, 0.062
    assert removed.tolist() == [1, 1]
    assert sim.state.body_active.numpy().tolist() == [1, 1, 0, 1, 1, 0]


# --------------------------------------------------------------------------- configs
def test_unknown_settings_and_parameters_raise_clear_errors():
    with pytest.raises(wd.ConfigError, match=r"unknown setting\(s\) \['baffle_hieght'\]"):
        make_experiment("baffle", "quick", baffle_hieght=0.5)
    with pytest.raises(wd.ConfigError, match="unknown scale"):
        make_experiment("drum", "huge")
    with pytest.raises(wd.ConfigError, match="max_skipped_snapshots must be a finite number >= 0"):
        make_experiment("drum", "quick", max_skipped_snapshots=-1)
    with pytest.raises(wd.ConfigError, match="unknown experiment"):
        make_experiment("chute")
    with pytest.raises(wd.ConfigError, match=r"worlds: unknown key; valid: contact_law, description, device"):
        check_config({"experiment": "baffle", "parameters": [{}], "worlds": 3})
    names = wd.ContactLaw(rolling="epsd").parameter_names
    with pytest.raises(wd.ConfigError, match="unknown contact parameter 'mu_pp'"):
        normalize_parameter_sets([{"mu_pp": 0.3}], names)
    with pytest.raises(wd.ConfigError, match="differ in length"):
        normalize_parameter_sets({"mu_s_pp": [0.1, 0.2], "mu_r_pp": [0.1]}, names)
    assert normalize_parameter_sets({"mu_s_pp": [0.1, 0.2]}, names) == [{"mu_s_pp": 0.1}, {"mu_s_pp": 0.2}]
    with pytest.raises(wd.ConfigError, match="lift_speed"):
        BaffleBox(lift_speed=-0.1)
    with pytest.raises(wd.ConfigError, match="crop_side"):
        RotatingDrum(crop_side=0.5)


def test_cli_rejects_unknown_key(tmp_path, capsys):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("experiment: baffle\nscale: quick\nparameters: [{}]\nsettings: {lift_sped: 0.2}\n")
    assert experiment_main([str(cfg), "--output", str(tmp_path / "out")]) == 2
    assert "lift_sped" in capsys.readouterr().err


# --------------------------------------------------------------------------- tiny runs
TINY_CYL = dict(fill_mass=0.4, lift_speed=0.5, max_time_after_lift=0.2)


def test_failed_measurement_is_recorded_not_dropped():
    exp = HollowCylinder.from_config("quick", min_bins=10_000, min_pile_layers=0.0, **TINY_CYL)
    res = exp.run([LOW, HIGH], device="cpu")
    assert [r.world for r in res] == [0, 1]
    for r in res:
        assert r.status == "failed" and r.angle_deg is None
        assert "10000" in r.error and "gamma_s" in r.error
        assert r.to_dict()["status"] == "failed"


def test_cli_writes_vtk_series_when_asked(tmp_path, monkeypatch):
    """``vtk_every`` makes ``warpdem experiment`` write <output>/vtk/*.pvd (default output folder)."""
    pv = pytest.importorskip("pyvista")
    monkeypatch.chdir(tmp_path)
    cfg = {"experiment": "cylinder", "scale": "quick", "device": "cpu", "processes": 2,
           "settings": {**TINY_CYL, "vtk_every": 0.1, "vtk_world": 1},
           "parameters": {"mu_s_pp": [0.5, 0.3], "mu_r_pp": [0.1, 0.1]}}
    (tmp_path / "tiny.json").write_text(json.dumps(cfg))
    assert experiment_main(["tiny.json", "--no-plots"]) in (0, 1)
    vtk = tmp_path / "experiment_cylinder_quick" / "vtk"
    assert sorted(p.name for p in vtk.glob("*.pvd")) == ["particles.pvd", "wall_cylinder.pvd", "wall_plate.pvd"]
    reader = pv.PVDReader(str(vtk / "particles.pvd"))
    times = np.array(reader.time_values)
    doc = json.loads((tmp_path / "experiment_cylinder_quick" / "results.json").read_text())
    r = doc["results"][1]
    assert times[0] == 0.0 and np.all(np.diff(times) > 0) and len(times) >= 4
    assert "vtk_every" not in r["protocol"]["deviations_from_paper"]  # output, not physics
    reader.set_active_time_value(times[-1])
    cloud = reader.read()[0]
    assert cloud.n_points > 0 and np.all(cloud["world"] == 1)
    assert {"velocity", "angular_velocity", "contact_force", "radius", "id"} <= set(cloud.point_data.keys())
    # the cylinder rose during the lift: its last frame is above its first
    walls = pv.PVDReader(str(vtk / "wall_cylinder.pvd"))
    walls.set_active_time_value(walls.time_values[0])
    z0 = walls.read()[0].points[:, 2].min()
    walls.set_active_time_value(walls.time_values[-1])
    assert walls.read()[0].points[:, 2].min() > z0 + 0.05


def test_vtk_settings_are_checked():
    with pytest.raises(wd.ConfigError, match="vtk_every"):
        HollowCylinder.from_config("quick", vtk_every=0.0)
    with pytest.raises(wd.ConfigError, match="vtk_world 3 does not exist"):
        HollowCylinder.from_config("quick", vtk_every=0.1, vtk_world=3, vtk_folder="unused", **TINY_CYL).run(
            [{"mu_s_pp": 0.5}], device="cpu")


def test_cli_writes_results_and_pictures(tmp_path):
    cfg = {"experiment": "cylinder", "scale": "quick", "device": "cpu", "settings": TINY_CYL,
           "parameters": {"mu_s_pp": [0.5], "mu_r_pp": [0.1]}}
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(cfg))
    code = experiment_main([str(path), "--output", str(tmp_path / "out")])
    assert code in (0, 1)  # a 15-sphere pile may be too small to measure; the run must still report
    doc = json.loads((tmp_path / "out" / "results.json").read_text())
    r = doc["results"][0]
    assert r["scale"] == "quick" and r["protocol"]["deviations_from_paper"]["lift_speed"]["paper"] == 0.01
    assert r["timing"]["steps"] > 0 and r["contact_parameters"]["mu_s_pp"] == pytest.approx(0.5)
    assert (tmp_path / "out" / "world_000.png").stat().st_size > 1000
    html = (tmp_path / "out" / "report.html").read_text()
    assert "Experiment: cylinder" in html and "pile_height [m]" in html and "data:image/png;base64" in html


def test_clump_material_runs_through_an_experiment():
    mat = dumbbell_material(size_scale=1.5)
    exp = HollowCylinder.from_config("quick", material=mat, fill_mass=0.5, lift_speed=0.5, max_time_after_lift=0.2)
    (r,) = exp.run([HIGH], device="cpu")
    assert r.timing["spheres"] > r.timing["bodies"] > 0  # clumps, not spheres
    assert r.status == "ok" or "gamma_s" in r.error
    assert r.protocol["settings"]["material"]["type"] == "clumps"


# --------------------------------------------------------------------------- quick experiments
def test_quick_baffle_higher_friction_steeper():
    exp = make_experiment("baffle", "quick")
    res = exp.run([LOW, HIGH], device="cpu")
    assert [r.status for r in res] == ["ok", "ok"], [r.error for r in res]
    a_low, a_high = (r.angle_deg for r in res)
    assert math.isfinite(a_low) and math.isfinite(a_high)
    assert a_high > a_low + 3.0, (a_low, a_high)
    for r in res:
        assert r.angle_name == "alpha_AoR_S" and r.diagnostics["fit"]["n_bins"] >= 3
        assert 900 < r.bulk_density < 2661  # loose, below the solid density
        assert 0.05 < r.diagnostics["h_fill_m"] < 0.4
        assert r.timing["steps"] > 0 and r.timing["phases_s"]["lift"] == pytest.approx(0.30 / 0.2, rel=0.01)
        json.dumps(r.to_dict())
    assert res[0].protocol["deviations_from_paper"]["lift_speed"] == {"value": 0.2, "paper": 0.1}


def test_quick_drum_dynamic_angle_with_spread():
    exp = make_experiment("drum", "quick")
    (r,) = exp.run([HIGH], device="cpu")
    assert r.ok, r.error
    d = r.diagnostics
    frames = exp.frames_per_revolution  # quick: 9 per revolution, start and end included
    assert frames == 9 and d["snapshots"] == frames * 2 and len(d["snapshot_angles_deg"]) == frames * 2
    assert np.diff(d["snapshot_times_s"][:frames]) == pytest.approx(np.full(frames - 1, 2.0 / (frames - 1)))
    assert 10.0 < r.angle_deg < 70.0
    assert math.isfinite(d["snapshot_std_deg"]) and d["snapshot_std_deg"] > 0
    # beta is atan of the mean slope, close to the mean of the snapshot angles
    assert abs(r.angle_deg - d["snapshot_mean_deg"]) < 3 * d["snapshot_std_deg"] + 1.0
    assert r.timing["phases_s"]["rotation"] == pytest.approx(3 * 60 / 30.0, rel=0.01)


def test_quick_cylinder_four_thetas():
    exp = make_experiment("cylinder", "quick")
    (r,) = exp.run([HIGH], device="cpu")
    assert r.ok, r.error
    th = np.array(r.diagnostics["thetas_deg"])
    assert th.shape == (4,) and np.all(np.isfinite(th)) and np.all(th > 0)
    assert r.angle_deg == pytest.approx(th.mean())
    assert r.diagnostics["peak_height_m"] > 0.03


@pytest.mark.slow
def test_quick_baffle_spread_of_friction_is_monotonic():
    """Four friction levels from frictionless-ish to rough, each the mean of 3 different loose
    fills (one world each): a single quick-scale fill scatters by ~3-5 deg (~3 min on 2 cores)."""
    vals = [(0.2, 0.0), (0.35, 0.05), (0.5, 0.1), (0.7, 0.2)]
    reps = 3
    res = make_experiment("baffle", "quick", fill_per_world=True).run(
        [dict(mu_s_pp=a, mu_s_pw=a, mu_r_pp=b, mu_r_pw=b) for a, b in vals for _ in range(reps)], device="cpu")
    per_world = [r.angle_deg if r.ok else 0.0 for r in res]
    angles = [float(np.mean(per_world[k * reps:(k + 1) * reps])) for k in range(len(vals))]
    assert all(b > a for a, b in zip(angles, angles[1:])), angles


def test_slot_overflow_reruns_with_more_slots_or_names_the_capacity():
    """A neighbour list too small for the packing is re-run from the same fill with the
    capacity the overflow reported (recorded in the timing); with retries off the error names
    the capacity needed."""
    exp = make_experiment("baffle", "quick", max_neighbours=3)
    r = exp.run([{"mu_s_pp": 0.5}], device="cpu")[0]
    assert r.ok, r.error
    retries = r.timing["retries"]
    assert 1 <= len(retries) <= exp.overflow_retries and retries[0]["capacity"] == 3
    for retry in retries:
        assert retry["kind"] == "neighbours" and retry["needed"] > retry["capacity"]
        assert retry["rerun_with"] >= 1.25 * retry["needed"]
    assert r.timing["max_neighbours"] == retries[-1]["rerun_with"]
    strict = make_experiment("baffle", "quick", max_neighbours=3, overflow_retries=0)
    r = strict.run([{"mu_s_pp": 0.5}], device="cpu")[0]
    assert not r.ok and "max_neighbours >=" in r.error and r.timing["retries"] == []


def test_cpu_worlds_split_over_processes_keep_order_and_parameters():
    """processes=2 runs the worlds in two spawned interpreters; results come back in world
    order with their own parameters and per-world fills (seeded by the global world index)."""
    from calibration.experiments.common import cpu_processes

    exp = make_experiment("baffle", "quick", fill_mass=8.0, max_time_after_lift=1.6, fill_per_world=True)
    sets = [{"mu_s_pp": v} for v in (0.3, 0.4, 0.5)]
    res = exp.run(sets, device="cpu", processes=2)
    assert [r.world for r in res] == [0, 1, 2]
    assert [r.parameters["mu_s_pp"] for r in res] == [0.3, 0.4, 0.5]
    assert [r.contact_parameters["mu_s_pp"] for r in res] == pytest.approx([0.3, 0.4, 0.5])
    assert {r.timing["processes"] for r in res} == {2} and res[2].timing["chunk_first_world"] == 2
    # world 2 ran alone in the second process with the fill of global world 2
    alone = make_experiment("baffle", "quick", fill_mass=8.0, max_time_after_lift=1.6, fill_per_world=True,
                            first_fill_index=2).run(sets[2:], device="cpu")[0]
    assert alone.diagnostics["particles_before_lift"] == res[2].diagnostics["particles_before_lift"]
    assert alone.angle_deg == res[2].angle_deg
    assert cpu_processes("auto", "cuda") == 1 and cpu_processes(3, "cpu") == 3
    with pytest.raises(wd.ConfigError, match="processes"):
        cpu_processes(0, "cpu")


def test_world_result_does_not_depend_on_its_batch():
    """Worlds sharing a fill are independent: a settled world is paused at rest while slower
    worlds settle, so world 1 of a three-world batch ends exactly as the same world run alone
    (even though the batch settles for longer)."""
    kw = dict(max_time_after_lift=2.5)
    # world 0 (bouncy, slippery) settles its fill last, so world 1 waits paused in the batch
    sets = [{"mu_s_pp": 0.1, "restitution_pp": 0.9}, {"mu_s_pp": 0.5}, {"mu_s_pp": 0.8}]
    batch = make_experiment("baffle", "quick", **kw).run(sets, device="cpu")
    alone = make_experiment("baffle", "quick", **kw).run(sets[1:2], device="cpu")[0]
    assert batch[1].ok and alone.ok
    assert batch[1].timing["phases_s"]["fill_settle"] > alone.timing["phases_s"]["fill_settle"]
    assert batch[1].angle_deg == alone.angle_deg
    np.testing.assert_array_equal(batch[1].particles[0], alone.particles[0])


def test_an_unstable_world_fails_alone_and_the_batch_goes_on(monkeypatch):
    """A world whose bodies turn NaN is frozen by the engine and marked failed with the cause;
    the other world of the batch is measured as if it had run alone."""
    original = HollowCylinder.protocol

    def poisoned(self, ctx, t_motion):
        v = ctx.sim.state.body_v.numpy()
        v[ctx.sim.model.host["body_world"] == 1] = np.nan
        ctx.sim.state.body_v.assign(v)
        return original(self, ctx, t_motion)

    exp = HollowCylinder.from_config("quick", min_pile_layers=0.0, **TINY_CYL)
    alone = exp.run([LOW], device="cpu", processes=1)[0]
    monkeypatch.setattr(HollowCylinder, "protocol", poisoned)
    with pytest.warns(Warning, match="unstable|frozen"):
        res = exp.run([LOW, LOW], device="cpu", processes=1)
    assert res[1].status == "failed" and "unstable" in res[1].error and "NaN" in res[1].error
    assert "unstable" not in (res[0].error or "")
    assert res[0].observables == alone.observables
