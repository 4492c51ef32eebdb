"""Null sub-models: the empty slots of a contact law (cost nothing once compiled)."""
from __future__ import annotations

import warp as wp

from .base import ContactInput, SubModel, register


@register
class NoCohesion(SubModel):
    kind = "cohesion"
    name = "none"
    pair_antisymmetric = True
    reference = "no cohesion"

    def make(self, column):
        @wp.func
        def no_cohesion(c: ContactInput, p: wp.array2d(dtype=float)):
            return float(0.0)

        return no_cohesion


@register
class NoRolling(SubModel):
    kind = "rolling"
    name = "none"
    pair_antisymmetric = True
    reference = "no rolling resistance"

    def make(self, column):
        @wp.func
        def no_rolling(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            return wp.vec3(0.0), spring

        return no_rolling


@register
class FrictionlessTangential(SubModel):
    kind = "tangential"
    name = "none"
    pair_antisymmetric = True
    reference = "frictionless contact"

    def make(self, column):
        @wp.func
        def no_tangential(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            return wp.vec3(0.0), spring

        return no_tangential
