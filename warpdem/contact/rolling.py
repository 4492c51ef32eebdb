"""Rolling-resistance sub-models.

``cdt``  constant directional torque (Ai et al. 2011 model A; EDEM's Hertz-Mindlin rolling
         friction): tau_i = -mu_r F_n R_i w_rel/|w_rel|, R_i = distance from the sphere centre
         to the contact point (EDEM convention). Guard against reversal jitter: the torque is
         capped so that it cannot reverse w_rel within one step, |tau| <= I* |w_rel| / dt.
``epsd`` elastic-plastic spring-dashpot without viscous term (Ai et al. 2011 model C;
         LIGGGHTS ``rolling_friction epsd2``): incremental spring torque
         M_r <- M_r - k_r dtheta_r with k_r = 2.25 k_n mu_r^2 R*^2, k_n = F_n/delta =
         4/3 E* sqrt(R* delta), capped at |M_r| <= mu_r R* F_n. Holds a static pile.

Reference: Ai, J., Chen, J.-F., Rotter, J. M., Ooi, J. Y. (2011) Assessment of rolling
resistance models in discrete element simulations. Powder Technology 206, 269-282.
"""
from __future__ import annotations

import warp as wp

from .base import ContactInput, ParameterSpec, SubModel, register

MU_R = ParameterSpec("mu_r", "-", 0.1, (0.0, 10.0), "rolling friction coefficient")


@register
class ConstantDirectionalTorque(SubModel):
    kind = "rolling"
    name = "cdt"
    parameters = (MU_R,)
    reference = "Ai et al. (2011) model A; EDEM Hertz-Mindlin rolling friction"

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
class ElasticPlasticSpringDashpot(SubModel):
    kind = "rolling"
    name = "epsd"
    parameters = (MU_R,)
    needs_history = True
    reference = "Ai et al. (2011) model C; LIGGGHTS rolling_friction epsd2"

    def make(self, column):
        c_mu = column("mu_r")

        @wp.func
        def epsd_rolling(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            n = c.normal
            mu_r = p[c.row, c_mu]
            # keep the stored torque in the current tangent plane (magnitude kept)
            m_len = wp.length(spring)
            m = spring - wp.dot(spring, n) * n
            m_proj = wp.length(m)
            if m_proj > 1.0e-30:
                m = m * (m_len / m_proj)
            w_roll = c.w_rel - wp.dot(c.w_rel, n) * n
            k_n = 4.0 / 3.0 * c.e_eff * wp.sqrt(c.r_eff * c.overlap)
            k_r = 2.25 * k_n * mu_r * mu_r * c.r_eff * c.r_eff
            m = m - k_r * w_roll * c.dt
            m_max = mu_r * c.r_eff * wp.max(fn, 0.0)
            ml = wp.length(m)
            if ml > m_max:
                if ml > 0.0:
                    m = m * (m_max / ml)
            return m, m

        return epsd_rolling
