"""Hertz-Mindlin (no-slip) normal and tangential sub-models with restitution damping.

Seed paper (Zhang et al.), Section 2.2, eqs. (1)-(12); the same law as EDEM's
"Hertz-Mindlin (no slip)" and LIGGGHTS' ``model hertz tangential history``:

    F_n   = 4/3 E* sqrt(R*) delta^(3/2)                              (eq. 1)
    S_n   = 2 E* sqrt(R* delta)                                      (eq. 12)
    beta  = ln e / sqrt(ln^2 e + pi^2)                               (eq. 11)
    F_n^d = -2 sqrt(5/6) beta sqrt(S_n m*) v_n                       (eq. 9)
    S_t   = 8 G* sqrt(R* delta)                                      (eq. 6)
    F_t   = -S_t delta_t,  F_t^d = -2 sqrt(5/6) beta sqrt(S_t m*) v_t (eqs. 4, 5)
    |F_t| <= mu_s |F_n|                                              (eq. 8, Coulomb)

G* is the Mindlin & Deresiewicz (1953) effective shear modulus
1/G* = (2 - nu_A)/G_A + (2 - nu_B)/G_B (the paper's eqs. (7)/(10) are a misprint).
Sign convention: v_n = v_rel . n > 0 when separating, so with beta <= 0 the damping term
``2 sqrt(5/6) beta sqrt(S_n m*) v_n`` opposes the normal motion.

The tangential spring delta_t is the contact's history: it is rotated into the current
tangent plane each step (magnitude kept). The Coulomb cap applies to the whole tangential
force (spring plus damping); while sliding the spring is reset so that spring plus damping
carry exactly mu F_n (Luding 2008, Granular Matter 10:235, eq. 21).
"""
from __future__ import annotations

import math

import warp as wp

from .base import ContactInput, ParameterSpec, SubModel, register

SQRT_5_6 = math.sqrt(5.0 / 6.0)


@wp.func
def restitution_beta(e: float):
    """beta = ln e / sqrt(ln^2 e + pi^2) (seed paper eq. 11); e in (0, 1]."""
    le = wp.log(e)
    return le / wp.sqrt(le * le + wp.pi * wp.pi)


@register
class HertzNormal(SubModel):
    kind = "normal"
    name = "hertz"
    parameters = (
        ParameterSpec("restitution", "-", 0.6, (0.01, 1.0), "coefficient of restitution e"),
    )
    reference = "Hertz (1882); Tsuji et al. (1992) damping; seed paper eqs. (1), (9), (11), (12)"

    def make(self, column):
        c_e = column("restitution")

        @wp.func
        def hertz_normal(c: ContactInput, p: wp.array2d(dtype=float)):
            sqrt_rd = wp.sqrt(c.r_eff * c.overlap)
            f_elastic = 4.0 / 3.0 * c.e_eff * sqrt_rd * c.overlap
            s_n = 2.0 * c.e_eff * sqrt_rd
            beta = restitution_beta(p[c.row, c_e])
            v_n = wp.dot(c.v_rel, c.normal)
            f_damp = 2.0 * SQRT_5_6 * beta * wp.sqrt(s_n * c.m_eff) * v_n
            return f_elastic + f_damp, s_n

        return hertz_normal


@register
class MindlinTangential(SubModel):
    kind = "tangential"
    name = "mindlin"
    parameters = (
        ParameterSpec("mu_s", "-", 0.5, (0.0, 10.0), "sliding (static) friction coefficient"),
    )
    needs_history = True
    reference = "Mindlin & Deresiewicz (1953); seed paper eqs. (4)-(8); LIGGGHTS tangential_history"

    def make(self, column):
        c_mu = column("mu_s")
        c_e = column("restitution")

        @wp.func
        def mindlin_tangential(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            n = c.normal
            v_t = c.v_rel - wp.dot(c.v_rel, n) * n
            # rotate the stored spring into the current tangent plane, keeping its length
            s_len = wp.length(spring)
            s = spring - wp.dot(spring, n) * n
            s_proj = wp.length(s)
            if s_proj > 1.0e-30:
                s = s * (s_len / s_proj)
            s = s + v_t * c.dt
            s_t = 8.0 * c.g_eff * wp.sqrt(c.r_eff * c.overlap)
            beta = restitution_beta(p[c.row, c_e])
            f_damp = 2.0 * SQRT_5_6 * beta * wp.sqrt(s_t * c.m_eff) * v_t
            f_t = -s_t * s + f_damp
            f_max = p[c.row, c_mu] * wp.max(fn, 0.0)
            f_len = wp.length(f_t)
            if f_len > f_max:
                # gross sliding: |F_t| = mu F_n (eq. 8); the spring is reset so that spring
                # plus damping carry exactly the Coulomb force (Luding 2008, eq. 21)
                f_t = f_t * (f_max / f_len)
                s = (f_t - f_damp) / (-wp.max(s_t, 1.0e-30))
            return f_t, s

        return mindlin_tangential
