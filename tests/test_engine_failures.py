"""Fail loudly, lose nothing (issue 12, engine part): unstable worlds are frozen and named while
the others finish unchanged; forced and per-step time steps above the limit are stated; spheres
started inside walls are refused; states and checkpoints carry their model's fingerprint; a
damaged checkpoint names its file; mismatched builder inputs name the argument and both lengths."""
import time
import zipfile

import numpy as np
import pytest

import warpdem as wd
from warpdem import geometry
from warpdem.io import load_checkpoint, save_checkpoint

R = 0.009
DT = 5e-5


def world_spheres(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """8 spheres in a 2x2x2 grid in the box, with random velocities (positions [m], velocities [m/s])."""
    rng = np.random.default_rng(seed)
    g = np.array([0.015, 0.04])
    pos = np.stack(np.meshgrid(g, g, g + 0.005, indexing="ij"), -1).reshape(-1, 3)
    pos += rng.uniform(-1e-3, 1e-3, pos.shape)
    return pos, rng.normal(0, 0.3, pos.shape)


def box_model(num_worlds: int, fast: dict | None = None, **kw) -> wd.ModelBuilder:
    """``num_worlds`` worlds of 8 spheres in a shared open box; ``fast`` = {world: velocity of
    its first sphere [m/s]}."""
    b = wd.ModelBuilder(num_worlds=num_worlds, **kw)
    b.add_material(wd.GRAVEL)
    for w in range(num_worlds):
        pos, vel = world_spheres(w)
        if fast and w in fast:
            vel[0] = fast[w]
        b.add_spheres(pos, R, "gravel", world=w, velocities=vel)
    b.add_wall(geometry.open_box((0, 0, 0), (0.055, 0.055, 0.2)), "gravel", name="box")
    return b


def world0_alone(steps: int) -> np.ndarray:
    sim = wd.Simulation(box_model(1).finalize("cpu"), DT)
    sim.run(steps)
    return sim.state.body_q.numpy()


# ----------------------------------------------------------------------------- 1. unstable worlds
def test_fast_world_frozen_named_and_others_unchanged():
    sim = wd.Simulation(box_model(2, fast={1: (1e4, 0.0, 0.0)}).finalize("cpu"), DT)
    with pytest.raises(wd.StabilityError, match=r"world 1: a body faster than v_max") as err:
        sim.run(50, check_every=50)
    assert set(err.value.worlds) == {1} and "v_max" in err.value.worlds[1]
    x1 = sim.state.body_q.numpy()[8:].copy()
    sim.run(150, check_every=50)  # already reported: the run goes on, world 1 stays frozen
    q = sim.state.body_q.numpy()
    np.testing.assert_array_equal(q[8:], x1)
    assert np.all(np.isfinite(q)) and np.abs(q[8:]).max() < 1.0  # put back, not left at 1e4 m/s
    np.testing.assert_array_equal(q[:8], world0_alone(200))
    assert sim.failed_worlds() == err.value.worlds


def test_nan_world_named_as_nan_not_overflow_and_freeze_mode_goes_on():
    """A NaN entering one body (here through an external force, e.g. a broken coupling) in a
    dense world: the world is frozen with cause NaN, no ContactOverflowError, the other world
    is untouched; with on_unstable="freeze" the run goes on and lists it."""
    b = box_model(2, gravity=(0, 0, 0))
    m = b.finalize("cpu")
    sim = wd.Simulation(m, DT)
    f = np.zeros((m.num_bodies, 3), np.float32)
    f[8:, :] = np.nan  # every body of world 1
    sim.solver.external_force.assign(f)
    sim.solver.use_external_force = True
    with pytest.warns(wd.StabilityWarning, match=r"world 1: NaN/inf"):
        failed = sim.run(100, check_every=20, on_unstable="freeze")
    assert failed == {1: "NaN/inf in a body state"} and sim.failed_worlds() == failed
    assert np.all(np.isfinite(sim.state.body_q.numpy()))
    ref = wd.Simulation(box_model(1, gravity=(0, 0, 0)).finalize("cpu"), DT)
    ref.run(100)
    np.testing.assert_array_equal(sim.state.body_q.numpy()[:8], ref.state.body_q.numpy())
    with pytest.raises(wd.ConfigError, match="on_unstable"):
        sim.run(1, on_unstable="ignore")


def test_instability_reported_before_contact_overflow():
    """A world that both blew up and overflowed its contact slots is named as unstable first
    (the overflow stays a separate, later error)."""
    b = wd.ModelBuilder(num_worlds=2, max_contacts=2, gravity=(0, 0, 0))
    b.add_material(wd.GRAVEL)
    b.add_spheres([(0, 0, 0), (0.0179, 0, 0), (-0.0179, 0, 0), (0, 0.0179, 0)], R, "gravel", world=1,
                  velocities=[(0, 0, 3e3), (0, 0, 0), (0, 0, 0), (0, 0, 0)])
    b.add_sphere((0, 0, 0), R, "gravel", world=0)
    sim = wd.Simulation(b.finalize("cpu"), DT)
    with pytest.raises(wd.StabilityError, match="world 1"):
        sim.run(5)
    with pytest.raises(wd.ContactOverflowError, match="max_contacts"):
        sim.solver.check()


def test_resume_keeps_unstable_world_frozen_and_settle_reports_it():
    sim = wd.Simulation(box_model(2, fast={0: (0.0, 0.0, -5e3)}).finalize("cpu"), DT)
    with pytest.warns(wd.StabilityWarning, match="world 0"):
        rep = sim.settle(max_time=0.01, check_interval=0.005, on_unstable="freeze")
    assert set(rep.failed) == {0} and not rep.settled
    assert sim.solver.paused_worlds.tolist() == [True, False]  # settle resumed all, world 0 stays frozen


def test_speed_bound_formula():
    m = box_model(1).finalize("cpu")
    q = m.initial["body_q"]
    pts = np.concatenate([q, m.walls[0].vertices])
    extent = np.linalg.norm(pts.max(0) - pts.min(0))
    assert wd.DEMSolver(m, DT, v_ref=3.0).v_max == pytest.approx(10 * 3.0 + np.sqrt(2 * 9.81 * extent))
    assert wd.DEMSolver(m, DT, v_max=7.0).v_max == 7.0


# ----------------------------------------------------------------------------- 2. time steps
def test_forced_time_step_warns_with_factor():
    m = box_model(1).finalize("cpu")
    lim = wd.time_step_limits(m).limit
    with pytest.warns(wd.StabilityWarning, match=r"2\.00 x the stability limit"):
        wd.Simulation(m, 2 * lim, force=True)


def test_step_dt_above_limit_refused_or_warned():
    m = box_model(1).finalize("cpu")
    lim = wd.time_step_limits(m).limit
    solver = wd.DEMSolver(m, 0.5 * lim)
    a, b = m.state(), m.state()
    with pytest.raises(wd.ConfigError, match=rf"dt = {3 * lim:.3g} s exceeds the stability limit {lim:.3g} s"):
        solver.step(a, b, dt=3 * lim)
    solver.step(a, b, dt=0.9 * lim)  # below the limit: accepted
    forced = wd.DEMSolver(m, 0.5 * lim, force=True)  # within the limit: no warning
    with pytest.warns(wd.StabilityWarning, match=rf"dt = {3 * lim:.3g} s .*3\.00 x the limit"):
        forced.step(a, b, dt=3 * lim)


# ----------------------------------------------------------------------------- 3. walls
def floor_model(z: float, world_of_floor: int = -1, motion=None) -> wd.ModelBuilder:
    b = wd.ModelBuilder(num_worlds=2)
    b.add_material(wd.GRAVEL)
    b.add_spheres([(0.0, 0.0, z), (0.05, 0.0, 0.1)], R, "gravel", world=[1, 0])
    b.add_wall(geometry.plane((0, 0, 0), 0.2, 0.2), "gravel", world=world_of_floor, name="floor", motion=motion)
    return b


def test_sphere_started_inside_a_wall_refused():
    with pytest.raises(wd.OverlapError, match=r"sphere 0 \(world 1\) overlaps wall 'floor' by .* = 50.0% of its radius"):
        floor_model(0.5 * R).finalize("cpu")
    floor_model(R).finalize("cpu")  # touching
    floor_model(0.97 * R).finalize("cpu")  # within the 5 % tolerance
    floor_model(0.5 * R, world_of_floor=0).finalize("cpu")  # the floor is in the other world
    floor_model(0.5 * R).finalize("cpu", overlap_tolerance=0.6)
    floor_model(0.5 * R).finalize("cpu", check_overlaps=False)
    # a wall that starts moving later is checked where it is at t = 0
    lift = wd.WallMotion.translation((0, 0, 1.0), start=0.5)
    with pytest.raises(wd.OverlapError, match="wall 'floor'"):
        floor_model(0.5 * R, motion=lift).finalize("cpu")


def test_wall_overlap_check_fast_for_1e5_spheres():
    n_side = 47  # 103823 spheres in a box, touching the floor
    b = wd.ModelBuilder()
    b.add_material(wd.GRAVEL)
    g = (np.arange(n_side) + 0.5) * 2.2 * R
    pos = np.stack(np.meshgrid(g, g, g + R - 1.1 * R, indexing="ij"), -1).reshape(-1, 3)
    b.add_spheres(pos, R, "gravel")
    side = n_side * 2.2 * R
    b.add_wall(geometry.open_box((0, 0, 0), (side, side, side)), "gravel")
    from warpdem.builder import _check_wall_overlaps

    m = b.finalize("cpu", check_overlaps=False)
    x = m.initial["body_q"].astype(np.float64)
    _check_wall_overlaps(m, x, 0.05)  # compile outside the timing
    t0 = time.perf_counter()
    _check_wall_overlaps(m, x, 0.05)
    assert time.perf_counter() - t0 < 2.0
    x[5, 2] = 0.3 * R
    with pytest.raises(wd.OverlapError, match="sphere 5"):
        _check_wall_overlaps(m, x, 0.05)


# ----------------------------------------------------------------------------- 4. fingerprints
def test_fingerprint_tells_models_apart():
    a = box_model(1).finalize("cpu")
    assert a.fingerprint == box_model(1).finalize("cpu").fingerprint
    b = box_model(1, max_contacts=12).finalize("cpu")
    c = box_model(2).finalize("cpu")
    bw = box_model(1)
    bw.walls[0].vertices[0, 0] += 1e-4
    assert len({a.fingerprint, b.fingerprint, c.fingerprint, bw.finalize("cpu").fingerprint}) == 4
    a.set_contact_parameter("mu_s_pp", 0.4)  # run settings are not part of the identity
    assert a.fingerprint == box_model(1).finalize("cpu").fingerprint
    solver = wd.DEMSolver(a, DT)
    with pytest.raises(wd.ConfigError, match=f"model {c.fingerprint}.*model {a.fingerprint}"):
        solver.step(c.state(), a.state())
    with pytest.raises(wd.ConfigError, match=f"{c.fingerprint}.*{a.fingerprint}"):
        a.state().assign(c.state())


def test_checkpoint_of_another_model_refused(tmp_path):
    sim = wd.Simulation(box_model(1).finalize("cpu"), DT)
    sim.run(10)
    path = save_checkpoint(tmp_path / "ck.npz", sim)
    other = box_model(1, gravity=(0, 0, -9.0)).finalize("cpu")
    with pytest.raises(wd.ConfigError, match=f"{sim.model.fingerprint}.*{other.fingerprint}"):
        load_checkpoint(path, "cpu", model=other)
    again = load_checkpoint(path, "cpu", model=box_model(1).finalize("cpu"))
    np.testing.assert_array_equal(again.state.body_q.numpy(), sim.state.body_q.numpy())
    assert again.steps == 10


def test_damaged_checkpoint_names_the_file(tmp_path):
    sim = wd.Simulation(box_model(1).finalize("cpu"), DT)
    path = save_checkpoint(tmp_path / "ck.npz", sim)
    raw = path.read_bytes()
    cut = tmp_path / "cut.npz"
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(wd.ConfigError, match="cut.npz"):
        load_checkpoint(cut, "cpu")
    # a complete zip missing one array
    holed = tmp_path / "holed.npz"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(holed, "w") as dst:
        for item in src.infolist():
            if item.filename != "state/body_q.npy":
                dst.writestr(item, src.read(item.filename))
    with pytest.raises(wd.ConfigError, match=r"holed.npz.*body_q"):
        load_checkpoint(holed, "cpu")
    # arrays edited after saving: the stored fingerprint no longer matches
    edited = tmp_path / "edited.npz"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(edited, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "host/sphere_radius.npy":
                data = data[:-4] + np.float32(0.5 * R).tobytes()
            dst.writestr(item, data)
    with pytest.raises(wd.ConfigError, match=r"edited.npz.*damaged or inconsistent"):
        load_checkpoint(edited, "cpu")


# ----------------------------------------------------------------------------- 5. builder lengths
def test_mismatched_builder_inputs_named():
    b = wd.ModelBuilder(num_worlds=2)
    b.add_material(wd.GRAVEL)
    pos = np.zeros((5, 3))
    with pytest.raises(wd.ConfigError, match="radii has 3 entries but positions has 5"):
        b.add_spheres(pos, [R] * 3, "gravel")
    with pytest.raises(wd.ConfigError, match="velocities has 4 entries but positions has 5"):
        b.add_spheres(pos, R, "gravel", velocities=np.zeros((4, 3)))
    with pytest.raises(wd.ConfigError, match="angular_velocities must have shape"):
        b.add_spheres(pos, R, "gravel", angular_velocities=np.zeros((5, 2)))
    with pytest.raises(wd.ConfigError, match="world has 2 entries but positions has 5"):
        b.add_spheres(pos, R, "gravel", world=[0, 1])
    with pytest.raises(wd.ConfigError, match="velocities must be finite"):
        b.add_spheres(pos[:1], R, "gravel", velocities=[[np.nan, 0, 0]])
    with pytest.raises(wd.ConfigError, match="sphere_radii has 2 entries but sphere_offsets has 3"):
        b.add_body((0, 0, 0), 1.0, (1, 1, 1), np.zeros((3, 3)), [R, R], "gravel")
    with pytest.raises(wd.ConfigError, match="mu_s_pp has 3 entries but the worlds has 2"):
        b.set_contact_parameters(mu_s_pp=[0.3, 0.4, 0.5])
    class Template:  # what add_clumps reads of a ClumpTemplate
        centers = np.zeros((2, 3))
        radii = np.array([R, R])
        mass = 1e-3
        inertia_principal = (1e-8, 1e-8, 1e-8)

    with pytest.raises(wd.ConfigError, match="rotations has 2 entries but positions has 3"):
        b.add_clumps(Template(), np.zeros((3, 3)), "gravel", rotations=np.tile([0, 0, 0, 1.0], (2, 1)))
    assert b.num_bodies == 0  # nothing half-added
