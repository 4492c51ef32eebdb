"""Body forces: per-body forces that are not contacts (fluid drag, buoyancy, fields...).

They plug into the step like contact sub-models do: a model is a :class:`BodyForceModel`
subclass that declares its parameters (:class:`~warpdem.contact.ParameterSpec`: name, unit,
default, admissible range, description) and its reference, registered by name with
:func:`register_body_force`. ``ModelBuilder.add_body_force(instance)`` puts an instance into the
model; every step :class:`~warpdem.solver.DEMSolver` evaluates the contacts, then launches each
body-force model, which adds its force to one per-body array, then integrates with it. The
solver knows nothing about what a model computes.

Two ways to write a model:

* **Per-body function** (most models): implement :meth:`BodyForceModel.make` returning a
  ``wp.func (b: BodyForceInput, p: wp.array(dtype=float)) -> wp.vec3`` (force [N]); ``p`` holds
  the declared parameters in declaration order (``self.column(name)`` gives the index). The base
  class compiles it into a kernel over the active bodies.
* **Own kernels** (models that need grids, history or several passes): override
  :meth:`BodyForceModel.bind` to allocate device buffers once and :meth:`BodyForceModel.launch`
  to launch kernels that add to ``ctx.force``. ``launch`` must only launch kernels or device
  copies (no host read-back, no allocation), so the step stays capturable in a CUDA graph.

Reusable drag laws (``wp.func``) live here too: :func:`schiller_naumann_drag`,
:func:`di_felice_drag`.
"""
from __future__ import annotations

import functools
import math
from typing import Callable, ClassVar

import numpy as np
import warp as wp

from .contact.base import ParameterSpec
from .errors import ConfigError

__all__ = ["BodyForceInput", "BodyForceModel", "BodyForceContext", "register_body_force", "available_body_forces",
           "body_force_model", "schiller_naumann_drag", "di_felice_drag", "UniformFluid", "BODY_FORCE_REGISTRY"]


@wp.struct
class BodyForceInput:
    """What a per-body force function sees (SI units, stationary frame)."""

    x: wp.vec3  # centre of mass [m]
    v: wp.vec3  # velocity [m/s]
    w: wp.vec3  # angular velocity [rad/s]
    mass: float  # [kg]
    volume: float  # solid volume [m^3] (mass / material density)
    radius: float  # volume-equivalent radius [m]
    gravity: wp.vec3  # [m/s^2]
    world: int
    body: int
    dt: float  # time step [s]


BODY_FORCE_REGISTRY: dict[str, type["BodyForceModel"]] = {}


def register_body_force(cls: type["BodyForceModel"]) -> type["BodyForceModel"]:
    """Class decorator registering a body-force model under ``cls.name``."""
    if not getattr(cls, "name", ""):
        raise ValueError(f"body-force model {cls.__name__} needs a 'name'")
    if cls.name in BODY_FORCE_REGISTRY:
        raise ValueError(f"a body-force model named '{cls.name}' is already registered")
    BODY_FORCE_REGISTRY[cls.name] = cls
    return cls


def available_body_forces() -> list[str]:
    return sorted(BODY_FORCE_REGISTRY)


def body_force_model(name: str, **parameters) -> "BodyForceModel":
    """Instantiate a registered body-force model by name (clear error for unknown names)."""
    if name not in BODY_FORCE_REGISTRY:
        raise ConfigError(f"unknown body-force model '{name}'; registered: {available_body_forces()}")
    return BODY_FORCE_REGISTRY[name](**parameters)


class BodyForceContext:
    """Per-solver data shared by the body-force models: per-body solid volume [m^3] and
    volume-equivalent radius [m] (device arrays), gravity, and ``force``, the per-body array
    [N] the models add to (zeroed, or set to the solver's external force, each step)."""

    def __init__(self, solver) -> None:
        m = solver.model
        self.solver = solver
        self.model = m
        self.device = m.device
        h = m.host
        dens = np.array([mat.density for mat in m.materials], dtype=np.float64)
        first_mat = h["sphere_material"][h["body_first"]]
        vol = h["body_mass"].astype(np.float64) / dens[first_mat]
        self.body_volume_host = vol
        self.body_radius_host = np.cbrt(3.0 * vol / (4.0 * math.pi))
        self.body_volume = wp.array(vol.astype(np.float32), dtype=float, device=m.device)
        self.body_radius = wp.array(self.body_radius_host.astype(np.float32), dtype=float, device=m.device)
        self.gravity = wp.vec3(*m.gravity)
        self.force = wp.zeros(m.num_bodies, dtype=wp.vec3, device=m.device)


class BodyForceModel:
    """Base class of a body-force model. Subclasses set ``name``, ``parameters``, ``reference``
    and implement :meth:`make` (or :meth:`bind` + :meth:`launch`).

    Instances take the declared parameters as keyword arguments (defaults where omitted);
    values outside a parameter's admissible range, or unknown names, raise ConfigError.
    """

    name: ClassVar[str] = ""
    parameters: ClassVar[tuple[ParameterSpec, ...]] = ()
    reference: ClassVar[str] = ""

    def __init__(self, **values: float) -> None:
        names = [p.name for p in self.parameters]
        unknown = sorted(set(values) - set(names))
        if unknown:
            raise ConfigError(f"body-force model '{self.name}': unknown parameter(s) {unknown}; valid: {names}")
        self.values: dict[str, float] = {}
        for spec in self.parameters:
            v = values.get(spec.name, spec.default)
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise ConfigError(f"body-force model '{self.name}': parameter '{spec.name}' must be a number "
                                  f"[{spec.unit}], got {v!r}") from None
            if not math.isfinite(v):
                raise ConfigError(f"body-force model '{self.name}': parameter '{spec.name}' must be finite, got {v}")
            spec.check(f"{self.name}.{spec.name}", v)
            self.values[spec.name] = v
        self._params: wp.array | None = None

    def column(self, name: str) -> int:
        """Index of a declared parameter in the parameter array ``p``."""
        names = [p.name for p in self.parameters]
        if name not in names:
            raise ConfigError(f"body-force model '{self.name}' has no parameter '{name}'; it has {names}")
        return names.index(name)

    def describe(self) -> dict:
        return {"model": self.name, **self.values, "reference": self.reference}

    # ---------------------------------------------------------------- per-body function path
    def make(self) -> "wp.Function":
        """Return ``wp.func (b: BodyForceInput, p: wp.array(dtype=float)) -> wp.vec3`` [N]."""
        raise NotImplementedError(f"body-force model '{self.name}' implements neither make() nor launch()")

    def bind(self, ctx: BodyForceContext) -> None:
        """Allocate device buffers once per solver (default: the parameter array)."""
        vals = np.array([self.values[p.name] for p in self.parameters] or [0.0], dtype=np.float32)
        self._params = wp.array(vals, dtype=float, device=ctx.device)

    def launch(self, ctx: BodyForceContext, state_in, state_out, dt: float) -> None:
        """Add this model's force to ``ctx.force`` for the step from ``state_in`` (kernels only)."""
        kernel = _per_body_kernel(self.make_cached())
        m = ctx.model
        wp.launch(kernel, dim=m.num_bodies, inputs=[
            state_in.body_q, state_in.body_v, state_in.body_w, state_in.body_active, m.body_mass, ctx.body_volume,
            ctx.body_radius, m.body_world, ctx.gravity, float(dt), self._params, ctx.force], device=m.device)

    def make_cached(self):
        f = getattr(self, "_func", None)
        if f is None:
            f = self.make()
            self._func = f
        return f


@functools.lru_cache(maxsize=None)
def _per_body_kernel(func: Callable) -> "wp.Kernel":
    """Kernel adding ``func(BodyForceInput, params)`` to the force of every active body."""

    @wp.kernel
    def per_body(
        body_q: wp.array(dtype=wp.vec3),
        body_v: wp.array(dtype=wp.vec3),
        body_w: wp.array(dtype=wp.vec3),
        body_active: wp.array(dtype=int),
        body_mass: wp.array(dtype=float),
        body_volume: wp.array(dtype=float),
        body_radius: wp.array(dtype=float),
        body_world: wp.array(dtype=int),
        gravity: wp.vec3,
        dt: float,
        params: wp.array(dtype=float),
        force: wp.array(dtype=wp.vec3),
    ):
        b = wp.tid()
        if body_active[b] == 0:
            return
        inp = BodyForceInput()
        inp.x = body_q[b]
        inp.v = body_v[b]
        inp.w = body_w[b]
        inp.mass = body_mass[b]
        inp.volume = body_volume[b]
        inp.radius = body_radius[b]
        inp.gravity = gravity
        inp.world = body_world[b]
        inp.body = b
        inp.dt = dt
        force[b] = force[b] + func(inp, params)

    return per_body


# ----------------------------------------------------------------------------- drag laws
@wp.func
def schiller_naumann_drag(u_rel: wp.vec3, d: float, rho_f: float, mu_f: float):
    """Drag on an isolated sphere [N] in the relative velocity u_rel = u_fluid - v [m/s]:
    F = 3 pi mu d f(Re) u_rel, f = 1 + 0.15 Re^0.687 for Re < 1000, else C_d = 0.44, i.e.
    f = 0.44 Re / 24 (Schiller & Naumann 1933; Clift, Grace & Weber 1978, Table 5.2);
    Re = rho_f d |u_rel| / mu_f. Equals (1/8) C_d rho_f pi d^2 |u_rel| u_rel with
    C_d = 24 / Re (1 + 0.15 Re^0.687), without the division by zero at Re = 0."""
    re = rho_f * d * wp.length(u_rel) / mu_f
    f = 1.0 + 0.15 * wp.pow(re, 0.687)
    if re >= 1000.0:
        f = 0.44 * re / 24.0
    return 3.0 * wp.pi * mu_f * d * f * u_rel


@wp.func
def di_felice_drag(u_rel: wp.vec3, d: float, eps: float, rho_f: float, mu_f: float):
    """Di Felice (1994, Int. J. Multiphase Flow 20:153) drag on a sphere in a suspension of
    voidage eps [N], as CFDEMcoupling's DiFeliceDrag: Re = rho_f d eps |u_rel| / mu_f,
    C_d = (0.63 + 4.8 / sqrt(Re))^2, chi = 3.7 - 0.65 exp(-(1.5 - log10 Re)^2 / 2),
    F = (1/8) C_d rho_f pi d^2 eps^(2 - chi) |u_rel| u_rel. Written as
    F = (pi / 8) mu_f d eps^(1 - chi) (0.63 sqrt(Re) + 4.8)^2 u_rel, finite at Re = 0."""
    re = rho_f * d * eps * wp.length(u_rel) / mu_f
    sq = wp.sqrt(re)
    lg = wp.log(wp.max(re, 1.0e-12)) / wp.log(10.0)
    chi = 3.7 - 0.65 * wp.exp(-(1.5 - lg) * (1.5 - lg) / 2.0)
    c = 0.63 * sq + 4.8
    return (wp.pi / 8.0) * mu_f * d * wp.pow(eps, 1.0 - chi) * c * c * u_rel


# ----------------------------------------------------------------------------- built-in model
@register_body_force
class UniformFluid(BodyForceModel):
    """A body immersed in a uniform stream (or still fluid): Schiller-Naumann drag on the
    volume-equivalent sphere plus buoyancy -rho_f V g. One-way (the fluid is not changed)."""

    name = "uniform_fluid"
    parameters = (
        ParameterSpec("density", "kg/m^3", 998.2, (0.0, 2.0e4), "fluid density rho_f"),
        ParameterSpec("viscosity", "Pa s", 1.002e-3, (1.0e-7, 1.0e4), "fluid dynamic viscosity mu_f"),
        ParameterSpec("u_x", "m/s", 0.0, (-1.0e3, 1.0e3), "fluid velocity, x"),
        ParameterSpec("u_y", "m/s", 0.0, (-1.0e3, 1.0e3), "fluid velocity, y"),
        ParameterSpec("u_z", "m/s", 0.0, (-1.0e3, 1.0e3), "fluid velocity, z"),
    )
    reference = "Schiller & Naumann (1933); Clift, Grace & Weber (1978), Bubbles, Drops and Particles"

    def make(self):
        c_rho, c_mu = self.column("density"), self.column("viscosity")
        c_ux, c_uy, c_uz = self.column("u_x"), self.column("u_y"), self.column("u_z")

        @wp.func
        def uniform_fluid(b: BodyForceInput, p: wp.array(dtype=float)):
            u = wp.vec3(p[c_ux], p[c_uy], p[c_uz])
            rho = p[c_rho]
            drag = schiller_naumann_drag(u - b.v, 2.0 * b.radius, rho, p[c_mu])
            return drag - rho * b.volume * b.gravity

        return uniform_fluid
