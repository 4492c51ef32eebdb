"""Hydraulic sizing of the prototype slurry pump from its duty (SI units throughout).

The seed paper (Zhang et al., Sec. 4.4) gives the duty -- 25 m^3/h at 1450 rpm, 2.1 m/s in a
65 mm inlet -- but no head and no drawing. :class:`PumpDesign` derives a consistent impeller
and volute from the duty, a chosen design head and slurry-pump passage rules:

* Specific speed (Gulich 2014, *Centrifugal Pumps*, 3rd ed., eq. 3.1):
  n_q = n sqrt(Q) / H^0.75   [rpm, m^3/s, m].
* Pressure coefficient at best efficiency (Gulich 2014, ch. 3, radial impellers):
  psi_opt = 1.21 exp(-0.77 n_q / 100);  psi = 2 g H / u2^2,  u2 = pi d2 n / 60.
  With the default H = 20 m: n_q = 12.8, psi = 1.10, u2 = 18.9 m/s, d2 = 249 mm (the
  issue's "blade tips at about 20 m/s").
* Euler head with slip, no pre-swirl: H_th = u2 c_u2 / g = H / eta_h.
* Wiesner slip factor (Wiesner 1967, J. Eng. Power 89:558) in the form given by Gulich (2014, ch. 3):
  gamma = f1 (1 - sqrt(sin beta_2B) / z^0.7) k_w, f1 = 0.98 (radial impellers),
  k_w = 1 - ((d1m* - eps_lim) / (1 - eps_lim))^3 if d1m* > eps_lim = exp(-8.16 sin beta_2B / z);
  c_u2 = gamma u2 - c_m2 / tan beta_2B.  beta_2B is solved so that the Euler head equals
  H / eta_h (angles from the circumferential direction).
* Volute: rectangular section of width b3 around the base circle r3 (cut-water radius); the
  flow in it is a free vortex r c_u = K_v plus the radial source flow c_r = Q / (2 pi r b3).
  Its streamlines are the log spirals r = r3 exp(theta Q / (2 pi K_v b3)), so the outer wall is
  one of them and the section at angle theta carries Q theta / (2 pi) (Pfleiderer/Stepanoff
  volute). K_v follows from continuity through the throat: Q = K_v b3 ln(r_throat / r3).

Passages for 10-25 mm gravel (slurry practice: no passage narrower than the largest particle):
3 blades, a 30 mm wide impeller, 45 mm leading-edge radius with 25 deg inlet blade angle
(32 mm blade-to-blade throat), a 25 mm tongue clearance and a 30 mm volute throat. Such an
oversized slurry volute cannot hold the impeller's angular momentum (K_v < r2 c_u2): the swirl
decays across the vaneless gap r2..r3, which is a mixing loss stated by :attr:`volute_loss_head`.

Side clearances (``side_gap`` g, the axial gap between each impeller disc -- shroud and hub -- and
the casing's side liner; the side rooms are the spaces r <= r2 between them). A sphere of diameter
d can enter a side room only where g > d (:mod:`pump.geometry`). Slurry pumps run either tight
side clearances (a few mm, usually with expelling vanes on the shrouds that keep the side rooms
clear of solids) or side rooms of the order of the particle size, where solids recirculate and
grind the suction liner (throatbush) and the back liner -- a wear pattern slurry-pump users look
for, and the reason the front clearance of slurry pumps is adjustable (Wilson, Addie, Sellgren &
Clift 2006, *Slurry Transport Using Centrifugal Pumps*, 3rd ed., Springer). The default, chosen
here (no drawing gives it), is g = 20 mm: of the order of the 10-25 mm gravel, so the quick
config's 10-14 mm spheres and three of the five calibrated clump classes (volume-equivalent
14-16 mm: discoids, spheres, ellipsoids, in some orientations) can enter, the cones and prisms
(21-23 mm) hardly; no expelling vanes. The casing is flat-sided, so the volute is b3 = b2 + 2 g
wide (70 mm, b3 / b2 = 2.3: a wide slurry volute); its swirl K_v is lower and the stated mixing
loss larger than with a narrow casing (7.6 m at the default duty against 4.9 m with g = 3 mm),
a limit of this flat-sided casing. With g = 3 mm (the value before issue 34, below every
particle's radius) no particle can enter a side room. The front side room is closed at the eye
by the throatbush lip down to a 1 mm running clearance (:data:`pump.geometry.EYE_SEAL_CLEARANCE`),
so no particle short-cuts from the eye into it; the flow in the side rooms is a rotating core
(:mod:`pump.flow`).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields

from scipy.optimize import brentq

from warpdem.errors import ConfigError

G = 9.81  # gravitational acceleration [m/s^2]


def specific_speed(speed_rpm: float, flow_rate: float, head: float) -> float:
    """n_q = n sqrt(Q) / H^0.75 [rpm, m^3/s, m] (Gulich 2014, eq. 3.1)."""
    return speed_rpm * math.sqrt(flow_rate) / head**0.75


def pressure_coefficient(n_q: float) -> float:
    """psi_opt = 1.21 exp(-0.77 n_q / 100) of radial impellers at best efficiency (Gulich 2014, ch. 3)."""
    return 1.21 * math.exp(-0.77 * n_q / 100.0)


def wiesner_slip(beta2_deg: float, blades: int, d1_over_d2: float, f1: float = 0.98) -> float:
    """Slip factor gamma (Wiesner 1967 as in Gulich 2014): f1 (1 - sqrt(sin b2)/z^0.7) k_w."""
    s = math.sin(math.radians(beta2_deg))
    eps_lim = math.exp(-8.16 * s / blades)
    k_w = 1.0
    if d1_over_d2 > eps_lim:
        k_w = 1.0 - ((d1_over_d2 - eps_lim) / (1.0 - eps_lim)) ** 3
    return f1 * (1.0 - math.sqrt(s) / blades**0.7) * k_w


@dataclass(frozen=True)
class PumpDesign:
    """Duty and main dimensions of the prototype pump [SI: m, s, rad, m^3/s].

    Inputs (defaults: the seed paper's duty, H = 20 m, slurry passages for 10-25 mm gravel):
        flow_rate_m3h: duty flow rate [m^3/h]; speed_rpm: impeller speed [rpm].
        head: design head H [m] (the paper gives none; 20 m gives u2 ~ 19 m/s, see module doc).
        hydraulic_efficiency: eta_h, assumed (typical of small low-n_q pumps).
        inlet_diameter: suction pipe and impeller eye diameter [m] (65 mm: 2.1 m/s at 25 m^3/h).
        inlet_length: straight suction pipe ahead of the eye [m].
        blades: number of blades z; blade_thickness [m]; outlet_width b2 [m].
        leading_edge_radius r1 [m]; beta1_deg: inlet blade angle [deg from circumferential].
        beta2_deg: outlet blade angle; None = solved from the head.
        tongue_clearance: r3 - r2 [m].
        side_gap: axial clearance g between each impeller disc (shroud, hub) and the casing's
            side liner [m]; the side rooms (r <= r2) admit particles of diameter below g (module
            docstring: 20 mm, of the order of the gravel; 0.003 keeps every particle out).
        throat_height: radial height of the volute throat [m]; discharge_length [m].
    """

    flow_rate_m3h: float = 25.0
    speed_rpm: float = 1450.0
    head: float = 20.0
    hydraulic_efficiency: float = 0.80
    inlet_diameter: float = 0.065
    inlet_length: float = 0.20
    blades: int = 3
    blade_thickness: float = 0.008
    outlet_width: float = 0.030
    leading_edge_radius: float = 0.045
    beta1_deg: float = 25.0
    beta2_deg: float | None = None
    tongue_clearance: float = 0.025
    side_gap: float = 0.020
    throat_height: float = 0.030
    discharge_length: float = 0.15
    derived: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        positive = ("flow_rate_m3h", "speed_rpm", "head", "inlet_diameter", "inlet_length", "blade_thickness",
                    "outlet_width", "leading_edge_radius", "tongue_clearance", "side_gap", "throat_height",
                    "discharge_length")
        for name in positive:
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"pump design: {name} must be a positive number, got {v!r}")
        if not 0.3 <= self.hydraulic_efficiency <= 1.0:
            raise ConfigError(f"pump design: hydraulic_efficiency must lie in [0.3, 1], "
                              f"got {self.hydraulic_efficiency}")
        if int(self.blades) != self.blades or not 2 <= self.blades <= 12:
            raise ConfigError(f"pump design: blades must be an integer in 2..12, got {self.blades}")
        if not 5.0 <= self.beta1_deg <= 60.0:
            raise ConfigError(f"pump design: beta1_deg must lie in [5, 60] deg, got {self.beta1_deg}")
        if self.beta2_deg is not None and not 8.0 <= self.beta2_deg <= 60.0:
            raise ConfigError(f"pump design: beta2_deg must lie in [8, 60] deg, got {self.beta2_deg}")
        object.__setattr__(self, "derived", self._derive())

    @classmethod
    def from_config(cls, cfg: dict | None) -> "PumpDesign":
        """Build from a mapping of the field names above; unknown keys are an error."""
        cfg = dict(cfg or {})
        valid = [f.name for f in fields(cls) if f.name != "derived"]
        unknown = sorted(set(cfg) - set(valid))
        if unknown:
            raise ConfigError(f"pump design: unknown key(s) {unknown}; valid: {valid}")
        return cls(**cfg)

    # ------------------------------------------------------------------ derived quantities
    def _derive(self) -> dict:
        q = self.flow_rate_m3h / 3600.0
        omega = self.speed_rpm * 2.0 * math.pi / 60.0
        n_q = specific_speed(self.speed_rpm, q, self.head)
        psi = pressure_coefficient(n_q)
        u2 = math.sqrt(2.0 * G * self.head / psi)
        r2 = u2 / omega
        b2 = self.outlet_width
        r1 = self.leading_edge_radius
        r_in = 0.5 * self.inlet_diameter
        if not r_in < r1 < 0.8 * r2:
            raise ConfigError(f"pump design: leading_edge_radius {r1} m must lie between the eye radius {r_in} m "
                              f"and 0.8 r2 = {0.8 * r2:.4f} m")
        c_m2 = q / (2.0 * math.pi * r2 * b2)
        h_th = self.head / self.hydraulic_efficiency
        c_u2_target = G * h_th / u2
        d1_d2 = r1 / r2

        def cu2(beta2: float) -> float:
            return wiesner_slip(beta2, self.blades, d1_d2) * u2 - c_m2 / math.tan(math.radians(beta2))

        if self.beta2_deg is None:
            lo, hi = 8.0, 60.0
            f_lo, f_hi = cu2(lo) - c_u2_target, cu2(hi) - c_u2_target
            if f_lo * f_hi > 0:
                raise ConfigError(f"pump design: no outlet blade angle in [8, 60] deg gives the Euler head "
                                  f"{h_th:.2f} m with {self.blades} blades (c_u2 from {cu2(lo):.2f} to {cu2(hi):.2f} "
                                  f"m/s, needed {c_u2_target:.2f}); change blades, head or efficiency")
            # c_u2(beta2) has one maximum; take the root on the rising side if there are two
            beta2 = brentq(lambda b: cu2(b) - c_u2_target, lo, hi, xtol=1e-10)
        else:
            beta2 = float(self.beta2_deg)
        gamma = wiesner_slip(beta2, self.blades, d1_d2)
        c_u2 = cu2(beta2)
        euler_head = u2 * c_u2 / G
        r3 = r2 + self.tongue_clearance
        g = self.side_gap
        b3 = b2 + 2.0 * g
        r_throat = r3 + self.throat_height
        k_impeller = r2 * c_u2
        k_volute = q / (b3 * math.log(r_throat / r3))
        u1 = omega * r1
        c_m1 = q / (2.0 * math.pi * r1 * b2)
        beta1_flow = math.degrees(math.atan2(c_m1, u1))
        pitch1 = 2.0 * math.pi * r1 / self.blades
        throat1 = pitch1 * math.sin(math.radians(self.beta1_deg)) - self.blade_thickness
        pitch2 = 2.0 * math.pi * r2 / self.blades
        throat2 = pitch2 * math.sin(math.radians(beta2)) - self.blade_thickness
        c3 = k_volute / r3
        # kinetic energy lost in the vaneless gap when the swirl drops from K_impeller to K_volute
        volute_loss = (c_u2**2 - (k_volute / r2) ** 2) / (2.0 * G) if k_volute < k_impeller else 0.0
        return dict(
            flow_rate=q, omega=omega, n_q=n_q, psi=psi, u2=u2, r2=r2, d2=2 * r2, b2=b2, r1=r1, u1=u1,
            r_inlet=r_in, inlet_velocity=q / (math.pi * r_in**2), c_m1=c_m1, c_m2=c_m2, beta1_flow_deg=beta1_flow,
            incidence_deg=self.beta1_deg - beta1_flow, beta2_blade_deg=beta2, slip_factor=gamma, c_u2=c_u2,
            euler_head=euler_head, design_euler_head=h_th, r3=r3, b3=b3, r_throat=r_throat,
            k_impeller=k_impeller, k_volute=k_volute, c3=c3,
            spiral_rate=q / (2.0 * math.pi * k_volute * b3), volute_loss_head=volute_loss,
            inlet_throat=throat1, outlet_throat=throat2, tip_speed=u2,
            discharge_velocity=q / (b3 * self.throat_height),
        )

    def __getattr__(self, name: str):
        d = object.__getattribute__(self, "derived")
        if name in d:
            return d[name]
        raise AttributeError(f"PumpDesign has no attribute '{name}'")

    @property
    def revolution_time(self) -> float:
        """Time of one impeller revolution [s]."""
        return 60.0 / self.speed_rpm

    def summary(self) -> dict:
        """Inputs and derived numbers (for reports), plain floats."""
        out = {k: v for k, v in asdict(self).items() if k != "derived"}
        out.update({k: float(v) for k, v in self.derived.items()})
        return out

    def describe(self) -> str:
        d = self.derived
        return (f"Q = {self.flow_rate_m3h:g} m^3/h at {self.speed_rpm:g} rpm, H = {self.head:g} m "
                f"(n_q = {d['n_q']:.1f}, psi = {d['psi']:.3f} after Gulich), d2 = {d['d2'] * 1e3:.1f} mm, "
                f"u2 = {d['u2']:.2f} m/s, z = {self.blades}, b2 = {self.outlet_width * 1e3:g} mm, "
                f"beta1B = {self.beta1_deg:g} deg, beta2B = {d['beta2_blade_deg']:.1f} deg, Wiesner slip "
                f"{d['slip_factor']:.3f}, Euler head {d['euler_head']:.2f} m "
                f"(H/eta_h = {d['design_euler_head']:.2f} m), "
                f"volute r3 = {d['r3'] * 1e3:.1f} mm, throat {self.throat_height * 1e3:g} x {d['b3'] * 1e3:g} mm, "
                f"K_v / K_2 = {d['k_volute'] / d['k_impeller']:.2f}")
