"""Wear tables with confidence intervals, the seed paper's wear findings re-tested on its own
metrics, and the wear-life sanity check of the erosion constants.

Every number here comes from the snapshots of :class:`pump.wear.WearRecorder` (per world, per
component and per region): the run after a spin-up is cut into blocks (one impeller revolution by
default) and each (world, block) is one sample of every rate metric (:data:`pump.wear.RATE_METRICS`,
:mod:`pump.regions` for the interval and the convergence rule).

A finding "A exceeds B, C, ..." is tested with paired differences per sample, A - B, A - C, ...
(same world, same block): **reproduced** when every difference's 95 % interval lies above 0, **not
reproduced** when some difference's interval lies below 0, **cannot tell** otherwise. For an
undecided comparison the number of samples that would decide it is estimated from the interval's
1 / sqrt(n) scaling: n_needed = n (half_width / |mean difference|)^2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .erosion import (WEAR_LIFE_FASTEST_H, WEAR_LIFE_SLOWEST_H, WEAR_LIFE_SOURCES, wear_life_hours,
                      wear_life_plausible)
from .regions import (MAX_RELATIVE_HALF_WIDTH, MIN_IMPACTS, SIDE_ROOM_LINERS, Estimate, estimate,
                      volute_sector_names)
from .wear import METRICS, RATE_METRICS, WearRecorder, derive

#: metrics with a per-sample estimate in the tables (rates, and the EDEM step-summed force per block)
TABLE_METRICS = RATE_METRICS + ("edem_cumulative_force_n", "edem_cumulative_force_t")
#: the paper's "volute" is the whole casing around the impeller: volute and tongue (cut-water)
CASING = ("volute", "tongue")
IMPELLER = ("shroud", "blade", "hub")
#: region groups: the casing's wetted wall (spiral sectors and cutwater, without the side walls and the
#: side-room liners), the side-room liners together, and the whole blade
REGION_MERGES = {"volute_wall_and_cutwater": ("cutwater",) + volute_sector_names(),
                 "side_room_liners": SIDE_ROOM_LINERS,
                 "blade_all_zones": ("blade_leading_edge", "blade_pressure_side", "blade_suction_side",
                                     "blade_trailing_edge", "blade_unzoned")}
#: impeller regions the blade leading edge is compared with (finding 2)
LEADING_EDGE_RIVALS = ("blade_pressure_side", "blade_suction_side", "blade_trailing_edge", "hub", "shroud")

REPRODUCED, NOT_REPRODUCED, CANNOT_TELL = "reproduced", "not reproduced", "cannot tell"


@dataclass
class WindowStats:
    """Per-group sample statistics over a steady window (see the module docstring).

    ``samples``: metric -> (n_samples, G) values, one row per (block, world); ``impacts`` (G,) in
    the window (all worlds); ``estimates``: group -> metric -> :class:`Estimate`."""

    kind: str
    names: list
    area: np.ndarray
    triangles: np.ndarray
    t_from: float
    t_to: float
    blocks: int
    worlds: int
    impacts: np.ndarray
    samples: dict = field(default_factory=dict)
    estimates: dict = field(default_factory=dict)
    converged: dict = field(default_factory=dict)

    def index(self, name: str) -> int:
        return self.names.index(name)


def window_stats(recorder: WearRecorder, kind: str, t_from: float, block: float,
                 merge: dict[str, tuple[str, ...]] | None = None) -> WindowStats:
    """Statistics of every group of ``kind`` ('component' or 'region') from ``t_from`` [s] in
    blocks of ``block`` [s]; ``merge`` adds groups summed from others (e.g. casing = volute +
    tongue)."""
    g = recorder.totals(kind)
    names, area, tri = list(g.names), np.asarray(g.area, float), np.asarray(g.triangles, float)
    series = recorder.series[kind]
    blocks = series.block_increments(t_from, block)
    members = {}
    for new, parts in (merge or {}).items():
        idx = [names.index(p) for p in parts if p in names]
        if idx:
            members[new] = idx
    for new, idx in members.items():
        names.append(new)
        area = np.append(area, area[idx].sum())
        tri = np.append(tri, tri[idx].sum())
    worlds = recorder.sim.model.num_worlds
    merged_blocks = []
    for inc, dur in blocks:
        inc = {f: np.concatenate([v] + [v[:, idx].sum(axis=1, keepdims=True) for idx in members.values()], axis=1)
               for f, v in inc.items()}
        merged_blocks.append((inc, dur))
    t = np.asarray(series.time)
    pairs = series.blocks(t_from, block)
    stats = WindowStats(kind, names, area, tri, float(t[pairs[0][0]]) if pairs else math.nan,
                        float(t[pairs[-1][1]]) if pairs else math.nan, len(pairs), worlds, np.zeros(len(names)))
    if not merged_blocks:
        return stats
    if "impacts" in merged_blocks[0][0]:
        stats.impacts = sum(inc["impacts"].sum(axis=0) for inc, _ in merged_blocks)
    for m in TABLE_METRICS:
        if m in ("dnv_depth_rate", "impact_rate_per_area") and "erosion" not in merged_blocks[0][0]:
            continue
        stats.samples[m] = np.concatenate([derive(m, inc, area, tri, dur, recorder.sim.dt, recorder.dnv,
                                                  recorder.archard) for inc, dur in merged_blocks], axis=0)
    for k, n in enumerate(names):
        stats.estimates[n] = {m: estimate(s[:, k], stats.impacts[k]) for m, s in stats.samples.items()}
        p = stats.estimates[n].get("pressure_n")
        stats.converged[n] = bool(stats.impacts[k] >= MIN_IMPACTS and p is not None
                                  and p.relative_half_width <= MAX_RELATIVE_HALF_WIDTH)
    return stats


def difference(stats: WindowStats, metric: str, a: str, b: str) -> Estimate:
    """Paired difference a - b of one metric over the samples (same world and block)."""
    s = stats.samples[metric]
    ia, ib = stats.index(a), stats.index(b)
    return estimate(s[:, ia] - s[:, ib], min(stats.impacts[ia], stats.impacts[ib]))


def verdict(diffs: dict[str, Estimate]) -> str:
    """reproduced / not reproduced / cannot tell from differences 'A - X' (module docstring)."""
    if diffs and all(d.low > 0 for d in diffs.values()):
        return REPRODUCED
    if any(d.high < 0 for d in diffs.values()):
        return NOT_REPRODUCED
    return CANNOT_TELL


def samples_needed(diffs: dict[str, Estimate]) -> int | None:
    """Samples (world x block) that would decide every undecided difference (None: all decided;
    -1: a difference with a single sample or a zero mean, no estimate)."""
    need = 0
    for d in diffs.values():
        if d.low > 0 or d.high < 0:
            continue
        if d.n < 2 or d.mean == 0 or not math.isfinite(d.half_width):
            return -1
        need = max(need, int(math.ceil(d.n * (d.half_width / abs(d.mean)) ** 2)))
    return need or None


def _test(stats: WindowStats, metric: str, a: str, rivals: tuple[str, ...]) -> dict:
    present = [r for r in rivals if r in stats.names and r != a]
    if a not in stats.names or not present or metric not in stats.samples:
        return {"group": a, "metric": metric, "verdict": CANNOT_TELL, "reason": "groups or samples missing",
                "differences": {}}
    diffs = {r: difference(stats, metric, a, r) for r in present}
    return {"group": a, "metric": metric, "unit": METRICS[metric][0], "verdict": verdict(diffs), "samples_needed": samples_needed(diffs),
            "value": stats.estimates[a][metric].as_dict(),
            "rivals": {r: stats.estimates[r][metric].as_dict() for r in present},
            "differences": {r: d.as_dict() for r, d in diffs.items()}}


def retest_findings(components: WindowStats, regions: WindowStats | None) -> dict:
    """The paper's two wear findings on the paper's own metrics (module docstring):

    1. "the volute wears most, through the cumulative tangential contact force" (Fig. 18, Sec. 4.4.3):
       casing (volute + tongue) vs shroud, blade, hub on the extensive time-averaged tangential force
       [N], on the paper's own per-element metric (EDEM step-summed force per element) and per
       unit area [Pa]; and per unit area of the casing's wetted wall only (spiral wall and cutwater,
       without its flat side walls and the side-room liners) vs the blade, hub and shroud;
    2. "the head of the blade reaches the maximum normal cumulative contact energy" (Fig. 17a):
       blade leading edge vs pressure side, suction side, trailing edge, hub, shroud on the normal
       contact energy per unit area and time [W/m^2]."""
    out = {"volute_wears_most": {
        "total": _test(components, "force_t", "casing", IMPELLER),
        "per_element": _test(components, "edem_cumulative_force_t", "casing", IMPELLER),
        "per_area": _test(components, "pressure_t", "casing", IMPELLER)}}
    if regions is not None:
        out["volute_wears_most"]["per_area_wetted_wall"] = _test(regions, "pressure_t", "volute_wall_and_cutwater",
                                                                 ("blade_all_zones", "hub", "shroud"))
        out["leading_edge_highest_normal_energy"] = {
            "per_area": _test(regions, "power_n_per_area", "blade_leading_edge", LEADING_EDGE_RIVALS)}
    return out


def wear_life_check(components: WindowStats, regions: WindowStats | None, thickness_m: float) -> dict:
    """Hours to wear through ``thickness_m`` (the blade) at the blade's mean DNV depth rate and at
    the fastest converged region's, against the published band (:mod:`pump.erosion`)."""
    out = {"thickness_mm": thickness_m * 1e3, "band_h": [WEAR_LIFE_FASTEST_H, WEAR_LIFE_SLOWEST_H],
           "sources": WEAR_LIFE_SOURCES}
    if "blade" in components.names and "dnv_depth_rate" in components.samples:
        e = components.estimates["blade"]["dnv_depth_rate"]
        life = wear_life_hours(e.mean, thickness_m * 1e3)
        out["blade_mean"] = {"depth_rate_mm_y": e.as_dict(), "life_h": life, "plausible": wear_life_plausible(life)}
    if regions is not None and "dnv_depth_rate" in regions.samples:
        conv = [n for n in regions.names if regions.converged.get(n)]
        if conv:
            worst = max(conv, key=lambda n: regions.estimates[n]["dnv_depth_rate"].mean)
            e = regions.estimates[worst]["dnv_depth_rate"]
            life = wear_life_hours(e.mean, thickness_m * 1e3)
            out["fastest_converged_region"] = {"region": worst, "depth_rate_mm_y": e.as_dict(), "life_h": life,
                                               "plausible": wear_life_plausible(life)}
    return out


def table(stats: WindowStats, metrics: tuple[str, ...] = TABLE_METRICS) -> dict:
    """{group: {area_m2, triangles, impacts, converged, <metric>: Estimate.as_dict()}}."""
    return {n: {"area_m2": float(stats.area[k]), "triangles": int(stats.triangles[k]),
                "impacts": float(stats.impacts[k]), "converged": bool(stats.converged.get(n, False)),
                **{m: stats.estimates[n][m].as_dict() for m in metrics if m in stats.estimates.get(n, {})}}
            for k, n in enumerate(stats.names)}
