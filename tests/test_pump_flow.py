"""Analytic pump flow and its grid: flow rates against the duty, Euler head against the design
head, continuity, and a pressure field consistent with the fluid acceleration."""
import math

import numpy as np
import pytest

from pump.design import G
from pump.flow import FlowGrid, PumpFlow
from pump.geometry import REGIONS, build_pump
from warpdem.errors import ConfigError


@pytest.fixture(scope="module")
def flow():
    return PumpFlow(build_pump())


@pytest.fixture(scope="module")
def grid(flow):
    return flow.sample(0.003)


@pytest.mark.parametrize("sampled", [False, True])
def test_flow_rates_match_the_duty(flow, grid, sampled):
    q = flow.geometry.design.flow_rate
    rates = flow.flow_rates(grid.interpolate_velocity if sampled else None)
    tol = 0.02 if sampled else 0.002
    for where in ("inlet", "impeller_outlet", "discharge"):
        assert rates[where] == pytest.approx(q, rel=tol), where
    # the section 1 deg before the tongue carries 359/360 of the flow
    assert rates["volute_throat"] == pytest.approx(q * 359 / 360, rel=tol)


@pytest.mark.parametrize("sampled", [False, True])
def test_euler_head_matches_the_design_head(flow, grid, sampled):
    d = flow.geometry.design
    h = flow.euler_head(grid.interpolate_velocity if sampled else None)
    assert h == pytest.approx(d.head / d.hydraulic_efficiency, rel=0.03 if sampled else 1e-4)
    # and the ideal head of the field: u2 c_u2 / g
    assert flow.impeller_swirl(np.array([d.r2]))[0] * d.u2 / G == pytest.approx(d.euler_head, rel=1e-9)


def test_axial_inlet_has_no_preswirl_and_swirl_grows_along_blades(flow):
    d = flow.geometry.design
    r = np.linspace(d.r_inlet, d.r2, 50)
    cu = flow.impeller_swirl(r)
    assert np.all(cu[r <= d.r1] == 0.0)
    assert abs(flow.impeller_swirl(np.array([d.r1 + 1e-9]))[0]) < 1e-3
    assert np.all(np.diff(cu[r > d.r1]) > 0)
    # relative flow leaves the blades deviated by Wiesner's slip: c_u2 = gamma u2 - c_m2 / tan beta2
    c_m2 = d.flow_rate / (2 * math.pi * d.r2 * d.b2)
    assert cu[-1] == pytest.approx(d.slip_factor * d.u2 - c_m2 / math.tan(math.radians(d.beta2_blade_deg)))


def test_field_is_divergence_free_in_the_fluid(flow, grid):
    h = grid.spacing
    div = sum(np.gradient(grid.velocity[..., k].astype(float), h, axis=k) for k in range(3))
    ax = [grid.origin[k] + h * np.arange(grid.shape[k]) for k in range(3)]
    geo = flow.geometry
    d = geo.design
    pts = np.stack(np.meshgrid(*ax, indexing="ij"), -1)
    r = np.hypot(pts[..., 0], pts[..., 1])
    z = pts[..., 2]
    speed = np.linalg.norm(grid.velocity, axis=-1)
    # away from the zone interfaces (pipe/eye/impeller, r1, r2, r3, the tongue)
    inner = ((r > d.r1 + 2 * h) & (r < d.r2 - 2 * h) & (z > 2 * h) & (z < d.b2 - 2 * h)) | \
            ((r > d.r3 + 2 * h) & (r < d.r3 + 0.02) & (pts[..., 1] < -0.02) & (z > 0) & (z < d.b2))
    rel = np.abs(div[inner]) * h / np.maximum(speed[inner], 1e-6)
    assert inner.sum() > 1000
    assert np.percentile(rel, 99) < 0.01


def test_pressure_gradient_is_consistent_with_the_acceleration(flow, grid):
    """Where no blade force acts, -grad p / rho = Du/Dt (Euler equations, steady)."""
    d = flow.geometry.design
    gp = grid.pressure_gradient()
    # points at least two grid spacings beyond r3, where the angular momentum has a kink (the gap's
    # linear decay meets the free vortex) that central differences smear over +-1 spacing
    th = np.linspace(3.2, 5.6, 30)
    rr = d.r3 + 0.4 * d.throat_height * th / (2 * np.pi)
    assert np.all(rr - d.r3 > 2 * grid.spacing)
    pts = np.stack([rr * np.cos(th), rr * np.sin(th), np.full_like(th, 0.5 * d.b2)], -1)
    acc = grid.interpolate(pts, "acceleration")
    idx = np.round((pts - grid.origin) / grid.spacing).astype(int)
    gpp = gp[idx[:, 0], idx[:, 1], idx[:, 2]]
    er = pts[:, :2] / rr[:, None]
    a_r = np.sum(acc[:, :2] * er, axis=1)
    assert a_r == pytest.approx(-(d.k_volute / rr) ** 2 / rr, rel=0.05)  # centripetal c_u^2 / r
    assert -np.sum(gpp[:, :2] * er, axis=1) / flow.density == pytest.approx(a_r, rel=0.08)
    # suction pipe: uniform flow, no acceleration, no pressure gradient
    p_pipe = np.array([[0.0, 0.0, flow.geometry.inlet_top - 0.05]])
    assert np.abs(grid.interpolate(p_pipe, "acceleration")).max() < 1e-3
    # the impeller raises the pressure (static rise from the eye to r2 of order rho (u2^2 - w2^2) / 2)
    p_eye = flow.pressure(np.array([[0.0, 0.0, 0.5 * d.b2]]))[0]
    p_out = flow.pressure(np.array([[d.r2, 0.0, 0.5 * d.b2]]))[0]
    assert 0.5 * G * d.euler_head * flow.density < p_out - p_eye < G * d.euler_head * flow.density


def test_side_rooms_hold_a_rotating_core_in_radial_equilibrium(flow, grid):
    """Side rooms (r <= r2 beside the discs): c_u = k omega r, no radial or axial flow, p*(r) =
    p*(r2) - rho k^2 omega^2 (r2^2 - r^2) / 2, and on the grid Du/Dt = -k^2 omega^2 r e_r = -grad p / rho."""
    geo, d = flow.geometry, flow.geometry.design
    k, w = flow.side_room_rotation, d.omega
    assert k == 0.5 and d.side_gap == pytest.approx(0.020)
    r = np.linspace(d.r_inlet + 0.01, d.r2 - 0.01, 7)
    th = np.linspace(0.3, 5.9, 7)
    for z in (d.b2 + 0.5 * d.side_gap, -0.5 * d.side_gap):
        pts = np.stack([r * np.cos(th), r * np.sin(th), np.full_like(r, z)], -1)
        assert np.all(geo.region_of(pts) == REGIONS.index("side_rooms"))
        v, p = flow.evaluate(pts)
        eu = np.stack([-np.sin(th), np.cos(th), np.zeros_like(th)], -1)
        assert v == pytest.approx(k * w * r[:, None] * eu, abs=1e-12)
        p2 = flow.pressure(np.array([[d.r2, 0.0, 0.5 * d.b2]]))[0]
        assert p == pytest.approx(p2 - 0.5 * flow.density * (k * w) ** 2 * (d.r2**2 - r**2), rel=1e-9)
        # on the grid, away from the discs and liners by two spacings (mid-gap of 20 mm, 3 mm grid)
        acc = grid.interpolate(pts, "acceleration")
        er = pts[:, :2] / r[:, None]
        a_r = np.sum(acc[:, :2] * er, axis=1)
        assert a_r == pytest.approx(-(k * w) ** 2 * r, rel=0.02)
        idx = np.round((pts - grid.origin) / grid.spacing).astype(int)
        gp = grid.pressure_gradient()[idx[:, 0], idx[:, 1], idx[:, 2]]
        assert -np.sum(gp[:, :2] * er, axis=1) / flow.density == pytest.approx(a_r, rel=0.05)
    # k is the user's: 0 is a still side room, a value outside [0, 1] is refused naming the key
    still = PumpFlow(geo, side_room_rotation=0.0)
    assert np.abs(still.velocity(np.array([[0.08, 0.0, d.b2 + 0.01]]))).max() == 0.0
    with pytest.raises(ConfigError, match="side_room_rotation"):
        PumpFlow(geo, side_room_rotation=1.5)


def test_uniform_grid_and_bad_input():
    g = FlowGrid.uniform((1.0, 0.0, 0.0), (0, 0, 0), (0.1, 0.1, 0.1), 0.01)
    assert g.interpolate(np.array([[0.05, 0.05, 0.05], [1, 1, 1]])) == pytest.approx(np.array([[1, 0, 0]] * 2))
    with pytest.raises(ConfigError, match="density"):
        PumpFlow(build_pump(), density=-1)
    with pytest.raises(ConfigError, match="spacing"):
        PumpFlow(build_pump()).sample(0.0)
