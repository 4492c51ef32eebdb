"""A. Baffle lifting box: static angle of repose alpha_AoR_S
(docs/experiments.md, section A; seed paper Sec. 2.1.2, Table 1)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

import warpdem as wd
from warpdem import ConfigError

from ..filling import Box, level
from ..materials import BulkMaterial
from ..measurement import baffle_static_angle, bulk_density, mean_surface_height
from .common import Experiment, RunContext, fit_to_dict, rectangle
from .lab_effort import LabEffort, LabSetting

__all__ = ["BaffleBox"]

QUICK_MATERIAL = BulkMaterial.spheres(0.024, 0.030, name="quick spheres d=24-30 mm")


@dataclass
class BaffleBox(Experiment):
    """Baffle lifting box (spec A), SI units.

    Box interior x in [0, box_length], y in [0, box_width], z in [0, box_height] [m]; fixed
    walls x = 0, y = 0, y = box_width; the baffle is the wall x = box_length. Floor z = 0 from
    x = 0 to ``floor_length`` (and ``floor_side_margin`` beyond the side walls in y).
    Particles past x = floor_length or below ``removal_z`` are removed.
    fill_mass [kg]; level_height [m] (None: no levelling). The baffle rises at ``lift_speed``
    [m/s] until its bottom edge is at ``lift_to`` [m]; the run ends when settled or
    ``max_time_after_lift`` [s] after the lift started.
    Measurement: ``measure_y`` slab, ``bin_width`` bins, fit band ``band`` x h_fill,
    ``min_bins``; bulk density in the box shrunk by ``density_margin`` (x, y, floor) and
    ``density_top_margin`` below h.
    Scale "quick": spheres d = 24-30 mm, same box, 28 kg (fill about 0.29 m high instead of
    0.17 m), baffle lifted at 0.2 m/s to 0.30 m, at most 4 s after the lift started, 25 mm bins.
    The taller fill is deliberate: inside the box the slope runs from the crest down to the
    height of the heap outside the baffle, only about 4 particle diameters of 24-30 mm spheres
    at 16 kg, so one pile's angle (and the camera view of it) scattered by 3.4 deg between loose
    fills; at 28 kg the slope spans ~7 diameters and the scatter is 1.6 deg, and the image and
    profile angles of 14 of 16 piles agree within 1 deg (7 of 16 at 16 kg; docs/notes/experiments_timing.md,
    "Camera view against particle profile").
    """

    name: ClassVar[str] = "baffle"
    angle_name: ClassVar[str] = "alpha_AoR_S"
    OBSERVABLES: ClassVar[dict[str, str]] = {"static_angle": "deg", "bulk_density": "kg/m^3"}
    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {
        "paper": {},
        "quick": {"material": QUICK_MATERIAL, "fill_mass": 28.0, "lift_speed": 0.2, "lift_to": 0.30, "max_time_after_lift": 4.0,
                  "bin_width": 0.025},
    }
    #: lab hours per repeat and settings a lab can change (calibration.experiments.lab_effort)
    LAB_EFFORT: ClassVar[LabEffort] = LabEffort(
        0.5, 4.0, "a repeat: weigh, fill and level, lift, photograph, sweep up; set-up: a box with a lifting baffle")
    LAB_SETTINGS: ClassVar[tuple[LabSetting, ...]] = (
        LabSetting("fill_mass", "fill mass", "kg", (1.5, 0.5), 0.1, 0.5,
                   "weigh another fill; a taller heap has a longer slope, in a lower one cohesion weighs more "
                   "against gravity (but a coarse fill may leave too short a slope to measure)"),
        LabSetting("lift_speed", "baffle lift speed", "m/s", (2.0, 0.5), 0.25, 0.5,
                   "set the drive to another speed; a faster lift lets the heap flow before it stops"),
        LabSetting("box_width", "box width", "m", (1.5,), 4.0, 0.5,
                   "a new box; the side walls hold less of a heap of the same height (fill mass and measured slab "
                   "scale with the width)", also_scaled=("measure_y", "fill_mass")),
    )

    box_length: float = 0.300
    box_width: float = 0.200
    box_height: float = 0.400
    floor_length: float = 0.700
    floor_side_margin: float = 0.100
    removal_z: float = -0.050
    fill_mass: float = 16.0
    level_height: float | None = None
    lift_speed: float = 0.1
    lift_to: float = 0.450
    max_time_after_lift: float = 8.0
    measure_y: tuple[float, float] = (0.030, 0.170)
    bin_width: float = 0.010
    band: tuple[float, float] = (0.15, 0.85)
    min_bins: int = 3
    density_margin: float = 0.020
    density_top_margin: float = 0.040

    def validate(self) -> None:
        self._check_positive("box_length", "box_width", "box_height", "fill_mass", "lift_speed", "lift_to",
                             "max_time_after_lift", "bin_width")
        self._check_nonnegative("floor_side_margin", "density_margin", "density_top_margin")
        if self.floor_length <= self.box_length:
            raise ConfigError(f"baffle: floor_length {self.floor_length} m must exceed box_length {self.box_length} m")
        if self.level_height is not None:
            self._check_positive("level_height")
        self._check_range("measure_y", (0.0, self.box_width))
        self._check_range("band", (0.0, 1.0))
        if int(self.min_bins) < 2:
            raise ConfigError(f"baffle: min_bins must be >= 2, got {self.min_bins}")

    # ------------------------------------------------------------------ set-up (spec A)
    def fill_region(self) -> Box:
        return Box((0.0, 0.0, 0.0), (self.box_length, self.box_width, self.box_height), open_top=True)

    def fill_amount(self, material: BulkMaterial) -> dict[str, float]:
        return {"mass": self.fill_mass}

    @property
    def lift_duration(self) -> float:
        return self.lift_to / self.lift_speed

    def add_walls(self, builder: wd.ModelBuilder, fill_top: float, t_motion: float, material: BulkMaterial) -> None:
        L, W = self.box_length, self.box_width
        # walls reach above a loose column taller than the box (they are immaterial above the fill)
        H = max(self.box_height, fill_top + material.max_bounding_radius)
        m = self.floor_side_margin
        wm = self.wall_material.name
        builder.add_wall(rectangle((0, 0, 0), (0, W, 0), (0, 0, H), 2), wm, name="back x=0")
        builder.add_wall(rectangle((0, 0, 0), (L, 0, 0), (0, 0, H), 2), wm, name="side y=0")
        builder.add_wall(rectangle((0, W, 0), (L, 0, 0), (0, 0, H), 2), wm, name="side y=W")
        builder.add_wall(rectangle((0, -m, 0), (self.floor_length, 0, 0), (0, W + 2 * m, 0), 4), wm, name="floor")
        lift = wd.WallMotion.translation((0.0, 0.0, self.lift_speed), start=t_motion, stop=t_motion + self.lift_duration)
        builder.add_wall(rectangle((L, 0, 0), (0, W, 0), (0, 0, H), 2), wm, motion=lift, name="baffle")

    def remove_box(self) -> tuple:
        return (-1.0, -10.0, self.removal_z), (self.floor_length, 10.0, 10.0)

    # ------------------------------------------------------------------ protocol (spec A)
    def _measure_fill(self, ctx: RunContext) -> tuple[list, list]:
        """h_fill [m] and bulk density [kg/m^3] of every world before the lift (None where the
        measurement failed; the world's error is set)."""
        nw = ctx.num_worlds
        x_all = ctx.sim.sphere_positions()
        h_fill, rho = [None] * nw, [None] * nw
        dm = self.density_margin
        for w in range(nw):
            xs, rs = ctx.world_spheres(w, x_all)
            ctx.diag[w]["particles_before_lift"] = int(np.count_nonzero(
                (ctx.sim.state.body_active.numpy() != 0) & (ctx.model.host["body_world"] == w)))
            h = ctx.measure(w, "h_fill", mean_surface_height, xs, rs, x_range=(0.0, self.box_length),
                            y_range=(0.0, self.box_width), bin_width=self.bin_width)
            h_fill[w] = h
            ctx.diag[w]["h_fill_m"] = h
            if h is None:
                continue
            xb, mb = ctx.world_bodies(w)
            rho[w] = ctx.measure(w, "bulk_density", bulk_density, xb, np.zeros(len(xb)), mb,
                                 box=((dm, self.box_length - dm), (dm, self.box_width - dm)), h=h, z_min=dm,
                                 top_margin=self.density_top_margin)
        return h_fill, rho

    def protocol(self, ctx: RunContext, t_motion: float) -> list[dict[str, Any]]:
        nw = ctx.num_worlds
        box = self.remove_box()
        out: list[dict[str, Any]] = [dict() for _ in range(nw)]
        # Fill: settle under gravity until KE/particle < 1e-6 J or 1.5 s (spec A "Fill"); with
        # fill_mode poured the batches are poured first (Experiment.pour)
        self.settle_fill(ctx, box)
        # level the surface if a levelling height is given (spec A "Fill")
        if self.level_height is not None:
            removed = ctx.once("level", lambda: level(ctx.sim, self.level_height))
            for w in range(nw):
                ctx.diag[w]["levelled_removed"] = int(removed[w])
        # h_fill and bulk density before the lift (spec A "Measurement", "Also reported"); kept
        # in a checkpoint, as the state they were measured on is gone after the lift
        h_fill, rho = ctx.once("fill_measurement", lambda: self._measure_fill(ctx))
        for w in range(nw):
            if h_fill[w] is not None:
                out[w]["bulk_density"] = rho[w]
                out[w]["observables"] = {"bulk_density": rho[w]}
        # lift the baffle in +z at lift_speed until its bottom edge is at lift_to (spec A "Protocol")
        ctx.jump_clock(t_motion)
        ctx.advance("lift", self.lift_duration, box)
        # run on until settled, at most max_time_after_lift after the lift started (spec A "Protocol")
        ctx.settle("after_lift_settle", max(self.max_time_after_lift - self.lift_duration, 0.0), 0.0, box)
        removed = ctx.removed_per_world()
        x_all = ctx.sim.sphere_positions()
        for w in range(nw):
            ctx.diag[w]["removed_total"] = int(removed[w])
            xs, rs = ctx.world_spheres(w, x_all)
            out[w]["particles"] = (xs.astype(np.float32), rs.astype(np.float32))
            if h_fill[w] is None:
                continue
            fit = ctx.measure(w, "alpha_AoR_S", baffle_static_angle, xs, rs, h_fill[w],
                              x_range=(0.0, self.box_length), y_range=self.measure_y, bin_width=self.bin_width,
                              band=self.band, min_bins=int(self.min_bins))
            if fit is not None:
                out[w].update(angle=fit.angle_deg, fit=fit)
                ctx.diag[w]["fit"] = fit_to_dict(fit)
        return out

