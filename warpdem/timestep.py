"""Time-step estimates for Hertzian DEM.

Rayleigh time (Li, Xu & Thornton 2005, Powder Technol. 160:219; EDEM's definition):
    T_R = pi R sqrt(rho / G) / (0.1631 nu + 0.8766)
Hertz contact duration and maximum overlap of an elastic impact at normal speed v
(Johnson 1985, Contact Mechanics, Sec. 11.4):
    t_c = 2.868 (m*^2 / (R* E*^2 v))^(1/5),  delta_max = (15 m* v^2 / (16 E* sqrt(R*)))^(2/5)

Stability limit used by the solver: dt must not exceed T_R of the smallest sphere, and an
impact at the reference speed must be resolved by at least ``MIN_STEPS_PER_CONTACT`` steps.

Speed bound (:func:`speed_bound`): a body faster than
    v_max = SPEED_BOUND_FACTOR (v_ref + v_wall) + sqrt(2 |g| L)
is taken as a sign of an unstable world (the step was checked for impacts up to v_ref):
v_wall is the largest wall surface speed (|v| + |w| max |x0 - c0| over each moving wall's
vertices), L the diagonal of the box holding every initial body centre and wall vertex (the
free-fall speed over the model's extent).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from .errors import StabilityError, StabilityWarning
from .materials import effective_youngs_modulus

MIN_STEPS_PER_CONTACT = 10
SPEED_BOUND_FACTOR = 10.0


def rayleigh_time(radius: float, density: float, shear_modulus: float, poisson_ratio: float) -> float:
    """Rayleigh wave time across a sphere [s]."""
    return math.pi * radius * math.sqrt(density / shear_modulus) / (0.1631 * poisson_ratio + 0.8766)


def hertz_contact_time(m_eff: float, r_eff: float, e_eff: float, v: float) -> float:
    """Duration of an elastic Hertz impact at normal speed v [s]."""
    return 2.868 * (m_eff**2 / (r_eff * e_eff**2 * v)) ** 0.2


def hertz_max_overlap(m_eff: float, r_eff: float, e_eff: float, v: float) -> float:
    """Maximum overlap of an elastic Hertz impact at normal speed v [m]."""
    return (15.0 * m_eff * v**2 / (16.0 * e_eff * math.sqrt(r_eff))) ** 0.4


@dataclass(frozen=True)
class TimeStepLimits:
    rayleigh: float  # T_R of the smallest sphere [s]
    hertz_contact: float  # t_c of the softest, lightest pair at v_ref [s]
    limit: float  # largest admissible step [s]
    recommended: float  # 20 % of T_R, capped by the limit [s]
    v_ref: float


def time_step_limits(model, v_ref: float = 2.0) -> TimeStepLimits:
    """Stability limits of a model for impacts up to ``v_ref`` [m/s]."""
    r = model.host["sphere_radius"]
    mats = model.materials
    smat = model.host["sphere_material"]
    mass = model.sphere_mass()
    smallest = []
    for mi in np.unique(smat):
        sel = smat == mi
        smallest.append((mats[int(mi)], float(r[sel].min()), float(mass[sel].min())))
    return time_step_limits_for(smallest, v_ref)


def time_step_limits_for(smallest: "list[tuple[object, float, float]]", v_ref: float = 2.0) -> TimeStepLimits:
    """Stability limits from (material, smallest sphere radius [m], smallest sphere mass [kg]) per
    sphere material: T_R of the smallest sphere, t_c of an impact of two of the lightest at ``v_ref``.
    A caller that knows the smallest sphere a material can have (its size distribution's lower end)
    gets a step that does not depend on which particles one fill happened to draw."""
    t_r = math.inf
    t_c = math.inf
    for m, rmin, mmin in smallest:
        t_r = min(t_r, rayleigh_time(rmin, m.density, m.shear_modulus, m.poisson_ratio))
        t_c = min(t_c, hertz_contact_time(mmin / 2, rmin / 2, effective_youngs_modulus(m, m), v_ref))
    limit = min(t_r, t_c / MIN_STEPS_PER_CONTACT)
    return TimeStepLimits(t_r, t_c, limit, min(0.2 * t_r, limit), v_ref)


def check_time_step(model, dt: float, v_ref: float = 2.0, force: bool = False) -> TimeStepLimits:
    """Raise StabilityError if ``dt`` exceeds the stability limit (unless ``force``)."""
    if not (dt > 0 and math.isfinite(dt)):
        raise StabilityError(f"time step must be a positive finite number of seconds, got {dt}")
    lim = time_step_limits(model, v_ref)
    if dt > lim.limit and force:
        warnings.warn(
            f"time step {dt:.3g} s is {dt / lim.limit:.2f} x the stability limit {lim.limit:.3g} s "
            f"(impacts up to v_ref = {v_ref} m/s); accepted because force=True", StabilityWarning, stacklevel=2)
    if dt > lim.limit and not force:
        raise StabilityError(
            f"time step {dt:.3g} s exceeds the stability limit {lim.limit:.3g} s "
            f"(Rayleigh time {lim.rayleigh:.3g} s, Hertz contact time {lim.hertz_contact:.3g} s at {v_ref} m/s "
            f"needs >= {MIN_STEPS_PER_CONTACT} steps); recommended {lim.recommended:.3g} s. Pass force=True to override.")
    return lim


def speed_bound(model, v_ref: float = 2.0) -> float:
    """Largest body speed [m/s] a stable run of ``model`` is expected to reach (module
    docstring): ``SPEED_BOUND_FACTOR (v_ref + v_wall) + sqrt(2 |g| L)``."""
    pts = [np.asarray(model.initial["body_q"], dtype=np.float64).reshape(-1, 3)]
    v_wall = 0.0
    for w in model.walls:
        x0 = np.asarray(w.vertices, dtype=np.float64)
        pts.append(x0)
        mo = w.motion
        if not mo.is_static:
            arm = float(np.linalg.norm(x0 - np.asarray(mo.origin), axis=1).max())
            v_wall = max(v_wall, float(np.linalg.norm(mo.velocity)) + float(np.linalg.norm(mo.angular_velocity)) * arm)
    allp = np.concatenate(pts)
    extent = float(np.linalg.norm(allp.max(axis=0) - allp.min(axis=0)))
    g = float(np.linalg.norm(model.gravity))
    return SPEED_BOUND_FACTOR * (float(v_ref) + v_wall) + math.sqrt(2.0 * g * extent)
