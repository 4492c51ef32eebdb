"""Fluid forces from a sampled flow (pump.coupling.GridFluidForces): terminal velocity in still
water (Di Felice with the local voidage, Schiller-Naumann), relaxation to a uniform stream, the
added-mass time constant, the undisturbed-flow force, buoyancy, the voidage grid."""
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

import warpdem as wd
from pump.coupling import GridFluidForces
from pump.flow import FlowGrid

RHO_F, MU_F = 998.2, 1.002e-3
NEUTRAL = wd.Material("neutral", 1.0e7, 0.3, RHO_F)


def still(lower=(-0.5, -0.5, -3.0), upper=(0.5, 0.5, 0.5), velocity=(0.0, 0.0, 0.0), viscosity=MU_F):
    return FlowGrid.uniform(velocity, lower, upper, 0.05, viscosity=viscosity)


def simulation(spheres, forces, material=wd.GRAVEL, gravity=(0.0, 0.0, -9.81), dt=5e-5, worlds=None, velocity=None):
    b = wd.ModelBuilder(num_worlds=1 if worlds is None else max(worlds) + 1, gravity=gravity)
    b.add_material(material)
    for k, (x, r) in enumerate(spheres):
        b.add_sphere(x, r, material.name, world=0 if worlds is None else worlds[k],
                     velocity=(0, 0, 0) if velocity is None else velocity)
    b.add_body_force(forces)
    return wd.Simulation(b.finalize("cpu", check_overlaps=False), dt=dt, force=True)  # no contacts here


def di_felice_terminal(d, rho_p, eps, g=9.81):
    weight = (rho_p - RHO_F) * math.pi * d**3 / 6 * g

    def balance(v):
        re = RHO_F * d * eps * v / MU_F
        chi = 3.7 - 0.65 * math.exp(-((1.5 - math.log10(re)) ** 2) / 2)
        cd = (0.63 + 4.8 / math.sqrt(re)) ** 2
        return 0.125 * cd * RHO_F * math.pi * d**2 * eps ** (2 - chi) * v**2 - weight

    return brentq(balance, 1e-9, 100.0, xtol=1e-14)


def schiller_naumann_terminal(d, rho_p, g=9.81):
    weight = (rho_p - RHO_F) * math.pi * d**3 / 6 * g

    def balance(v):
        re = RHO_F * d * v / MU_F
        cd = 24 / re * (1 + 0.15 * re**0.687) if re < 1000 else 0.44
        return 0.125 * cd * RHO_F * math.pi * d**2 * v**2 - weight

    return brentq(balance, 1e-9, 100.0, xtol=1e-14)


@pytest.mark.parametrize("drag", ["di_felice", "schiller_naumann"])
def test_terminal_velocity_in_still_water(drag):
    d, cell = 0.01, 0.1
    forces = GridFluidForces(still(), drag=drag, voidage_cell=cell)
    sim = simulation([((0.0, 0.0, 0.0), d / 2)], forces)
    sim.run(14_000)  # 0.7 s
    eps = 1 - math.pi * d**3 / 6 / cell**3
    expected = di_felice_terminal(d, wd.GRAVEL.density, eps) if drag == "di_felice" else \
        schiller_naumann_terminal(d, wd.GRAVEL.density)
    v = sim.state.body_v.numpy()[0]
    assert forces.voidage.numpy()[0] == pytest.approx(eps, abs=1e-6)
    assert -v[2] == pytest.approx(expected, rel=0.01)
    assert np.hypot(v[0], v[1]) < 1e-9


def test_sphere_takes_the_velocity_of_a_uniform_stream():
    u = np.array([2.1, 0.0, -0.7])
    forces = GridFluidForces(still(velocity=u, viscosity=0.05))
    sim = simulation([((0.0, 0.0, 0.0), 0.002)], forces, gravity=(0.0, 0.0, 0.0))
    sim.run(10_000)  # 0.5 s, 10 Stokes times
    v = sim.state.body_v.numpy()[0]
    assert np.linalg.norm(v - u) < 0.01 * np.linalg.norm(u)


@pytest.mark.parametrize("c_a", [0.0, 0.5])
def test_added_mass_lengthens_the_stokes_time_constant(c_a):
    """Stokes regime from rest: v = v_t (1 - exp(-t / tau)), tau = (m + C_a m_f) / (3 pi mu d)."""
    r, mu, dt = 0.001, 10.0, 1e-6
    forces = GridFluidForces(still(viscosity=mu), drag="schiller_naumann", added_mass=c_a)
    sim = simulation([((0.0, 0.0, 0.0), r)], forces, dt=dt)
    vol = 4 / 3 * math.pi * r**3
    tau = (wd.GRAVEL.density + c_a * RHO_F) * vol / (6 * math.pi * mu * r)
    v_t = 2 / 9 * (wd.GRAVEL.density - RHO_F) * 9.81 * r**2 / mu
    times, speeds = [], []
    for _ in range(int(3 * tau / dt)):
        sim.run(1)
        times.append(sim.time)
        speeds.append(-sim.state.body_v.numpy()[0][2])
    t63 = float(np.interp(1 - math.exp(-1), np.array(speeds) / v_t, times))
    assert t63 == pytest.approx(tau, rel=0.02)


def test_undisturbed_flow_force_accelerates_a_neutral_sphere_with_the_fluid():
    """rho_p = rho_f: (m + C_a m_f) dv/dt = m_f Du/Dt + C_a m_f Du/Dt, so dv/dt = Du/Dt."""
    grid = still(viscosity=1e-7)
    a_f = np.array([10.0, -4.0, 0.0], dtype=np.float32)
    grid.acceleration[...] = a_f
    sim = simulation([((0.0, 0.0, 0.0), 0.005)], GridFluidForces(grid, drag="schiller_naumann"), material=NEUTRAL,
                     gravity=(0.0, 0.0, -9.81), dt=1e-5)
    sim.run(100)
    v = sim.state.body_v.numpy()[0]
    # horizontal: follows Du/Dt (within the lagged added mass' start-up); vertical: buoyancy = weight
    assert v[:2] == pytest.approx(a_f[:2] * sim.time, rel=0.01)
    assert abs(v[2]) < 1e-6
    sim_off = simulation([((0.0, 0.0, 0.0), 0.005)], GridFluidForces(grid, drag="schiller_naumann",
                                                                    pressure_gradient=0.0), material=NEUTRAL,
                         gravity=(0.0, 0.0, 0.0), dt=1e-5)
    sim_off.run(100)
    assert np.abs(sim_off.state.body_v.numpy()[0]).max() < 1e-9


def test_voidage_counts_the_solids_of_each_world_in_its_cell():
    cell, r = 0.1, 0.01
    pts = [((0.02, 0.02, 0.02), r), ((0.05, 0.05, 0.05), r), ((0.08, 0.02, 0.06), r), ((0.05, 0.05, 0.05), r),
           ((0.25, 0.05, 0.05), r)]
    forces = GridFluidForces(still(lower=(0, 0, 0), upper=(0.5, 0.5, 0.5)), voidage_cell=cell)
    sim = simulation(pts, forces, worlds=[0, 0, 0, 1, 0], gravity=(0, 0, 0))
    sim.run(1)
    v = 4 / 3 * math.pi * r**3
    assert forces.voidage.numpy() == pytest.approx([1 - 3 * v / cell**3] * 3 + [1 - v / cell**3] * 2, abs=1e-6)


def test_bad_coupling_input_is_named():
    with pytest.raises(wd.ConfigError, match="unknown drag law 'ergun'"):
        GridFluidForces(still(), drag="ergun")
    with pytest.raises(wd.ConfigError, match="FlowGrid"):
        GridFluidForces(np.zeros((3, 3, 3)))
    with pytest.raises(wd.ConfigError, match="grid_fluid.added_mass"):
        GridFluidForces(still(), added_mass=-1)


# ----------------------------------------------------------------------------- closed-form drag, reference run
def linear_stream(u0, shear, lower=(0.0, 0.0, 0.0), upper=(0.4, 0.4, 0.4), spacing=0.05, viscosity=MU_F):
    """u(x) = u0 + shear @ (x - lower) [m/s], zero Du/Dt: trilinear sampling reproduces it exactly."""
    grid = FlowGrid.uniform((0.0, 0.0, 0.0), lower, upper, spacing, viscosity=viscosity)
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in grid.shape], indexing="ij"), -1)
    grid.velocity[...] = (np.asarray(u0) + (idx * spacing) @ np.asarray(shear).T).astype(np.float32)
    return grid


@pytest.mark.parametrize("drag", ["di_felice", "schiller_naumann"])
def test_per_body_force_in_a_linear_stream_is_the_closed_form_drag(drag):
    """Bodies at rest, no gravity, Du/Dt = 0: the first step's force on each is the drag law's
    (1/8) C_d rho_f pi d^2 eps^(2 - chi) |u| u (Di Felice; eps from its own coarse cell) or
    (1/8) C_d rho_f pi d^2 |u| u, C_d = 24 / Re (1 + 0.15 Re^0.687), 0.44 from Re = 1000
    (Schiller-Naumann)."""
    cell, u0 = 0.1, np.array([0.05, -0.02, 0.01])
    shear = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -0.5], [0.25, 0.0, 0.0]])  # du_i/dx_j [1/s]
    forces = GridFluidForces(linear_stream(u0, shear), drag=drag, voidage_cell=cell)
    bodies = [((0.05, 0.05, 0.05), 0.004), ((0.25, 0.12, 0.31), 0.006), ((0.17, 0.33, 0.08), 0.001),
              ((0.36, 0.27, 0.22), 0.005)]  # one per coarse cell; Re from 770 to 3600
    sim = simulation(bodies, forces, gravity=(0.0, 0.0, 0.0))
    sim.run(1)
    got = sim.solver.body_force_context.force.numpy().astype(np.float64)
    for (x, r), f in zip(bodies, got):
        u = u0 + shear @ np.asarray(x)
        d, speed = 2 * r, np.linalg.norm(u)
        if drag == "di_felice":
            eps = 1 - math.pi * d**3 / 6 / cell**3
            re = RHO_F * d * eps * speed / MU_F
            chi = 3.7 - 0.65 * math.exp(-((1.5 - math.log10(re)) ** 2) / 2)
            cd, void = (0.63 + 4.8 / math.sqrt(re)) ** 2, eps ** (2 - chi)
        else:
            re = RHO_F * d * speed / MU_F
            cd, void = (24 / re * (1 + 0.15 * re**0.687) if re < 1000 else 0.44), 1.0
        expected = 0.125 * cd * RHO_F * math.pi * d**2 * void * speed * u
        assert f == pytest.approx(expected, rel=1e-4, abs=1e-6 * np.linalg.norm(expected))


REFERENCE = Path(__file__).parent / "data" / "pump_fluid_forces_reference.npz"


def swirling_flow():
    """A non-uniform flow with Du/Dt != 0 on [0, 0.2]^3 (grid 0.01 m) for the reference runs."""
    grid = FlowGrid.uniform((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.2, 0.2, 0.2), 0.01)
    x = np.stack(np.meshgrid(*[np.arange(n) * 0.01 for n in grid.shape], indexing="ij"), -1)
    k = 2 * math.pi / 0.2
    u = np.stack([1.0 + 0.8 * np.sin(k * x[..., 1]), 0.4 * np.cos(k * x[..., 0]),
                  -0.2 + 0.3 * np.sin(k * x[..., 2])], -1)
    grid.velocity[...] = u.astype(np.float32)
    grid.acceleration[...] = np.stack([0.8 * k * np.cos(k * x[..., 1]) * u[..., 1],
                                       -0.4 * k * np.sin(k * x[..., 0]) * u[..., 0],
                                       0.3 * k * np.cos(k * x[..., 2]) * u[..., 2]], -1).astype(np.float32)
    return grid


def reference_runs(steps=30, saved=(1, 2, 3, 10, 20, 30), device="cpu"):
    """Fluid force [N] after the ``saved`` steps on 2 x 27 spheres (two worlds, no contacts) in :func:`swirling_flow`:
    two-way (Di Felice, added mass, buoyancy, pressure gradient) and one-way (Schiller-Naumann)."""
    rng = np.random.default_rng(7)
    g = np.arange(3) * 0.016
    lattice = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    centres = np.concatenate([lattice + 0.056, lattice + (0.11, 0.03, 0.12)])
    worlds = [0] * 27 + [1] * 27
    v0 = rng.normal(0.0, 0.2, (54, 3))
    out = {}
    for key, kwargs in (("two_way", dict(two_way=True, relaxation=0.7)), ("one_way", dict(drag="schiller_naumann"))):
        forces = GridFluidForces(swirling_flow(), voidage_cell=0.05, **kwargs)
        b = wd.ModelBuilder(num_worlds=2, gravity=(0.0, 0.0, -9.81))
        b.add_material(wd.GRAVEL)
        for x, w, v in zip(centres, worlds, v0):
            b.add_sphere(tuple(x), 0.005, wd.GRAVEL.name, world=w, velocity=tuple(v))
        b.add_body_force(forces)
        sim = wd.Simulation(b.finalize(device, check_overlaps=False), dt=1e-4, force=True)
        history = []
        for step in range(1, steps + 1):
            sim.run(1)
            if step in saved:
                history.append(sim.solver.body_force_context.force.numpy().copy())
        out[f"{key}_force"] = np.asarray(history)
        out[f"{key}_voidage"] = forces.voidage.numpy().copy()
        out[f"{key}_cell_velocity_change"] = forces.fluid_velocity_change()
    return out


@pytest.mark.filterwarnings("ignore::warpdem.StabilityWarning")
def test_fluid_forces_match_the_saved_reference_run():
    """Regression: forces of a short two-way and one-way run equal those saved before the
    kernels took struct arguments (tests/data/pump_fluid_forces_reference.npz)."""
    ref = np.load(REFERENCE)
    got = reference_runs()
    assert sorted(got) == sorted(ref.files)
    for key in ref.files:
        scale = np.abs(ref[key]).max()
        assert scale > 0 or key == "one_way_cell_velocity_change", key
        np.testing.assert_allclose(got[key], ref[key], rtol=1e-6, atol=1e-6 * scale, err_msg=key)


if __name__ == "__main__":  # regenerate the reference only when the physics changes on purpose
    np.savez(REFERENCE, **reference_runs())


# ----------------------------------------------------------------------------- finite size: the drag's fluid velocity
def schiller_naumann_force(u, d):
    """(1/8) C_d rho_f pi d^2 |u| u for a body at rest [N], C_d = 24 / Re (1 + 0.15 Re^0.687), 0.44 from Re = 1000."""
    speed = np.linalg.norm(u)
    re = RHO_F * d * speed / MU_F
    cd = 24 / re * (1 + 0.15 * re**0.687) if re < 1000 else 0.44
    return 0.125 * cd * RHO_F * math.pi * d**2 * speed * np.asarray(u)


def profile_stream(spacing, quadratic, upper=(0.12, 0.12, 0.12)):
    """u(x) = u0 + S x + Q(x - x_ref) on [0, upper] (Du/Dt set to 0), x_ref = (0.06, 0.06, 0.06) m: S a
    linear shear [1/s], Q quadratic with lap u = 2e4 (0.8 + 0.5, -0.6, 0.4) [1/(m s)] times ``quadratic`` [-];
    returns the grid, u(x) and lap u."""
    u0, shear = np.array([0.2, -0.1, 0.05]), np.array([[0.0, 3.0, 0.0], [0.0, 0.0, -2.0], [1.0, 0.0, 0.0]])
    c = quadratic * np.array([0.8, 0.5, -0.6, 0.4]) * 1e4  # [1/(m s)]

    def u(x):
        x = np.asarray(x, dtype=float)
        y = x - 0.06
        q = np.stack([c[0] * y[..., 1] ** 2 + c[1] * y[..., 2] ** 2, c[2] * y[..., 0] ** 2, c[3] * y[..., 0] ** 2], -1)
        return u0 + x @ shear.T + q

    lap = 2.0 * np.array([c[0] + c[1], c[2], c[3]])
    grid = FlowGrid.uniform((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), upper, spacing)
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in grid.shape], indexing="ij"), -1)
    grid.velocity[...] = u(idx * spacing).astype(np.float32)
    return grid, u, lap


def first_step_forces(grid, bodies, drag_velocity):
    forces = GridFluidForces(grid, drag="schiller_naumann", drag_velocity=drag_velocity, voidage_cell=0.05)
    sim = simulation(bodies, forces, gravity=(0.0, 0.0, 0.0))
    sim.run(1)
    return sim.solver.body_force_context.force.numpy().astype(np.float64)


# (drag_velocity, rho / a of its six-point rule, the analytic mean u + k a^2 lap u: k)
AVERAGES = [("surface_average", 1.0, 1.0 / 6.0), ("volume_average", math.sqrt(0.6), 1.0 / 10.0)]


@pytest.mark.parametrize("mode,rho_over_a,k", AVERAGES)
def test_drag_velocity_is_the_faxen_mean_over_the_particle(mode, rho_over_a, k):
    """Bodies at rest on grid nodes, their six-point samples on nodes too (trilinear sampling exact):
    in a linear shear the mean equals the centre value; in a quadratic flow the drag reads
    u + a^2/6 lap u (the mean over the sphere: Faxen's first law) or u + a^2/10 lap u (over the
    volume), and the centre value differs from it by more than the test's tolerance."""
    h = 0.002
    radius = 3 * h / rho_over_a  # the rule's samples sit three nodes from the centre
    centres = [np.array([0.052, 0.06, 0.066]), np.array([0.07, 0.054, 0.06]), np.array([0.06, 0.068, 0.05])]
    bodies = [(tuple(x), radius) for x in centres]
    for quadratic in (0.0, 1.0):
        grid, u, lap = profile_stream(h, quadratic)
        got = first_step_forces(grid, bodies, mode)
        centre = first_step_forces(grid, bodies, "centre")
        for x, f, f_c in zip(centres, got, centre):
            mean = u(x) + k * radius**2 * lap
            assert f == pytest.approx(schiller_naumann_force(mean, 2 * radius), rel=2e-4)
            assert f_c == pytest.approx(schiller_naumann_force(u(x), 2 * radius), rel=2e-4)
            if quadratic == 0.0:  # linear: every mean is the centre value
                assert f == pytest.approx(f_c, rel=2e-4)
            else:  # the correction k a^2 lap u is 12-20 % of |u| here: the test can tell a wrong mean
                assert np.linalg.norm(f - f_c) > 0.1 * np.linalg.norm(f_c)


def test_drag_velocity_choice_is_checked_and_reported():
    with pytest.raises(wd.ConfigError, match="drag_velocity must be one of"):
        GridFluidForces(still(), drag_velocity="volume")
    assert GridFluidForces(still(), drag_velocity="surface_average").describe()["drag_velocity"] == "surface_average"
    from pump.config_schema import load_config

    with pytest.raises(wd.ConfigError, match=r"fluid.drag_velocity must be one of 'centre', 'surface_average' or "
                                             r"'volume_average', got 'average'"):
        load_config({"fluid": {"drag_velocity": "average"}})
    with pytest.raises(wd.ConfigError, match=r"fluid.side_room_rotation"):
        load_config({"fluid": {"side_room_rotation": 1.5}})
    with pytest.raises(wd.ConfigError, match=r"design: side_gap must be a positive number"):
        load_config({"design": {"side_gap": 0.0}})
