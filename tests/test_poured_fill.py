"""Poured fills (``fill_mode: poured``, issue 27): batches inserted at rest in the insertion region
as LIGGGHTS' ``insert/rate/region`` (docs/experiments.md, "Fill mode")."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

import calibration.experiments.common as common
from calibration.experiments import BaffleBox, HollowCylinder, make_experiment
from calibration.experiments.common import Experiment
from calibration.filling import member_positions, random_fill
from calibration.materials import BulkMaterial, sample_particles
from warpdem import ConfigError

FRICTION = dict(mu_s_pp=0.45, mu_s_pw=0.35)
#: a tiny poured baffle fill: 3 kg of the quick spheres, two insertion batches, a short lift
TINY = dict(fill_mass=3.0, lift_to=0.1, max_time_after_lift=0.3)


def test_bad_fill_mode_names_the_setting_and_the_choices():
    with pytest.raises(ConfigError, match=r"fill_mode must be one of \['loose', 'poured'\].*'heaped'"):
        BaffleBox.from_config("quick", fill_mode="heaped")
    with pytest.raises(ConfigError, match="fill_mode"):
        BaffleBox.from_config("quick", fill_mode=3)  # the schema: text
    with pytest.raises(ConfigError, match="pour_batch_fraction"):
        HollowCylinder.from_config("quick", fill_mode="poured", pour_batch_fraction=0.5)
    with pytest.raises(ConfigError, match="closed"):  # the drum's fill region is closed
        make_experiment("drum", "quick", fill_mode="poured")


def test_default_is_the_loose_fill_bit_for_bit(monkeypatch):
    """fill_mode defaults to loose; its fill is random_fill's and its protocol the settle it was
    (Experiment.settle_fill replaced by the two lines the protocols had): same positions, bit for bit."""
    exp = HollowCylinder.from_config("quick", fill_mass=0.6, lift_speed=0.5, max_time_after_lift=0.2)
    assert exp.fill_mode == "loose"
    m = exp.bulk_material()
    fill = exp.make_fill(m, np.random.default_rng(3))
    rng = np.random.default_rng(3)
    ref = random_fill(exp.fill_region(), sample_particles(m, rng=rng, **exp.fill_amount(m)), rng)
    assert np.array_equal(fill.positions, ref.positions) and fill.batch is None
    (new,) = exp.run([FRICTION], device="cpu")

    def old_fill_phase(self, ctx, remove_box=None):
        t_min, t_max = self.fill_settle_times_per_world(ctx.fills, ctx.num_worlds)
        ctx.settle("fill_settle", t_max, t_min, remove_box)

    monkeypatch.setattr(Experiment, "settle_fill", old_fill_phase)
    (old,) = exp.run([FRICTION], device="cpu")
    assert new.particles is not None and np.array_equal(new.particles[0], old.particles[0])
    assert new.timing["steps"] == old.timing["steps"] and "pour" not in new.timing["phases_s"]


def test_poured_fill_batches_lie_in_the_insertion_region():
    exp = BaffleBox.from_config("quick", fill_mode="poured", **TINY)
    m = exp.bulk_material()
    plan = exp.pour_plan(m)
    fill = exp.make_fill(m, np.random.default_rng(1))
    x, r, owner = member_positions(fill)
    drop = fill.batch[owner] * fill.batch_stride
    lo, hi = plan.region.bounds
    at_release = x - np.c_[np.zeros((len(x), 2)), drop]
    assert np.all(at_release - r[:, None] >= lo - 1e-12) and np.all(at_release + r[:, None] <= hi + 1e-12)
    # the region: LIGGGHTS' (inset by half the smallest radius and 1 mm, above the bed estimate)
    assert lo[0] == pytest.approx(0.5 * 0.012 + 1e-3) and hi[1] == pytest.approx(0.2 - 0.5 * 0.012 - 1e-3)
    # each batch holds pour_batch_fraction of the region as solid (to one particle)
    vol = fill.sample.mass / m.particle.density
    per_batch = np.bincount(fill.batch, weights=vol)
    assert len(per_batch) == 2 and np.all(per_batch <= plan.batch_volume + vol.max())
    assert plan.batch_volume == pytest.approx(0.10 * plan.volume)
    assert plan.interval >= np.sqrt(2.0 * (hi[2] - lo[2]) / 9.81) and plan.interval >= 0.1
    # the walls contain the insertion region, the motion starts after the pour and its settling
    assert exp.loose_top_bound(m) >= hi[2]
    assert exp.motion_start(m) == pytest.approx(plan.duration + exp.fill_settle_max_time + plan.t_fall)


def test_poured_fill_releases_without_overlap_and_stays_in_the_box(monkeypatch):
    """Every batch enters at rest clear of the particles in play; the whole fill ends in the box."""
    exp = BaffleBox.from_config("quick", fill_mode="poured", **TINY)
    releases, measured = [], []
    real_release = common.release_batches

    def checked_release(sim, bodies, drop, gap=0.0):
        done = real_release(sim, bodies, drop, gap)
        h = sim.model.host
        x = sim.sphere_positions()
        on = sim.state.body_active.numpy()[h["sphere_body"]] != 0
        new = np.isin(h["sphere_body"], np.asarray(bodies)[done])
        xa, ra, ba = x[on], h["sphere_radius"][on], h["sphere_body"][on]
        pairs = cKDTree(xa).query_pairs(2.0 * float(ra.max()), output_type="ndarray")
        pairs = pairs[ba[pairs[:, 0]] != ba[pairs[:, 1]]]
        fresh = new[on][pairs[:, 0]] | new[on][pairs[:, 1]]
        gaps = np.linalg.norm(xa[pairs[:, 0]] - xa[pairs[:, 1]], axis=1) - ra[pairs[:, 0]] - ra[pairs[:, 1]]
        v = sim.state.body_v.numpy()[np.asarray(bodies, dtype=np.int64)[done]]
        releases.append((int(done.sum()), float(gaps[fresh].min()) if fresh.any() else np.inf,
                         float(np.abs(v).max()) if v.size else 0.0))
        return done

    real_measure = BaffleBox._measure_fill

    def measure(self, ctx):
        xs, rs = ctx.world_spheres(0)
        measured.append((xs, rs, int(ctx.sim.state.body_active.numpy().sum())))
        return real_measure(self, ctx)

    monkeypatch.setattr(common, "release_batches", checked_release)
    monkeypatch.setattr(BaffleBox, "_measure_fill", measure)
    (r,) = exp.run([FRICTION], device="cpu")
    n = r.protocol["fill"]["particles_per_world"]
    assert len(releases) == r.diagnostics["pour_batch_times"] == 2
    held = np.count_nonzero(exp.make_fill(exp.bulk_material(), np.random.default_rng(exp.seed)).batch > 0)
    assert releases[0][0] > 0 and releases[0][0] + releases[1][0] == held  # batch 1, then nothing left
    assert all(gap >= -1e-6 for _, gap, _ in releases)  # no overlap at release
    assert all(v == 0.0 for *_, v in releases)  # at rest
    assert r.diagnostics["pour_not_inserted"] == 0 and r.diagnostics["fill_settle_settled"]
    xs, rs, active = measured[0]
    assert active == n == len(xs)  # every particle poured, none lost
    assert np.all(xs[:, 0] - rs > -1e-3) and np.all(xs[:, 0] + rs < exp.box_length + 1e-3)
    assert np.all(xs[:, 1] - rs > -1e-3) and np.all(xs[:, 1] + rs < exp.box_width + 1e-3)
    assert np.all(xs[:, 2] - rs > -1e-3) and np.all(xs[:, 2] + rs < exp.box_height)
    assert r.timing["phases_s"]["pour"] == pytest.approx(2 * exp.pour_plan(exp.bulk_material()).interval, rel=1e-3)


#: a small box of 12-15 mm spheres: 3.5 kg, about 1000 particles, fills 0.1 m high
SMALL_BOX = dict(material=BulkMaterial.spheres(0.012, 0.015), box_length=0.15, box_width=0.12, floor_length=0.30,
                 measure_y=(0.02, 0.10), fill_mass=3.5, lift_to=0.05, max_time_after_lift=0.3, density_margin=0.015,
                 density_top_margin=0.02, bin_width=0.015, fill_per_world=True)


@pytest.mark.slow
def test_poured_fill_packs_denser_than_the_loose_one():
    """Impact compaction: the poured box fill is denser than the loose column settled (at the quick
    scale of the LIGGGHTS labs' base case 1505 against 1456 kg/m^3, LIGGGHTS' pour 1513)."""
    rho = {}
    for mode in ("loose", "poured"):
        exp = BaffleBox.from_config("quick", fill_mode=mode, contact_law={"rolling": "none"}, **SMALL_BOX)
        res = exp.run([FRICTION] * 2, device="cpu")
        assert all(r.bulk_density is not None for r in res), [r.error for r in res]
        rho[mode] = np.array([r.bulk_density for r in res])
    assert rho["poured"].mean() > rho["loose"].mean() + 15.0, rho


def test_poured_cylinder_fill_ends_inside_the_tube(monkeypatch):
    exp = HollowCylinder.from_config("quick", fill_mass=1.5, fill_mode="poured", lift_speed=0.5,
                                     max_time_after_lift=0.3)
    seen = []
    real_plan = HollowCylinder._lift_plan

    def plan(self, ctx):
        seen.append(ctx.world_spheres(0))
        return real_plan(self, ctx)

    monkeypatch.setattr(HollowCylinder, "_lift_plan", plan)
    (r,) = exp.run([FRICTION], device="cpu")
    assert r.ok, r.error
    assert r.diagnostics["pour_batch_times"] == r.diagnostics["pour_batches"] > 1
    assert r.diagnostics["pour_not_inserted"] == 0
    xs, rs = seen[0]
    assert len(xs) == r.protocol["fill"]["particles_per_world"]
    assert np.all(np.hypot(xs[:, 0], xs[:, 1]) + rs < 0.5 * exp.diameter + 1e-3) and np.all(xs[:, 2] - rs > -1e-3)
    assert r.protocol["fill"]["loose_top_bound_m"] >= exp.pour_plan(exp.bulk_material()).top


def test_a_poured_world_does_not_depend_on_its_batch():
    """The pour's schedule follows the settings and the material, and each world's batches are
    released against its own particles: a world alone and in a batch of two pour alike, bit for bit."""
    kw = dict(fill_mass=1.5, fill_mode="poured", lift_speed=0.5, max_time_after_lift=0.2, fill_per_world=True)
    pair = HollowCylinder.from_config("quick", **kw).run([FRICTION, dict(mu_s_pp=0.3, mu_s_pw=0.3)], device="cpu")
    (alone,) = HollowCylinder.from_config("quick", **kw).run([FRICTION], device="cpu")
    assert pair[0].ok and alone.ok, (pair[0].error, alone.error)
    assert np.array_equal(pair[0].particles[0], alone.particles[0])
    assert pair[0].observables == alone.observables


def test_a_poured_batch_killed_mid_pour_continues_from_its_checkpoint(tmp_path, monkeypatch):
    """The pour's steps (hold, advance, release) resume from a batch checkpoint: killed mid-pour after
    a batch was released, the batch ends as the uninterrupted one, bit for bit."""
    from calibration.experiments.checkpoints import BatchCheckpoints
    from tests.test_batch_checkpoint import Killed, kill_after_save, outcome

    kw = dict(fill_mass=1.0, fill_mode="poured", lift_speed=0.5, max_time_after_lift=0.2, fill_per_world=True)
    sets = [FRICTION, dict(mu_s_pp=0.3, mu_s_pw=0.3)]
    reference = HollowCylinder.from_config("quick", **kw).run(sets, device="cpu")
    folder = tmp_path / "ck"
    saves = kill_after_save(monkeypatch, 5)  # 2 saves per 0.12 s interval: in the 3rd, after 2 releases
    with pytest.raises(Killed):
        HollowCylinder.from_config("quick", **kw).run(sets, device="cpu", checkpoints=BatchCheckpoints(folder, 1e-9))
    assert saves[-1][0] == "advance:pour"
    monkeypatch.undo()
    resumed = HollowCylinder.from_config("quick", **kw).run(sets, device="cpu", checkpoints=BatchCheckpoints(folder, 1e9))
    assert resumed[0].timing["checkpoint"]["resumed"]["in_step"] == "advance:pour"
    assert outcome(resumed) == outcome(reference)
    assert all(np.array_equal(a.particles[0], b.particles[0]) for a, b in zip(resumed, reference))


def test_release_order_and_overlap_rules_without_a_model():
    """LIGGGHTS' ``overlapcheck``: a waiting body goes in unless it would overlap an active sphere of
    its world or a body inserted before it in the same release; one that waits does not block later
    ones. Four single-sphere bodies of radius 0.01 m in one world, body 0 active at the origin."""
    import numpy as np

    from calibration.filling import release_batches

    class Arr:
        def __init__(self, a):
            self.a = np.array(a)

        def numpy(self):
            return self.a

        def assign(self, b):
            self.a = np.array(b)

    class FakeSim:
        def __init__(self, centres):
            n = len(centres)
            self.x = np.array(centres, float)
            self.model = type("M", (), {})()
            self.model.host = {"sphere_body": np.arange(n), "sphere_radius": np.full(n, 0.01, np.float32),
                               "sphere_world": np.zeros(n, int), "body_first": np.arange(n),
                               "body_count": np.ones(n, int), "body_world": np.zeros(n, int)}
            self.state = type("S", (), {})()
            self.state.body_q = Arr(np.c_[self.x, np.zeros((n, 4))].astype(np.float32))
            self.state.body_active = Arr([1] + [0] * (n - 1))
            self.state.body_v, self.state.body_w = Arr(np.ones((n, 3))), Arr(np.ones((n, 3)))
            self.solver = type("V", (), {"invalidate_views": lambda s: None,
                                         "request_neighbour_rebuild": lambda s: None})()

        def sphere_positions(self):
            return self.x

    # after the drop of 0.1 m: body 1 lands 0.015 m from the active body 0 (blocked), body 2 lands free,
    # body 3 lands 0.015 m from body 2 (waits: 2 went in first), body 4 lands 0.015 m from body 1 (free:
    # body 1 stayed out)
    sim = FakeSim([[0, 0, 0], [0.015, 0, 0.1], [0.2, 0, 0.1], [0.215, 0, 0.1], [0.015, 0.015, 0.1]])
    done = release_batches(sim, np.array([1, 2, 3, 4]), np.full(4, 0.1))
    assert done.tolist() == [False, True, False, True]
    assert sim.state.body_active.a.tolist() == [1, 0, 1, 0, 1]
    assert sim.state.body_q.a[[2, 4], 2] == pytest.approx(0.0, abs=1e-6) and sim.state.body_q.a[3, 2] == pytest.approx(0.1)  # float32
    assert np.all(sim.state.body_v.a[[2, 4]] == 0) and np.all(sim.state.body_v.a[[1, 3]] == 1)
