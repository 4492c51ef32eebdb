"""The solver's GPU levers of issue 15 change where data lies and which kernel writes it, never a
result: with ``neighbour_layout="slot_major"`` (the Verlet list entry k of sphere i at
k * n + i), ``history_layout="slot_major"`` (the same for the contact slots) and
``fused_placement=True`` (the integrator places the member spheres of the bodies it moved), alone
and all together, the CPU scenes of tests/test_contact_stages.py give body states, contact
counts, forces and wall wear equal to the default's **bit for bit** (``np.array_equal``): every
float operation is the same, in the same order; only integer indices and the kernel that
computes a sphere's position and view differ.

Further scenes reach the code paths the levers touch: settling with removal outside a box and
worlds paused at different times (``pause_worlds``, ``remove_outside``), a world frozen as
unstable (bodies put back by ``isolate_unstable_bodies``), a body's velocity changed between
steps (``invalidate_views``), checkpoints saved by a solver of one layout and loaded by another,
the Finnie impact recorder of pump/wear.py (which reads the contact slots) and the pump inlet
(bodies activated and removed by kernels between steps). The CUDA variants of the same
comparisons are in tests/test_gpu.py (``pytest -m gpu -k layout``).
"""
from __future__ import annotations

import functools
import math
import sys
from pathlib import Path

import numpy as np
import pytest

import warpdem as wd
from warpdem import geometry, layouts
from warpdem.bench_settled_bed import LEVER_VARIANTS, LEVERS_OFF

sys.path.insert(0, str(Path(__file__).parent))
from test_contact_stages import SCENES, run_scene  # noqa: E402

# every lever off (the CPU's "auto"), and each lever alone or all on top of that
OFF = LEVERS_OFF
LEVERS = {name: options for name, options in LEVER_VARIANTS.items() if name != "off"}


def settle_scene() -> dict[str, np.ndarray]:
    """The two-world drum settled with removal: world 0 stops (paused) at 2 ms, world 1 at 4 ms,
    bodies beyond x = 8 mm are removed at each check (``remove_outside``)."""
    sim = SCENES["drum"]()
    rep = sim.settle(ke_per_particle=1e-12, max_time=np.array([0.002, 0.004]), check_interval=0.001,
                     remove_box=((-1.0, -1.0, -1.0), (0.008, 1.0, 1.0)))
    assert rep.removed > 0
    sim.run(20)
    return state_arrays(sim)


def unstable_scene() -> dict[str, np.ndarray]:
    """A sphere of world 1 of the drum set to 500 m/s between steps (``invalidate_views``): its
    world is frozen as unstable at the next step, the body put back at rest, world 0 runs on."""
    sim = SCENES["drum"]()
    sim.run(60)
    v = sim.state.body_v.numpy()
    v[30] = (500.0, 0.0, 0.0)
    sim.state.body_v.assign(v)
    sim.solver.invalidate_views()  # a State's bodies changed between steps
    with pytest.warns(wd.StabilityWarning, match="world 1"):
        failed = sim.run(60, on_unstable="freeze")
    assert set(failed) == {1}
    return state_arrays(sim)


def walls_off_scene() -> dict[str, np.ndarray]:
    """tests/test_contact_stages.py's contact launch without the walls, after placing the spheres
    of the State it is launched for (its reference launches with the views of the State before,
    which fused_placement does not keep)."""
    sim = SCENES["drum_walls_off"]()
    sim.run(50)
    sim.solver.place_spheres(sim.state)
    sim.solver.launch_contacts(sim.state, sim._next, sim.dt, walls_on=False)
    return {"contact_count": sim._next.contact_count.numpy(), "sphere_f": sim.solver.sphere_f.numpy(),
            "sphere_t": sim.solver.sphere_t.numpy()}


def state_arrays(sim: wd.Simulation) -> dict[str, np.ndarray]:
    """Body states, contact counts and slots (in the default layout), forces and wear of ``sim``."""
    s = sim.state
    out = {k: v for k, v in sim.solver.export_state(s).items() if k != "sphere_x"}
    out["sphere_f"] = sim.solver.sphere_f.numpy()
    for f in sim.solver.wall_stats.FIELDS:
        ws = sim.solver.wall_stats  # world-major over every wall (the one zero entry without walls)
        out[f"wear_{f}"] = ws.per_triangle(f).ravel() if sim.model.walls else ws.summed(f).numpy()
    return out


RUNS = {name: functools.partial(run_scene, name) for name in SCENES if name != "drum_walls_off"}
RUNS.update(drum_walls_off=walls_off_scene, drum_settle=settle_scene, drum_unstable=unstable_scene)


def run_with(run, options: dict, device: str, monkeypatch: pytest.MonkeyPatch, use_graph: bool | None = None):
    """``run()`` with every Simulation built with ``options`` (and ``use_graph`` if given) and
    every model on ``device`` (the scenes ask for ``"cpu"``)."""
    finalize = wd.ModelBuilder.finalize
    simulation = wd.Simulation

    def finalize_on_device(builder: wd.ModelBuilder, _asked: str | None = None, **kw) -> wd.Model:
        return finalize(builder, device, **kw)

    def make(*args, **kwargs):
        kwargs.update(options)
        if use_graph is not None:
            kwargs["use_graph"] = use_graph
        return simulation(*args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(wd, "Simulation", make)
        patch.setattr(wd.ModelBuilder, "finalize", finalize_on_device)
        return run()


@functools.lru_cache(maxsize=None)
def default_cpu(name: str) -> dict[str, np.ndarray]:
    with pytest.MonkeyPatch.context() as mp:
        return run_with(RUNS[name], OFF, "cpu", mp)


def assert_bitwise(got: dict, want: dict, label: str) -> None:
    assert got.keys() == want.keys()
    for key, w in want.items():
        assert np.array_equal(got[key], w), f"{label}/{key}: differs from the default (max |diff| " \
                                            f"{np.abs(got[key].astype(float) - w.astype(float)).max():.3g})"


@pytest.mark.parametrize("lever", list(LEVERS))
@pytest.mark.parametrize("name", list(RUNS))
def test_lever_is_bitwise_identical_to_the_default(name, lever, monkeypatch):
    want = default_cpu(name)
    assert int(want["contact_count"].sum()) > 0  # the scene has contacts
    assert_bitwise(run_with(RUNS[name], LEVERS[lever], "cpu", monkeypatch), want, f"{name}/{lever}")


def test_neighbour_rows_are_the_same_in_both_layouts():
    lists = {}
    for layout in layouts.SLOT_LAYOUTS:
        sim = SCENES["no_walls"]()
        sim = wd.Simulation(sim.model, sim.dt, use_graph=False, neighbour_layout=layout)
        sim.run(30)
        lists[layout] = sim.solver.neighbour_rows()
        if layout == "slot_major":  # the raw array really is transposed
            n, cap = sim.model.num_spheres, sim.solver.max_neighbours
            raw = sim.solver.nb_index.numpy().reshape(cap, n)
            np.testing.assert_array_equal(raw.T, lists[layout][1])
    (c0, i0), (c1, i1) = lists["sphere_major"], lists["slot_major"]
    np.testing.assert_array_equal(c0, c1)
    assert c0.sum() > 0
    for i, c in enumerate(c0):
        np.testing.assert_array_equal(i0[i, :c], i1[i, :c])


def test_slot_reorder_round_trip():
    rng = np.random.default_rng(0)
    for shape in [(6 * 4,), (6 * 4, 3)]:
        a = rng.normal(size=shape)
        b = layouts.from_sphere_major(a, "slot_major", 6, 4)
        assert not np.array_equal(a, b)
        np.testing.assert_array_equal(b.reshape((4, 6) + shape[1:])[2, 5], a.reshape((6, 4) + shape[1:])[5, 2])
        np.testing.assert_array_equal(layouts.to_sphere_major(b, "slot_major", 6, 4), a)
        np.testing.assert_array_equal(layouts.to_sphere_major(a, "sphere_major", 6, 4), a)
    one = np.zeros((1, 3))  # the 1-entry rolling history of a law that keeps none
    np.testing.assert_array_equal(layouts.to_sphere_major(one, "slot_major", 6, 4), one)


@pytest.mark.parametrize("save_with,load_with", [("all", None), (None, "all"), ("history_slot_major", "all")])
def test_checkpoints_load_across_layouts(tmp_path, save_with, load_with):
    """A checkpoint holds the contact slots in the default layout: saved by a solver of one layout
    and continued by another, the run ends bit for bit where the uninterrupted default run does."""
    from warpdem.io import load_checkpoint, save_checkpoint

    def scene(options):
        sim = SCENES["clumps"]()
        return wd.Simulation(sim.model, sim.dt, use_graph=False, **(options or OFF))

    ref = scene(OFF)
    ref.run(150)
    sim = scene(LEVERS.get(save_with))
    sim.run(80)
    path = save_checkpoint(tmp_path / "c.npz", sim)
    with np.load(path) as data:  # the file holds the default layout
        np.testing.assert_array_equal(data["state/contact_partner"],
                                      sim.solver.export_state(sim.state)["contact_partner"])
    back = load_checkpoint(path, device="cpu", model=sim.model, use_graph=False, **LEVERS.get(load_with, OFF))
    assert back.solver.history_layout == LEVERS.get(load_with, OFF)["history_layout"]
    back.run(70)
    assert_bitwise(state_arrays(back), state_arrays(ref), f"checkpoint {save_with} -> {load_with}")


def test_unknown_layout_is_a_config_error():
    model = SCENES["wear"]().model
    with pytest.raises(wd.ConfigError, match=r"neighbour_layout must be one of \('sphere_major', 'slot_major', 'auto'\)"):
        wd.DEMSolver(model, 1e-6, force=True, neighbour_layout="row_major")
    with pytest.raises(wd.ConfigError, match="history_layout"):
        wd.Simulation(model, 1e-6, force=True, use_graph=False, history_layout="transposed")


def test_auto_defaults_by_device():
    """"auto" (the default): every lever off on the CPU, all on on a GPU; explicit values pass."""
    s = SCENES["wear"]().solver
    assert (s.neighbour_layout, s.history_layout, s.fused_placement) == ("sphere_major", "sphere_major", False)
    assert wd.resolve_performance_options(False) == ("sphere_major", "sphere_major", False)
    assert wd.resolve_performance_options(True) == ("slot_major", "slot_major", True)
    assert wd.resolve_performance_options(True, "sphere_major", "auto", "off") == ("sphere_major", "slot_major", False)
    assert wd.resolve_performance_options(False, fused_placement="on")[2] is True
    with pytest.raises(wd.ConfigError, match="fused_placement must be True, False or one of"):
        wd.resolve_performance_options(True, fused_placement="sometimes")


# ----------------------------------------------------------------------------- pump code that reads slots
def impacts_run(options: dict) -> dict[str, np.ndarray]:
    """Spheres thrown obliquely onto a labelled plate with the Finnie impact recorder
    (pump/wear.py reads this step's and last step's contact slots)."""
    from pump.geometry import COMPONENTS
    from pump.wear import ImpactRecorder

    rng = np.random.default_rng(7)
    r = 0.006
    rec = ImpactRecorder(finnie_k=5e-10)
    b = wd.ModelBuilder()
    b.add_material(wd.GRAVEL)
    pos = np.column_stack([rng.uniform(-0.05, 0.05, 12), rng.uniform(-0.05, 0.05, 12), rng.uniform(0.008, 0.02, 12)])
    vel = np.column_stack([rng.uniform(-0.5, 0.5, 12), rng.uniform(-0.5, 0.5, 12), -rng.uniform(0.5, 1.5, 12)])
    b.add_spheres(pos, r, "gravel", velocities=vel)
    mesh = geometry.plane((0.0, 0.0, 0.0), 0.2, 0.2, subdivisions=10)
    labels = np.where(mesh.triangles_center[:, 0] > 0.0, COMPONENTS.index("volute"), COMPONENTS.index("tongue"))
    b.add_wall(mesh, "gravel", triangle_labels=labels, name="plate")
    b.set_contact_parameters(restitution_pw=0.5)
    b.add_body_force(rec)
    sim = wd.Simulation(b.finalize("cpu", check_overlaps=False), dt=2e-5, use_graph=False, **options)
    sim.run(800)
    out = state_arrays(sim)
    out.update(erosion=rec.erosion.numpy(), impacts=rec.impacts.numpy(), impact_energy=rec.impact_energy.numpy())
    assert out["impacts"].sum() >= 8  # most spheres hit the plate
    return out


@pytest.mark.parametrize("lever", ["history_slot_major", "all"])
def test_impact_recorder_reads_the_slots_in_either_layout(lever):
    assert_bitwise(impacts_run(LEVERS[lever]), impacts_run(OFF), f"impacts/{lever}")


@pytest.fixture(scope="module")
def pump_geometry():
    from pump.design import PumpDesign
    from pump.geometry import build_pump

    return build_pump(PumpDesign(inlet_length=0.06), resolution=0.5)


def inlet_sim(geo, options: dict):
    """Two pump worlds of 10-12 mm spheres that the inlet activates, with the solver ``options``;
    returns the Simulation and the inlet attached to it."""
    from calibration.materials import BulkMaterial, sample_particles
    from pump.inlet import ParticleInlet, plan_injection

    material = BulkMaterial.spheres(0.010, 0.012)
    plan = plan_injection(geo, 600.0, 0.01, material.max_bounding_radius, worlds=2, seed=2)
    samples = [sample_particles(material, n=int((plan.world == w).sum()), rng=w) for w in range(2)]
    inlet = ParticleInlet(geo, plan, samples)
    b = wd.ModelBuilder(num_worlds=2, gravity=(0, -9.81, 0))
    b.add_material(wd.GRAVEL)
    b.add_wall((geo.casing.vertices, geo.casing.faces), "gravel", name="casing")
    inlet.add_to_builder(b, "gravel")
    sim = wd.Simulation(b.finalize("cpu", check_overlaps=False), dt=2e-5, use_graph=False, **options)
    inlet.attach(sim)
    return sim, inlet


def inlet_run(geo, options: dict) -> dict[str, np.ndarray]:
    """Bodies activated by the pump inlet's kernel (which requests a list rebuild) and removed by
    it between run chunks (``invalidate_views``); one body moved past the outlet by hand."""
    sim, inlet = inlet_sim(geo, options)
    inlet.update(sim)
    for chunk in range(8):
        sim.run(50)
        if chunk == 4:
            on = np.flatnonzero(sim.state.body_active.numpy())
            q = sim.state.body_q.numpy()
            d = geo.design
            q[on[0]] = (0.5 * (d.r3 + d.r_throat), geo.outlet_y + 0.01, 0.015)  # past the discharge
            sim.state.body_q.assign(q)
        inlet.update(sim)
    assert inlet.injected > 4 and inlet.removed_per_world()[0].sum() == 1
    return state_arrays(sim)


def test_pump_inlet_with_all_levers(pump_geometry):
    """An integration run (the bodies the inlet activates touch nothing in their first step, so
    this run alone would not notice stale views; the next test checks the views themselves)."""
    assert_bitwise(inlet_run(pump_geometry, LEVERS["all"]), inlet_run(pump_geometry, OFF), "pump inlet/all")


# ----------------------------------------------------------------------------- fused placement's trigger
def views_the_next_step_sees(sim: wd.Simulation) -> tuple[bytes, bytes]:
    """The views and sphere positions after the placement launch a fused_placement step starts with."""
    sim.solver._place_spheres_on_request(sim.state)
    return sim.solver.views.numpy().tobytes(), sim.state.sphere_x.numpy().tobytes()


def views_of_the_state(sim: wd.Simulation) -> tuple[bytes, bytes]:
    sim.solver.place_spheres(sim.state)
    return sim.solver.views.numpy().tobytes(), sim.state.sphere_x.numpy().tobytes()


def test_fused_placement_places_again_after_every_change(pump_geometry):
    """After each way a State's bodies change between steps, the views the next step starts with
    are the State's: bodies activated or removed by the pump inlet's kernels, a body moved by hand
    with a list rebuild requested, bodies removed outside a box, a paused world, a body put back
    by the instability check, a step from another State; and on a plain step the placement
    launch does nothing."""
    geo = pump_geometry
    sim, inlet = inlet_sim(geo, {**OFF, "fused_placement": True})
    so = sim.solver

    def check(what: str) -> None:
        assert views_the_next_step_sees(sim) == views_of_the_state(sim), what

    sim.run(100)
    assert so.place_request.numpy()[0] == 0 and so.rebuild.numpy()[0] == 0  # a plain step places nothing
    before = so.views.numpy().tobytes()
    check("plain step")
    assert so.views.numpy().tobytes() == before
    inlet.update(sim)  # activates the bodies due (kernel; requests a list rebuild)
    assert inlet.injected > 0
    check("bodies activated by the inlet kernel")
    sim.run(50)
    q = sim.state.body_q.numpy()
    on = np.flatnonzero(sim.state.body_active.numpy())
    d = geo.design
    q[on[0]] = (0.5 * (d.r3 + d.r_throat), geo.outlet_y + 0.01, 0.015)  # past the discharge
    sim.state.body_q.assign(q)
    inlet.update(sim)
    assert inlet.removed_per_world()[0].sum() == 1
    check("a body removed at the outlet")
    sim.run(10)
    q = sim.state.body_q.numpy()
    q[on[1]] += (0.0, 0.0, 0.002)
    sim.state.body_q.assign(q)
    so.request_neighbour_rebuild()  # the documented call after moving bodies
    check("a body moved by hand, list rebuild requested")
    sim.run(10)
    lo, hi = geo.bounds()
    assert sim.remove_outside(lo, (hi[0], 0.5 * (lo[1] + hi[1]), hi[2])) > 0
    check("bodies removed outside a box")
    sim.run(10)
    sim.pause_worlds([1])
    check("a world paused")
    sim.resume_worlds()
    sim.run(10)
    v = sim.state.body_v.numpy()
    v[np.flatnonzero(sim.state.body_active.numpy())[-1]] = (500.0, 0.0, 0.0)
    sim.state.body_v.assign(v)
    so.invalidate_views()
    with pytest.warns(wd.StabilityWarning):
        sim.run(1, on_unstable="freeze")
    assert len(sim.failed_worlds()) == 1
    check("a body put back to its last pose by the instability check")
    so.step(sim.state, sim._next)  # the views are now _next's
    check("a step from a State whose spheres the views do not show")


@pytest.mark.parametrize("bad", [8, 300, 64.0, True, "64"])
def test_force_registers_rejects_what_is_not_a_register_count(bad):
    model = SCENES["drum"]().model
    with pytest.raises(wd.ConfigError, match="force_registers"):
        wd.Simulation(model, 2e-5, force_registers=bad)


def test_force_registers_changes_no_result_on_the_cpu(monkeypatch):
    """The cap is a CUDA compile option: the CPU builds the same kernels (the CUDA comparison is
    tests/test_gpu.py's ``test_cuda_register_cap_matches_the_default``)."""
    want = default_cpu("drum")
    got = run_with(RUNS["drum"], {**OFF, "force_registers": 48}, "cpu", monkeypatch)
    for key, w in want.items():
        assert np.array_equal(got[key], w), key


def test_force_registers_auto_caps_only_large_models_on_a_gpu():
    """``"auto"``: the occupancy cap (80) on a CUDA device for models of more than 2 x SMs x 512
    spheres (where the H100 measured +7.4 % at 1e6 spheres), the compiler's choice below that and
    on the CPU; explicit values pass through."""
    from types import SimpleNamespace

    from warpdem.stages.launch import OCCUPANCY_REGISTER_CAP, resolve_register_cap

    h100 = SimpleNamespace(is_cuda=True, sm_count=132)
    cpu = SimpleNamespace(is_cuda=False, sm_count=0)
    assert resolve_register_cap("auto", h100, 1_000_000) == OCCUPANCY_REGISTER_CAP == 80
    assert resolve_register_cap("auto", h100, 200_450) == 80
    assert resolve_register_cap("auto", h100, 124_352) is None  # the 64-world paper-scale baffle batch
    assert resolve_register_cap("auto", cpu, 10_000_000) is None
    assert resolve_register_cap(None, h100, 1_000_000) is None
    assert resolve_register_cap(64, cpu, 10) == 64
    with pytest.raises(wd.ConfigError, match="force_registers"):
        resolve_register_cap("fast", h100, 10)
