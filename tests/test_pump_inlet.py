"""Particle inlet and outlet: rate from the volume fraction, slot schedule, activation of
pre-allocated bodies without reallocation, removal at the outlet, counts per region."""
import math

import numpy as np
import pytest

import warpdem as wd
from calibration.materials import BulkMaterial, sample_particles
from pump.design import PumpDesign
from pump.geometry import REGIONS, build_pump
from pump.inlet import ParticleInlet, inlet_slots, injection_rate, plan_injection


@pytest.fixture(scope="module")
def geo():
    return build_pump(PumpDesign(inlet_length=0.06), resolution=0.5)


def test_rate_delivers_the_volume_fraction():
    q, v = 25 / 3600, math.pi / 6 * 0.012**3
    rate = injection_rate(0.01, q, v)
    assert rate * v == pytest.approx(0.01 * q)
    with pytest.raises(wd.ConfigError, match="volume_fraction"):
        injection_rate(0.9, q, v)


def test_schedule_spacing_and_slots(geo):
    r_b = 0.006
    slots = inlet_slots(geo, r_b)
    assert np.all(np.hypot(slots[:, 0], slots[:, 1]) <= geo.design.r_inlet - r_b)
    d = np.sqrt(((slots[:, None] - slots[None]) ** 2).sum(-1)) + np.eye(len(slots))
    assert d.min() >= 2 * r_b
    plan = plan_injection(geo, 300.0, 0.1, r_b, worlds=3, seed=4)
    for w in range(3):
        t = plan.time[plan.world == w]
        assert abs(len(t) - 300.0 * 0.1) <= 1
        assert np.allclose(np.diff(t), 1 / 300.0)
        pos = plan.position[plan.world == w]
        # a slot is reused only once its particle moved one spacing down the pipe
        for s in np.unique(pos[:, :2], axis=0):
            ts = t[np.all(pos[:, :2] == s, axis=1)]
            assert np.all(np.diff(ts) * geo.design.inlet_velocity >= 2 * r_b + 0.002 - 1e-9)
    # different worlds get different phases
    assert plan.time[plan.world == 0][0] != plan.time[plan.world == 1][0]
    with pytest.raises(wd.ConfigError, match="too high for the inlet"):
        plan_injection(geo, 1e5, 0.1, r_b)
    with pytest.raises(wd.ConfigError, match="do not fit the suction pipe"):
        inlet_slots(geo, 0.04)


def small_case(geo, rate=400.0, t_end=0.02, worlds=2):
    material = BulkMaterial.spheres(0.010, 0.012)
    plan = plan_injection(geo, rate, t_end, material.max_bounding_radius, worlds=worlds, seed=2)
    samples = [sample_particles(material, n=int((plan.world == w).sum()), rng=w) for w in range(worlds)]
    inlet = ParticleInlet(geo, plan, samples)
    b = wd.ModelBuilder(num_worlds=worlds, gravity=(0, -9.81, 0))
    b.add_material(wd.GRAVEL)
    b.add_wall((geo.casing.vertices, geo.casing.faces), "gravel", name="casing")
    inlet.add_to_builder(b, "gravel")
    sim = wd.Simulation(b.finalize("cpu", check_overlaps=False), dt=2e-5)
    inlet.attach(sim)
    return sim, inlet, plan


def test_injection_activates_reserve_bodies_on_time_without_reallocation(geo):
    sim, inlet, plan = small_case(geo)
    ptrs = {k: getattr(sim.state, k).ptr for k in ("body_q", "body_v", "body_active")}
    assert sim.state.body_active.numpy().sum() == 0
    inlet.update(sim)
    for _ in range(10):
        sim.run(50)
        inlet.update(sim)
        due = int((plan.time <= sim.time).sum())
        assert inlet.injected == due
        assert sim.state.body_active.numpy().sum() == due
    assert {k: getattr(sim.state, k).ptr for k in ptrs} == ptrs  # same device arrays throughout
    # a body activated late is placed where it would be had it entered on time
    first = inlet.body_ids[np.argmin(plan.time)]
    assert sim.state.body_q.numpy()[first][2] < plan.position[0][2]
    counts = inlet.region_counts(sim)
    assert counts.sum() == inlet.injected
    assert counts[:, REGIONS.index("inlet")].sum() > 0


def test_outlet_removes_and_counts_per_world(geo):
    sim, inlet, plan = small_case(geo, t_end=0.01)
    sim.run(400)
    inlet.update(sim)
    act = sim.state.body_active.numpy()
    on = np.flatnonzero(act)
    q = sim.state.body_q.numpy()
    d = geo.design
    q[on[0]] = (0.5 * (d.r3 + d.r_throat), geo.outlet_y + 0.01, 0.015)  # past the discharge
    q[on[1]] = (0.0, 0.0, geo.inlet_top + 0.2)  # back out of the suction pipe
    sim.state.body_q.assign(q)
    inlet.update(sim)
    out, lost = inlet.removed_per_world()
    w = sim.model.host["body_world"]
    assert out.sum() == 1 and out[w[on[0]]] == 1
    assert lost.sum() == 1 and lost[w[on[1]]] == 1
    assert sim.state.body_active.numpy()[on[:2]].tolist() == [0, 0]


def test_inlet_needs_enough_particles(geo):
    material = BulkMaterial.spheres(0.010)
    plan = plan_injection(geo, 400.0, 0.02, 0.005, worlds=1)
    with pytest.raises(wd.ConfigError, match="the plan injects"):
        ParticleInlet(geo, plan, [sample_particles(material, n=1, rng=0)])
