"""The contact law as one ``wp.func``: the sub-models of a :class:`ContactLaw` composed."""
from __future__ import annotations

import functools

import warp as wp

from ..contact.base import ContactInput
from ..contact.law import ContactLaw

wp.set_module_options({"enable_backward": False, "fast_math": True})


@functools.lru_cache(maxsize=None)
def law_evaluator(law: ContactLaw) -> "wp.Function":
    """``evaluate(c, p, spring, roll) -> (fn, ft, torque, spring_new, roll_new)`` of one law.

    The registered sub-models' ``wp.func``s (warpdem.contact.base, one per kind) are composed:
    normal force fn [N] plus cohesion [N], then the tangential force ft [N] (capped by fn) and
    the rolling torque [N m] with their updated history vectors. The tangential and rolling
    sub-models get fn with the cohesion, or without it for a cohesion sub-model that declares
    ``cohesion_in_friction_limit = False`` (LIGGGHTS 3.8's default, ``tangential_reduce off``:
    src/cohesion_model_sjkr.h adds its force to ``sidata.Fn`` only when the option is on). A
    ``none`` sub-model compiles to nothing; a sub-model found by the package scan plugs in with
    no edit here."""
    normal_f = law.submodels["normal"].make(law.column)
    cohesion_f = law.submodels["cohesion"].make(law.column)
    tangential_f = law.submodels["tangential"].make(law.column)
    rolling_f = law.submodels["rolling"].make(law.column)
    limit_sees_cohesion = bool(getattr(law.submodels["cohesion"], "cohesion_in_friction_limit", True))

    @wp.func
    def evaluate(c: ContactInput, p: wp.array2d(dtype=float), spring: wp.vec3, roll: wp.vec3):
        fn_normal, s_n = normal_f(c, p)
        fn = fn_normal + cohesion_f(c, p)
        fn_limit = fn_normal
        if wp.static(limit_sees_cohesion):
            fn_limit = fn
        ft, spring_new = tangential_f(c, p, fn_limit, spring)
        tr, roll_new = rolling_f(c, p, fn_limit, roll)
        return fn, ft, tr, spring_new, roll_new

    return evaluate
