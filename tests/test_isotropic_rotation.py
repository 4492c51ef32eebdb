"""The integrator's isotropic branch (every single sphere): free spin against the exact rotation,
and against the general (angular-momentum, midpoint) branch on a body whose inertia differs from
isotropic by one part in 1e6."""
from __future__ import annotations

import numpy as np

import warpdem as wd

DT, STEPS = 1.0e-4, 400
W0 = np.array([3.0, -2.0, 5.0])  # rad/s


def _spin(inertia_scale: tuple[float, float, float]):
    b = wd.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_material(wd.Material("steel", 2.0e11, 0.3, 7800.0))
    r, m = 0.01, 7800.0 * 4.0 / 3.0 * np.pi * 0.01 ** 3
    i0 = 0.4 * m * r * r
    b.add_body((0.0, 0.0, 0.0), m, np.array(inertia_scale) * i0, [(0.0, 0.0, 0.0)], [r], "steel",
               angular_velocity=tuple(W0))
    sim = wd.Simulation(b.finalize("cpu"), DT, force=True)  # no contacts: the stability limit does not apply
    sim.run(STEPS)
    return sim.state.body_rot.numpy()[0].astype(float), sim.state.body_w.numpy()[0].astype(float)


def _exact_rotation(w: np.ndarray, t: float) -> np.ndarray:
    """Quaternion (x, y, z, w) of a turn by |w| t about w."""
    angle = np.linalg.norm(w) * t
    axis = w / np.linalg.norm(w)
    return np.concatenate([axis * np.sin(angle / 2), [np.cos(angle / 2)]])


def test_free_sphere_spins_at_constant_rate_about_a_fixed_axis():
    q, w = _spin((1.0, 1.0, 1.0))
    np.testing.assert_allclose(w, W0, rtol=1e-6)
    exact = _exact_rotation(W0, STEPS * DT)
    assert min(np.abs(q - exact).max(), np.abs(q + exact).max()) < 1e-5


def test_isotropic_branch_agrees_with_the_general_branch():
    q_iso, w_iso = _spin((1.0, 1.0, 1.0))
    q_gen, w_gen = _spin((1.0, 1.0 + 1e-6, 1.0 - 1e-6))
    np.testing.assert_allclose(w_gen, w_iso, atol=1e-4 * np.linalg.norm(W0))
    assert min(np.abs(q_gen - q_iso).max(), np.abs(q_gen + q_iso).max()) < 1e-5
