"""Pair evaluation on the CPU: each sphere pair once with the reaction on the partner ("half",
the CPU's default) against both sides ("full"): the same forces, torques and motion to float
rounding (Newton's third law is exact for antisymmetric sub-models), the same contact history
in checkpoints, a State never stepped by a solver of the other kind, and the choices refused
where they do not hold."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import warpdem as wd
from warpdem import contact_rows, geometry
from warpdem.clump_geometry import make_template
from warpdem.errors import ConfigError
from warpdem.solver import resolve_pair_evaluation

DT = 2.0e-5
LAWS = {"epsd": wd.ContactLaw(rolling="epsd"), "epsd2_sjkr": wd.ContactLaw(rolling="epsd2", cohesion="sjkr"),
        "mindlin_cdt_liggghts": wd.ContactLaw(tangential="mindlin", rolling="cdt_liggghts")}


def _model(law: wd.ContactLaw, clumps: bool, seed: int = 3) -> wd.Model:
    """A loose heap of spheres (radii 4-6 mm) or three-sphere clumps in a box, two worlds."""
    rng = np.random.default_rng(seed)
    b = wd.ModelBuilder(num_worlds=2, contact_law=law)
    b.add_material(wd.Material("grain", 5.0e6, 0.3, 2600.0))
    g = np.stack(np.meshgrid(np.arange(6), np.arange(6), np.arange(5), indexing="ij"), -1).reshape(-1, 3)
    pos = (g + 0.5) * 0.0125 + rng.uniform(-1e-3, 1e-3, (len(g), 3))
    for w in range(2):
        if clumps:
            tpl = make_template(np.array([[0.0, 0.0, 0.0], [0.005, 0.0, 0.0], [0.001, 0.004, 0.0]]),
                                [0.0035, 0.003, 0.0032], 2600.0, name="tri")
            b.add_clumps(tpl, pos, "grain", world=w, rotations=Rotation.random(len(pos), random_state=seed + w).as_quat())
        else:
            b.add_spheres(pos, rng.uniform(0.004, 0.006, len(pos)), "grain", world=w)
    b.add_wall(geometry.open_box((-0.002, -0.002, 0.0), (0.08, 0.08, 0.1)), "grain")
    params = dict(mu_s_pp=0.5, mu_s_pw=0.4)
    if law.rolling != "none":
        params.update(mu_r_pp=0.2, mu_r_pw=0.1)
    if law.cohesion != "none":
        params.update(cohesion_energy_density_pp=2e4, cohesion_energy_density_pw=1e4)
    b.set_contact_parameters(**params)
    return b.finalize("cpu", check_overlaps=False)


def _collapsed(law: wd.ContactLaw, clumps: bool) -> tuple[wd.Model, dict]:
    """The heap after 0.16 s of falling (full evaluation): a state with many contacts in motion."""
    model = _model(law, clumps)
    sim = wd.Simulation(model, DT, pair_evaluation="full", use_graph=False)
    sim.run(8000)
    return model, sim.solver.export_state(sim.state)


def _from(model: wd.Model, data: dict, pairs: str) -> wd.Simulation:
    sim = wd.Simulation(model, DT, pair_evaluation=pairs, use_graph=False)
    for state in (sim.state, sim._next):
        sim.solver.import_state(state, data)
    sim.solver.request_neighbour_rebuild()
    return sim


@pytest.mark.parametrize("clumps", [False, True], ids=["spheres", "clumps"])
@pytest.mark.parametrize("name", list(LAWS))
def test_half_and_full_give_the_same_forces_history_and_motion(name, clumps):
    law = LAWS[name]
    model, data = _collapsed(law, clumps)
    full, half = _from(model, data, "full"), _from(model, data, "half")
    assert half.solver.pair_evaluation == "half"
    np.testing.assert_array_equal(half.solver.contact_counts(half.state), full.solver.contact_counts(full.state))
    full.run(1)
    half.run(1)
    f_full, f_half = full.solver.sphere_f.numpy(), half.solver.sphere_f.numpy()
    t_full, t_half = full.solver.sphere_t.numpy(), half.solver.sphere_t.numpy()
    assert np.abs(f_full).max() > 0.02  # several times a member sphere's weight (5e-3 N): contacts are loaded
    np.testing.assert_allclose(f_half, f_full, rtol=0, atol=2e-5 * np.abs(f_full).max())
    np.testing.assert_allclose(t_half, t_full, rtol=0, atol=2e-5 * np.abs(t_full).max())
    # the checkpoint of the half rows is the full rows, entry for entry (springs to rounding)
    e_full, e_half = full.solver.export_state(full.state), half.solver.export_state(half.state)
    np.testing.assert_array_equal(e_half["contact_count"], e_full["contact_count"])
    k = model.max_contacts
    used = (np.arange(k)[None, :] < e_full["contact_count"][:, None]).reshape(-1)  # slots beyond a row's count are stale
    assert used.sum() > model.num_spheres
    np.testing.assert_array_equal(e_half["contact_partner"][used], e_full["contact_partner"][used])
    for key in ("contact_spring", "contact_roll"):
        if e_full[key].shape[0] == used.size:
            a, b = e_half[key][used], e_full[key][used]
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-4 * max(np.abs(b).max(), 1e-30))
    # and the motion stays the same over 200 steps of a collapsing heap (rounding, not physics)
    full.run(200)
    half.run(200)
    np.testing.assert_allclose(half.state.body_q.numpy(), full.state.body_q.numpy(), rtol=0, atol=1e-6)


def test_row_conversions_invert_each_other():
    model, data = _collapsed(LAWS["epsd"], clumps=False)
    n, k = model.num_spheres, model.max_contacts
    assert (data["contact_count"] > 0).mean() > 0.5
    half = contact_rows.full_rows_to_half(data, n, k)
    assert half["contact_count"].sum() < data["contact_count"].sum()
    back = contact_rows.half_rows_to_full(half, n, k)
    used = (np.arange(k)[None, :] < data["contact_count"][:, None]).reshape(-1)
    np.testing.assert_array_equal(back["contact_count"], data["contact_count"])
    np.testing.assert_array_equal(back["contact_partner"][used], data["contact_partner"][used])
    # full rows keep both views of a pair: the partner's spring is the negated one (to rounding)
    np.testing.assert_allclose(back["contact_spring"][used], data["contact_spring"][used], rtol=0,
                               atol=1e-5 * np.abs(data["contact_spring"]).max())


def test_auto_is_half_on_the_cpu_only_where_the_law_allows_it():
    assert resolve_pair_evaluation(False, wd.ContactLaw(rolling="epsd")) == "half"
    assert resolve_pair_evaluation(True, wd.ContactLaw(rolling="epsd")) == "full"
    # cdt reads one side's lever arm (r_i - delta/2): not antisymmetric for unequal spheres
    assert resolve_pair_evaluation(False, wd.ContactLaw(rolling="cdt")) == "full"
    with pytest.raises(ConfigError, match="rolling:cdt"):
        resolve_pair_evaluation(False, wd.ContactLaw(rolling="cdt"), "half")
    with pytest.raises(ConfigError, match="CPU only"):
        resolve_pair_evaluation(True, wd.ContactLaw(rolling="epsd"), "half")
    with pytest.raises(ConfigError, match="pair_evaluation must be one of"):
        resolve_pair_evaluation(False, wd.ContactLaw(), "both")


def test_a_state_is_never_stepped_by_a_solver_of_the_other_kind():
    model = _model(LAWS["epsd"], clumps=False)
    half = wd.Simulation(model, DT, pair_evaluation="half", use_graph=False)
    half.run(2)
    full = wd.DEMSolver(model, DT, pair_evaluation="full")
    with pytest.raises(ConfigError, match="export_state / import_state"):
        full.step(half.state, model.state())
