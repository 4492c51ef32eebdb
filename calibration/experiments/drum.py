"""B. Rotating drum: dynamic angle of repose beta_AoR_D
(docs/experiments.md, section B; seed paper Sec. 2.1.2, Table 1)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np

import warpdem as wd
from warpdem import ConfigError
import trimesh
from scipy.spatial import Delaunay

from ..filling import HorizontalCylinder
from ..materials import BulkMaterial
from ..measurement import drum_dynamic_angle, revolution_snapshot_times
from .baffle import QUICK_MATERIAL
from .common import Experiment, ExperimentResult, RunContext, fit_to_dict, normalize_parameter_sets
from .lab_effort import LabEffort, LabSetting

__all__ = ["RotatingDrum", "drum_mesh"]


def drum_mesh(radius: float, length: float, sections: int = 72) -> trimesh.Trimesh:
    """Closed drum [m]: axis along y through x = z = 0, end walls at y = 0 and y = length.

    The shell has ``sections`` facets around. The end walls are Delaunay triangulations of
    concentric rings (about 6 triangles per vertex) rather than fans: at a fan's centre
    ``sections`` triangles meet, and a sphere touching it there collects more wall
    candidates than the engine's contact slots hold (a false ContactOverflowError).
    """
    n_r = max(1, int(round(sections / (2.0 * math.pi))))
    pts = [np.zeros((1, 2))]
    for k in range(1, n_r + 1):
        m = int(sections) if k == n_r else max(6, int(round(sections * k / n_r)))
        a = 2.0 * math.pi * (np.arange(m) + (0.0 if k == n_r else 0.5 * (k % 2))) / m
        pts.append(radius * k / n_r * np.stack([np.cos(a), np.sin(a)], 1))
    p2 = np.concatenate(pts)
    tri = Delaunay(p2).simplices
    nc = len(p2)
    rim = np.arange(nc - int(sections), nc)  # outer ring, angles 2 pi j / sections
    verts = np.concatenate([np.stack([p2[:, 0], np.zeros(nc), p2[:, 1]], 1),
                            np.stack([p2[:, 0], np.full(nc, length), p2[:, 1]], 1)])
    j = np.arange(int(sections))
    a0, a1 = rim[j], rim[(j + 1) % int(sections)]
    b0, b1 = a0 + nc, a1 + nc
    shell = np.concatenate([np.stack([a0, a1, b1], 1), np.stack([a0, b1, b0], 1)])
    faces = np.concatenate([tri, tri + nc, shell])
    return trimesh.Trimesh(verts, faces, process=False)


@dataclass
class RotatingDrum(Experiment):
    """Rotating drum (spec B), SI units.

    Drum of inner ``diameter`` and ``length`` [m], axis along y through x = z = 0, end walls
    at y = 0 and y = length (``sections`` facets around). Filled with ``fill_fraction`` of
    its volume as bulk material of solids fraction ``solids_fraction`` (None: the material's,
    0.60 by default), settled at rest, then rotated about +y at ``rpm``; ``discard``
    revolutions are skipped and ``record`` measured (paper: 5 and 10 of 15; the spec's short
    protocol: 2 and 4). Snapshots at the start, middle and end of each recorded revolution
    (``frames_per_revolution`` = 3; more frames are spaced evenly, start and end included);
    crop square ``crop_side`` [m] on the axis, particles with y in ``measure_y``, bins of
    ``bin_width`` [m].
    Several speeds in one run: a parameter set may hold ``rpm`` (that world's speed; the
    drum wall is then one per world instead of one shared by all).
    ``max_skipped_snapshots``: how many snapshots with fewer than ``min_bins`` bins may be left
    out of the mean (listed in the diagnostics as ``skipped_snapshots``); 0 (paper) makes any
    such snapshot an error.
    Scale "quick": spheres d = 24-30 mm, discard 1 and record 2 revolutions, 20 mm bins, 9 frames
    per revolution (every 1/8 revolution: with ~240 particles a single frame scatters by 3-4 deg),
    up to 2 of the 18 frames may be left out (a steep frame of 24-30 mm spheres can leave only 2 of
    the crop's 7 bins below its top edge; this failed 1 of 56 quick drum runs before).
    """

    name: ClassVar[str] = "drum"
    angle_name: ClassVar[str] = "beta_AoR_D"
    OBSERVABLES: ClassVar[dict[str, str]] = {"dynamic_angle": "deg"}
    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {
        "paper": {},
        "short": {"discard": 2, "record": 4},
        "quick": {"material": QUICK_MATERIAL, "discard": 1, "record": 2, "bin_width": 0.020,
                  "frames_per_revolution": 9, "max_skipped_snapshots": 2},
    }
    #: lab hours per repeat and settings a lab can change (calibration.experiments.lab_effort)
    LAB_EFFORT: ClassVar[LabEffort] = LabEffort(
        0.5, 8.0, "a repeat: fill, settle, 15 revolutions filmed, empty; set-up: a drum with a clear end wall and a motor")
    LAB_SETTINGS: ClassVar[tuple[LabSetting, ...]] = (
        LabSetting("rpm", "drum speed", "rpm", (2.0, 1 / 3), 0.0, 0.1,
                   "a speed change on a filled drum costs minutes; cohesion and shape act unequally on slow and fast flow"),
        LabSetting("fill_fraction", "fill fraction", "-", (0.625, 1.5), 0.1, 0.5,
                   "weigh another fill; a shallower bed flows over fewer particle layers"),
        LabSetting("diameter", "drum diameter", "m", (1.5, 0.75), 8.0, 0.5,
                   "a new drum is a day's work; it changes the bed depth against the particle size"),
    )

    diameter: float = 0.300
    length: float = 0.150
    sections: int = 72
    fill_fraction: float = 0.40
    solids_fraction: float | None = None
    rpm: float = 30.0
    discard: int = 5
    record: int = 10
    frames_per_revolution: int = 3
    crop_side: float = 0.150
    measure_y: tuple[float, float] = (0.030, 0.120)
    bin_width: float = 0.010
    min_bins: int = 3
    max_skipped_snapshots: int = 0

    def validate(self) -> None:
        self._check_positive("diameter", "length", "fill_fraction", "rpm", "crop_side", "bin_width")
        self._check_nonnegative("max_skipped_snapshots")
        if not self.fill_fraction < 1.0:
            raise ConfigError(f"drum: fill_fraction must be < 1, got {self.fill_fraction}")
        if self.solids_fraction is not None and not 0 < self.solids_fraction < 1:
            raise ConfigError(f"drum: solids_fraction must lie in (0, 1), got {self.solids_fraction}")
        if int(self.frames_per_revolution) < 2:
            raise ConfigError(f"drum: frames_per_revolution must be >= 2 (start and end), got {self.frames_per_revolution}")
        if int(self.discard) < 0 or int(self.record) < 1:
            raise ConfigError(f"drum: need discard >= 0 and record >= 1, got {self.discard}, {self.record}")
        if int(self.sections) < 8:
            raise ConfigError(f"drum: sections must be >= 8, got {self.sections}")
        if self.crop_side > self.diameter:
            raise ConfigError(f"drum: crop_side {self.crop_side} m exceeds the diameter {self.diameter} m")
        self._check_range("measure_y", (0.0, self.length))

    # ------------------------------------------------------------------ set-up (spec B)
    def fill_region(self) -> HorizontalCylinder:
        return HorizontalCylinder((0.0, 0.0), 0.5 * self.diameter, 0.0, self.length)

    def fill_amount(self, material: BulkMaterial) -> dict[str, float]:
        """40 % of the drum volume as bulk material at solids fraction 0.60 (spec B "Fill")."""
        phi = self.solids_fraction if self.solids_fraction is not None else material.solids_fraction
        volume = math.pi * (0.5 * self.diameter) ** 2 * self.length
        return {"mass": self.fill_fraction * volume * phi * material.particle.density}

    def _run(self, parameter_sets: Sequence[Mapping[str, float]] | Mapping[str, Any], device: str | None,
             progress: bool, checkpoints=None) -> list[ExperimentResult]:
        """As :meth:`Experiment.run`; a parameter set may also give the world's ``rpm``."""
        sets = normalize_parameter_sets(parameter_sets, [*self.parameter_names, "rpm"])
        rpms = [float(s.pop("rpm", self.rpm)) for s in sets]
        for w, v in enumerate(rpms):
            if not v > 0:
                raise ConfigError(f"drum: parameter set {w}: rpm must be > 0, got {v}")
        self._world_rpm = rpms
        try:
            results = super()._run(sets, device, progress, checkpoints)
        finally:
            self._world_rpm = None
        given = normalize_parameter_sets(parameter_sets, [*self.parameter_names, "rpm"])
        for r, g in zip(results, given):
            if "rpm" in g:
                r.parameters["rpm"] = g["rpm"]
        return results

    def checkpoint_identity(self) -> dict[str, Any]:
        """The per-world drum speeds [rpm] (given in the parameter sets) are part of a batch."""
        return {"world_rpm": self.world_rpm(0) if getattr(self, "_world_rpm", None) is not None else None}

    def world_rpm(self, num_worlds: int) -> list[float]:
        rpms = getattr(self, "_world_rpm", None)
        return list(rpms) if rpms is not None else [float(self.rpm)] * num_worlds

    def add_walls(self, builder: wd.ModelBuilder, fill_top: float, t_motion: float, material: BulkMaterial) -> None:
        drum = drum_mesh(0.5 * self.diameter, self.length, int(self.sections))
        rpms = self.world_rpm(builder.num_worlds)
        shared = len(set(rpms)) == 1
        for w, rpm in enumerate(rpms[:1] if shared else rpms):
            spin = wd.WallMotion.rotation((0.0, 1.0, 0.0), rpm, origin=(0.0, 0.0, 0.0), start=t_motion)
            builder.add_wall(drum, self.wall_material.name, world=-1 if shared else w, motion=spin,
                             name="drum" if shared else f"drum world {w}")

    def fill_walls(self, builder: wd.ModelBuilder) -> None:
        builder.add_wall(drum_mesh(0.5 * self.diameter, self.length, int(self.sections)), self.wall_material,
                         name="drum (fill)")

    def remove_box(self) -> tuple:
        m = 0.05 + 0.5 * self.diameter  # anything outside the drum has leaked through a wall
        return (-m, -0.05, -m), (m, self.length + 0.05, m)

    # ------------------------------------------------------------------ protocol (spec B)
    def protocol(self, ctx: RunContext, t_motion: float) -> list[dict[str, Any]]:
        nw = ctx.num_worlds
        box = self.remove_box()
        # Fill: settled at rest (spec B "Fill")
        t_min, t_max = self.fill_settle_times_per_world(ctx.fills, ctx.num_worlds)
        ctx.settle("fill_settle", t_max, t_min, box)
        # rotate; snapshots at start/middle/end of each recorded revolution (spec B "Protocol", "Measurement")
        ctx.jump_clock(t_motion)
        rpms = self.world_rpm(nw)
        times = [np.round(revolution_snapshot_times(rpm, int(self.discard), int(self.record), t0=t_motion,
                                                    frames=int(self.frames_per_revolution)).ravel(), 9)
                 for rpm in rpms]
        snaps: dict[tuple[float, int], tuple[np.ndarray, np.ndarray]] = {}
        last = np.array([tw.max() for tw in times])

        def snapshot(t: float) -> list:
            """Sphere centres and radii [m] of the worlds that take a frame at ``t`` (else None)."""
            x_all = ctx.sim.sphere_positions()
            return [ctx.world_spheres(w, x_all) if t in times[w] else None for w in range(nw)]

        for t in np.unique(np.concatenate(times)):
            ctx.advance("rotation", t - ctx.sim.time, box)
            # the frames are part of a checkpoint: a resumed batch gets them back, not re-taken
            for w, frame in enumerate(ctx.once("snapshot", lambda: snapshot(t))):
                if frame is not None:
                    snaps[(float(t), w)] = tuple(frame)
            # a faster drum has its last frame sooner: hold its world at rest (no contact work)
            # while the slower ones turn on (a resumed batch pauses them again: same flags)
            done = last <= t
            if done.any() and not done.all():
                ctx.sim.pause_worlds(done)
        ctx.sim.resume_worlds()
        out: list[dict[str, Any]] = [dict() for _ in range(nw)]
        removed = ctx.removed_per_world()
        for w in range(nw):
            ctx.diag[w].update(removed_total=int(removed[w]), rpm=rpms[w])
            series = [snaps[(float(t), w)] for t in times[w]]
            out[w]["particles"] = tuple(a.astype(np.float32) for a in series[-1])
            res = ctx.measure(w, "beta_AoR_D", drum_dynamic_angle, series, axis_xz=(0.0, 0.0),
                              crop_side=self.crop_side, y_range=self.measure_y, bin_width=self.bin_width,
                              min_bins=int(self.min_bins), max_skipped=int(self.max_skipped_snapshots))
            if res is None:
                continue
            out[w].update(angle=res.angle_deg, fit=res)
            ctx.diag[w].update(
                mean_slope=res.mean_slope, snapshot_slopes=res.slopes, snapshot_angles_deg=res.angles_deg,
                snapshot_mean_deg=res.mean_deg, snapshot_std_deg=res.std_deg, snapshots=len(series),
                snapshot_times_s=times[w] - t_motion, revolutions_discarded=int(self.discard),
                revolutions_recorded=int(self.record),
                skipped_snapshots=[dict(index=i, reason=why) for i, why in res.skipped],
                n_bins=[f.n_bins for f in res.fits], residual_rms_m=[f.residual_rms for f in res.fits],
                last_fit=fit_to_dict(res.fits[-1]))
        return out
