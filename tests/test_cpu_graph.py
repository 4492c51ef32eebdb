"""On the CPU a Simulation replays its steps from Warp's CPU graph by default (recorded launches
replayed in a native loop, no Python per launch): the same results as stepping one by one, bit
for bit; a solver change that alters what a step launches makes it capture again."""
from __future__ import annotations

import numpy as np
import pytest

import warpdem as wd
from warpdem import geometry

R = 0.005


def drum(**options) -> wd.Simulation:
    """27 spheres tumbling in a drum turning at 60 rpm (moving wall, contacts, list rebuilds)."""
    rng = np.random.default_rng(3)
    b = wd.ModelBuilder(contact_law=wd.ContactLaw(rolling="epsd2"))
    b.add_material(wd.GRAVEL)
    g = np.arange(3) * 2.2 * R
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3) - (2.2 * R, 2.2 * R, 2.2 * R + 0.025)
    b.add_spheres(pos + rng.uniform(-1e-4, 1e-4, pos.shape), R, "gravel")
    b.add_wall(geometry.cylinder_shell(0.05, 0.04, axis=(0.0, 1.0, 0.0), sections=48), "gravel",
               motion=wd.WallMotion.rotation((0, 1, 0), 60.0))
    b.set_contact_parameters(mu_s_pp=0.5, mu_s_pw=0.5, mu_r_pp=0.1, mu_r_pw=0.1)
    return wd.Simulation(b.finalize("cpu"), dt=2e-5, steps_per_graph=20, **options)


def test_cpu_graph_is_the_default_and_matches_stepping_bit_for_bit():
    graphed, stepped = drum(), drum(use_graph=False)
    assert graphed.use_graph and not stepped.use_graph
    for sim in (graphed, stepped):
        sim.run(3003)  # not a multiple of the graph: the parity step and the rest run ungraphed
    assert graphed._graph is not None and graphed.steps == stepped.steps == 3003
    a, b = graphed.solver.export_state(graphed.state), stepped.solver.export_state(stepped.state)
    assert int(a["contact_count"].sum()) > 0
    for key, want in b.items():
        assert np.array_equal(a[key], want), f"{key}: the CPU graph differs from stepping"


def test_hash_grid_search_steps_without_a_cpu_graph():
    # Warp's HashGrid is built on the host: a CPU capture would not replay the build
    assert not drum(neighbour_search="hash_grid").use_graph


def test_turning_on_the_external_force_after_a_graphed_run_takes_effect():
    sim = drum()
    sim.run(40)
    assert sim._graph is not None
    v0 = sim.state.body_v.numpy()[:, 0].copy()
    sim.solver.external_force.assign(np.tile(np.float32([0.5, 0.0, 0.0]), (sim.model.num_bodies, 1)))
    sim.solver.use_external_force = True  # read when a step is captured: the graph must be captured again
    sim.run(40)
    dv = sim.state.body_v.numpy()[:, 0] - v0
    # 0.5 N on a ~1.4 g sphere for 0.8 ms: about +0.3 m/s each, far beyond what the contacts add
    mass = sim.model.host["body_mass"]
    assert np.median(dv) == pytest.approx(np.median(0.5 / mass * 40 * 2e-5), rel=0.5)


def test_a_replaced_state_is_stepped_not_the_captured_one():
    """Code that gives the Simulation a new State (a checkpoint loaded into a fresh one) after a
    graphed run: the graph is captured again for the new buffers, and the run goes on exactly as
    if nothing had been replaced."""
    graphed, stepped = drum(), drum(use_graph=False)
    graphed.run(1000)
    fresh = graphed.model.state()
    graphed.solver.import_state(fresh, graphed.solver.export_state(graphed.state))
    graphed.state = fresh
    graphed.run(2000)
    stepped.run(3000)
    a, b = graphed.solver.export_state(graphed.state), stepped.solver.export_state(stepped.state)
    assert int(b["contact_count"].sum()) > 0
    for key, want in b.items():
        assert np.array_equal(a[key], want), f"{key}: the run after replacing the State differs"
