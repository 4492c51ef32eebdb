"""Particle shape as a physical effect: families of clumps with continuous shape parameters.

A *shape family* turns a volume-equivalent diameter d_eq [m], a density [kg/m^3] and its
declared shape parameters into a rigid multi-sphere :class:`~warpdem.clump_geometry.ClumpTemplate`
whose volume is that of the sphere of diameter d_eq (pi d_eq^3 / 6). Its parameters are
declared like a contact sub-model's (:class:`warpdem.contact.ParameterSpec`: name, unit,
default, admissible bounds, description) and the family carries its literature
``reference``, so a shape parameter (``aspect_ratio``) can be put into a calibration design
next to a friction coefficient. Mass properties are those of the union of the member
spheres (:func:`warpdem.clump_geometry.union_mass_properties`).

Families are registered with :func:`register_shape_family` and listed by
:func:`available_shape_families`; :func:`shape_family` returns an instance by name. Adding a
family is one module that subclasses :class:`ShapeFamily` and applies the decorator (importing
it registers it); packages may also declare modules in the entry-point group
``warpdem.shape_families``, which are imported on the first lookup.

Built-in family ``elongated`` (:class:`ElongatedClumps`): a rounded rod of ``MEMBERS`` = 5
equal overlapping spheres on a line, after the multi-element particles of Favier et al.
(1999). Parameter ``aspect_ratio`` = length / width (1 = the sphere itself, one member).
See the class docstring for the geometry, its continuity in the parameter, the contact
multiplicity just above 1 and the surface bumpiness (dimples 6.7 % of the width at 3).
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from .contact.base import ParameterSpec
from .errors import ConfigError

if TYPE_CHECKING:  # clump_geometry (scipy.optimize) is imported on first use: ``import warpdem`` stays light
    from .clump_geometry import ClumpTemplate, MassProperties

__all__ = [
    "ShapeFamily",
    "ElongatedClumps",
    "SHAPE_FAMILIES",
    "ENTRY_POINT_GROUP",
    "register_shape_family",
    "available_shape_families",
    "shape_family",
]

#: Entry-point group whose modules are imported (and so register their families) on first lookup.
ENTRY_POINT_GROUP = "warpdem.shape_families"

#: Registered shape families by name.
SHAPE_FAMILIES: dict[str, type["ShapeFamily"]] = {}
_entry_points_loaded = False


class ShapeFamily:
    """Base class of a shape family. Subclasses set the class attributes and implement
    :meth:`unit_geometry`; the base class checks parameters, scales to d_eq and computes
    the union mass properties.

    Class attributes:
        name: registry key (e.g. ``"elongated"``).
        parameters: the declared shape parameters.
        reference: literature reference of the geometry.
        spheres_per_particle: member spheres of a template (fixed for the family, so the DEM
            cost barely depends on the parameters and worlds of one batch stay balanced; a
            family may use fewer at a degenerate value, e.g. ``elongated`` at aspect 1).
    """

    name: ClassVar[str]
    parameters: ClassVar[tuple[ParameterSpec, ...]] = ()
    reference: ClassVar[str] = ""
    spheres_per_particle: ClassVar[int] = 1

    # ------------------------------------------------------------------ to implement
    def unit_geometry(self, **params: float) -> tuple[np.ndarray, np.ndarray]:
        """Member centres (n, 3) and radii (n,) of the clump at checked ``params``, in any
        length unit and any frame (the base class rescales to the volume of d_eq and moves
        it to the principal frame)."""
        raise NotImplementedError

    def mass_properties(self, centers: np.ndarray, radii: np.ndarray) -> MassProperties:
        """Union mass properties at density 1 of the spheres from :meth:`unit_geometry`;
        default :func:`~warpdem.clump_geometry.union_mass_properties` (quadrature, relative
        error <~2e-4). Families with a closed form override it."""
        from .clump_geometry import union_mass_properties

        return union_mass_properties(centers, radii, 1.0)

    def surface_bumpiness(self, **params: float) -> float:
        """Largest depth of the dimples between member spheres divided by the particle
        width [-] (0 for a smooth body); families that do not know it return NaN."""
        return float("nan")

    # ------------------------------------------------------------------ provided
    @property
    def parameter_specs(self) -> dict[str, ParameterSpec]:
        """Declared parameters by name."""
        return {p.name: p for p in self.parameters}

    @property
    def defaults(self) -> dict[str, float]:
        """Default value of every declared parameter."""
        return {p.name: float(p.default) for p in self.parameters}

    def check_parameters(self, **params: Any) -> dict[str, float]:
        """All parameters (defaults filled in) as floats; ConfigError for an unknown name, a
        non-number or a value outside the admissible range, naming the parameter and range."""
        specs = self.parameter_specs
        unknown = sorted(set(params) - set(specs))
        if unknown:
            raise ConfigError(f"shape family '{self.name}': unknown shape parameter(s) {unknown}; "
                              f"valid: {list(specs)}")
        out = self.defaults
        for key, value in params.items():
            spec = specs[key]
            try:
                v = float(value)
            except (TypeError, ValueError):
                raise ConfigError(f"shape parameter '{key}' of family '{self.name}' must be a number, "
                                  f"got {value!r}") from None
            lo, hi = spec.bounds
            if not (math.isfinite(v) and lo <= v <= hi):
                raise ConfigError(f"shape parameter '{key}' of family '{self.name}' = {value!r} outside its "
                                  f"admissible range [{lo}, {hi}] ({spec.unit})")
            out[key] = v
        return out

    def template(self, d_eq: float, density: float, **params: float) -> ClumpTemplate:
        """Clump of volume pi d_eq^3 / 6 [m^3] (d_eq [m]) at ``density`` [kg/m^3], in its
        principal frame, with union mass properties. Missing parameters take their defaults."""
        d = float(d_eq)
        if not (d > 0 and math.isfinite(d)):
            raise ConfigError(f"shape family '{self.name}': volume-equivalent diameter must be > 0 m, got {d_eq}")
        rho = float(density)
        if not (rho > 0 and math.isfinite(rho)):
            raise ConfigError(f"shape family '{self.name}': density must be > 0 kg/m^3, got {density}")
        from .clump_geometry import ClumpTemplate

        values = self.check_parameters(**params)
        unit = _unit_template(type(self), tuple(sorted(values.items())))
        f = d  # the unit template has d_eq = 1 m and density 1 kg/m^3
        pars = ", ".join(f"{k}={v:g}" for k, v in sorted(values.items()))
        label = f"{self.name}({pars}) d_eq={d * 1e3:.4g} mm"
        return ClumpTemplate(label, unit.centers * f, unit.radii * f, rho, unit.volume * f**3,
                             rho * unit.volume * f**3, unit.inertia_principal * (rho * f**5), unit.rotation,
                             unit.offset * f, unit.volume_error * f**3)

    def describe(self, **params: float) -> dict[str, Any]:
        """JSON-able record: family, parameter values (defaults filled in), declarations, reference."""
        values = self.check_parameters(**params)
        members = _unit_template(type(self), tuple(sorted(values.items()))).n_spheres
        return {"family": self.name, "parameters": values, "spheres_per_particle": members,
                "surface_bumpiness": self.surface_bumpiness(**values), "reference": self.reference,
                "declared": {p.name: {"unit": p.unit, "default": p.default, "bounds": list(p.bounds),
                                      "description": p.description} for p in self.parameters}}


@lru_cache(maxsize=256)
def _unit_template(cls: type[ShapeFamily], values: tuple[tuple[str, float], ...]) -> ClumpTemplate:
    """Template of d_eq = 1 m at density 1 kg/m^3 in its principal frame; cached per parameter set."""
    from .clump_geometry import ClumpTemplate, principal_frame

    family = cls()
    c, r = family.unit_geometry(**dict(values))
    c = np.asarray(c, dtype=float).reshape(-1, 3)
    r = np.asarray(r, dtype=float).ravel()
    mp = family.mass_properties(c, r)
    # exact rescaling of the union to the volume of the sphere of diameter 1 m
    f = (math.pi / 6.0 / mp.volume) ** (1.0 / 3.0)
    inertia = np.asarray(mp.inertia, dtype=float) * f**5
    diag = np.diag(inertia)
    if np.all(inertia == np.diag(diag)) and np.all(np.diff(diag) >= 0):
        moments, axes = diag.copy(), np.eye(3)       # built in its principal frame already
    else:
        moments, axes = principal_frame(inertia)
    body = ((c - mp.com) @ axes) * f
    body[np.abs(body) < 1e-12] = 0.0
    return ClumpTemplate(f"{cls.name} unit", body, r * f, 1.0, math.pi / 6.0, math.pi / 6.0, moments, axes,
                         mp.com * f, mp.volume_error * f**3)


# ---------------------------------------------------------------------------- registry
def register_shape_family(cls: type[ShapeFamily]) -> type[ShapeFamily]:
    """Class decorator registering a shape family under ``cls.name``."""
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name:
        raise ValueError(f"shape family {cls.__name__} needs a non-empty class attribute 'name'")
    if name in SHAPE_FAMILIES and SHAPE_FAMILIES[name] is not cls:
        raise ValueError(f"a shape family named '{name}' is already registered ({SHAPE_FAMILIES[name].__name__})")
    names = [p.name for p in cls.parameters]
    if len(set(names)) != len(names):
        raise ValueError(f"shape family '{name}': duplicate parameter names {names}")
    for p in cls.parameters:
        lo, hi = p.bounds
        if not (lo <= p.default <= hi):
            raise ValueError(f"shape family '{name}': default {p.name}={p.default} outside its bounds [{lo}, {hi}]")
    SHAPE_FAMILIES[name] = cls
    return cls


def _load_entry_points() -> None:
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            ep.load()
        except Exception as exc:  # noqa: BLE001 - name the plugin that failed
            raise ConfigError(f"shape-family plugin '{ep.name}' ({ep.value}) failed to import: {exc}") from exc


def available_shape_families() -> list[str]:
    """Names of the registered shape families (entry-point plugins included)."""
    _load_entry_points()
    return sorted(SHAPE_FAMILIES)


def shape_family(family: "str | ShapeFamily") -> ShapeFamily:
    """A family instance by name (an instance is returned as is); ConfigError if unknown."""
    if isinstance(family, ShapeFamily):
        return family
    if isinstance(family, type) and issubclass(family, ShapeFamily):
        return family()
    _load_entry_points()
    if family not in SHAPE_FAMILIES:
        raise ConfigError(f"unknown shape family {family!r}; available: {sorted(SHAPE_FAMILIES)}")
    return SHAPE_FAMILIES[family]()


# ---------------------------------------------------------------------------- built-in families
@register_shape_family
class ElongatedClumps(ShapeFamily):
    """Rounded rod: ``MEMBERS`` equal spheres of radius r, centres on the body x axis at an
    even spacing s (Favier et al. 1999's multi-element particle).

    Geometry: length L = 2 r + (MEMBERS - 1) s, width W = 2 r, so
    ``aspect_ratio`` a = L / W = 1 + (MEMBERS - 1) s / (2 r), i.e. s / (2 r) = (a - 1) / (MEMBERS - 1).
    r follows from the volume of the union (volume equivalence); for equal collinear spheres
    with s < 2 r it is exactly V = V_ball + (MEMBERS - 1) (V_ball - lens(r, r, s)) (each ball
    meets the union of the previous ones only in its neighbour's lens).

    Continuity: for a > 1 the member count is fixed and the spacing grows linearly from 0,
    so the geometry, mass and inertia are smooth in a on (1, 3.5]; at a = 1 the template is
    the single sphere of diameter d_eq, the limit of the union as a -> 1 (continuous
    geometry and mass properties). Contact multiplicity is not continuous there: members
    closer than about the contact overlap touch a partner together, so just above a = 1 a
    contact counts several times (stiffer contacts, more contact slots). Measured in a
    settled box of 30 particles (d_eq 12 mm, gravel): member contacts per particle 3.3
    (spheres), 3.7 (a = 1), 34 (1.001), 22 (1.003), 9.7 (1.01), 5.6 (1.03), 4.8 (1.1),
    5.9 (1.5), 5.5 (3); the largest per member sphere 20 at 1.001 (default slots 16), <= 5
    from a = 1.1. So treat (1, ~1.03) as a transition zone of the model: a design may
    start at 1 (the sphere) but should not resolve that zone.

    Cost and bumpiness: MEMBERS spheres per particle (the DEM cost grows about linearly
    with the member count). The dimple between neighbours has depth
    r (1 - sqrt(1 - (s / 2r)^2)); relative to the width W (:meth:`surface_bumpiness`) it is
    at a = 2 / 3 / 3.5 for 3 members: 0.067 / 0.50 (spheres just touch) / disconnected;
    4 members: 0.029 / 0.127 / 0.224; 5 members: 0.016 / 0.067 / 0.110; 7 members: 0.007 /
    0.029 / 0.046 (a subclass may set another ``MEMBERS``; it is fixed within a family so
    that the response stays continuous). 5 is the smallest count whose dimples stay below
    7 % of the width at a = 3 (bumpiness acts as extra interlocking / rolling resistance,
    Markauskas et al. 2010), at a cost comparable to the seed paper's "low" gravel fill
    (5-8 spheres); 1 sphere at a = 1. Member radius r / (d_eq / 2) = 1, 0.830, 0.740,
    0.683, 0.644, 0.617 at a = 1, 1.5, 2, 2.5, 3, 3.5: the Rayleigh time step shrinks in
    the same ratio.

    Contacts: a rod lying on a flat wall touches it with all its members (a line contact),
    so the contact stiffness depends on orientation, as for any multi-sphere particle.

    References: Favier, Abbaspour-Fard, Kremmer & Raji (1999) Shape representation of
    axi-symmetrical, non-spherical particles in discrete element simulation using
    multi-element model particles, Eng. Comput. 16:467-480; Markauskas, Kacianauskas,
    Dziugys & Navakas (2010) Investigation of adequacy of multi-sphere approximation of
    elliptical particles for DEM simulations, Granul. Matter 12:107-123.
    """

    name = "elongated"
    MEMBERS: ClassVar[int] = 5
    spheres_per_particle = 5
    parameters = (
        ParameterSpec("aspect_ratio", "length / width", 1.0, (1.0, 3.5),
                      "elongation of the rounded rod: bounding length over width (1 = sphere)",
                      design_range=(1.0, 2.5), off_value=1.0),
    )
    reference = ("Favier et al. (1999) Eng. Comput. 16:467 (overlapping spheres on an axis); "
                 "Markauskas et al. (2010) Granul. Matter 12:107 (multi-sphere surface bumpiness)")

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        cls.spheres_per_particle = cls.MEMBERS

    def spacing_over_diameter(self, aspect_ratio: float) -> float:
        """Centre spacing over member diameter, s / (2 r) = (a - 1) / (MEMBERS - 1) [-]."""
        return (float(aspect_ratio) - 1.0) / (self.MEMBERS - 1)

    def member_radius(self, d_eq: float, aspect_ratio: float) -> float:
        """Member radius r [m] that gives the rod the volume of the sphere of diameter d_eq [m]
        (closed form, see the class docstring)."""
        from .clump_geometry import lens_volume

        q = 2.0 * self.spacing_over_diameter(aspect_ratio)  # s / r
        v_ball = 4.0 / 3.0 * math.pi
        v_unit = v_ball + (self.MEMBERS - 1) * (v_ball - lens_volume(1.0, 1.0, q) if q > 0 else 0.0)
        return 0.5 * float(d_eq) * (math.pi / 6.0 * 8.0 / v_unit) ** (1.0 / 3.0)

    def unit_geometry(self, aspect_ratio: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        if self.spacing_over_diameter(aspect_ratio) > 1.0:
            raise ConfigError(f"shape family '{self.name}': {self.MEMBERS} members cannot reach aspect_ratio "
                              f"{aspect_ratio} without coming apart (need aspect_ratio <= {self.MEMBERS})")
        if float(aspect_ratio) == 1.0:  # the sphere itself: one member, not MEMBERS coincident ones
            return np.zeros((1, 3)), np.array([0.5])
        r = self.member_radius(1.0, aspect_ratio)
        s = 2.0 * r * self.spacing_over_diameter(aspect_ratio)
        x = (np.arange(self.MEMBERS) - 0.5 * (self.MEMBERS - 1)) * s
        return np.c_[x, np.zeros(self.MEMBERS), np.zeros(self.MEMBERS)], np.full(self.MEMBERS, r)

    def mass_properties(self, centers: np.ndarray, radii: np.ndarray) -> MassProperties:
        """Exact union mass properties (density 1) of equal balls centred on the x axis.

        The union is a solid of revolution; the radical plane of two equal neighbours is the
        mid-plane between them, so ball i owns the slab between its mid-planes (Edelsbrunner
        1995's power cells, as in :mod:`warpdem.clump_geometry`). With u = x - x_i and
        rho^2 = r^2 - u^2 per slab: V = int pi rho^2 dx, I_xx = int pi rho^4 / 2 dx,
        I_yy = I_zz = int pi rho^2 (rho^2 / 4 + x^2) dx (about the centroid) -- polynomials
        in u, integrated exactly.
        """
        from .clump_geometry import MassProperties

        x = np.sort(np.asarray(centers, dtype=float)[:, 0])
        r = float(np.asarray(radii, dtype=float)[0])
        x = x - x.mean()
        cuts = np.concatenate([[x[0] - r], 0.5 * (x[1:] + x[:-1]), [x[-1] + r]])  # slab of each ball
        P = np.polynomial.Polynomial
        vol = i_axial = i_transverse = 0.0
        for i, xi in enumerate(x):
            lo, hi = cuts[i] - xi, cuts[i + 1] - xi
            if hi <= lo:
                continue
            rho2 = P([r * r, 0.0, -1.0])                     # r^2 - u^2
            pos2 = P([xi, 1.0]) ** 2                           # x^2 = (x_i + u)^2
            for integrand, acc in ((math.pi * rho2, "v"), (0.5 * math.pi * rho2**2, "a"),
                                   (math.pi * rho2 * (0.25 * rho2 + pos2), "t")):
                F = integrand.integ()
                val = float(F(hi) - F(lo))
                if acc == "v":
                    vol += val
                elif acc == "a":
                    i_axial += val
                else:
                    i_transverse += val
        i_axial = min(i_axial, i_transverse)  # equal at a = 1; a prolate body has I_xx <= I_yy (round-off)
        return MassProperties(volume=vol, mass=vol, com=np.zeros(3),
                              inertia=np.diag([i_axial, i_transverse, i_transverse]), volume_error=0.0)

    def surface_bumpiness(self, aspect_ratio: float = 1.0) -> float:
        """Dimple depth between neighbours over the width, (1 - sqrt(1 - (s/2r)^2)) / 2 [-]."""
        h = min(self.spacing_over_diameter(aspect_ratio), 1.0)
        return 0.5 * (1.0 - math.sqrt(1.0 - h * h))
