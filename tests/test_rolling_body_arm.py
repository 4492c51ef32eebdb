"""``cdt_body_arm``: EDEM's Standard Rolling Friction, tau_i = -mu_r F_n R_i w_i/|w_i| with R_i the
distance from the contact point to the body's centre of mass and w_i the body's own angular
velocity (Altair EDEM documentation; warpdem.contact.rolling.BodyArmCDT).

One step from a fixed overlap, frictionless tangentially and without gravity, so the torque on a
sphere about the body's centre is the rolling torque (plus the normal force's moment, which has no
component along the rolling axis here). A sphere of its own gets ``cdt``'s torque bit for bit; a
two-sphere clump rolling about its axis on a plane gets the lever of its centre of mass,
sqrt(a^2 + (r - delta)^2), where ``cdt`` takes r - delta.
"""
import math

import numpy as np
import pytest

import warpdem as wd
from warpdem import geometry

R = np.float32(0.009).item()
R_SMALL = np.float32(0.6 * 0.009).item()
MU_R, DELTA, DT, W = 0.3, 1.0e-4, 1.0e-5, 1.0  # the guard I |w| / dt (~0.03 N m) does not bind


def one_step(rolling: str, build):
    b = wd.ModelBuilder(num_worlds=1, contact_law=wd.ContactLaw(tangential="none", rolling=rolling),
                        gravity=(0.0, 0.0, 0.0))
    b.add_material(wd.GRAVEL)
    build(b)
    b.add_wall(geometry.plane((0.0, 0.0, 0.0), 0.2, 0.2), "gravel")
    b.set_contact_parameters(mu_r_pp=MU_R, mu_r_pw=MU_R, restitution_pp=0.5, restitution_pw=0.5)
    sim = wd.Simulation(b.finalize("cpu"), DT)
    sim.run(1)
    return sim.solver.sphere_t.numpy().astype(np.float64), sim.solver.sphere_f.numpy().astype(np.float64)


def spheres(b):
    """0: on the wall, turning about y; 1: turning about y, touching 2 (at rest) in x."""
    b.add_sphere((0.0, 0.0, R - DELTA), R, "gravel", angular_velocity=(0.0, W, 0.0))
    b.add_sphere((0.0, 0.0, 0.1), R, "gravel", angular_velocity=(0.0, W, 0.0))
    b.add_sphere((R + R_SMALL - DELTA, 0.0, 0.1), R_SMALL, "gravel")


A = 0.006  # member centres at y = +-A [m]: a rolling pin along y


def dumbbell(b):
    mass = 2 * wd.GRAVEL.density * 4.0 / 3.0 * math.pi * R**3  # the overlap's volume is not the point
    i_axis = 2 * 0.4 * (mass / 2) * R**2
    i_cross = i_axis + mass * A**2
    b.add_body((0.0, 0.0, R - DELTA), mass, (i_cross, i_axis, i_cross), [(0.0, -A, 0.0), (0.0, A, 0.0)],
               [R, R], "gravel", angular_velocity=(0.0, W, 0.0))


def test_registered_and_discovered_like_the_other_rolling_models():
    law = wd.ContactLaw(rolling="cdt_body_arm")
    assert "cdt_body_arm" in wd.contact.available("rolling")
    assert law.needs_body_kinematics and not wd.ContactLaw(rolling="cdt").needs_body_kinematics
    assert law.parameter_names == wd.ContactLaw(rolling="cdt").parameter_names


def test_a_sphere_of_its_own_gets_cdts_torque_bit_for_bit():
    t_cdt, f_cdt = one_step("cdt", spheres)
    t_arm, f_arm = one_step("cdt_body_arm", spheres)
    assert np.array_equal(f_arm, f_cdt)
    assert t_cdt[0, 1] < 0.0 and t_cdt[1, 1] < 0.0  # opposing the rotation about +y
    assert np.array_equal(t_arm[:2], t_cdt[:2])  # on the wall, and against a sphere at rest
    # the partner at rest: cdt turns it (relative spin), EDEM's convention does not (its own spin is 0)
    assert abs(t_cdt[2, 1]) > 0.0 and np.array_equal(t_arm[2], np.zeros(3))


def test_two_sphere_clump_rolling_on_a_plane_gets_the_lever_of_its_centre_of_mass():
    t_cdt, f_cdt = one_step("cdt", dumbbell)
    t_arm, f_arm = one_step("cdt_body_arm", dumbbell)
    arm = R - DELTA  # the contact point on the wall, below each member's centre
    for k in range(2):
        fn = f_arm[k, 2]
        assert fn > 0.0 and fn == pytest.approx(f_cdt[k, 2], rel=1e-6)
        assert t_cdt[k, 1] == pytest.approx(-MU_R * fn * arm, rel=1e-4)
        assert t_arm[k, 1] == pytest.approx(-MU_R * fn * math.hypot(A, arm), rel=1e-4)
    # the lever ratio itself: 1.23 for these sizes
    ratio = t_arm[:, 1] / t_cdt[:, 1]
    assert ratio == pytest.approx([math.hypot(A, arm) / arm] * 2, rel=1e-4)
