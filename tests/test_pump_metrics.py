"""The wear metrics of pump/wear.py mean what they say: the time-averaged contact force (impulse /
elapsed time) and the contact energy per area do not change when the time step halves, when every
triangle is subdivided, or when the number of worlds grows (ensemble mean); EDEM's step-summed
"average cumulative contact force" (seed paper Fig. 18) does, which the controls below check so
that each configuration could tell a wrong metric from a right one.

Configuration: 24 gravel spheres (r = 5 mm, 2 m/s, 20-70 deg from the plate, no gravity) thrown
at a labelled plate from staggered heights, each hitting once, 40 ms simulated; contact time
about 1 ms (50 steps at dt = 2e-5 s)."""
import math

import numpy as np
import pytest

import warpdem as wd
from pump.geometry import COMPONENTS
from pump.regions import BlockSeries, estimate
from pump.wear import METRICS, ImpactRecorder, WearRecorder, derive
from warpdem import geometry

R = 0.005
T_END = 0.04  # [s] simulated
N = 24


def throw(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities of the 24 spheres of one world."""
    g = np.stack(np.meshgrid(np.linspace(-0.17, 0.07, 6), np.linspace(-0.1, 0.1, 4), indexing="ij"), -1).reshape(-1, 2)
    pos = np.column_stack([g + rng.uniform(-0.01, 0.01, (N, 2)), R + 0.001 + rng.uniform(0.0, 0.02, N)])
    ang = np.radians(rng.uniform(20.0, 70.0, N))
    speed = 2.0
    return pos, np.column_stack([speed * np.cos(ang), np.zeros(N), -speed * np.sin(ang)])


def stream_on_plate(dt: float = 2e-5, subdivide: bool = False, worlds: int = 1, same_worlds: bool = True,
                    seed: int = 0) -> WearRecorder:
    """Run the sphere stream to T_END; returns the recorder (labels: x > 0 'volute', else 'tongue')."""
    mesh = geometry.plane((0.0, 0.0, 0.0), 0.4, 0.4, subdivisions=20)
    if subdivide:
        mesh = mesh.subdivide()  # every triangle into four (edge midpoints): same surface
    labels = np.where(mesh.triangles_center[:, 0] > 0.0, COMPONENTS.index("volute"), COMPONENTS.index("tongue"))
    b = wd.ModelBuilder(num_worlds=worlds, gravity=(0.0, 0.0, 0.0))
    b.add_material(wd.GRAVEL)
    for w in range(worlds):
        pos, vel = throw(np.random.default_rng(seed if same_worlds else seed + 1000 * w))
        b.add_spheres(pos, R, "gravel", world=w, velocities=vel)
    b.add_wall(mesh, "gravel", triangle_labels=labels, name="plate")
    b.set_contact_parameters(mu_s_pw=0.4, restitution_pw=0.6)
    imp = ImpactRecorder()
    b.add_body_force(imp)
    sim = wd.Simulation(b.finalize("cpu"), dt=dt)
    sim.run(int(round(T_END / dt)))
    return WearRecorder(sim, [0], impacts=imp)


INTENSIVE = ("force_n", "force_t", "pressure_n", "pressure_t", "energy_n_per_area", "energy_t_per_area",
             "power_n_per_area", "power_t_per_area", "impact_rate_per_area")


@pytest.fixture(scope="module")
def base() -> WearRecorder:
    return stream_on_plate()


def test_every_sphere_hits_once(base):
    imp = base.metric("impacts")
    assert sum(imp.values()) == N
    assert base.elapsed == pytest.approx(T_END)


# tolerance per metric for dt -> dt / 2 (50 -> 100 steps per contact): impulses are exact to
# O(dt / t_c)^2; the energies sum F v dt with the step's start velocity, +O(dt / t_c) (pump/README.md)
DT_TOLERANCE = {"force_n": 0.005, "pressure_n": 0.005, "force_t": 0.02, "pressure_t": 0.02,
                "energy_n_per_area": 0.03, "power_n_per_area": 0.03, "energy_t_per_area": 0.03,
                "power_t_per_area": 0.03, "impact_rate_per_area": 1e-9}


def test_time_averaged_force_and_energy_per_area_do_not_depend_on_dt(base):
    half = stream_on_plate(dt=1e-5)
    assert half.elapsed == pytest.approx(base.elapsed)
    for name in INTENSIVE:
        a, b = base.metric(name), half.metric(name)
        for comp in a:
            assert b[comp] == pytest.approx(a[comp], rel=DT_TOLERANCE[name]), (name, comp)
    # control: the step-summed force of EDEM / the seed paper's Fig. 18 counts steps
    for kind in ("normal", "tangential"):
        a, b = base.edem_cumulative_force()[kind], half.edem_cumulative_force()[kind]
        for comp in a:
            assert b[comp] / a[comp] == pytest.approx(2.0, rel=0.03), (kind, comp)


def test_per_area_metrics_do_not_depend_on_the_mesh(base):
    fine = stream_on_plate(subdivide=True)
    assert sum(fine.triangles_per_component().values()) == 4 * sum(base.triangles_per_component().values())
    for name in INTENSIVE:
        a, b = base.metric(name), fine.metric(name)
        for comp in a:
            assert b[comp] == pytest.approx(a[comp], rel=0.01), (name, comp)
    # per triangle: the triangles' area-weighted mean pressure is the component's pressure
    names, p = fine.metric_per_world("pressure_n", "triangle")
    area = fine.areas()[0]
    assert np.sum(p[0] * area) / area.sum() == pytest.approx(sum(fine.metric("force_n").values()) / area.sum(),
                                                             rel=1e-6)
    # control: the per-element EDEM force shrinks with the element
    for comp, v in base.edem_cumulative_force()["normal"].items():
        assert fine.edem_cumulative_force()["normal"][comp] / v == pytest.approx(0.25, rel=0.03), comp


def test_metrics_are_ensemble_means_over_worlds(base):
    """Four identical worlds give the one-world values exactly (a sum over worlds would give 4x)."""
    four = stream_on_plate(worlds=4)
    for name in INTENSIVE + ("impulse_n", "energy_n", "impacts"):
        a, b = base.metric(name), four.metric(name)
        for comp in a:
            assert b[comp] == pytest.approx(a[comp], rel=1e-5), (name, comp)
    _, per_world = four.metric_per_world("pressure_n")
    assert np.ptp(per_world, axis=0) == pytest.approx(0.0, abs=1e-6 * per_world.max())


def test_ensemble_mean_is_stable_as_worlds_are_added():
    """Different (seeded) throws per world: the 4- and 12-world means of the normal pressure
    agree within their 95 % intervals (the 12 worlds include the 4)."""
    few = stream_on_plate(worlds=4, same_worlds=False, seed=3)
    many = stream_on_plate(worlds=12, same_worlds=False, seed=3)
    for name in ("pressure_n", "power_n_per_area"):
        _, a = few.metric_per_world(name)
        _, b = many.metric_per_world(name)
        for g in range(a.shape[1]):
            ea, eb = estimate(a[:, g]), estimate(b[:, g])
            assert 0 < eb.half_width < math.inf and ea.n == 4 and eb.n == 12
            assert abs(ea.mean - eb.mean) <= ea.half_width + eb.half_width, (name, g, ea, eb)
        np.testing.assert_allclose(a, b[:4], rtol=1e-6)  # the same four worlds


def test_every_metric_is_defined_with_a_unit_and_derived():
    tot = {f: np.array([[2.0, 4.0]]) for f in ("impulse_n", "impulse_t", "energy_n", "energy_t", "impacts",
                                                "erosion", "sliding_work")}
    area, tri = np.array([0.5, 2.0]), np.array([10.0, 40.0])
    for name, (unit, text) in METRICS.items():
        assert unit and text
        v = derive(name, tot, area, tri, duration=4.0, dt=1e-3)
        assert v.shape == (1, 2) and np.all(np.isfinite(v)), name
    assert derive("force_n", tot, area, tri, 4.0, 1e-3)[0, 0] == pytest.approx(0.5)  # 2 N s / 4 s
    assert derive("pressure_n", tot, area, tri, 4.0, 1e-3)[0, 1] == pytest.approx(4.0 / 4.0 / 2.0)
    assert derive("edem_cumulative_force_n", tot, area, tri, 4.0, 1e-3)[0, 0] == pytest.approx(2.0 / 1e-3 / 10)
    with pytest.raises(wd.ConfigError, match="unknown wear metric"):
        derive("force", tot, area, tri, 4.0, 1e-3)


def test_block_intervals_cover_a_known_rate():
    """Poisson impacts at a known rate in 8 worlds x 10 blocks: the 95 % interval of the block
    rates covers the true rate in about 95 % of 400 repetitions (between 90 and 99 %)."""
    rng = np.random.default_rng(11)
    rate, block, cover = 50.0, 0.04, 0
    for _ in range(400):
        counts = rng.poisson(rate * block, size=(10, 8))  # (blocks, worlds)
        series = BlockSeries()
        series.append(0.0, {"impacts": np.zeros((8, 1))})
        cum = np.zeros((8, 1))
        for k in range(10):
            cum = cum + counts[k][:, None]
            series.append((k + 1) * block, {"impacts": cum})
        rates, window = series.block_rates("impacts", 0.0, block)
        assert rates.shape == (10, 8, 1) and window == pytest.approx(10 * block)
        e = estimate(rates[..., 0], impacts=counts.sum())
        cover += e.low <= rate <= e.high
    assert 0.90 <= cover / 400 <= 0.99


def test_convergence_rule_needs_impacts_and_a_narrow_interval():
    assert estimate(np.full(10, 1.0) + np.linspace(-0.01, 0.01, 10), impacts=100).converged
    assert not estimate(np.full(10, 1.0), impacts=5).converged  # too few impacts
    assert not estimate(np.array([0.0, 0.0, 0.0, 10.0]), impacts=100).converged  # too wide
    one = estimate(np.array([3.0]), impacts=100)
    assert math.isinf(one.half_width) and not one.converged
