"""Wall-material loss from the DEM contacts, with published constants and their sources.

Two mechanisms, each with its own published law (both give a lost volume; depth = volume / area):

* **Impact erosion, DNV-RP-O501** (DNV GL, Recommended Practice DNVGL-RP-O501, August 2015
  edition, Sec. 3; the 2007 edition was titled "Erosive wear in piping systems"). Per impact of a
  particle of mass m_p [kg] at speed U_p [m/s] and angle alpha [rad] from the wall, the wall loses
  the mass

      dM = m_p E_m,   E_m = K U_p^n F(alpha)   [kg of wall per kg of particles]                 (Sec. 3)
      F(alpha) = A (sin alpha + B (sin alpha - sin^2 alpha))^k (1 - exp(-C alpha))               (eq. 3.3)

  ductile materials (steel): A = 0.6, B = 7.2, C = 20, k = 0.6 (F peaks at 1.0 near 35 deg and is
  0.6 at a head-on impact); material constants, steel grades: K = 2.0e-9 (m/s)^-n, n = 2.6, density
  rho_t = 7800 kg/m^3 (lost volume dM / rho_t). Checked against Equinor's open implementation of
  the RP (github.com/equinor/pysand: ``pysand/erosion.py`` F(), K and n defaults;
  ``tests/test_erosion.py``: carbon steel (7800, 2e-9, 2.6, ductile), F(34.8 deg) = 1, F(90 deg) = 0.6).
  The RP is validated for sand of 0.02-5 mm; the pump's gravel (10-25 mm) is outside that range,
  so the numbers are an order-of-magnitude estimate, not a prediction.

  Sanity of the constants: at U_p = 10 m/s, F = 1, E_m = 2e-9 * 10^2.6 = 8.0e-7 kg/kg; the
  prototype's former Finnie constant k = 5e-10 m^3/J gave about 4e-5 kg/kg (issue 34), 50x more.

* **Sliding wear, Archard** (Archard 1953, J. Appl. Phys. 24:981): V = (K_a / H) F_n s, with s the
  sliding distance. K_a = 1e-2: the low end of the range for abrasive wear, 1e-2 to 1e-1 (NPTEL
  Tribology, lecture 7.5, IIT Kanpur: fretting 1e-6 to 1e-4, adhesive 1e-4, abrasive 1e-2 to
  1e-1), as gravel sliding on a steel casing is abrasive. H = 1.18e9 Pa: mild steel of Brinell
  hardness 120 (120 kgf/mm^2 = 1.18 GPa; the worked example of Wikipedia's "Wear coefficient").
  In the DEM, sum F_n s over a contact = E_t / mu_pw while it slides (|F_t| = mu F_n; see
  :mod:`pump.wear`), so sticking contacts add almost nothing.

Depth rates are reported in mm/year of continuous operation (:data:`SECONDS_PER_YEAR`, 365.25 d)
at the run's delivered solids loading; erosion is linear in the particle flux, so in the dilute
limit a rate at loading phi scales as phi.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SECONDS_PER_YEAR = 365.25 * 24 * 3600.0  # [s] of continuous operation


@dataclass(frozen=True)
class DNVErosion:
    """DNV-RP-O501 (2015) impact erosion of a ductile wall (module docstring): the RP's material
    constants for steel grades and its eq. 3.3 (ductile angle function)."""

    K: float = 2.0e-9  # [(m/s)^-n] material constant, steel grades
    n: float = 2.6  # [-] velocity exponent, steel grades
    density: float = 7800.0  # [kg/m^3] wall density, steel grades
    A: float = 0.6  # eq. 3.3, ductile
    B: float = 7.2
    C: float = 20.0
    k: float = 0.6
    source: str = "DNVGL-RP-O501 (Aug 2015) Sec. 3, eq. 3.3, material constants for steel grades"

    def angle_function(self, alpha: np.ndarray) -> np.ndarray:
        """F(alpha) [-], alpha [rad] from the wall in [0, pi/2] (eq. 3.3)."""
        a = np.clip(np.asarray(alpha, dtype=float), 0.0, 0.5 * math.pi)
        s = np.sin(a)
        return self.A * (s + self.B * (s - s * s)) ** self.k * (1.0 - np.exp(-self.C * a))

    def mass_ratio(self, speed: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """E_m = K U_p^n F(alpha) [kg of wall per kg of impacting particles]; speed [m/s]."""
        return self.K * np.asarray(speed, dtype=float) ** self.n * self.angle_function(alpha)

    def mass_loss(self, particle_mass: np.ndarray, speed: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """Wall mass lost to impacts, m_p E_m [kg]."""
        return np.asarray(particle_mass, dtype=float) * self.mass_ratio(speed, alpha)


@dataclass(frozen=True)
class ArchardWear:
    """Archard sliding wear V = (K_a / H) F_n s (module docstring)."""

    wear_coefficient: float = 1.0e-2  # K_a [-], abrasive wear, low end of 1e-2..1e-1 (NPTEL lecture 7.5)
    hardness: float = 1.18e9  # H [Pa], mild steel HB 120
    source: str = ("Archard (1953) J. Appl. Phys. 24:981; K_a: abrasive-wear range 1e-2..1e-1 (NPTEL Tribology "
                   "lecture 7.5); H: mild steel HB 120 = 1.18 GPa")

    def volume(self, normal_force_times_distance: np.ndarray) -> np.ndarray:
        """Worn volume [m^3] from sum F_n s [N m]."""
        return self.wear_coefficient / self.hardness * np.asarray(normal_force_times_distance, dtype=float)


def depth_rate_mm_per_year(volume: np.ndarray, area: np.ndarray, duration: float) -> np.ndarray:
    """Mean depth rate [mm/year] of a lost volume [m^3] spread over an area [m^2] in ``duration``
    [s] of simulated operation (0 where the area is 0)."""
    v = np.asarray(volume, dtype=float)
    a = np.asarray(area, dtype=float)
    if duration <= 0:
        return np.zeros(np.broadcast(v, a).shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(a > 0, v / np.where(a > 0, a, 1.0) / duration * 1e3 * SECONDS_PER_YEAR, 0.0)


# ----------------------------------------------------------------------------- wear life, literature
#: Order-of-magnitude anchors for the wear life of slurry-pump wet-end parts (the sanity check of the
#: report and tests/test_pump_erosion.py). The fast end is a laboratory test made to wear quickly:
#: Kang et al., Ain Shams Eng. J. 15 (2024) 102277 (steel pump, 2 mm particles, 10 % solids by
#: mass): "after a 30-hour wear experiment ... the outlet part of the long blades is worn through".
#: The slow end is field service: Walker & Robbie, Wear 302 (2013) 1026, monitored one slurry-pump
#: application "for over 2 years and over 40 parts run to destruction" (parts last months, not
#: decades); a rubber-lined Warman 4/3 cyclone-feed pump averaged 5.3 weeks of liner life over 9
#: years (slurrytech.com.au Ceramax trial report). Wear lives between about a day and a few years.
WEAR_LIFE_FASTEST_H = 30.0  # [h] Kang et al. (2024): blade outlet worn through in a 30 h test
WEAR_LIFE_SLOWEST_H = 10 * 2 * 8766.0  # [h] 10x the 2-year window in which Walker & Robbie (2013) wore out 40 parts
WEAR_LIFE_SOURCES = (
    "Kang et al., Ain Shams Eng. J. 15 (2024) 102277: blade outlet worn through in a 30 h test (2 mm particles, "
    "10 % solids by mass); Walker & Robbie, Wear 302 (2013) 1026: over 40 pump parts run to destruction in "
    "2 years of field service; slurrytech.com.au: rubber liners of a Warman 4/3 pump lasted 5.3 weeks on average")


def wear_life_hours(depth_rate_mm_y: float, wall_thickness_mm: float) -> float:
    """Hours of continuous operation to wear through ``wall_thickness_mm`` at ``depth_rate_mm_y``."""
    if depth_rate_mm_y <= 0:
        return math.inf
    return wall_thickness_mm / depth_rate_mm_y * SECONDS_PER_YEAR / 3600.0


def wear_life_plausible(life_h: float) -> bool:
    """Whether a wear life [h] lies within the published order-of-magnitude band
    [:data:`WEAR_LIFE_FASTEST_H`, :data:`WEAR_LIFE_SLOWEST_H`]."""
    return WEAR_LIFE_FASTEST_H <= life_h <= WEAR_LIFE_SLOWEST_H
