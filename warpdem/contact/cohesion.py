"""Cohesion sub-models: the simplified JKR models of LIGGGHTS (``cohesion sjkr``/``sjkr2``).

While two surfaces overlap (the kernel evaluates cohesion only in contact, delta > 0), an
attractive normal force proportional to the contact area is added to the normal force:

    F_coh = -k A                                                     (k: cohesion energy density [J/m^3])

``sjkr`` (LIGGGHTS-PUBLIC ``src/cohesion_model_sjkr.h``, ``CohesionModel<COHESION_SJKR>::collision``),
A = area of the circle in which the two sphere surfaces intersect, d = centre distance:

    particle-particle  A = -pi/4 (d - r_i - r_j)(d + r_i - r_j)(d - r_i + r_j)(d + r_i + r_j) / d^2
    particle-wall      A = pi (r_i^2 - d^2),  d = r_i - delta  (= pi (2 r_i delta - delta^2))

With d = r_i + r_j - delta the four factors are -delta, 2 r_i - delta, 2 r_j - delta and
2 (r_i + r_j) - delta, so the code evaluates the identical

    A_pp = pi/4 delta (2 r_i - delta)(2 r_j - delta)(2 r_i + 2 r_j - delta) / d^2

which avoids the cancellation of d - r_i - r_j in single precision (at delta = 1e-4 R the
literal form loses ~1e-3 of A in float32). LIGGGHTS multiplies the wall area and the wall
force by ``area_ratio``, which LIGGGHTS-PUBLIC 3.8 sets to 1 for every wall contact
(src/fix_wall_gran_base.h); its contact history keeps one contact where a sphere touches an
edge or vertex of a flat mesh, and warpdem merges the triangles of one flat contact (measured
alike on a face, an edge and a vertex: ``docs/liggghts_reference.md``).

``sjkr2`` (LIGGGHTS-PUBLIC ``src/cohesion_model_sjkr2.h``; doc ``gran_cohesion_sjkr2``), a
linearised area:

    particle-particle  A = 2 pi (2 R*) delta,  R* = r_i r_j / (r_i + r_j)
    particle-wall      A = 2 pi r_i delta

Note that for particles this is twice the first-order expansion of the exact ``sjkr`` area
(two equal spheres: A_sjkr ~ pi R delta, A_sjkr2 = 2 pi R delta), while at a wall both
agree to first order (2 pi r_i delta); a k calibrated with one model does not carry over to
the other.

Which normal force the friction limits see. LIGGGHTS 3.8 adds the cohesion force to the ``F_n``
that the tangential (Coulomb, mu |F_n|) and rolling (mu_r R* |F_n|) sub-models get only with the
keyword ``tangential_reduce on`` (src/cohesion_model_sjkr.h: ``if(tangentialReduce_) sidata.Fn +=
Fn_coh;``); its default is ``off``: the friction and rolling limits see the Hertz force plus damping
alone, which in a resting cohesive contact carries the load plus k A. ``sjkr``/``sjkr2`` follow that
default (what a LIGGGHTS user means by ``cohesion sjkr``); ``sjkr_reduced``/``sjkr2_reduced`` are
the same forces with ``tangential_reduce on`` (warpdem's ``sjkr`` before 2026-11-27). At k = 1e5
J/m^3 the two differ by a factor 7 in the friction limit of an 18 mm gravel grain resting on a
wall, and the baffle box's static angle by 5-7 deg (checked against the LIGGGHTS binary contact
by contact and in whole experiments: ``docs/liggghts_reference.md``). LIGGGHTS 3.8 sets the wall's
``area_ratio`` to 1 for every wall contact (src/fix_wall_gran_base.h), as here.

Not built: a JKR model with a pull-off range (e.g. LAMMPS ``pair granular jkr``), in which
a contact survives separation up to a negative overlap and its force depends on the loading
history. It needs contact detection beyond touching (the contact kernel only creates a
contact while delta > 0, and the Verlet skin would have to cover the pull-off distance), a
per-contact "was touching" flag, and a normal model replacing Hertz rather than an additive
term: a change of the contact kernel, not a sub-model. For the free-flowing to mildly
cohesive bulk materials calibrated here (static angle of repose, draw-down), SJKR's energy
density is the usual single cohesion knob of LIGGGHTS calibrations, so JKR was not worth
that change.
"""
from __future__ import annotations

import warp as wp

from .base import ContactInput, ParameterSpec, SubModel, register

COHESION_ENERGY_DENSITY = ParameterSpec(
    "cohesion_energy_density", "J/m^3", 0.0, (0.0, 1.0e7),
    "cohesion energy density k of SJKR: attractive normal force k A over the contact area A "
    "(LIGGGHTS cohesionEnergyDensity)",
    # about 1e5 J/m^3 holds a 20 mm gravel sphere (E = 1e7 Pa) under a ceiling against its weight;
    # the default design explores up to a few times that (bond numbers up to ~5)
    design_range=(0.0, 5.0e5), off_value=0.0,
)


@wp.func
def sjkr_contact_area(c: ContactInput):
    """Area [m^2] of the intersection circle of the overlapping surfaces (LIGGGHTS sjkr)."""
    delta = c.overlap
    ri = c.radius_i
    rj = c.radius_j
    if rj <= 0.0:
        # wall: pi (r_i^2 - (r_i - delta)^2)
        return wp.pi * delta * (2.0 * ri - delta)
    d = ri + rj - delta
    return 0.25 * wp.pi * delta * (2.0 * ri - delta) * (2.0 * rj - delta) * (2.0 * (ri + rj) - delta) / (d * d)


@wp.func
def sjkr2_contact_area(c: ContactInput):
    """Linearised contact area [m^2] of LIGGGHTS sjkr2: 2 pi (2 R*) delta, or 2 pi r_i delta at a wall."""
    if c.radius_j <= 0.0:
        return 2.0 * wp.pi * c.radius_i * c.overlap
    return 2.0 * wp.pi * (2.0 * c.r_eff) * c.overlap


@register
class SimplifiedJKR(SubModel):
    """F_coh = -k A with the exact intersection area (LIGGGHTS 3.8 ``cohesion sjkr``, its default
    ``tangential_reduce off``: the friction and rolling limits see F_n without it)."""

    kind = "cohesion"
    name = "sjkr"
    pair_antisymmetric = True
    default_candidate = True
    cohesion_in_friction_limit = False
    parameters = (COHESION_ENERGY_DENSITY,)
    reference = ("LIGGGHTS-PUBLIC 3.8 src/cohesion_model_sjkr.h with its default tangential_reduce off (simplified "
                 "JKR, F = -k A, A = exact intersection area; the tangential and rolling limits see F_n without it)")

    def make(self, column):
        c_k = column("cohesion_energy_density")

        @wp.func
        def sjkr_cohesion(c: ContactInput, p: wp.array2d(dtype=float)):
            return -p[c.row, c_k] * sjkr_contact_area(c)

        return sjkr_cohesion


@register
class SimplifiedJKR2(SubModel):
    """F_coh = -k A with A = 2 pi (2 R*) delta (LIGGGHTS 3.8 ``cohesion sjkr2``, default
    ``tangential_reduce off``)."""

    kind = "cohesion"
    name = "sjkr2"
    pair_antisymmetric = True
    cohesion_in_friction_limit = False
    parameters = (COHESION_ENERGY_DENSITY,)
    reference = ("LIGGGHTS-PUBLIC 3.8 src/cohesion_model_sjkr2.h with its default tangential_reduce off (F = -k A, "
                 "A = 2 pi (2 R*) delta; wall 2 pi r_i delta; the tangential and rolling limits see F_n without it)")

    def make(self, column):
        c_k = column("cohesion_energy_density")

        @wp.func
        def sjkr2_cohesion(c: ContactInput, p: wp.array2d(dtype=float)):
            return -p[c.row, c_k] * sjkr2_contact_area(c)

        return sjkr2_cohesion


@register
class SimplifiedJKRReduced(SimplifiedJKR):
    """``sjkr`` with LIGGGHTS' ``tangential_reduce on``: the friction and rolling limits see F_n
    with the (attractive) cohesion force, i.e. about the load alone in a resting contact."""

    name = "sjkr_reduced"
    default_candidate = False
    cohesion_in_friction_limit = True
    reference = ("LIGGGHTS-PUBLIC src/cohesion_model_sjkr.h with tangential_reduce on (F = -k A, A = exact "
                 "intersection area; the tangential and rolling limits see F_n including it)")


@register
class SimplifiedJKR2Reduced(SimplifiedJKR2):
    """``sjkr2`` with LIGGGHTS' ``tangential_reduce on``."""

    name = "sjkr2_reduced"
    cohesion_in_friction_limit = True
    reference = ("LIGGGHTS-PUBLIC src/cohesion_model_sjkr2.h with tangential_reduce on (F = -k A, A = 2 pi (2 R*) "
                 "delta; the tangential and rolling limits see F_n including it)")
