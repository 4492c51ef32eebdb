"""Hertz-Mindlin (no-slip) normal and tangential sub-models with restitution damping.

Seed paper (Zhang et al.), Section 2.2, eqs. (1)-(12); EDEM's "Hertz-Mindlin (no slip)" and
LIGGGHTS' ``model hertz tangential history``:

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

Two tangential sub-models share the Mindlin spring and differ in how sliding is handled:

``history`` (default; LIGGGHTS ``tangential history``, src/tangential_model_history.h): the
    spring is projected into the current tangent plane, then only its *elastic* force is
    compared with the Coulomb limit:
        S_t |delta_t| > mu_s |F_n|  ->  F_t = mu_s |F_n| (-delta_t / |delta_t|),
                                         delta_t <- -F_t / S_t   (no damping while sliding)
        otherwise                   ->  F_t = -S_t delta_t + F_t^d
    F_n includes the normal damping, as LIGGGHTS' ``sidata.Fn`` does; the cohesion force only
    with ``sjkr_reduced``/``sjkr2_reduced`` (LIGGGHTS ``tangential_reduce on``), not with
    ``sjkr``/``sjkr2`` (LIGGGHTS' default: :mod:`warpdem.contact.cohesion`).
``mindlin`` (before 2026-11-27 the default): the spring is turned into the tangent plane with
    its magnitude kept; the Coulomb cap applies to the whole tangential force (spring plus
    damping), and while sliding the spring is reset so that spring plus damping carry exactly
    mu F_n (Luding 2008, Granular Matter 10:235, eq. 21).

Why ``history`` is the default: with Hertz-Mindlin the tangential dashpot grows as
sqrt(S_t m*) while the spring stiffness S_t grows as delta^(1/2), so at the first steps of a
contact the reset spring of ``mindlin``, (F_t^d - F_t) / S_t, scales as delta^(-1/4) and depends
on how small the first overlap happens to be, i.e. on the time step. An oblique impact
(45 deg, 16 mm gravel on Plexiglas) with ``mindlin`` leaves with a tangential speed and spin
that are 4-6 % off their converged values at 0.2 of the Rayleigh time and converge only near
0.002 of it; with ``history`` they are within 1.5 % at 0.2 and 0.3 % at 0.1
(``benchmarks/impact_resolution.py``, ``tests/test_tangential_models.py``).
"""
from __future__ import annotations

import math

import warp as wp

from .base import ContactInput, ParameterSpec, SubModel, register

SQRT_5_6 = math.sqrt(5.0 / 6.0)
#: the sliding friction both tangential sub-models declare (a parameter two sub-models share must be declared identically)
MU_S = ParameterSpec("mu_s", "-", 0.5, (0.0, 10.0), "sliding (static) friction coefficient")


@wp.func
def restitution_beta(e: float):
    """beta = ln e / sqrt(ln^2 e + pi^2) (seed paper eq. 11); e in (0, 1]."""
    le = wp.log(e)
    return le / wp.sqrt(le * le + wp.pi * wp.pi)


@register
class HertzNormal(SubModel):
    kind = "normal"
    name = "hertz"
    pair_antisymmetric = True
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
class HertzNormalLiggghtsWall(HertzNormal):
    """``hertz`` with LIGGGHTS' wall contact point: half the overlap from the wall, r - delta / 2
    from the sphere centre (LIGGGHTS src/surface_model_default.h: ``cr = radi - 0.5*deltan`` is
    both the lever of the tangential force and the radius of the contact point's velocity).
    ``hertz`` puts it on the wall surface (r - delta), exact for a rigid wall; LIGGGHTS' point
    is exact for a wall as stiff as the sphere. The forces are the same; spin and tangential
    rebound at a wall differ by O(delta / r) (``docs/liggghts_reference.md``)."""

    name = "hertz_liggghts"
    wall_contact_at_half_overlap = True
    reference = ("Hertz (1882); Tsuji et al. (1992) damping; seed paper eqs. (1), (9), (11), (12); wall contact point "
                 "at r - delta/2 as LIGGGHTS-PUBLIC 3.8 src/surface_model_default.h")


@register
class MindlinTangential(SubModel):
    kind = "tangential"
    name = "mindlin"
    pair_antisymmetric = True
    parameters = (MU_S,)
    needs_history = True
    # This text enters every record's and DEM-cache key's fingerprint, so it stays as written when
    # this was the default; the sliding rule is Luding's reset, not LIGGGHTS' (that is ``history``).
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


@register
class HistoryTangential(SubModel):
    kind = "tangential"
    name = "history"
    pair_antisymmetric = True
    parameters = (MU_S,)
    needs_history = True
    reference = ("Mindlin & Deresiewicz (1953); seed paper eqs. (4)-(8); LIGGGHTS tangential history "
                 "(src/tangential_model_history.h): elastic force capped at mu |F_n|, no damping while sliding")

    def make(self, column):
        c_mu = column("mu_s")
        c_e = column("restitution")

        @wp.func
        def history_tangential(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            n = c.normal
            v_t = c.v_rel - wp.dot(c.v_rel, n) * n
            # LIGGGHTS: add this step's slip, then project into the current tangent plane
            s = spring + v_t * c.dt
            s = s - wp.dot(s, n) * n
            s_t = 8.0 * c.g_eff * wp.sqrt(c.r_eff * c.overlap)
            f_t = -s_t * s
            f_shear = s_t * wp.length(s)
            f_friction = p[c.row, c_mu] * wp.abs(fn)
            if f_shear > f_friction:
                # gross sliding: the elastic force is scaled to mu |F_n|, the spring follows it
                if f_shear > 0.0:
                    f_t = f_t * (f_friction / f_shear)
                    s = f_t / (-s_t)
                else:
                    f_t = wp.vec3(0.0)
            else:
                beta = restitution_beta(p[c.row, c_e])
                f_t = f_t + 2.0 * SQRT_5_6 * beta * wp.sqrt(s_t * c.m_eff) * v_t
            return f_t, s

        return history_tangential
