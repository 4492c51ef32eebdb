"""Body-force models plugged into the step: registry and parameter errors, a custom model,
terminal velocity in still fluid and relaxation to a uniform stream (Schiller-Naumann drag)."""
import math

import numpy as np
import pytest
import warp as wp
from scipy.optimize import brentq

import warpdem as wd
from warpdem.body_forces import (BodyForceInput, BodyForceModel, ParameterSpec, UniformFluid, body_force_model,
                                 register_body_force)

RHO_F, MU_F = 998.2, 1.002e-3


def one_sphere(radius: float, body_force, gravity=(0.0, 0.0, -9.81), dt: float = 5e-5, extra_spheres: int = 0):
    b = wd.ModelBuilder(gravity=gravity)
    b.add_material(wd.GRAVEL)
    b.add_sphere((0.0, 0.0, 0.0), radius, "gravel")
    for k in range(extra_spheres):
        b.add_sphere((1.0 + k, 0.0, 0.0), radius, "gravel")
    b.add_body_force(body_force)
    # no contacts happen here, so the contact stability limit does not apply (force=True)
    return wd.Simulation(b.finalize("cpu"), dt=dt, force=True)


def sn_terminal_velocity(d: float, rho_p: float, rho_f: float, mu: float, g: float = 9.81) -> float:
    """Solve (1/8) C_d rho_f pi d^2 v^2 = (rho_p - rho_f) pi d^3 / 6 g for v with Schiller-Naumann
    C_d = 24 / Re (1 + 0.15 Re^0.687) below Re = 1000 and C_d = 0.44 above."""
    weight = (rho_p - rho_f) * math.pi * d**3 / 6.0 * g

    def balance(v):
        re = rho_f * d * v / mu
        cd = 24.0 / re * (1 + 0.15 * re**0.687) if re < 1000 else 0.44
        return 0.125 * cd * rho_f * math.pi * d**2 * v**2 - weight

    return brentq(balance, 1e-12, 100.0, xtol=1e-14)


@pytest.mark.parametrize("d, steps", [(0.01, 12_000), (0.002, 8_000)])
def test_terminal_velocity_in_still_water(d, steps):
    """10 mm gravel falls in the Newton regime (Re ~ 7000), 2 mm in the intermediate one (Re ~ 500)."""
    sim = one_sphere(0.5 * d, UniformFluid(density=RHO_F, viscosity=MU_F), dt=5e-5 if d > 0.005 else 2e-5)
    v_t = sn_terminal_velocity(d, wd.GRAVEL.density, RHO_F, MU_F)
    sim.run(steps)  # 0.6 s / 0.16 s: about 10 time constants of the approach
    v = sim.state.body_v.numpy()[0]
    assert abs(v[0]) < 1e-9 and abs(v[1]) < 1e-9
    assert -v[2] == pytest.approx(v_t, rel=0.01)
    assert -v[2] < v_t * 1.0001  # approached from below, no overshoot


def test_stokes_terminal_velocity_in_a_viscous_fluid():
    """Re << 1: v_t = 2/9 (rho_p - rho_f) g r^2 / mu (Stokes 1851)."""
    r, mu = 0.001, 10.0
    sim = one_sphere(r, UniformFluid(density=RHO_F, viscosity=mu), dt=2e-6)
    sim.run(1000)  # 2 ms = 30 Stokes times m / (6 pi mu r)
    v_stokes = 2.0 / 9.0 * (wd.GRAVEL.density - RHO_F) * 9.81 * r**2 / mu
    assert -sim.state.body_v.numpy()[0][2] == pytest.approx(v_stokes, rel=0.01)


def test_sphere_takes_the_velocity_of_a_uniform_stream():
    u = np.array([1.5, -0.5, 0.25])
    # 4 mm sphere in an oil (0.05 Pa s): Stokes time m / (3 pi mu d) = 0.047 s; run 0.5 s
    sim = one_sphere(0.002, UniformFluid(viscosity=0.05, u_x=u[0], u_y=u[1], u_z=u[2]), gravity=(0.0, 0.0, 0.0),
                     extra_spheres=1)
    sim.run(10_000)
    v = sim.state.body_v.numpy()
    assert np.linalg.norm(v[0] - u) < 0.01 * np.linalg.norm(u)
    assert np.allclose(v[0], v[1])


def test_body_force_adds_to_external_force_and_skips_removed_bodies():
    sim = one_sphere(0.005, UniformFluid(density=RHO_F), gravity=(0.0, 0.0, -9.81), extra_spheres=1)
    m = sim.model.host["body_mass"][0]
    sim.solver.external_force.assign(np.array([[0.0, 0.0, m * 9.81], [0, 0, 0]], dtype=np.float32))
    sim.solver.use_external_force = True
    act = sim.state.body_active.numpy()
    act[1] = 0
    sim.state.body_active.assign(act)
    sim.run(1)
    v = sim.state.body_v.numpy()
    # weight cancelled by the external force, buoyancy left: a = rho_f / rho_p g upwards (drag 0 at v = 0)
    assert v[0][2] == pytest.approx(RHO_F / wd.GRAVEL.density * 9.81 * sim.dt, rel=1e-4)
    assert np.all(v[1] == 0.0)


@register_body_force
class _ConstantPush(BodyForceModel):
    name = "test_constant_push"
    parameters = (ParameterSpec("accel_x", "m/s^2", 1.0, (-100.0, 100.0), "acceleration along x"),)
    reference = "test"

    def make(self):
        c = self.column("accel_x")

        @wp.func
        def push(b: BodyForceInput, p: wp.array(dtype=float)):
            return wp.vec3(b.mass * p[c], 0.0, 0.0)

        return push


def test_custom_registered_model_runs_in_the_step():
    sim = one_sphere(0.005, body_force_model("test_constant_push", accel_x=3.0), gravity=(0.0, 0.0, 0.0))
    sim.run(100)
    assert sim.state.body_v.numpy()[0][0] == pytest.approx(3.0 * 100 * sim.dt, rel=1e-5)


def test_bad_body_force_input_is_named():
    with pytest.raises(wd.ConfigError, match="unknown body-force model 'magic'"):
        body_force_model("magic")
    with pytest.raises(wd.ConfigError, match="unknown parameter.*'viscosty'"):
        UniformFluid(viscosty=1.0)
    with pytest.raises(wd.ConfigError, match="uniform_fluid.viscosity"):
        UniformFluid(viscosity=-1.0)
    with pytest.raises(wd.ConfigError, match="BodyForceModel"):
        wd.ModelBuilder().add_body_force("drag")
    with pytest.raises(ValueError, match="already registered"):
        register_body_force(type("Dup", (BodyForceModel,), {"name": "uniform_fluid"}))
