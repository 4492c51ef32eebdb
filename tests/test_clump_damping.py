"""The damping mass of a clump's contacts: ``ContactLaw(clump_damping_mass=...)``.

``"contact_point"`` (default) damps a contact for the mass felt at the contact point along
the normal, m_f = 1 / (1/m + |r x n|^2 / I_mean) (Kruggel-Emden et al. 2008, Powder Technol.
188:153); ``"body"`` for the whole-body mass m (LIGGGHTS ``fix multisphere``). Checks: the two
agree bitwise where m_f = m (spheres; clumps hit on a line through the centre of mass, on a
wall and on each other); an off-centre impact on a plane rebounds at the contact point with
the restitution predicted by Hertz's law with the seed paper's damping sized for the chosen
mass while the point moves with the mass it really has; a bad value is refused by name.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

import warpdem as wd
from calibration.model_description import ModelDescription, contact_law_from_config
from warpdem import ConfigError, geometry
from warpdem.clump_geometry import make_template

R_MEMBER = 0.005  # m
V0 = 0.5  # impact speed [m/s]
CONVENTIONS = ("contact_point", "body")


@pytest.fixture(scope="module")
def dumbbell():
    # body x axis (smallest moment) is the dumbbell axis; members 4 mm from the centre of mass
    return make_template([[-0.004, 0.0, 0.0], [0.004, 0.0, 0.0]], [R_MEMBER] * 2, wd.GRAVEL.density, name="dumbbell")


def builder(convention: str) -> wd.ModelBuilder:
    b = wd.ModelBuilder(num_worlds=1, gravity=(0.0, 0.0, 0.0),
                        contact_law=wd.ContactLaw(clump_damping_mass=convention))
    b.add_material(wd.GRAVEL)
    return b


def final_state(b: wd.ModelBuilder, steps: int = 3000, dt: float = 2e-6) -> dict[str, np.ndarray]:
    sim = wd.Simulation(b.finalize("cpu"), dt)
    sim.run(steps)
    return {k: getattr(sim.state, k).numpy().copy() for k in ("body_q", "body_v", "body_w", "body_rot")}


def wall(b: wd.ModelBuilder) -> None:
    b.add_wall(geometry.plane((0.0, 0.0, 0.0), 0.2, 0.2, normal=(1.0, 0.0, 0.0), subdivisions=2), "gravel")


def place_clump(b, tpl, axis_dir, x_lead: float, velocity, flip: bool = False):
    """A clump with its body x axis along ``axis_dir`` whose leading (lowest x, or highest x
    with ``flip``) member centre lies at ``x_lead``; returns (centre of mass, member offsets)."""
    rot, _ = Rotation.align_vectors([np.asarray(axis_dir, float) / np.linalg.norm(axis_dir)], [[1.0, 0.0, 0.0]])
    offs = rot.apply(np.array(tpl.centers))
    lead = int(np.argmax(offs[:, 0])) if flip else int(np.argmin(offs[:, 0]))
    pos = np.array([x_lead - offs[lead, 0], 0.0, 0.0])
    b.add_clumps(tpl, [pos], "gravel", rotations=[rot.as_quat()], velocities=[velocity])
    return pos, offs[lead]


# ------------------------------------------------------------------ (a) m_f = m: identical
def sphere_on_wall(b, _tpl):
    wall(b)
    b.add_spheres([[R_MEMBER + 2e-4, 0.0, 0.0]], R_MEMBER, "gravel", velocities=[(-V0, 0.0, 0.0)])
    return -V0


def spheres_head_on(b, _tpl):
    b.add_spheres([[-R_MEMBER - 1e-4, 0.0, 0.0], [R_MEMBER + 1e-4, 0.0, 0.0]], [R_MEMBER, 0.8 * R_MEMBER], "gravel",
                  velocities=[(V0, 0.0, 0.0), (-V0, 0.0, 0.0)])
    return V0


def clump_on_wall_along_axis(b, tpl):
    wall(b)
    place_clump(b, tpl, (1.0, 0.0, 0.0), R_MEMBER + 2e-4, (-V0, 0.0, 0.0))
    return -V0


def clumps_along_common_axis(b, tpl):
    place_clump(b, tpl, (1.0, 0.0, 0.0), -R_MEMBER - 1e-4, (V0, 0.0, 0.0), flip=True)
    place_clump(b, tpl, (1.0, 0.0, 0.0), R_MEMBER + 1e-4, (-V0, 0.0, 0.0))
    return V0


@pytest.mark.parametrize("scene", [sphere_on_wall, spheres_head_on, clump_on_wall_along_axis, clumps_along_common_axis])
def test_conventions_agree_bitwise_where_the_felt_mass_is_the_body_mass(dumbbell, scene):
    """A sphere (lever 0) or a clump hit on a line through its centre of mass (lever x n = 0)
    feels m at the contact: both conventions give the same bits, on a wall and between bodies."""
    runs = []
    for convention in CONVENTIONS:
        b = builder(convention)
        v_first = scene(b, dumbbell)  # x velocity of body 0 before the impact
        runs.append(final_state(b))
    assert runs[0]["body_v"][0, 0] * v_first < 0.0, "no rebound: the scene did not collide"
    for k in runs[0]:
        assert np.array_equal(runs[0][k], runs[1][k]), k


def test_off_centre_clump_collision_differs_between_conventions(dumbbell):
    """The particle stage follows the option: two dumbbells meeting off their centres of mass
    (tilted 45 deg) end differently, the whole-body masses damping harder (slower rebound)."""
    speeds = {}
    for convention in CONVENTIONS:
        b = builder(convention)
        place_clump(b, dumbbell, (1.0, 0.0, 1.0), -R_MEMBER - 1e-4, (V0, 0.0, 0.0), flip=True)
        place_clump(b, dumbbell, (1.0, 0.0, -1.0), R_MEMBER + 1e-4, (-V0, 0.0, 0.0))
        st = final_state(b)
        speeds[convention] = st["body_v"][1, 0] - st["body_v"][0, 0]  # separation speed of the centres
    assert 0.0 < speeds["body"] < speeds["contact_point"]


# ------------------------------------------------------------------ (b) off-centre on a plane
def hertz_restitution(m_moved: float, m_damped: float, e: float, r_eff: float, e_eff: float, v0: float) -> float:
    """Restitution of one Hertz contact with the seed paper's damping (eqs. 1, 9, 11, 12),
    the point moving with ``m_moved`` [kg] while the dashpot is sized for ``m_damped`` [kg]:

        m_moved d'' = -4/3 E* sqrt(R*) d^(3/2) - 2 sqrt(5/6) |beta| sqrt(2 E* sqrt(R* d) m_damped) d'

    (d: overlap [m], d(0) = 0, d'(0) = v0; no clipping of an attractive end force, as in the
    engine). Dividing by m_moved, the restitution depends only on beta sqrt(m_damped / m_moved)
    (Tsuji et al. 1992: independent of v0), so damping for m > m_f acts like a larger |beta|.
    Integrated until d returns to 0; returns -d'(end) / v0."""
    beta = math.log(e) / math.sqrt(math.log(e) ** 2 + math.pi**2)
    k = 4.0 / 3.0 * e_eff * math.sqrt(r_eff)
    c = 2.0 * math.sqrt(5.0 / 6.0) * abs(beta) * math.sqrt(2.0 * e_eff * math.sqrt(r_eff) * m_damped)

    def rhs(_t, y):
        d = max(y[0], 0.0)
        return [y[1], -(k * d**1.5 + c * d**0.25 * y[1]) / m_moved]

    def separated(_t, y):
        return y[0]

    separated.terminal, separated.direction = True, -1
    t_scale = 2.87 * (m_moved**2 / (r_eff * e_eff**2 * v0)) ** 0.2  # Hertz contact time [s]
    sol = solve_ivp(rhs, (0.0, 5.0 * t_scale), [0.0, v0], events=separated, rtol=1e-10, atol=1e-14,
                    first_step=t_scale * 1e-6)
    assert sol.t_events[0].size, "the overlap did not close"
    return -sol.y_events[0][0][1] / v0


def mass_felt(m: float, inertia_inv: np.ndarray, lever: np.ndarray, n: np.ndarray) -> float:
    """1 / (1/m + (lever x n)^T I^-1 (lever x n)) [kg]: the body's mass along n at the point."""
    a = np.cross(lever, n)
    return 1.0 / (1.0 / m + a @ inertia_inv @ a)


# a stiff material: the contact lasts ~0.15 ms, so the dumbbell turns < 0.01 rad while touching
# and the felt mass, linearised at the first touch, holds through the contact (with gravel's
# E = 1e7 Pa it turns ~0.05 rad and the rebound departs ~2 % from the linearised prediction)
STIFF = wd.Material("stiff gravel", youngs_modulus=1.0e10, poisson_ratio=0.3, density=wd.GRAVEL.density)


def off_centre_rebound(tpl, convention: str, e: float, dt: float = 2e-7) -> float:
    """Dumbbell with its axis at 45 deg onto the plane x = 0, frictionless: normal velocity of
    the leading member's centre at separation (its lever taken then) over the impact speed."""
    b = wd.ModelBuilder(num_worlds=1, gravity=(0.0, 0.0, 0.0),
                        contact_law=wd.ContactLaw(clump_damping_mass=convention))
    b.add_material(STIFF)
    b.add_wall(geometry.plane((0.0, 0.0, 0.0), 0.2, 0.2, normal=(1.0, 0.0, 0.0), subdivisions=2), STIFF.name)
    rot, _ = Rotation.align_vectors([[1.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    offs = rot.apply(np.array(tpl.centers))
    lead = int(np.argmin(offs[:, 0]))
    b.add_clumps(tpl, [[R_MEMBER + 2e-5 - offs[lead, 0], 0.0, 0.0]], STIFF.name, rotations=[rot.as_quat()],
                 velocities=[(-V0, 0.0, 0.0)])
    b.set_contact_parameters(restitution_pw=e, mu_s_pw=0.0)
    sim = wd.Simulation(b.finalize("cpu"), dt, force=True)
    touched = False
    for _ in range(1000):
        sim.run(5)
        x_lead = sim.sphere_positions()[lead].astype(float)
        if x_lead[0] < R_MEMBER:
            touched = True
        elif touched:
            break
    else:
        raise AssertionError("the dumbbell did not leave the wall")
    lever = x_lead - sim.state.body_q.numpy()[0].astype(float)
    v = sim.state.body_v.numpy()[0].astype(float) + np.cross(sim.state.body_w.numpy()[0].astype(float), lever)
    return v[0] / V0


@pytest.mark.parametrize("e", [0.5, 0.8])
def test_off_centre_impact_restitution_per_convention(dumbbell, e):
    """The leading member hits 2.8 mm (|r x n|) off the centre of mass: the contact point moves
    with m_f = 0.77 m (exact inertia tensor). "contact_point" damps for 0.73 m (m_f with the
    isotropic mean inertia) and rebounds with e within 3 % (0.511 for e = 0.5); "body" damps
    for m, as if |beta| were sqrt(m / m_f) = 1.14 times larger, and rebounds lower (0.451 for
    e = 0.5, 0.775 for e = 0.8). Both match the integrated Hertz law
    (:func:`hertz_restitution`, which gives e exactly when m_damped = m_moved) within 0.5 %."""
    n = np.array([1.0, 0.0, 0.0])
    rot, _ = Rotation.align_vectors([[1.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    rm = rot.as_matrix()
    lever = rot.apply(np.array(dumbbell.centers))[0]  # the leading member's centre from the centre of mass
    m = dumbbell.mass
    m_true = mass_felt(m, rm @ np.diag(1.0 / np.asarray(dumbbell.inertia_principal)) @ rm.T, lever, n)
    m_engine = mass_felt(m, np.eye(3) / np.mean(dumbbell.inertia_principal), lever, n)
    e_eff = 1.0 / (2.0 * (1.0 - STIFF.poisson_ratio**2) / STIFF.youngs_modulus)
    assert m_true < 0.8 * m  # a real off-centre effect
    assert hertz_restitution(m_true, m_true, e, R_MEMBER, e_eff, V0) == pytest.approx(e, rel=1e-6)
    predicted = {"contact_point": hertz_restitution(m_true, m_engine, e, R_MEMBER, e_eff, V0),
                 "body": hertz_restitution(m_true, m, e, R_MEMBER, e_eff, V0)}
    measured = {c: off_centre_rebound(dumbbell, c, e) for c in CONVENTIONS}
    for c in CONVENTIONS:
        assert measured[c] == pytest.approx(predicted[c], rel=0.005), c
    assert measured["contact_point"] == pytest.approx(e, rel=0.03)
    # the whole-body mass over-damps the off-centre contact
    assert measured["body"] < measured["contact_point"] - 0.02


# ------------------------------------------------------------------ (c) config and errors
def test_option_travels_from_a_config_and_names_itself():
    law = contact_law_from_config({"rolling": "epsd2", "clump_damping_mass": "body"})
    assert law.clump_damping_mass == "body" and law.rolling == "epsd2"
    assert law != wd.ContactLaw(rolling="epsd2")  # its own compiled kernels and records
    assert law.describe().endswith("+clump_damping:body")
    assert wd.ContactLaw().describe() == "hertz+history+rolling:none+cohesion:none"  # default text unchanged
    desc = ModelDescription.from_config({"contact_law": {"clump_damping_mass": "contact_point"}})
    assert desc.contact_law == wd.ContactLaw()
    # the default is left out of records, so records and DEM-cache keys of earlier laws stay valid
    assert "clump_damping_mass" not in desc.describe()["contact_law"]
    body = ModelDescription.from_config({"contact_law": {"clump_damping_mass": "body"}})
    assert body.describe()["contact_law"]["clump_damping_mass"] == "body"
    import pickle

    assert pickle.loads(pickle.dumps(law)) == law


@pytest.mark.parametrize("bad", ["whole_body", "Body", 1, None])
def test_bad_clump_damping_mass_is_refused_by_name(bad):
    with pytest.raises(ConfigError, match=r"clump_damping_mass.*contact_point.*body"):
        wd.ContactLaw(clump_damping_mass=bad)
    with pytest.raises(ConfigError, match=r"contact_law: unknown clump_damping_mass"):
        ModelDescription.from_config({"contact_law": {"clump_damping_mass": bad}})


def test_the_convention_is_part_of_the_model_fingerprint_and_the_checkpoint(tmp_path):
    """A 'body' model is another model (a checkpoint of one is refused by the other), and a
    checkpoint restores its convention."""
    from warpdem.io import load_checkpoint, save_checkpoint

    models = {}
    for convention in ("contact_point", "body"):
        b = builder(convention)
        b.add_spheres([[0.0, 0.0, 0.0]], R_MEMBER, "gravel")
        models[convention] = b.finalize("cpu")
    assert models["body"].fingerprint != models["contact_point"].fingerprint
    path = save_checkpoint(tmp_path / "body.npz", wd.Simulation(models["body"], 1e-6))
    assert load_checkpoint(path, "cpu").model.contact_law.clump_damping_mass == "body"
