"""C. Hollow cylinder lifting: validation pile angle gamma_s
(docs/experiments.md, section C; seed paper Table 10)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

import warpdem as wd
from warpdem import ConfigError
from warpdem.geometry import cylinder_shell

from ..filling import VerticalCylinder, body_tops, level
from ..materials import BulkMaterial
from ..measurement import CylinderPileResult, cylinder_pile_angle
from .common import Experiment, RunContext, fit_to_dict, rectangle
from .lab_effort import LabEffort, LabSetting

__all__ = ["HollowCylinder"]


def _pile_height(x: np.ndarray, r: np.ndarray, d_mean: float) -> float:
    """Highest particle top [m] above the plate within one mean diameter of the axis (0 if none)."""
    if len(x) == 0:
        return 0.0
    near = np.hypot(x[:, 0], x[:, 1]) < max(d_mean, 1e-9) * 1.5
    return float((x[near, 2] + r[near]).max()) if np.any(near) else 0.0

QUICK_CYLINDER_MATERIAL = BulkMaterial.spheres(0.014, 0.018, name="quick spheres d=14-18 mm")


@dataclass
class HollowCylinder(Experiment):
    """Hollow cylinder lifting (spec C), SI units.

    Open cylinder of inner ``diameter`` and ``height`` [m] (``sections`` facets) standing on
    a square floor plate of side ``plate_size`` [m] centred on the axis x = y = 0. Filled
    with ``fill_mass`` [kg], settled, levelled at ``level_height`` [m] if given; lifted in +z
    at ``lift_speed`` [m/s] until its bottom edge is ``lift_clearance`` [m] (None: one
    largest particle diameter) above the pile top, then run until settled or
    ``max_time_after_lift`` [s] after the lift ended (the spec gives no limit; this is the
    config's). Particles off the plate or below ``removal_z`` are removed.
    Measurement: four half-profiles, ``bin_width`` bins, fit band ``band`` x peak height.
    "No pile" is an outcome, not a failure: when the peak height near the axis is below
    ``min_pile_layers`` mean particle diameters (the material spread to one or two layers), the
    world reports ``pile_formed`` 0, ``pile_angle`` 0 deg and the measured ``pile_height``.
    Scale "quick": spheres d = 14-18 mm, 5 kg in a 150 mm cylinder, lift at 0.1 m/s (paper
    0.01 m/s), at most 3 s after.
    """

    name: ClassVar[str] = "cylinder"
    angle_name: ClassVar[str] = "gamma_s"
    OBSERVABLES: ClassVar[dict[str, str]] = {"pile_angle": "deg", "pile_height": "m", "pile_formed": "1/0"}
    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {
        "paper": {},
        # smaller spheres in a narrower cylinder than the box/drum quick scale: with 24-30 mm spheres
        # the pile is only 3-4 particles high and its flanks are not measurable
        "quick": {"material": QUICK_CYLINDER_MATERIAL, "diameter": 0.150, "fill_mass": 5.0, "lift_speed": 0.1,
                  "max_time_after_lift": 3.0, "bin_width": 0.020},
    }
    #: lab hours per repeat and settings a lab can change (calibration.experiments.lab_effort)
    LAB_EFFORT: ClassVar[LabEffort] = LabEffort(
        0.4, 2.0, "a repeat: weigh, fill, lift, scan four profiles, sweep up; set-up: a tube, a plate and a lift")
    LAB_SETTINGS: ClassVar[tuple[LabSetting, ...]] = (
        LabSetting("fill_mass", "fill mass", "kg", (0.5, 2.0), 0.1, 0.4,
                   "weigh another fill; a small pile may not form at all, a large one is taller and steeper"),
        LabSetting("lift_speed", "cylinder lift speed", "m/s", (2.0, 0.5), 0.25, 0.4,
                   "set the lift to another speed; a fast lift spreads the material further"),
        LabSetting("diameter", "cylinder diameter", "m", (1.5, 0.75), 4.0, 0.4,
                   "cut a new tube (expensive); the column then spreads from a wider base"),
    )

    diameter: float = 0.200
    height: float = 0.500
    sections: int = 64
    plate_size: float = 1.0
    fill_mass: float = 10.0
    level_height: float | None = None
    lift_speed: float = 0.01
    lift_clearance: float | None = None
    max_time_after_lift: float = 8.0
    bin_width: float = 0.010
    band: tuple[float, float] = (0.20, 0.80)
    min_bins: int = 3
    removal_z: float = -0.050
    min_pile_layers: float = 2.0

    def validate(self) -> None:
        self._check_positive("diameter", "height", "plate_size", "fill_mass", "lift_speed", "bin_width")
        self._check_nonnegative("max_time_after_lift", "min_pile_layers")
        for name in ("level_height", "lift_clearance"):
            if getattr(self, name) is not None:
                self._check_positive(name)
        if self.plate_size <= self.diameter:
            raise ConfigError(f"cylinder: plate_size {self.plate_size} m must exceed the diameter {self.diameter} m")
        if int(self.sections) < 8:
            raise ConfigError(f"cylinder: sections must be >= 8, got {self.sections}")
        self._check_range("band", (0.0, 1.0))

    # ------------------------------------------------------------------ set-up (spec C)
    def fill_region(self) -> VerticalCylinder:
        return VerticalCylinder((0.0, 0.0), 0.5 * self.diameter, 0.0, self.height, open_top=True)

    def fill_amount(self, material: BulkMaterial) -> dict[str, float]:
        return {"mass": self.fill_mass}

    def add_walls(self, builder: wd.ModelBuilder, fill_top: float, t_motion: float, material: BulkMaterial) -> None:
        # the shell reaches above a loose column taller than ``height``
        h = max(self.height, fill_top + material.max_bounding_radius)
        shell = cylinder_shell(0.5 * self.diameter, h, axis=(0.0, 0.0, 1.0), center=(0.0, 0.0, 0.5 * h),
                               sections=int(self.sections), caps=False)
        lift = wd.WallMotion.translation((0.0, 0.0, self.lift_speed), start=t_motion)
        wm = self.wall_material.name
        builder.add_wall(shell, wm, motion=lift, name="cylinder")
        s = self.plate_size
        builder.add_wall(rectangle((-s / 2, -s / 2, 0.0), (s, 0, 0), (0, s, 0), 4), wm, name="plate")

    def remove_box(self) -> tuple:
        s = 0.5 * self.plate_size
        return (-s, -s, self.removal_z), (s, s, 100.0)

    # ------------------------------------------------------------------ protocol (spec C)
    def _lift_plan(self, ctx: RunContext) -> list[float]:
        """Each world's lift time [s]: until the bottom edge clears that world's own pile top
        (spec C "Protocol"), so that a world's lift does not depend on the worlds of its batch."""
        active = ctx.sim.state.body_active.numpy() != 0
        tops = body_tops(ctx.sim)
        clearance = self.lift_clearance if self.lift_clearance is not None else \
            2.0 * self.bulk_material().max_bounding_radius
        times = []
        for w in range(ctx.num_worlds):
            sel = active & (ctx.model.host["body_world"] == w)
            top = float(tops[sel].max()) if sel.any() else 0.0
            ctx.diag[w]["fill_top_m"] = top
            times.append((top + clearance) / self.lift_speed)
        return times

    def protocol(self, ctx: RunContext, t_motion: float) -> list[dict[str, Any]]:
        nw = ctx.num_worlds
        box = self.remove_box()
        # Fill: settled and levelled as in A (spec C "Fill")
        # (fill_mode poured: poured in batches first, Experiment.pour)
        self.settle_fill(ctx, box)
        if self.level_height is not None:
            removed = ctx.once("level", lambda: level(ctx.sim, self.level_height))
            for w in range(nw):
                ctx.diag[w]["levelled_removed"] = int(removed[w])
        lift_time = np.asarray(ctx.once("lift_plan", lambda: self._lift_plan(ctx)), dtype=float)
        ctx.jump_clock(t_motion)
        # the cylinder rises from t_motion on and does not stop; a world's pile is settled (spec C
        # "Protocol") once its own lift has cleared its pile: not before lift_time[w], at the latest
        # max_time_after_lift after it, checked per world on one clock (a world's lift and settling
        # do not wait for the tallest pile of the batch)
        ctx.settle("lift_and_settle", lift_time + self.max_time_after_lift, lift_time, box)
        for w in range(nw):  # the name the settling after the lift had before (records compare it)
            ctx.diag[w]["after_lift_settle_settled"] = ctx.diag[w]["lift_and_settle_settled"]
        removed = ctx.removed_per_world()
        x_all = ctx.sim.sphere_positions()
        out: list[dict[str, Any]] = [dict() for _ in range(nw)]
        for w in range(nw):
            ctx.diag[w].update(removed_total=int(removed[w]), lift_speed_m_s=self.lift_speed,
                               lift_time_s=float(lift_time[w]))
            xs, rs = ctx.world_spheres(w, x_all)
            out[w]["particles"] = (xs.astype(np.float32), rs.astype(np.float32))
            d_mean = float(np.mean(ctx.fill(w).sample.equivalent_diameter))
            peak = _pile_height(xs, rs, d_mean)
            ctx.diag[w].update(peak_height_m=peak, mean_diameter_m=d_mean)
            if peak < float(self.min_pile_layers) * d_mean:
                out[w].update(angle=0.0, observables={"pile_height": peak, "pile_formed": 0.0})
                ctx.diag[w].update(no_pile=True, no_pile_reason=f"peak height {peak * 1e3:.1f} mm < "
                                   f"{self.min_pile_layers:g} mean diameters ({d_mean * 1e3:.1f} mm)")
                continue
            res = ctx.measure(w, "gamma_s", cylinder_pile_angle, xs, rs, d_mean, axis_xy=(0.0, 0.0),
                              bin_width=self.bin_width, band=self.band, min_bins=int(self.min_bins))
            if res is None:
                continue
            out[w].update(angle=res.gamma_s_deg, fit=res,
                          observables={"pile_height": res.peak_height, "pile_formed": 1.0})
            ctx.diag[w].update(thetas_deg=res.thetas_deg, halves=list(CylinderPileResult.HALVES),
                               peak_height_m=res.peak_height, mean_diameter_m=d_mean,
                               fits={h: fit_to_dict(f) for h, f in zip(CylinderPileResult.HALVES, res.fits)})
        return out
