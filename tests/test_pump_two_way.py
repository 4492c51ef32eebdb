"""Two-way coupling of pump.coupling.GridFluidForces: the fluid loses the momentum the particles
gain from drag, one-way mode leaves the fluid alone, a dense cloud slows the fluid in its cell as
the model's steady local momentum balance says (more with more solids), bad settings are named."""
import math

import numpy as np
import pytest
from scipy.optimize import brentq

import warpdem as wd
from pump.coupling import GridFluidForces
from pump.flow import FlowGrid
from pump.run import load_config

RHO_F, MU_F = 998.2, 1.002e-3
CELL = 0.05  # coarse cell edge [m]
# heavy enough that drag does not move the spheres during the test (they stand in the stream)
ANCHORED = wd.Material("anchored", 1.0e7, 0.3, 1.0e9)


def stream(u=(1.0, 0.0, 0.0), size=0.2):
    return FlowGrid.uniform(u, (0.0, 0.0, 0.0), (size, size, size), CELL)


def simulation(centres, radius, forces, material=wd.GRAVEL, worlds=None, velocities=None, dt=1e-4):
    n_worlds = 1 if worlds is None else max(worlds) + 1
    b = wd.ModelBuilder(num_worlds=n_worlds, gravity=(0.0, 0.0, 0.0))
    b.add_material(material)
    for k, x in enumerate(centres):
        b.add_sphere(tuple(x), radius, material.name, world=0 if worlds is None else worlds[k],
                     velocity=(0, 0, 0) if velocities is None else tuple(velocities[k]))
    b.add_body_force(forces)
    return wd.Simulation(b.finalize("cpu", check_overlaps=False), dt=dt, force=True)


def lattice(per_axis, pitch, corner):
    g = np.arange(per_axis) * pitch
    return np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3) + np.asarray(corner)


@pytest.mark.parametrize("drag_velocity", ["centre", "surface_average"])
def test_fluid_loses_the_momentum_the_particles_gain_per_world(drag_velocity):
    """Closed box (no relaxation): sum_i m_i (v_i - v_i0) = -sum_c P_c in each world, also when the
    drag reads the fluid velocity averaged over the particle (both passes use the same average)."""
    rng = np.random.default_rng(3)
    centres = np.concatenate([lattice(3, 0.016, (0.06, 0.06, 0.06)), lattice(3, 0.03, (0.02, 0.11, 0.02))])
    worlds = [0] * 27 + [1] * 27
    v0 = rng.normal(0.0, 0.5, (54, 3))
    grid = stream()
    x = grid.origin + grid.spacing * np.stack(np.meshgrid(*[np.arange(n) for n in grid.shape], indexing="ij"), -1)
    grid.velocity[..., 0] += (20.0 * (x[..., 1] - 0.1) ** 2).astype(np.float32)  # curved: the averages differ
    forces = GridFluidForces(grid, two_way=True, relaxation=0.0, added_mass=0.0, voidage_cell=CELL,
                             drag_velocity=drag_velocity)
    sim = simulation(centres, 0.005, forces, worlds=worlds, velocities=v0)
    mass = sim.model.host["body_mass"].astype(np.float64)
    for steps in (1, 200):  # one coupling interval, then many
        sim.run(steps if steps == 1 else steps - 1)
        gained = (mass[:, None] * (sim.state.body_v.numpy() - v0))
        fluid = forces.fluid_momentum_change().astype(np.float64)
        for w in (0, 1):
            particles = gained[np.asarray(worlds) == w].sum(0)
            lost = -fluid[w].reshape(-1, 3).sum(0)
            assert np.linalg.norm(particles) > 1e-6  # there is an exchange to check
            assert np.linalg.norm(particles - lost) < 0.01 * np.linalg.norm(particles), (steps, w, particles, lost)
    # the slowed fluid is felt: particles that started slower than u0 now see less slip than one-way
    assert forces.fluid_velocity_change()[0, :, :, :, 0].min() < -1e-3


def test_one_way_leaves_the_fluid_unchanged_bit_for_bit():
    grid = stream()
    before = (grid.velocity.copy(), grid.acceleration.copy(), grid.pressure.copy())
    centres = lattice(3, 0.016, (0.06, 0.06, 0.06))
    results = {}
    for two_way in (False, True):
        forces = GridFluidForces(grid, two_way=two_way)
        sim = simulation(centres, 0.005, forces)
        sim.run(50)
        for a, b0 in zip((grid.velocity, grid.acceleration, grid.pressure), before):
            assert np.array_equal(a, b0)  # the prescribed field is never written, in either mode
        assert np.array_equal(forces._velocity.numpy(), before[0])
        results[two_way] = (forces.fluid_velocity_change(), sim.state.body_v.numpy())
    assert not results[False][0].any()  # one-way: no correction
    assert results[True][0].min() < -1e-3  # two-way: there is one, so the check above can fail
    assert not np.array_equal(results[False][1], results[True][1])


def steady_slowdown(n, radius, u0):
    """The model's steady state for n spheres at rest in one cell: du m_c / tau = -n F(u0 + du)."""
    vol = n * 4.0 / 3.0 * math.pi * radius**3
    eps = 1.0 - vol / CELL**3
    m_c, tau, d = RHO_F * eps * CELL**3, CELL / u0, 2.0 * radius

    def balance(du):
        re = RHO_F * d * eps * (u0 + du) / MU_F
        chi = 3.7 - 0.65 * math.exp(-((1.5 - math.log10(re)) ** 2) / 2)
        cd = (0.63 + 4.8 / math.sqrt(re)) ** 2
        drag = 0.125 * cd * RHO_F * math.pi * d**2 * eps ** (2 - chi) * (u0 + du) ** 2
        return du * m_c / tau + n * drag

    return brentq(balance, -u0 * (1 - 1e-9), 0.0, xtol=1e-12), 1.0 - eps


def test_dense_cloud_slows_the_fluid_in_its_cell_more_with_more_solids():
    u0, r = 1.0, 0.005
    slowdown = []
    for per_axis in (2, 3, 4):  # 8, 27, 64 spheres of 10 mm in the cell [0.05, 0.10)^3
        forces = GridFluidForces(stream((u0, 0.0, 0.0)), two_way=True, voidage_cell=CELL)
        centres = lattice(per_axis, 0.012, (0.056, 0.056, 0.056))
        sim = simulation(centres, r, forces, material=ANCHORED, dt=1e-3)
        sim.run(600)  # 12 flow-through times
        du = forces.fluid_velocity_change()[0]
        expected, solids = steady_slowdown(per_axis**3, r, u0)
        assert du[1, 1, 1, 0] == pytest.approx(expected, rel=0.01)
        assert np.abs(du[1, 1, 1, 1:]).max() < 1e-6
        du[1, 1, 1] = 0.0
        assert not du.any()  # the correction stays in the cloud's cell (not advected downstream)
        assert np.abs(sim.state.body_v.numpy()).max() < 1e-4  # the cloud stood still
        slowdown.append((solids, -expected))
    fractions, drops = zip(*slowdown)
    assert fractions[0] < fractions[1] < fractions[2]
    assert 0.0 < drops[0] < drops[1] < drops[2] < u0  # grows with the solids; never reverses the flow


def test_bad_two_way_settings_are_named():
    with pytest.raises(wd.ConfigError, match="two_way must be true or false"):
        GridFluidForces(stream(), two_way="yes")
    with pytest.raises(wd.ConfigError, match="relaxation must be a number in \\[0, 100\\]"):
        GridFluidForces(stream(), two_way=True, relaxation=-1.0)
    with pytest.raises(wd.ConfigError, match="relaxation"):
        GridFluidForces(stream(), two_way=True, relaxation="fast")
    with pytest.raises(wd.ConfigError, match="coupling.two_way must be true or false"):
        load_config({"coupling": {"two_way": "on"}})
    with pytest.raises(wd.ConfigError, match="coupling.relaxation"):
        load_config({"coupling": {"two_way": True, "relaxation": float("nan")}})
    with pytest.raises(wd.ConfigError, match=r"coupling.twoway: unknown key; valid: relaxation, two_way"):
        load_config({"coupling": {"twoway": True}})
    cfg = load_config({"coupling": {"two_way": True}})
    assert cfg["coupling"] == {"two_way": True, "relaxation": 1.0}
    assert load_config({})["coupling"]["two_way"] is False  # one-way by default
