"""CUDA checks (run on a GPU machine with ``pytest -m gpu``): the same kernels give the same
physics on ``cuda`` as on ``cpu``, with and without CUDA-graph capture."""
import numpy as np
import pytest
import warp as wp

import warpdem as wd
from warpdem import geometry

pytestmark = pytest.mark.gpu
R = 0.009


def needs_cuda():
    if not wp.is_cuda_available():
        pytest.skip("no CUDA device")


def pile(device, worlds=2, use_graph=None, steps=1000):
    b = wd.ModelBuilder(num_worlds=worlds, contact_law=wd.ContactLaw(rolling="epsd"))
    b.add_material(wd.GRAVEL)
    g = np.arange(4) * 0.02 + 0.01
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    pos[:, :2] += np.random.default_rng(0).uniform(-1e-3, 1e-3, (len(pos), 2))
    for w in range(worlds):
        b.add_spheres(pos, R, "gravel", world=w)
    b.add_wall(geometry.open_box((-0.005, -0.005, 0), (0.085, 0.085, 0.2)), "gravel")
    b.add_wall(geometry.plane((0.04, 0.04, 0.15), 0.09, 0.09, normal=(0, 0, -1)), "gravel",
               motion=wd.WallMotion.translation((0, 0, -0.2), start=0.0, stop=0.2))
    b.set_contact_parameters(mu_s_pp=np.linspace(0.2, 0.6, worlds), mu_r_pp=0.1, mu_r_pw=0.1)
    sim = wd.Simulation(b.finalize(device), 5e-5, use_graph=use_graph)
    sim.run(steps)
    return sim


def test_cuda_matches_cpu_short_run():
    needs_cuda()
    cpu = pile("cpu", steps=200)
    gpu = pile("cuda", steps=200, use_graph=False)
    np.testing.assert_allclose(gpu.state.body_q.numpy(), cpu.state.body_q.numpy(), atol=2e-5)


def test_cuda_graph_equals_plain_launches():
    needs_cuda()
    a = pile("cuda", use_graph=False)
    b = pile("cuda", use_graph=True)
    np.testing.assert_allclose(a.state.body_q.numpy(), b.state.body_q.numpy(), atol=1e-4)
    assert a.steps == b.steps


def test_cuda_restitution_and_hertz():
    needs_cuda()
    b = wd.ModelBuilder(gravity=(0, 0, 0))
    b.add_material(wd.GRAVEL)
    b.add_sphere((0, 0, R + 1e-6), R, "gravel", velocity=(0, 0, -1.0))
    b.add_wall(geometry.plane((0, 0, 0), 1, 1, subdivisions=4), "gravel")
    b.set_contact_parameters(restitution_pw=0.6)
    sim = wd.Simulation(b.finalize("cuda"), 2e-6)
    sim.run(1500)
    assert sim.state.body_v.numpy()[0, 2] == pytest.approx(0.6, rel=0.02)


@pytest.mark.parametrize("clump_damping_mass", ["contact_point", "body"])
def test_cuda_clumps_match_cpu(clump_damping_mass):
    needs_cuda()
    from warpdem.clump_geometry import make_template

    tpl = make_template(np.array([[0, 0, 0], [0.012, 0, 0], [0.004, 0.01, 0.003]]), np.array([0.008, 0.007, 0.006]),
                        2661.0, name="tri")

    def run(device):
        b = wd.ModelBuilder(num_worlds=2, contact_law=wd.ContactLaw(rolling="cdt",
                                                                    clump_damping_mass=clump_damping_mass))
        b.add_material(wd.GRAVEL)
        g = np.arange(3) * 0.035 + 0.02
        pos = np.stack(np.meshgrid(g, g, [0.03, 0.07], indexing="ij"), -1).reshape(-1, 3)
        rot = wd.random_quaternions(len(pos), np.random.default_rng(2))
        for w in range(2):
            b.add_clumps(tpl, pos, "gravel", world=w, rotations=rot)
        b.add_wall(geometry.open_box((0, 0, 0), (0.11, 0.11, 0.3)), "gravel")
        b.set_contact_parameters(mu_s_pp=[0.3, 0.6], mu_r_pp=0.05, mu_r_pw=0.05)
        sim = wd.Simulation(b.finalize(device), 2e-5, use_graph=False)
        sim.run(300)
        return sim.state.body_q.numpy()

    np.testing.assert_allclose(run("cuda"), run("cpu"), atol=5e-5)


@pytest.mark.parametrize("law", [dict(rolling="epsd2", cohesion="sjkr"), dict(rolling="epsd", cohesion="sjkr2"),
                                 dict(rolling="epsd2", cohesion="sjkr", tangential="mindlin")])
def test_cuda_effects_match_cpu(law):
    """The effect sub-models (LIGGGHTS epsd2 rolling, SJKR cohesion; both tangential rules) give the CPU's physics on CUDA."""
    needs_cuda()

    def run(device):
        b = wd.ModelBuilder(num_worlds=2, contact_law=wd.ContactLaw(**law))
        b.add_material(wd.GRAVEL)
        g = np.arange(4) * 0.02 + 0.01
        pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
        pos[:, :2] += np.random.default_rng(0).uniform(-1e-3, 1e-3, (len(pos), 2))
        for w in range(2):
            b.add_spheres(pos, R, "gravel", world=w)
        b.add_wall(geometry.open_box((-0.005, -0.005, 0), (0.085, 0.085, 0.2)), "gravel")
        b.set_contact_parameters(mu_s_pp=0.4, mu_r_pp=[0.05, 0.2], mu_r_pw=0.1,
                                 cohesion_energy_density_pp=[2e4, 8e4], cohesion_energy_density_pw=5e4)
        sim = wd.Simulation(b.finalize(device), 5e-5, use_graph=False)
        sim.run(200)
        return sim.state.body_q.numpy()

    np.testing.assert_allclose(run("cuda"), run("cpu"), atol=2e-5)


def test_cuda_elongated_rods_match_cpu():
    needs_cuda()
    from warpdem.shape_families import shape_family

    tpl = shape_family("elongated").template(0.018, 2661.0, aspect_ratio=2.0)

    def run(device):
        b = wd.ModelBuilder(num_worlds=1)
        b.add_material(wd.GRAVEL)
        g = np.arange(3) * 0.04 + 0.03
        pos = np.stack(np.meshgrid(g, g, [0.03, 0.08], indexing="ij"), -1).reshape(-1, 3)
        rot = wd.random_quaternions(len(pos), np.random.default_rng(3))
        b.add_clumps(tpl, pos, "gravel", world=0, rotations=rot)
        b.add_wall(geometry.open_box((0, 0, 0), (0.15, 0.15, 0.3)), "gravel")
        sim = wd.Simulation(b.finalize(device), 2e-5, use_graph=False)
        sim.run(300)
        return sim.state.body_q.numpy()

    np.testing.assert_allclose(run("cuda"), run("cpu"), atol=5e-5)


def test_cuda_turning_drums_match_cpu():
    """The staged wall contacts (candidates in each wall's rest frame, then forces and wear) give
    the CPU's result on CUDA for drums turning at different speeds in different worlds."""
    needs_cuda()

    def run(device):
        rng = np.random.default_rng(1)
        b = wd.ModelBuilder(num_worlds=2)
        b.add_material(wd.GRAVEL)
        g = np.arange(3) * 0.0102 - 0.0102
        pos = np.stack(np.meshgrid(g, g, g - 0.03, indexing="ij"), -1).reshape(-1, 3)
        pos += rng.uniform(-1e-4, 1e-4, pos.shape)
        for w in range(2):
            b.add_spheres(pos, 0.005, "gravel", world=w)
        drum = geometry.cylinder_shell(0.05, 0.04, axis=(0.0, 1.0, 0.0), sections=48)
        b.add_wall(drum, wd.PLEXIGLAS, world=0, motion=wd.WallMotion.rotation((0, 1, 0), 30.0), name="drum 0")
        b.add_wall(drum, wd.PLEXIGLAS, world=1, motion=wd.WallMotion.rotation((0, 1, 0), -60.0), name="drum 1")
        b.set_contact_parameters(mu_s_pp=[0.3, 0.6], mu_s_pw=[0.5, 0.2], restitution_pp=0.5)
        sim = wd.Simulation(b.finalize(device), 2e-5, use_graph=False)
        sim.run(300)
        return sim.state.body_q.numpy()

    np.testing.assert_allclose(run("cuda"), run("cpu"), atol=2e-5)
