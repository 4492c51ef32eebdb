"""Framework for composable contact laws (after LIGGGHTS' `pair gran` sub-models).

A contact law is the composition of orthogonal sub-models, one per *kind*:

==============  ===============================================================
kind            contract of the generated ``wp.func``
==============  ===============================================================
``normal``      ``(c: ContactInput, p: array2d) -> (fn: float, stiffness: float)``
                fn [N] along the normal, > 0 repulsive (damping included).
``cohesion``    ``(c, p) -> float`` extra normal force [N] (< 0 attractive).
``tangential``  ``(c, p, fn, spring: vec3) -> (ft: vec3, spring_new: vec3)``
``rolling``     ``(c, p, fn, spring: vec3) -> (torque: vec3, spring_new: vec3)``
==============  ===============================================================

A sub-model declares its parameters (:class:`ParameterSpec`), whether it needs a history
vector per contact, and its literature reference. Parameters are stored per world and per
pair type (``pp`` particle-particle, ``pw`` particle-wall) in one table ``p[row, column]``
with ``row = 2 * world + pair_type``; each declared parameter ``mu_s`` becomes the calibration
names ``mu_s_pp`` and ``mu_s_pw``. Adding a physical effect is one module that subclasses
:class:`SubModel` plus the :func:`register` decorator; calibration reads the declarations.
Such a module is found without any list kept by hand: a file in ``warpdem/contact/``, a
module named by an installed package's ``warpdem.contact_models`` entry point, or a file or
module loaded with :func:`warpdem.contact.load_module` (see ``docs/adding_an_effect.md``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, ClassVar

import warp as wp

from ..errors import ConfigError

PAIR_TYPES = ("pp", "pw")
KINDS = ("normal", "cohesion", "tangential", "rolling")


@wp.struct
class ContactInput:
    """Geometry and kinematics of one contact, seen from sphere i (SI units).

    ``radius_i`` and ``radius_j`` are the two sphere radii (LIGGGHTS ``radi``/``radj``), for
    effects that need more than ``r_eff`` (e.g. the exact intersection area of two spheres in
    :mod:`warpdem.contact.cohesion`). A wall is a flat partner of infinite radius:
    ``radius_j = 0.0`` marks a particle-wall contact (then ``r_eff = radius_i``).
    """

    normal: wp.vec3  # unit normal pointing from the partner towards sphere i
    overlap: float  # normal overlap delta_n [m], > 0 in contact
    v_rel: wp.vec3  # velocity of i's contact point minus the partner's [m/s]
    w_rel: wp.vec3  # angular velocity of i minus the partner's [rad/s]
    r_eff: float  # effective radius R* [m]: r_i r_j / (r_i + r_j), or r_i against a wall
    radius_i: float  # radius of sphere i [m]
    radius_j: float  # radius of the partner sphere j [m]; 0.0 for a wall (flat, infinite radius)
    m_eff: float  # effective mass m* [kg]
    e_eff: float  # effective Young's modulus E* [Pa]
    g_eff: float  # effective shear modulus G* [Pa]
    arm: float  # distance from i's sphere centre to the contact point [m]
    i_eff: float  # effective moment of inertia 1/(1/I_i + 1/I_j) [kg m^2]
    dt: float  # time step [s]
    row: int  # parameter-table row = 2 * world + pair_type
    # i's rigid body (a clump, or the sphere itself), set only when a sub-model of the law declares
    # ``needs_body_kinematics`` (a compile-time switch of the stages; else left 0):
    arm_body: float  # distance from the contact point to the centre of mass of i's body [m]
    w_body: wp.vec3  # angular velocity of i's body [rad/s] (not relative to the partner)
    i_body: float  # mean principal moment of inertia of i's body [kg m^2]


@dataclass(frozen=True)
class ParameterSpec:
    """A parameter declared by a sub-model or shape family (contact ones are stored per world and
    per pair type).

    bounds: admissible range (anything outside is refused). design_range: the range a calibration
    or diagnosis design explores by default when the config gives none (None: ``bounds``).
    off_value: the value at which the physical effect is absent (rolling friction 0, cohesion 0,
    aspect ratio 1); None for parameters that are never "off" (friction, restitution).
    """

    name: str
    unit: str
    default: float
    bounds: tuple[float, float]
    description: str
    design_range: tuple[float, float] | None = None
    off_value: float | None = None

    def __post_init__(self) -> None:
        lo, hi = self.bounds
        for what, rng in (("design_range", self.design_range),):
            if rng is not None and not (lo <= rng[0] < rng[1] <= hi):
                raise ConfigError(f"parameter '{self.name}': {what} {rng} must lie within its bounds [{lo}, {hi}]")
        if self.off_value is not None and not lo <= self.off_value <= hi:
            raise ConfigError(f"parameter '{self.name}': off_value {self.off_value} outside its bounds [{lo}, {hi}]")

    @property
    def exploration_range(self) -> tuple[float, float]:
        """``design_range`` if declared, else the admissible ``bounds``."""
        return tuple(self.design_range) if self.design_range is not None else tuple(self.bounds)

    def check(self, full_name: str, value: float) -> None:
        lo, hi = self.bounds
        if not (lo <= value <= hi):
            raise ConfigError(f"contact parameter '{full_name}' = {value} outside its admissible range [{lo}, {hi}] {self.unit}")


class SubModel:
    """Base class of a contact sub-model. Subclasses set the class attributes and ``make``."""

    kind: ClassVar[str]
    name: ClassVar[str]
    parameters: ClassVar[tuple[ParameterSpec, ...]] = ()
    needs_history: ClassVar[bool] = False
    reference: ClassVar[str] = ""
    #: the sub-model a diagnosis tries first for its kind's effect (e.g. rolling resistance)
    default_candidate: ClassVar[bool] = False
    #: whether the sub-model reads ``ContactInput.arm_body``, ``w_body`` and ``i_body`` (the lever
    #: from the contact point to the body's centre of mass, the body's own angular velocity and
    #: moment of inertia); the contact stages compute them only for a law that has such a sub-model
    #: (:attr:`ContactLaw.needs_body_kinematics`), so other laws compile to the same code as before
    needs_body_kinematics: ClassVar[bool] = False
    #: cohesion sub-models: whether the tangential (Coulomb) and rolling limits see this force,
    #: i.e. get ``fn`` = normal + cohesion (LIGGGHTS ``tangential_reduce on``); False: they get
    #: the normal sub-model's force alone (LIGGGHTS 3.8's default, ``tangential_reduce off``).
    #: Read by :func:`warpdem.stages.law.law_evaluator`.
    cohesion_in_friction_limit: ClassVar[bool] = True
    #: normal sub-models: where a wall contact's point lies, from which the wall stage takes the
    #: contact point's velocity and the lever arm of the contact force. False: on the wall
    #: surface, r - delta from the sphere centre (a rigid wall); True: at half the overlap,
    #: r - delta / 2 (LIGGGHTS src/surface_model_default.h; two bodies of equal stiffness).
    #: Sphere-sphere contacts lie at half the overlap either way. Read by
    #: :func:`warpdem.stages.wall_contacts.wall_stage_kernels`.
    wall_contact_at_half_overlap: ClassVar[bool] = False
    #: sphere-sphere contacts: whether the evaluation from the partner's side (normal, relative
    #: velocities and history negated, radii swapped) gives exactly the negated force and torque
    #: (Newton's third law, with rolling torques -M on the partner). A law whose sub-models all say
    #: so may evaluate each pair once on the CPU (``DEMSolver(pair_evaluation="half")``); False (the
    #: safe default for a plug-in) keeps both sides. False for sub-models that read one side's
    #: lever (``c.arm``, the body fields).
    pair_antisymmetric: ClassVar[bool] = False

    def make(self, column: Callable[[str], int]) -> "wp.Function":
        """Return the ``wp.func`` implementing this sub-model.

        Args:
            column: maps a declared parameter name to its column in the parameter table;
                use the returned int as a compile-time constant inside the function.
        """
        raise NotImplementedError


REGISTRY: dict[str, dict[str, type[SubModel]]] = {k: {} for k in KINDS}


def _qualified_name(cls: type) -> str:
    return f"{getattr(cls, '__module__', '?')}.{getattr(cls, '__qualname__', repr(cls))}"


def _check_declaration(cls: type[SubModel]) -> None:
    """Clear errors for a malformed sub-model class (caught at registration, not in a kernel)."""
    what = f"contact sub-model class {_qualified_name(cls)}"
    if not (isinstance(cls, type) and issubclass(cls, SubModel)):
        raise ConfigError(f"{what} must subclass warpdem.contact.SubModel")
    kind = getattr(cls, "kind", None)
    if kind not in REGISTRY:
        raise ConfigError(f"{what}: unknown sub-model kind {kind!r}, expected one of {KINDS}")
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name.isidentifier():
        raise ConfigError(f"{what}: 'name' must be an identifier-like string, got {name!r}")
    if cls.make is SubModel.make:
        raise ConfigError(f"{what}: does not implement make(column)")
    for spec in cls.parameters:
        if not isinstance(spec, ParameterSpec):
            raise ConfigError(f"{what}: parameters must be ParameterSpec instances, got {spec!r}")
        lo, hi = spec.bounds
        if not lo <= spec.default <= hi:
            raise ConfigError(f"{what}: default of '{spec.name}' = {spec.default} outside its bounds [{lo}, {hi}]")


def register(cls: type[SubModel]) -> type[SubModel]:
    """Class decorator registering a sub-model under ``(cls.kind, cls.name)``.

    Idempotent for re-imports: a class with the same qualified name (module + class name)
    replaces the registered one silently (a module imported again, a notebook cell run
    twice). A *different* class under a taken ``(kind, name)`` is a :class:`ConfigError`.
    """
    _check_declaration(cls)
    current = REGISTRY[cls.kind].get(cls.name)
    if current is not None and current is not cls and _qualified_name(current) != _qualified_name(cls):
        raise ConfigError(
            f"a {cls.kind} sub-model named '{cls.name}' is already registered by {_qualified_name(current)}; "
            f"{_qualified_name(cls)} must use another name"
        )
    REGISTRY[cls.kind][cls.name] = cls
    return cls


def available(kind: str) -> list[str]:
    """Names of the registered sub-models of one kind."""
    if kind not in REGISTRY:
        raise ConfigError(f"unknown sub-model kind '{kind}', expected one of {KINDS}")
    return sorted(REGISTRY[kind])
