"""CUDA checks (run on a GPU machine with ``pytest -m gpu``): the same kernels give the same
physics on ``cuda`` as on ``cpu``, with and without CUDA-graph capture."""
import sys
from pathlib import Path

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


# ----------------------------------------------------------------------------- issue 15 levers
# The solver's layout and placement levers (tests/test_layout_levers.py on the CPU) on CUDA, with
# the CUDA graph: each lever alone and all together against the default, same scenes. Only
# integer indices and the kernel that writes a sphere's position and view differ, so the body
# states should agree bit for bit; the wear sums use unordered atomic adds (rtol 1e-5, as in
# tests/test_wall_stage.py). Should a compiler contract the placement's float operations
# differently in the integrator than in the placement kernel, the bodies are held to rtol 1e-5 /
# atol 1e-9 (tests/test_contact_stages.py's tolerance) and a warning names the arrays that
# differ in the last bits.
LAYOUT_SCENES = ["drum", "clumps", "wear", "drum_settle", "drum_unstable"]  # two contact laws: few kernels to compile
LAYOUT_LEVERS = ["neighbour_slot_major", "history_slot_major", "fused_placement", "all", "default"]


@pytest.fixture(scope="module")
def layout_kernels():
    """Build every kernel variant these tests use before the first launch, so that Warp compiles
    each module once (a module is compiled again whenever a kernel is added to it)."""
    needs_cuda()
    from warpdem import kernels, stages
    from warpdem.stages.cell_list import build_neighbour_list_from_cells_kernel

    for law in (wd.ContactLaw(), wd.ContactLaw(rolling="cdt")):
        for nl in ("sphere_major", "slot_major"):
            for hl in ("sphere_major", "slot_major"):
                stages.contact_stages(law, nl, hl)
    for layout in ("sphere_major", "slot_major"):
        build_neighbour_list_from_cells_kernel(layout)
    for fused in (False, True):
        kernels.integrate_bodies_kernel(fused)
        kernels.isolate_unstable_bodies_kernel(fused)


_cuda_default: dict = {}


@pytest.mark.parametrize("lever", LAYOUT_LEVERS)
@pytest.mark.parametrize("name", LAYOUT_SCENES)
def test_cuda_layout_levers_match_the_default(name, lever, layout_kernels, monkeypatch):
    import warnings

    sys.path.insert(0, str(Path(__file__).parent))
    from test_layout_levers import LEVERS, OFF, RUNS, run_with

    if name not in _cuda_default:  # every lever off (on CUDA "auto" turns them all on: lever "default")
        _cuda_default[name] = run_with(RUNS[name], OFF, "cuda", monkeypatch, use_graph=True)
    want = _cuda_default[name]
    got = run_with(RUNS[name], LEVERS.get(lever, {}), "cuda", monkeypatch, use_graph=True)
    assert int(want["contact_count"].sum()) > 0
    assert got.keys() == want.keys()
    not_bitwise = []
    for key, w in want.items():
        if np.array_equal(got[key], w):
            continue
        if key.startswith("wear_"):
            np.testing.assert_allclose(got[key], w, rtol=1e-5, atol=1e-12, err_msg=f"{name}/{lever}/{key}")
            continue
        if key in ("contact_count", "contact_partner", "body_active"):
            raise AssertionError(f"{name}/{lever}/{key}: integer arrays differ from the default")
        np.testing.assert_allclose(got[key], w, rtol=1e-5, atol=1e-9, err_msg=f"{name}/{lever}/{key}")
        not_bitwise.append(f"{key} (max |diff| {np.abs(got[key].astype(float) - w.astype(float)).max():.2g})")
    if not_bitwise:
        warnings.warn(f"{name}/{lever}: within tolerance but not bit for bit: {', '.join(not_bitwise)}")


# ----------------------------------------------------------------------------- register cap
# ``force_registers`` (warpdem.stages.launch) only changes how the CUDA compiler allocates registers
# to the force kernels: the same instructions, so the same bodies, contacts and forces, bit for bit,
# as the compiler's own choice (the "auto" levers on). The cap must also really be compiled in: the
# capped kernel reports at most that many registers per thread.
REGISTER_CAPS = [40, 80]


@pytest.mark.parametrize("cap", REGISTER_CAPS)
@pytest.mark.parametrize("name", ["drum", "clumps", "wear"])
def test_cuda_register_cap_matches_the_default(name, cap, monkeypatch):
    needs_cuda()
    sys.path.insert(0, str(Path(__file__).parent))
    from test_layout_levers import RUNS, run_with

    key = ("auto", name)
    if key not in _cuda_default:
        _cuda_default[key] = run_with(RUNS[name], {}, "cuda", monkeypatch, use_graph=True)
    want = _cuda_default[key]
    got = run_with(RUNS[name], {"force_registers": cap}, "cuda", monkeypatch, use_graph=True)
    assert int(want["contact_count"].sum()) > 0
    for k, w in want.items():
        if k.startswith("wear_"):  # unordered atomic adds
            np.testing.assert_allclose(got[k], w, rtol=1e-5, atol=1e-12, err_msg=f"{name}/{cap}/{k}")
        else:
            assert np.array_equal(got[k], w), f"{name}/{cap}/{k} differs from the compiler's own register choice"


def test_cuda_register_cap_is_compiled_in(monkeypatch):
    needs_cuda()
    sys.path.insert(0, str(Path(__file__).parent))
    from test_contact_stages import SCENES
    from test_layout_levers import run_with

    from warpdem.bench_settled_bed import kernel_resources

    def scene():
        sim = SCENES["drum"]()
        sim.run(4)
        return sim

    sims = {cap: run_with(scene, {"force_registers": cap}, "cuda", monkeypatch, use_graph=True) for cap in (None, 40)}
    used = {cap: kernel_resources(sim.solver.stages.particle_forces, "cuda") for cap, sim in sims.items()}
    assert used[40] is not None and used[None] is not None, used
    assert used[40]["registers"] <= 40 < used[None]["registers"], used


# ----------------------------------------------------------------------------- wear lanes
@pytest.mark.parametrize("name", ["wear", "drum"])
def test_cuda_wear_lanes_change_no_force(name, monkeypatch):
    """The GPU default (32 copies of the wall accumulators) against one copy: bodies, contacts and
    forces bit for bit, wear to float rounding (tests/test_wear_lanes.py on the CPU)."""
    needs_cuda()
    sys.path.insert(0, str(Path(__file__).parent))
    from test_layout_levers import RUNS, run_with

    one = run_with(RUNS[name], {"wear_lanes": 1}, "cuda", monkeypatch, use_graph=True)
    auto = run_with(RUNS[name], {}, "cuda", monkeypatch, use_graph=True)
    for k, w in one.items():
        if k.startswith("wear_"):
            np.testing.assert_allclose(auto[k], w, rtol=1e-5, atol=1e-12, err_msg=f"{name}/{k}")
        else:
            assert np.array_equal(auto[k], w), f"{name}/{k}"
