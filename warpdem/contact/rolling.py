"""Rolling-resistance sub-models.

``cdt``   constant directional torque (Ai et al. 2011 model A). **This is EDEM's "Rolling
          Friction"** (Hertz-Mindlin with the standard rolling friction option, used by the
          seed paper's EDEM runs): tau_i = -mu_r F_n R_i w_rel/|w_rel|, R_i = distance from
          the sphere centre to the contact point (EDEM convention). Guard against reversal
          jitter: the torque is capped so that it cannot reverse w_rel within one step,
          |tau| <= I* |w_rel| / dt. (LIGGGHTS ``rolling_friction cdt``, src/rolling_model_cdt.h,
          is the same model with the elastic F_n = k_n delta and lever R* instead, no guard:
          ``cdt_liggghts``. Between equal spheres R* = r/2 against EDEM's R_i ~ r.)
``cdt_body_arm`` EDEM's "Standard Rolling Friction" as its documentation defines it, for
          multi-sphere particles: tau_i = -mu_r F_n R_i w_i/|w_i| with R_i = the distance from
          the contact point to the **centre of mass of i's body** (the clump's, not the member
          sphere's centre) and w_i the **body's own angular velocity** (not relative to the
          partner, not projected on the tangent plane; EDEM: "the unit angular velocity vector
          of the object at the contact point"). Same guard as ``cdt`` with the body's inertia,
          |tau| <= I_i |w_i| / dt. It differs from ``cdt`` for clumps (a longer lever: a member
          sphere's contact point lies up to the clump's bounding radius from the centre of mass),
          wherever the partner turns too (a bed turning rigidly with a drum, w_i = w_j = w_drum,
          feels no ``cdt`` torque but this one) and for spin about the normal. A sphere of its own
          rolling on a fixed wall, or on a sphere at rest, gets ``cdt``'s torque bit for bit
          (while the guard does not bind).
``cdt_liggghts`` LIGGGHTS 3.8 ``rolling_friction cdt`` (src/rolling_model_cdt.h):
          tau_i = -mu_r (k_n delta) R* w_rel / |w_rel|, its component along the normal removed,
          k_n delta = 4/3 E* sqrt(R* delta) delta the elastic Hertz force (no damping, no
          cohesion), R* = r_i r_j / (r_i + r_j) or r_i at a wall; no guard (the torque flips
          with w_rel, so a sphere at rest jitters by ~mu_r F_n R* dt / I).
``epsd``  elastic-plastic spring-dashpot of **Ai et al. (2011) model C** without its viscous
          term (eta_r = 0); the spring is LIGGGHTS ``rolling_friction epsd``'s
          (src/rolling_model_epsd.h: ``kr = 2.25*cdata.kn*rmu*rmu*reff*reff``), its dashpot is
          left out. **It is not LIGGGHTS epsd2** (older warpdem docs said so; the name is kept
          for configs and records). Incremental spring torque M_r <- M_r - k_r w_roll dt,
              k_r = 2.25 k_n mu_r^2 R*^2,  k_n = F_n,el / delta = 4/3 E* sqrt(R* delta)
          (Ai et al. 2011, with the Hertz secant stiffness as k_n), capped at
          |M_r| <= mu_r R* max(F_n, 0). Holds a static pile.
``epsd2`` LIGGGHTS ``rolling_friction epsd2`` (LIGGGHTS-PUBLIC src/rolling_model_epsd2.h,
          ``RollingModel<ROLLING_EPSD2>::calcRollTorque``): the same incremental spring without
          dashpot, but the rolling stiffness is tied to the *current* tangential stiffness of
          the step and does not depend on mu_r:
              k_r = k_t R*^2,  k_t = 8 G* sqrt(R* delta)   (``kr = cdata.kt*reff*reff``;
                                                          kt = St of normal_model_hertz.h)
              |M_r| <= mu_r R* |F_n|                        (``fabs(cdata.Fn)*reff*rmu``)
          R* = r_i r_j / (r_i + r_j) between particles and r_i at a wall (LIGGGHTS ``reff``
          there). F_n includes damping, as LIGGGHTS' ``sidata.Fn`` does; cohesion only with
          ``sjkr_reduced``/``sjkr2_reduced`` (LIGGGHTS ``tangential_reduce on``; LIGGGHTS' default
          and warpdem's ``sjkr`` leave it out, :mod:`warpdem.contact.cohesion`). At a wall LIGGGHTS turns
          the spring by w (r - delta/2) / (r - delta) per step instead of w (its ``wr`` is
          scaled to the contact radius), a difference of O(delta / r).
          One difference: LIGGGHTS keeps the stored torque as is; here, as for ``epsd`` and
          the tangential spring, it is turned into the current tangent plane (magnitude kept),
          which only matters while the contact normal rotates.

For the same mu_r, k_r(epsd2) / k_r(epsd) = 8 G* / (3 E* mu_r^2) (6.1 for equal materials
with nu = 0.3 and mu_r = 0.3). The plastic limit mu_r R* F_n is the same, so both hold a
sphere on a slope iff tan(theta) <= mu_r; they differ in the rolling angle needed to
mobilise it (smaller for epsd2 while mu_r < sqrt(8 G* / (3 E*)), ~0.74 at nu = 0.3).

Reference: Ai, J., Chen, J.-F., Rotter, J. M., Ooi, J. Y. (2011) Assessment of rolling
resistance models in discrete element simulations. Powder Technology 206, 269-282.
"""
from __future__ import annotations

import warp as wp

from .base import ContactInput, ParameterSpec, SubModel, register

MU_R = ParameterSpec("mu_r", "-", 0.1, (0.0, 10.0), "rolling friction coefficient",
                     design_range=(0.0, 0.3), off_value=0.0)


@wp.func
def rolling_spring_torque(c: ContactInput, spring: wp.vec3, k_r: float, m_max: float):
    """Elastic-plastic rolling spring: M <- M - k_r w_roll dt, |M| <= m_max (returns M).

    The stored torque is first turned into the current tangent plane (magnitude kept)."""
    n = c.normal
    m_len = wp.length(spring)
    m = spring - wp.dot(spring, n) * n
    m_proj = wp.length(m)
    if m_proj > 1.0e-30:
        m = m * (m_len / m_proj)
    w_roll = c.w_rel - wp.dot(c.w_rel, n) * n
    m = m - k_r * w_roll * c.dt
    ml = wp.length(m)
    if ml > m_max:
        if ml > 0.0:
            m = m * (m_max / ml)
    return m


@register
class ConstantDirectionalTorque(SubModel):
    kind = "rolling"
    name = "cdt"
    parameters = (MU_R,)
    reference = "Ai et al. (2011) model A; EDEM Hertz-Mindlin rolling friction; LIGGGHTS rolling_friction cdt"

    def make(self, column):
        c_mu = column("mu_r")

        @wp.func
        def cdt_rolling(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            w_roll = c.w_rel - wp.dot(c.w_rel, c.normal) * c.normal
            w_len = wp.length(w_roll)
            if w_len < 1.0e-12:
                return wp.vec3(0.0), spring
            t_mag = p[c.row, c_mu] * wp.max(fn, 0.0) * c.arm
            t_guard = c.i_eff * w_len / c.dt
            t_mag = wp.min(t_mag, t_guard)
            return -t_mag / w_len * w_roll, spring

        return cdt_rolling


@register
class BodyArmCDT(SubModel):
    """EDEM's "Standard Rolling Friction" (Altair EDEM Creator documentation, Physics > Rolling
    Friction > "Standard Rolling Friction Model": tau_i = -mu_r F_n R_i w_i, "R_i the distance of
    the contact point from the center of mass, and w_i the unit angular velocity vector of the
    object at the contact point"; EDEM's separate "RVD Rolling Friction" model is the one that
    uses the relative angular velocity of the two elements). For a multi-sphere particle the
    centre of mass and the angular velocity are the clump's.

    Differences from ``cdt`` (which follows Ai et al. 2011 model A with the member sphere's
    lever): the lever is |p - x_body| (:func:`warpdem.kernels.body_lever`) instead of the
    distance r_i - delta/2 (wall: r_i - delta) from the member sphere's centre, and the torque
    opposes the body's own angular velocity w_i (full vector) instead of the tangential part of
    w_i - w_j. The guard caps |tau| at I_i |w_i| / dt (I_i: the body's mean principal moment),
    so that one contact cannot reverse the body's spin within a step."""

    kind = "rolling"
    name = "cdt_body_arm"
    parameters = (MU_R,)
    needs_body_kinematics = True
    reference = ("EDEM Standard Rolling Friction (Altair EDEM documentation): tau_i = -mu_r F_n R_i w_i/|w_i|, "
                 "R_i = contact point to the particle's centre of mass, w_i the particle's own angular velocity")

    def make(self, column):
        c_mu = column("mu_r")

        @wp.func
        def cdt_body_arm_rolling(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            w_len = wp.length(c.w_body)
            if w_len < 1.0e-12:
                return wp.vec3(0.0), spring
            t_mag = p[c.row, c_mu] * wp.max(fn, 0.0) * c.arm_body
            t_guard = c.i_body * w_len / c.dt
            t_mag = wp.min(t_mag, t_guard)
            return -t_mag / w_len * c.w_body, spring

        return cdt_body_arm_rolling


@register
class LiggghtsCDT(SubModel):
    kind = "rolling"
    name = "cdt_liggghts"
    pair_antisymmetric = True
    parameters = (MU_R,)
    reference = ("LIGGGHTS-PUBLIC 3.8 rolling_friction cdt (src/rolling_model_cdt.h): tau = -mu_r k_n delta R* "
                 "w_rel/|w_rel| without its normal component, k_n delta the elastic Hertz force; no guard")

    def make(self, column):
        c_mu = column("mu_r")

        @wp.func
        def cdt_liggghts_rolling(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            w_len = wp.length(c.w_rel)
            if w_len <= 0.0:
                return wp.vec3(0.0), spring
            # elastic Hertz force k_n delta, k_n = 4/3 E* sqrt(R* delta) (normal_model_hertz.h)
            f_elastic = 4.0 / 3.0 * c.e_eff * wp.sqrt(c.r_eff * c.overlap) * c.overlap
            t = -(p[c.row, c_mu] * f_elastic * c.r_eff / w_len) * c.w_rel
            t = t - wp.dot(t, c.normal) * c.normal  # torsion part removed (torsionTorque off)
            return t, spring

        return cdt_liggghts_rolling


@register
class ElasticPlasticSpringDashpot(SubModel):
    kind = "rolling"
    name = "epsd"
    pair_antisymmetric = True
    parameters = (MU_R,)
    needs_history = True
    reference = ("Ai et al. (2011) model C without viscous term: k_r = 2.25 k_n mu_r^2 R*^2 "
                 "(LIGGGHTS rolling_friction epsd's spring; not LIGGGHTS epsd2)")

    def make(self, column):
        c_mu = column("mu_r")

        @wp.func
        def epsd_rolling(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            mu_r = p[c.row, c_mu]
            k_n = 4.0 / 3.0 * c.e_eff * wp.sqrt(c.r_eff * c.overlap)
            k_r = 2.25 * k_n * mu_r * mu_r * c.r_eff * c.r_eff
            m = rolling_spring_torque(c, spring, k_r, mu_r * c.r_eff * wp.max(fn, 0.0))
            return m, m

        return epsd_rolling


@register
class LiggghtsEPSD2(SubModel):
    kind = "rolling"
    name = "epsd2"
    pair_antisymmetric = True
    default_candidate = True
    parameters = (MU_R,)
    needs_history = True
    reference = ("LIGGGHTS rolling_friction epsd2 (LIGGGHTS-PUBLIC src/rolling_model_epsd2.h): "
                 "k_r = k_t R*^2, k_t = 8 G* sqrt(R* delta), |M_r| <= mu_r R* |F_n|")

    def make(self, column):
        c_mu = column("mu_r")

        @wp.func
        def epsd2_rolling(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            k_t = 8.0 * c.g_eff * wp.sqrt(c.r_eff * c.overlap)
            k_r = k_t * c.r_eff * c.r_eff
            m = rolling_spring_torque(c, spring, k_r, p[c.row, c_mu] * c.r_eff * wp.abs(fn))
            return m, m

        return epsd2_rolling
