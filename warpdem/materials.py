"""Elastic material properties and the effective (pair) quantities of Hertz contact.

References
----------
Johnson, K. L. (1985) *Contact Mechanics*, Cambridge University Press, Sec. 4.2 (E*, R*).
Mindlin, R. D. & Deresiewicz, H. (1953) J. Appl. Mech. 20, 327 -- effective shear modulus
    1/G* = (2 - nu_A)/G_A + (2 - nu_B)/G_B (the seed paper's eqs. (7)/(10) misprint this).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import ConfigError


@dataclass(frozen=True)
class Material:
    """Isotropic elastic solid.

    Attributes:
        name: label used in configs and reports.
        youngs_modulus: E [Pa] (> 0).
        poisson_ratio: nu [-] in (-1, 0.5).
        density: rho [kg/m^3] (> 0; walls may use any positive value).
    """

    name: str
    youngs_modulus: float
    poisson_ratio: float
    density: float

    def __post_init__(self) -> None:
        if not (self.youngs_modulus > 0 and math.isfinite(self.youngs_modulus)):
            raise ConfigError(f"material '{self.name}': youngs_modulus must be > 0 Pa, got {self.youngs_modulus}")
        if not (-1.0 < self.poisson_ratio < 0.5):
            raise ConfigError(f"material '{self.name}': poisson_ratio must lie in (-1, 0.5), got {self.poisson_ratio}")
        if not (self.density > 0 and math.isfinite(self.density)):
            raise ConfigError(f"material '{self.name}': density must be > 0 kg/m^3, got {self.density}")

    @property
    def shear_modulus(self) -> float:
        """G = E / (2 (1 + nu)) [Pa]."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    @classmethod
    def from_shear_modulus(cls, name: str, shear_modulus: float, poisson_ratio: float, density: float) -> "Material":
        """Build from G [Pa] (the seed paper gives Plexiglas as G = 3e9 Pa, nu = 0.25)."""
        return cls(name, 2.0 * shear_modulus * (1.0 + poisson_ratio), poisson_ratio, density)


def effective_youngs_modulus(a: Material, b: Material) -> float:
    """E* from 1/E* = (1 - nu_A^2)/E_A + (1 - nu_B^2)/E_B [Pa] (seed paper eq. 2; Johnson 1985)."""
    return 1.0 / ((1 - a.poisson_ratio**2) / a.youngs_modulus + (1 - b.poisson_ratio**2) / b.youngs_modulus)


def effective_shear_modulus(a: Material, b: Material) -> float:
    """G* from 1/G* = (2 - nu_A)/G_A + (2 - nu_B)/G_B [Pa] (Mindlin & Deresiewicz 1953)."""
    return 1.0 / ((2 - a.poisson_ratio) / a.shear_modulus + (2 - b.poisson_ratio) / b.shear_modulus)


def effective_radius(r_a: float, r_b: float | None) -> float:
    """R* from 1/R* = 1/R_A + 1/R_B [m]; R_B = None means a flat wall (R* = R_A)."""
    return r_a if r_b is None else r_a * r_b / (r_a + r_b)


# The seed paper's materials (Table 6): gravel and Plexiglas walls.
GRAVEL = Material("gravel", youngs_modulus=1.0e7, poisson_ratio=0.3, density=2661.0)
PLEXIGLAS = Material.from_shear_modulus("plexiglas", shear_modulus=3.0e9, poisson_ratio=0.25, density=1190.0)
STEEL = Material("steel", youngs_modulus=2.0e11, poisson_ratio=0.3, density=7850.0)
