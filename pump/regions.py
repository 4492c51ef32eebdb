"""Wear regions of the pump walls and the statistics of their wear rates.

Regions (:func:`pump_regions`) split the two pump walls where a pump engineer looks for wear:

* impeller: blade leading edge, pressure side, suction side, trailing edge (the blade zones of
  :mod:`pump.geometry`), hub, shroud;
* casing: the cutwater (the tongue component), the volute's spiral wall in 45-deg sectors of the
  angle from the tongue (``volute_000_045`` ... ``volute_315_360``, flow direction +theta), the
  volute's flat side walls (``volute_side_front`` = suction side, ``volute_side_back`` = drive
  side, r > r2), the side-room liners behind the impeller discs (r <= r2): ``suction_liner``
  facing the shroud (the throatbush's face) and ``back_liner`` facing the hub (particles reach
  them only where the side clearance exceeds their size, :mod:`pump.design`), the suction pipe
  (with the throatbush lip at the eye) and the discharge duct.

Statistics (:func:`block_statistics`): a run is cut into blocks (one revolution each, after a
spin-up) in every world; each (world, block) gives one sample of a rate (an increment over the
block divided by its duration). The reported value is the mean of the samples (= the rate over the
window, ensemble-averaged over the worlds); its 95 % confidence interval is mean +- t(0.975, n - 1)
s / sqrt(n), treating blocks as independent (a particle stays in the pump for about one to three
revolutions, so consecutive blocks of one world are mildly correlated and the interval is somewhat
optimistic for a single world; worlds are independent replicates). A region is **converged** when
it holds at least :data:`MIN_IMPACTS` impacts in the window (all worlds) and the interval's
half-width is at most :data:`MAX_RELATIVE_HALF_WIDTH` of the mean; otherwise it is shown greyed and
not ranked.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .geometry import COMPONENTS, PumpGeometry

#: fewest impacts (all worlds, steady window) for a region's numbers to be ranked
MIN_IMPACTS = 30
#: largest 95 % CI half-width, relative to the mean, for a region's numbers to be ranked
MAX_RELATIVE_HALF_WIDTH = 0.5
#: angular width of the volute sectors [deg]
VOLUTE_SECTOR_DEG = 45

IMPELLER_REGIONS = ("blade_leading_edge", "blade_pressure_side", "blade_suction_side", "blade_trailing_edge",
                    "blade_unzoned", "hub", "shroud")
_ZONE_REGION = {1: "blade_leading_edge", 2: "blade_pressure_side", 3: "blade_suction_side", 4: "blade_trailing_edge"}


def volute_sector_names(width_deg: int = VOLUTE_SECTOR_DEG) -> tuple[str, ...]:
    return tuple(f"volute_{a:03d}_{a + width_deg:03d}" for a in range(0, 360, width_deg))


CASING_REGIONS = ("cutwater",) + volute_sector_names() + (
    "volute_side_front", "volute_side_back", "suction_liner", "back_liner", "suction_pipe", "discharge")
#: the side-room liners (r <= r2 behind the shroud and the hub)
SIDE_ROOM_LINERS = ("suction_liner", "back_liner")
REGIONS = IMPELLER_REGIONS + CASING_REGIONS


def impeller_regions(geo: PumpGeometry) -> np.ndarray:
    """Region index (into :data:`REGIONS`) of every impeller triangle."""
    imp = geo.impeller
    out = np.empty(imp.num_triangles, dtype=np.int64)
    for k, comp in enumerate(imp.component):
        name = COMPONENTS[comp]
        if name == "blade":
            name = _ZONE_REGION.get(int(imp.zone[k]), "blade_unzoned")
        out[k] = REGIONS.index(name)
    return out


def casing_regions(geo: PumpGeometry) -> np.ndarray:
    """Region index (into :data:`REGIONS`) of every casing triangle (see the module docstring)."""
    cas, d = geo.casing, geo.design
    cen = cas.centroids()
    tri = cas.vertices[cas.faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    r = np.hypot(cen[:, 0], cen[:, 1])
    theta = np.degrees(np.mod(np.arctan2(cen[:, 1], cen[:, 0]), 2 * np.pi))
    flat = np.abs(nrm[:, 2]) > 0.9
    front = cen[:, 2] > 0.5 * (geo.z_front + geo.z_back)
    sectors = volute_sector_names()
    out = np.empty(cas.num_triangles, dtype=np.int64)
    for k, comp in enumerate(cas.component):
        name = COMPONENTS[comp]
        if name == "tongue":
            reg = "cutwater"
        elif name == "inlet":
            reg = "suction_pipe"
        elif name == "outlet":
            reg = "discharge"
        elif name == "volute" and flat[k]:
            if r[k] <= d.r2:
                reg = "suction_liner" if front[k] else "back_liner"
            else:
                reg = "volute_side_front" if front[k] else "volute_side_back"
        else:  # the spiral wall (or a user volute mesh)
            reg = sectors[min(int(theta[k] // VOLUTE_SECTOR_DEG), len(sectors) - 1)]
        out[k] = REGIONS.index(reg)
    return out


def pump_regions(geo: PumpGeometry) -> dict[str, np.ndarray]:
    """{"impeller": (Ti,), "casing": (Tc,)} region indices into :data:`REGIONS`."""
    return {"impeller": impeller_regions(geo), "casing": casing_regions(geo)}


# ----------------------------------------------------------------------------- statistics
def t_quantile_975(dof: int) -> float:
    """Two-sided 95 % Student-t quantile for ``dof`` degrees of freedom (inf for dof < 1)."""
    if dof < 1:
        return math.inf
    from scipy.stats import t

    return float(t.ppf(0.975, dof))


@dataclass
class Estimate:
    """A rate estimated from block samples: ``mean``, 95 % CI ``half_width`` (inf with one sample),
    ``n`` samples, and the impacts behind it."""

    mean: float
    half_width: float
    n: int
    impacts: float = 0.0
    converged: bool = False

    @property
    def low(self) -> float:
        return self.mean - self.half_width

    @property
    def high(self) -> float:
        return self.mean + self.half_width

    @property
    def relative_half_width(self) -> float:
        return self.half_width / abs(self.mean) if self.mean != 0 else math.inf

    def as_dict(self) -> dict:
        return {"mean": self.mean, "ci95_low": self.low, "ci95_high": self.high, "half_width": self.half_width,
                "samples": self.n, "impacts": self.impacts, "converged": self.converged}


def estimate(samples: np.ndarray, impacts: float = 0.0, min_impacts: int = MIN_IMPACTS,
             max_relative_half_width: float = MAX_RELATIVE_HALF_WIDTH) -> Estimate:
    """Mean and 95 % CI of independent samples (1-D), with the convergence rule of the module."""
    x = np.asarray(samples, dtype=float).ravel()
    x = x[np.isfinite(x)]
    n = int(x.size)
    if n == 0:
        return Estimate(math.nan, math.inf, 0, float(impacts), False)
    mean = float(x.mean())
    hw = t_quantile_975(n - 1) * float(x.std(ddof=1)) / math.sqrt(n) if n > 1 else math.inf
    e = Estimate(mean, hw, n, float(impacts))
    e.converged = bool(impacts >= min_impacts and e.relative_half_width <= max_relative_half_width)
    return e


@dataclass
class BlockSeries:
    """Snapshots of per-world, per-group accumulated totals: ``time`` (k,) [s] and, per field,
    (k, worlds, groups) arrays (accumulated since the recorder's start)."""

    time: list = field(default_factory=list)
    totals: dict = field(default_factory=dict)

    def append(self, t: float, values: dict[str, np.ndarray]) -> None:
        self.time.append(float(t))
        for f, v in values.items():
            self.totals.setdefault(f, []).append(np.asarray(v, dtype=np.float64).copy())

    def array(self, fld: str) -> np.ndarray:
        return np.asarray(self.totals[fld])

    def blocks(self, t_from: float, block: float) -> list[tuple[int, int]]:
        """Pairs (i, j) of snapshot indices bounding consecutive blocks: the snapshots nearest to
        the nominal boundaries t_from + k block [s], for every boundary up to the last snapshot
        (within half a snapshot spacing)."""
        t = np.asarray(self.time)
        if t.size < 2 or block <= 0:
            return []
        half = 0.5 * float(np.median(np.diff(t)))
        bounds = []
        k = 0
        while t_from + k * block <= t[-1] + half:
            i = int(np.argmin(np.abs(t - (t_from + k * block))))
            if not bounds or i > bounds[-1]:
                bounds.append(i)
            k += 1
        return list(zip(bounds[:-1], bounds[1:]))

    def block_increments(self, t_from: float, block: float) -> list[tuple[dict[str, np.ndarray], float]]:
        """Per block of :meth:`blocks`: ({field: (worlds, groups) increment}, duration [s])."""
        t = np.asarray(self.time)
        return [({f: np.asarray(v[j]) - np.asarray(v[i]) for f, v in self.totals.items()}, float(t[j] - t[i]))
                for i, j in self.blocks(t_from, block)]

    def block_rates(self, fld: str, t_from: float, block: float) -> tuple[np.ndarray, float]:
        """(n_blocks, worlds, groups) increments per second of one field over the blocks, and the
        steady window's duration [s]."""
        pairs = self.blocks(t_from, block)
        if not pairs:
            return np.zeros((0,) + self.array(fld).shape[1:]), 0.0
        a, t = self.array(fld), np.asarray(self.time)
        rates = np.stack([(a[j] - a[i]) / (t[j] - t[i]) for i, j in pairs])
        return rates, float(t[pairs[-1][1]] - t[pairs[0][0]])

    def window_increment(self, fld: str, t_from: float, block: float) -> np.ndarray:
        """(worlds, groups) increment of one field over the whole window of :meth:`blocks`."""
        pairs = self.blocks(t_from, block)
        a = self.array(fld)
        if not pairs:
            return np.zeros(a.shape[1:])
        return a[pairs[-1][1]] - a[pairs[0][0]]
