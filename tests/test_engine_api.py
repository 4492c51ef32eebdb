"""Engine API: bad input errors, time-step limits, checkpoint/restart, VTK output, sub-model registry."""
import numpy as np
import pytest

import warpdem as wd
from warpdem import geometry
from warpdem.io import load_checkpoint, save_checkpoint, write_vtk

R = 0.009


def small_model(**kw):
    b = wd.ModelBuilder(**kw)
    b.add_material(wd.GRAVEL)
    rng = np.random.default_rng(1)
    g = np.arange(3) * 0.021 + 0.012
    pos = np.stack(np.meshgrid(g, g, g + 0.01, indexing="ij"), -1).reshape(-1, 3)
    pos += rng.uniform(-1e-3, 1e-3, pos.shape)
    b.add_spheres(pos, R, "gravel", velocities=rng.normal(0, 0.2, pos.shape))
    b.add_wall(geometry.open_box((0, 0, 0), (0.07, 0.07, 0.2)), "gravel")
    b.add_wall(geometry.plane((0.035, 0.035, 0.0), 0.07, 0.07), "gravel",
               motion=wd.WallMotion.translation((0, 0, 0.05), start=0.01, stop=0.02), name="lift")
    return b


def test_negative_radius_named():
    b = wd.ModelBuilder()
    b.add_material(wd.GRAVEL)
    with pytest.raises(wd.ConfigError, match="radius"):
        b.add_sphere((0, 0, 0), -0.01, "gravel")


def test_unknown_material_named():
    b = wd.ModelBuilder()
    with pytest.raises(wd.ConfigError, match="unknown material 'granite'"):
        b.add_sphere((0, 0, 0), 0.01, "granite")


def test_unknown_contact_parameter_and_model_named():
    b = wd.ModelBuilder()
    with pytest.raises(wd.ConfigError, match="mu_x_pp"):
        b.set_contact_parameters(mu_x_pp=0.3)
    with pytest.raises(wd.ConfigError, match="outside its admissible range"):
        b.set_contact_parameters(mu_s_pp=-0.1)
    with pytest.raises(wd.ConfigError, match="unknown rolling contact model 'magic'"):
        wd.ContactLaw(rolling="magic")


def test_bad_material_values():
    with pytest.raises(wd.ConfigError, match="poisson_ratio"):
        wd.Material("x", 1e7, 0.7, 1000)
    with pytest.raises(wd.ConfigError, match="youngs_modulus"):
        wd.Material("x", -1, 0.3, 1000)


def test_huge_initial_overlap_rejected():
    b = wd.ModelBuilder()
    b.add_material(wd.GRAVEL)
    b.add_spheres([(0, 0, 0), (0.01, 0, 0)], R, "gravel")
    with pytest.raises(wd.OverlapError, match="overlap"):
        b.finalize("cpu")


def test_world_out_of_range():
    b = wd.ModelBuilder(num_worlds=2)
    b.add_material(wd.GRAVEL)
    with pytest.raises(wd.ConfigError, match="world 2"):
        b.add_sphere((0, 0, 0), R, "gravel", world=2)


def test_time_step_above_limit_refused_unless_forced():
    m = small_model().finalize("cpu")
    lim = wd.time_step_limits(m)
    assert lim.rayleigh == pytest.approx(wd.rayleigh_time(R, 2661, wd.GRAVEL.shear_modulus, 0.3))
    with pytest.raises(wd.StabilityError, match="stability limit"):
        wd.Simulation(m, 2 * lim.limit)
    wd.Simulation(m, 2 * lim.limit, force=True)


def test_nan_reported_not_hidden():
    """A non-finite value entering the state (here through an external force, e.g. a broken
    fluid coupling) is reported at the next check, naming the cause."""
    b = wd.ModelBuilder()
    b.add_material(wd.GRAVEL)
    b.add_spheres([(0, 0, 0), (0.05, 0, 0)], R, "gravel")
    sim = wd.Simulation(b.finalize("cpu"), 1e-5)
    sim.run(10)
    sim.solver.external_force.assign(np.array([[np.nan, 0, 0], [0, 0, 0]], dtype=np.float32))
    sim.solver.use_external_force = True
    with pytest.raises(wd.StabilityError, match="NaN"):
        sim.run(20, check_every=10)


def test_contact_overflow_reported():
    b = wd.ModelBuilder(max_contacts=2, gravity=(0, 0, 0))
    b.add_material(wd.GRAVEL)
    b.add_spheres([(0, 0, 0), (0.0179, 0, 0), (-0.0179, 0, 0), (0, 0.0179, 0)], R, "gravel")
    m = b.finalize("cpu")
    sim = wd.Simulation(m, 1e-5)
    with pytest.raises(wd.ContactOverflowError, match="max_contacts"):
        sim.run(5)


def test_checkpoint_restart_equals_uninterrupted(tmp_path):
    dt = 5e-5
    ref = wd.Simulation(small_model().finalize("cpu"), dt)
    ref.run(600)
    sim = wd.Simulation(small_model().finalize("cpu"), dt)
    sim.run(300)
    path = save_checkpoint(tmp_path / "ck.npz", sim)
    again = load_checkpoint(path, "cpu")
    assert again.steps == 300
    again.run(300)
    np.testing.assert_array_equal(again.state.body_q.numpy(), ref.state.body_q.numpy())
    np.testing.assert_array_equal(again.state.body_w.numpy(), ref.state.body_w.numpy())
    np.testing.assert_array_equal(again.solver.wall_stats.energy_n.numpy(), ref.solver.wall_stats.energy_n.numpy())
    assert again.time == pytest.approx(ref.time)


def test_checkpoint_missing_file(tmp_path):
    with pytest.raises(wd.ConfigError, match="not found"):
        load_checkpoint(tmp_path / "nope.npz")


def test_vtk_output_readable(tmp_path):
    import pyvista as pv

    sim = wd.Simulation(small_model().finalize("cpu"), 5e-5)
    sim.run(100)
    paths = write_vtk(tmp_path, sim, 0)
    cloud = pv.read(paths[0])
    assert cloud.n_points == 27
    np.testing.assert_allclose(cloud["radius"], R)
    wall = pv.read(paths[1])
    assert "energy_n" in wall.cell_data and wall.n_cells == sim.model.walls[0].num_triangles


def test_lifted_wall_moves_by_schedule():
    sim = wd.Simulation(small_model().finalize("cpu"), 5e-5)
    sim.run(600)  # 0.03 s: the lift ran from 0.01 s to 0.02 s at 0.05 m/s
    sim.run(1)  # vertices are placed at the start of a step
    z = sim.model.walls[1].points_at(sim.time)[:, 2]
    np.testing.assert_allclose(z, 0.05 * 0.01, atol=1e-6)


def test_parameters_declared_by_submodels():
    law = wd.ContactLaw(rolling="epsd")
    assert law.parameter_names == ["restitution_pp", "restitution_pw", "mu_s_pp", "mu_s_pw", "mu_r_pp", "mu_r_pw"]
    b = wd.ModelBuilder(num_worlds=3, contact_law=law)
    b.add_material(wd.GRAVEL)
    b.add_sphere((0, 0, 0), R, "gravel")
    b.set_contact_parameters(mu_r_pw=[0.1, 0.2, 0.3])
    m = b.finalize("cpu")
    np.testing.assert_allclose(m.get_contact_parameter("mu_r_pw"), [0.1, 0.2, 0.3], rtol=1e-6)
    m.set_contact_parameter("mu_s_pp", [0.4, 0.5, 0.6])
    np.testing.assert_allclose(m.contact_params.numpy()[0::2, law.column("mu_s")], [0.4, 0.5, 0.6], rtol=1e-6)


def test_new_submodel_is_one_registration():
    """A new effect: one class + @register; its parameter flows into the law's names."""
    import warp as wp

    from warpdem.contact import REGISTRY, ContactInput, ParameterSpec, SubModel, register

    @register
    class ConstantPull(SubModel):
        kind = "cohesion"
        name = "test_constant_pull"
        parameters = (ParameterSpec("pull", "N", 0.0, (0.0, 1.0), "constant attraction"),)

        def make(self, column):
            c = column("pull")

            @wp.func
            def pull(ci: ContactInput, p: wp.array2d(dtype=float)):
                return -p[ci.row, c]

            return pull

    try:
        law = wd.ContactLaw(cohesion="test_constant_pull")
        assert "pull_pp" in law.parameter_names
        b = wd.ModelBuilder(contact_law=law, gravity=(0, 0, 0))
        b.add_material(wd.GRAVEL)
        b.add_spheres([(0, 0, 0), (2 * R - 1e-5, 0, 0)], R, "gravel")
        b.set_contact_parameters(pull_pp=0.5)
        sim = wd.Simulation(b.finalize("cpu"), 1e-5)
        sim.run(1)
        f = sim.solver.sphere_f.numpy()
        # elastic repulsion at 1e-5 m overlap is ~0.04 N, so a 0.5 N pull dominates
        assert f[0, 0] > 0.4 and f[1, 0] < -0.4
    finally:
        del REGISTRY["cohesion"]["test_constant_pull"]


def test_removed_bodies_leave_the_neighbour_lists():
    """Bodies removed by remove_outside stay where they left but take no part in contacts or
    neighbour lists (otherwise removed particles piling up at an outflow edge overflow the
    lists of the active ones passing by)."""
    b = wd.ModelBuilder(gravity=(0, 0, 0))
    b.add_material(wd.GRAVEL)
    g = np.arange(3) * 0.0185
    cluster = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3) + (0.10, 0.0, 0.0)
    b.add_spheres(cluster, R, "gravel")
    b.add_sphere((0.10 - 0.0185, 0.0185, 0.0185), R, "gravel")  # touches the cluster's face
    sim = wd.Simulation(b.finalize("cpu"), 1e-5)
    sim.run(2)
    probe = len(cluster)
    assert sim.solver.nb_count.numpy()[probe] > 0
    assert sim.remove_outside((-1.0, -1.0, -1.0), (0.095, 1.0, 1.0)) == len(cluster)
    sim.solver.request_neighbour_rebuild()
    sim.run(2)
    assert sim.solver.nb_count.numpy()[probe] == 0
    assert np.allclose(sim.state.body_v.numpy()[probe], 0.0)  # no force from removed bodies


def test_paused_world_holds_still_with_its_contacts():
    """pause_worlds holds a world's bodies at rest with their contact history while the other
    worlds move; resume_worlds releases it."""
    b = wd.ModelBuilder(num_worlds=2)
    b.add_material(wd.GRAVEL)
    for w in range(2):
        b.add_spheres([(0.0, 0.0, R - 1e-4), (0.0, 0.0, 3 * R + 0.01)], R, "gravel", world=w)
    b.add_wall(geometry.plane((0.0, 0.0, 0.0), 0.2, 0.2), "gravel")
    sim = wd.Simulation(b.finalize("cpu"), 1e-5)
    sim.run(10)
    sim.pause_worlds([1])
    assert sim.solver.paused_worlds.tolist() == [False, True]
    x0, n0 = sim.state.body_q.numpy().copy(), sim.state.contact_count.numpy().copy()
    sim.run(200)
    x1 = sim.state.body_q.numpy()
    np.testing.assert_array_equal(x1[2:], x0[2:])                    # world 1 (bodies 2, 3) held
    np.testing.assert_array_equal(sim.state.contact_count.numpy()[2:], n0[2:])
    assert np.all(np.abs(x1[:2] - x0[:2]).max(axis=1) > 1e-6)        # world 0 falls / rebounds
    assert np.all(sim.state.body_v.numpy()[2:] == 0)
    sim.resume_worlds()
    sim.run(50)
    assert not np.array_equal(sim.state.body_q.numpy()[3], x0[3])    # released: falls again
    with pytest.raises(wd.ConfigError, match="out of range"):
        sim.pause_worlds([2])


def test_kinetic_energy_is_summed_per_world_in_body_order():
    """Each body's translational + rotational energy, summed per world in float64 (on a GPU an
    atomic float32 sum changed in the last digits from run to run)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from test_contact_stages import SCENES

    sim = SCENES["clumps"]()
    sim.run(200)
    s, m = sim.state, sim.model
    v, w = s.body_v.numpy().astype(float), s.body_w.numpy().astype(float)
    q = s.body_rot.numpy().astype(float)  # (x, y, z, w)
    inertia = m.host["body_inertia"].astype(float)
    e = []
    for b in range(m.num_bodies):
        x, y, z, qw = q[b]
        rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * qw), 2 * (x * z + y * qw)],
                        [2 * (x * y + z * qw), 1 - 2 * (x * x + z * z), 2 * (y * z - x * qw)],
                        [2 * (x * z - y * qw), 2 * (y * z + x * qw), 1 - 2 * (x * x + y * y)]])
        wb = rot.T @ w[b]
        e.append(0.5 * m.host["body_mass"][b] * v[b] @ v[b] + 0.5 * wb @ (inertia[b] * wb))
    e = np.array(e) * s.body_active.numpy()
    want = np.bincount(m.host["body_world"], weights=e, minlength=m.num_worlds)
    got = sim.kinetic_energy()
    assert got.dtype == np.float64 and want.sum() > 0
    np.testing.assert_allclose(got, want, rtol=1e-5)
    assert np.array_equal(sim.kinetic_energy(), got)


def test_a_state_of_another_model_is_refused_even_where_sizes_agree():
    """``State.to_numpy`` carries its model's fingerprint; ``load_numpy`` refuses another model's
    arrays (issue 29: it loaded silently when the counts matched)."""
    def model(gravity_z):
        b = wd.ModelBuilder()
        b.add_material(wd.GRAVEL)
        b.add_sphere((0.0, 0.0, 0.05), 0.009, "gravel")
        b.add_sphere((0.03, 0.0, 0.05), 0.009, "gravel")
        b.gravity = (0.0, 0.0, gravity_z)
        return b.finalize("cpu")

    a, other = model(-9.81), model(-1.62)
    assert a.fingerprint != other.fingerprint
    data = wd.State(a).to_numpy()
    wd.State(a).load_numpy(data)  # its own model: loads
    with pytest.raises(wd.ConfigError, match="saved from model"):
        wd.State(other).load_numpy(data)
