"""The two tangential sub-models: LIGGGHTS ``history`` (default) and ``mindlin`` (Luding reset).

An oblique impact of a sphere on a plane in the sticking / micro-slip regime
(v_t / v_n = 1 < 3.5 mu (1 + e); Chung & Ooi 2011, test 6) is integrated by the engine and,
for ``history``, by an independent float64 integrator of the same equations written here from
LIGGGHTS-PUBLIC src/tangential_model_history.h and the seed paper's eqs. (1)-(12).
"""
import math

import numpy as np
import pytest

import warpdem as wd
from warpdem import geometry

R = 0.008  # m
HARD = wd.Material("hard", 1.0e9, 0.3, 2661.0)  # stiff: overlap << R, so the lever arm is R
E, MU = 0.6, 0.35


def _law(tangential: str) -> wd.ContactLaw:
    return wd.ContactLaw(tangential=tangential)


def oblique_impacts(tangential: str, fraction: float, material=wd.GRAVEL, speeds=(0.25, 1.0, 4.0)):
    """(v_t' / v_t, w' R / v_t) after a 45 deg impact at each speed [m/s]; dt = fraction x T_R."""
    b = wd.ModelBuilder(num_worlds=len(speeds), gravity=(0.0, 0.0, 0.0), contact_law=_law(tangential))
    b.add_material(material)
    for w, s in enumerate(speeds):
        c = s / math.sqrt(2.0)
        b.add_sphere((0.0, 0.0, R + 1e-7), R, material.name, world=w, velocity=(c, 0.0, -c))
    b.add_wall(geometry.plane((0.0, 0.0, 0.0), 0.6, 0.6), wd.PLEXIGLAS)
    b.set_contact_parameters(restitution_pw=E, mu_s_pw=MU)
    m = b.finalize("cpu")
    dt = fraction * wd.time_step_limits(m).rayleigh
    t_c = wd.hertz_contact_time(float(m.host["body_mass"][0]), R, wd.materials.effective_youngs_modulus(
        material, wd.PLEXIGLAS), min(speeds))
    sim = wd.Simulation(m, dt, force=True, v_ref=max(speeds))
    sim.run(int(math.ceil(3.0 * t_c / dt)), check_every=10**9)
    assert np.all(sim.state.body_q.numpy()[:, 2] > R), "still in contact"
    v, w = sim.state.body_v.numpy().astype(float), sim.state.body_w.numpy().astype(float)
    return [(v[k, 0] / (s / math.sqrt(2.0)), w[k, 1] * R / (s / math.sqrt(2.0))) for k, s in enumerate(speeds)]


def liggghts_reference(material, speed: float, steps_per_contact: int = 20000):
    """The same impact by a float64 semi-implicit Euler integration of Hertz + LIGGGHTS
    tangential history (lever arm R: valid for overlap << R)."""
    e_eff = wd.materials.effective_youngs_modulus(material, wd.PLEXIGLAS)
    g_eff = wd.materials.effective_shear_modulus(material, wd.PLEXIGLAS)
    m = material.density * 4.0 / 3.0 * math.pi * R**3
    inertia = 0.4 * m * R * R
    beta = math.log(E) / math.sqrt(math.log(E) ** 2 + math.pi**2)
    s56 = math.sqrt(5.0 / 6.0)
    c = speed / math.sqrt(2.0)
    dt = wd.hertz_contact_time(m, R, e_eff, speed) / steps_per_contact
    z, vz, vx, w, shear = R, -c, c, 0.0, 0.0
    while z <= R or vz < 0.0:
        d = R - z
        if d > 0.0:
            sq = math.sqrt(R * d)
            fn = 4.0 / 3.0 * e_eff * sq * d + 2.0 * s56 * beta * math.sqrt(2.0 * e_eff * sq * m) * vz
            v_t = vx - R * w
            shear += v_t * dt
            k_t = 8.0 * g_eff * sq
            ft = -k_t * shear
            if abs(ft) > MU * abs(fn):
                ft = math.copysign(MU * abs(fn), ft)
                shear = -ft / k_t
            else:
                ft += 2.0 * s56 * beta * math.sqrt(k_t * m) * v_t
        else:
            fn, ft, shear = 0.0, 0.0, 0.0
        vz += fn / m * dt
        vx += ft / m * dt
        w += -R * ft / inertia * dt
        z += vz * dt
    return vx / c, w * R / c


def test_history_matches_an_independent_integration_of_liggghts_rule():
    got = oblique_impacts("history", 0.02, material=HARD, speeds=(0.5,))[0]
    ref = liggghts_reference(HARD, 0.5)
    assert got[0] == pytest.approx(ref[0], rel=0.01)
    assert got[1] == pytest.approx(ref[1], rel=0.01)


def test_history_converges_at_the_default_step():
    """At 0.2 and 0.1 of the Rayleigh time the rebound is within 3 % / 2 % of a 100 x finer step."""
    fine = oblique_impacts("history", 0.002)
    for frac, tol in ((0.2, 0.03), (0.1, 0.02)):
        for (vt, spin), (vt_f, spin_f) in zip(oblique_impacts("history", frac), fine):
            assert vt == pytest.approx(vt_f, rel=tol)
            assert spin == pytest.approx(spin_f, rel=tol)


def test_luding_reset_depends_on_the_time_step():
    """``mindlin`` (spring reset including the dashpot) is told apart: its spin after the
    slow impact moves by more than 5 % between 0.05 and 0.002 of the Rayleigh time, and its
    converged rebound differs from ``history``'s by more than 10 % in spin."""
    coarse = oblique_impacts("mindlin", 0.05, speeds=(0.25,))[0]
    fine = oblique_impacts("mindlin", 0.002, speeds=(0.25,))[0]
    assert abs(fine[1] / coarse[1] - 1.0) > 0.05
    hist = oblique_impacts("history", 0.002, speeds=(0.25,))[0]
    assert abs(fine[1] / hist[1] - 1.0) > 0.10


def test_gross_sliding_is_the_same_for_both():
    """v_t / v_n = 5 > 3.5 mu (1 + e): both slide throughout, v_t' = v_t - mu (1 + e) v_n."""
    for tang in ("history", "mindlin"):
        b = wd.ModelBuilder(gravity=(0.0, 0.0, 0.0), contact_law=_law(tang))
        b.add_material(HARD)
        b.add_sphere((0.0, 0.0, R + 1e-7), R, "hard", velocity=(5.0, 0.0, -1.0))
        b.add_wall(geometry.plane((0.0, 0.0, 0.0), 1.0, 1.0), HARD)
        b.set_contact_parameters(restitution_pw=0.9, mu_s_pw=0.3)
        m = b.finalize("cpu")
        sim = wd.Simulation(m, 5e-7)
        sim.run(2000, check_every=10**9)
        v = sim.state.body_v.numpy()[0].astype(float)
        assert v[0] == pytest.approx(5.0 - 0.3 * (1.0 + v[2]) * 1.0, rel=0.02)


def test_default_law_and_names():
    assert wd.ContactLaw().tangential == "history"
    assert wd.ContactLaw().describe() == "hertz+history+rolling:none+cohesion:none"
    assert wd.ContactLaw(tangential="mindlin").describe() == "hertz+mindlin+rolling:none+cohesion:none"
    assert wd.ContactLaw().parameter_names == wd.ContactLaw(tangential="mindlin").parameter_names
