"""Measurement files: repeated lab (or simulated) measurements with their protocol settings.

Two formats (YAML, or JSON with a ``.json`` extension), documented in
docs/measurement_format.md:

``warpdem-measurements/1`` (example: calibration/data/zhang2023_table1.yaml, seed paper Tables
1 and 10): per experiment and condition the repeats of one angle (``angles_deg``), of fitted
slopes (``slopes``; angle = atan(|slope|)), or images / a video to be measured with
:mod:`.images`. A repeat may be a list of views (theta_1..4 of the hollow cylinder, Table 10),
whose mean is the repeat's value.

``warpdem-measurements/2`` (example: calibration/data/example_v2.yaml): per registered experiment
(baffle, drum, cylinder) and condition the protocol ``settings`` the simulation must reproduce
(experiment field names, SI units: drum ``rpm``, ``lift_speed`` [m/s], ``fill_mass`` [kg], ...)
and several ``observables``, each a quantity with a unit and its repeats (angles in deg, bulk
density in kg/m^3, pile height in m, any other scalar with its unit), or a censored result
("no pile formed": ``no_pile: n``; ``below_detection: {n, limit}``). Angles may be given as
slopes, images or a video as in version 1. The material that was measured is stated once.

Loading validates everything and raises :class:`.errors.MeasurementFileError` naming the file
and the dotted key. :meth:`ConditionRecord.stats` gives the mean, sample standard deviation
(ddof=1) and standard error of a condition's angle; :meth:`MeasurementFile.observations` gives
one plain :class:`ObservationRecord` per experiment, condition and quantity for either version;
:func:`check_settings` checks experiment and setting names against the experiments a simulation can
run (given as a mapping, e.g. ``calibration.experiments.EXPERIMENTS``: this module sits below the
experiments, which measure with this package);
:func:`write_measurements_v2` writes records to a version-2 file that loads back identically.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
import yaml

from .errors import MeasurementError, MeasurementFileError
from .profiles import slope_to_angle_deg

__all__ = [
    "FORMAT",
    "FORMAT_V1",
    "FORMAT_V2",
    "KINDS",
    "QUANTITY_UNITS",
    "UNIT_CONVERSIONS",
    "NO_PILE_LIMIT_DEG",
    "SIMULATION_SETTINGS",
    "AngleStats",
    "ConditionRecord",
    "ExperimentRecord",
    "MeasurementFile",
    "ObservableRecord",
    "ObservationRecord",
    "load_measurements",
    "parse_measurements",
    "check_settings",
    "protocol_settings",
    "unreported_observables",
    "measurements_v2_mapping",
    "write_measurements_v2",
]

#: version 1 (one angle per experiment and condition); ``FORMAT`` kept for existing callers
FORMAT = FORMAT_V1 = "warpdem-measurements/1"
#: version 2 (several observables per condition, protocol settings, censored results)
FORMAT_V2 = "warpdem-measurements/2"

#: experiment kinds (spec sections A, B, C) and their default averaging rule:
#: "angle" = mean of per-repeat angles (Table 1 static, Table 10),
#: "slope" = atan(|mean slope|) (spec B / Table 1 dynamic).
KINDS: dict[str, str] = {
    "baffle_static": "angle",
    "drum_dynamic": "slope",
    "hollow_cylinder": "angle",
    "other": "angle",
}

_TOP_KEYS = {"format", "title", "source", "notes", "experiments"}
_EXP_KEYS = {"kind", "description", "conditions"}
_DATA_KEYS = ("angles_deg", "slopes", "images", "video")
_COND_KEYS = {"description", "origin", "parameters", "average", "reported", "image_settings", *_DATA_KEYS}
_ORIGINS = ("lab", "simulation")
#: image settings -> :func:`.images.measure_image` keyword (window_* handled apart)
_IMG_NUM = {
    "scale_px_per_mm": "scale_px_per_mm",
    "threshold": "threshold",
    "h_ref": "h_ref",
    "min_angle_deg": "min_angle_deg",
    "blur_sigma_px": "blur_sigma_px",
    "min_area_frac": "min_area_frac",
    "min_separability": "min_separability",
    "min_contrast": "min_contrast",
}
_IMG_INT = {"open_px": "open_px", "close_px": "close_px", "illumination_degree": "illumination_degree",
            "min_points": "min_points"}
_IMG_KEYS = {*_IMG_NUM, *_IMG_INT, "window_mm", "window_px", "origin_px", "fit_band", "material"}
_VIDEO_KEYS = {"path", "fps", "rpm", "discard", "record", "t0_s"}

# ---- version 2
#: registered experiment -> the v1 kind of its angle (averaging rule of slopes / images / video)
EXPERIMENT_KINDS: dict[str, str] = {"baffle": "baffle_static", "drum": "drum_dynamic", "cylinder": "hollow_cylinder"}
#: registered experiment -> its angle quantity (what ``ConditionRecord.stats`` of a v2 condition measures)
ANGLE_QUANTITIES: dict[str, str] = {"baffle": "static_angle", "drum": "dynamic_angle", "cylinder": "pile_angle"}
#: v1 kind -> (experiment, quantity) of its observations; kind "other" -> (v1 experiment name, "angle")
V1_OBSERVABLES: dict[str, tuple[str, str]] = {
    "baffle_static": ("baffle", "static_angle"),
    "drum_dynamic": ("drum", "dynamic_angle"),
    "hollow_cylinder": ("cylinder", "pile_angle"),
}
#: known quantity -> the unit the simulation reports it in (values are stored in this unit);
#: a quantity not listed accepts any unit string and is kept as written
QUANTITY_UNITS: dict[str, str] = {
    "static_angle": "deg",       # A, alpha_AoR_S
    "dynamic_angle": "deg",      # B, beta_AoR_D
    "pile_angle": "deg",         # C, gamma_s
    "angle": "deg",              # v1 kind "other"
    "bulk_density": "kg/m^3",    # A, bulk density of the fill
    "pile_height": "m",          # C, peak height of the pile
    "pile_formed": "1/0",        # C, 1 if a pile formed, else 0
    "mass_left_in_box": "kg",    # A, mass left in the box after the lift
}
#: stored unit -> {accepted unit as written: factor to the stored unit}
UNIT_CONVERSIONS: dict[str, dict[str, float]] = {
    "deg": {"deg": 1.0},
    "kg/m^3": {"kg/m^3": 1.0, "kg/m3": 1.0, "g/cm^3": 1000.0, "g/cm3": 1000.0},
    "m": {"m": 1.0, "cm": 0.01, "mm": 0.001},
    "kg": {"kg": 1.0, "g": 0.001},
    "1/0": {"1/0": 1.0},
}
#: valid values per stored unit (checked on the values as written; every bound is 0 or an angle)
_UNIT_RANGES: dict[str, dict[str, Any]] = {
    "deg": dict(lo=0.0, hi=90.0, hi_open=True),
    "kg/m^3": dict(lo=0.0, lo_open=True),
    "m": dict(lo=0.0),
    "kg": dict(lo=0.0),
}
#: quantities that take ``no_pile: n`` (hollow cylinder C: the material spread, no angle to read)
NO_PILE_QUANTITIES: tuple[str, ...] = ("pile_angle",)
#: detection limit [deg] of ``no_pile``: the smallest pile angle a profile resolves
NO_PILE_LIMIT_DEG = 3.0
#: base-experiment fields that are no condition setting: the model and the numerics (never a lab
#: protocol) and ``material`` (stated once, at the top of a v2 file)
SIMULATION_SETTINGS = frozenset({
    "scale", "material", "contact_law", "plugins", "contact_defaults", "dt", "dt_rayleigh_fraction", "v_ref",
    "force_dt", "max_contacts", "max_neighbours", "overflow_retries", "seed", "fill_per_world", "first_fill_index",
    "ke_per_particle", "fill_settle_max_time", "settle_check_interval", "removal_interval", "sections",
    "max_skipped_snapshots",
})
_ORIGIN_DEFAULT = "lab"
_V2_TOP_KEYS = {"format", "title", "source", "notes", "material", "experiments"}
_V2_EXP_KEYS = {"description", "conditions"}
_V2_COND_KEYS = {"description", "origin", "settings", "observables"}
_V2_DATA_KEYS = ("repeats", "slopes", "images", "video")
_V2_CENSOR_KEYS = ("no_pile", "below_detection")
_V2_OBS_KEYS = {"unit", "resolution", "label", "description", "image_settings", "average",
                *_V2_DATA_KEYS, *_V2_CENSOR_KEYS}
_ANGLE_ONLY_KEYS = ("slopes", "images", "video", "image_settings", "average")
#: experiment and quantity names: identifiers; condition names: no "/" and no white space
_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_COND_NAME = re.compile(r"^[^/\s]+$")


# --------------------------------------------------------------------------- #
# results
# --------------------------------------------------------------------------- #
@dataclass(frozen=True)
class AngleStats:
    """Statistics over the repeats of one condition (degrees).

    mean_deg: mean of ``values_deg`` (average "angle") or atan(|mean slope|)
    (average "slope"). std_deg: sample std (ddof=1) of ``values_deg``, NaN for
    one repeat. sem_deg: std_deg / sqrt(n). values_deg: per-repeat angles.
    mean_slope: mean of per-repeat slopes (None without slopes).
    views_deg: per-repeat lists of view angles (None without views).
    """

    n: int
    mean_deg: float
    std_deg: float
    sem_deg: float
    values_deg: np.ndarray
    average: str
    mean_slope: float | None = None
    views_deg: list[list[float]] | None = None

    def as_dict(self) -> dict:
        d = {
            "n": self.n, "mean_deg": self.mean_deg,
            "std_deg": None if math.isnan(self.std_deg) else self.std_deg,
            "sem_deg": None if math.isnan(self.sem_deg) else self.sem_deg,
            "values_deg": [float(v) for v in self.values_deg], "average": self.average,
        }
        if self.mean_slope is not None:
            d["mean_slope"] = self.mean_slope
        if self.views_deg is not None:
            d["views_deg"] = self.views_deg
        return d


def _stats(values_deg: np.ndarray, average: str, slopes: np.ndarray | None,
           views: list[list[float]] | None) -> AngleStats:
    n = int(values_deg.size)
    if average == "slope":
        if slopes is None:
            raise MeasurementError("average 'slope' needs slopes")
        mean = slope_to_angle_deg(float(np.mean(slopes)))
    else:
        mean = float(np.mean(values_deg))
    std = float(np.std(values_deg, ddof=1)) if n > 1 else float("nan")
    sem = std / math.sqrt(n) if n > 1 else float("nan")
    return AngleStats(n, float(mean), std, sem, values_deg, average,
                      None if slopes is None else float(np.mean(slopes)), views)


@dataclass
class ConditionRecord:
    """One condition of one experiment (see docs/measurement_format.md).

    data: "angles_deg", "slopes", "images" or "video". repeats: per-repeat
    number or list of view numbers (angles in degrees, or slopes).
    images: list of (path, measure_image kwargs). video: dict or None.

    Version 2: the fields above describe the condition's angle (the experiment's angle quantity,
    e.g. ``dynamic_angle`` of the drum, or its only quantity in deg), so that :meth:`stats`
    works as for version 1; data is "censored" when that angle fell below detection in every
    repeat ("no pile formed") and "none" without an angle. ``settings``: the protocol settings
    (experiment field names, SI units). ``observables``: every quantity by name.
    """

    experiment: str
    name: str
    kind: str
    data: str
    average: str
    origin: str = "lab"
    description: str = ""
    parameters: dict[str, Any] = field(default_factory=dict)
    reported: dict[str, Any] = field(default_factory=dict)
    repeats: list[Any] = field(default_factory=list)
    images: list[tuple[str, dict]] = field(default_factory=list)
    video: dict[str, Any] | None = None
    video_settings: dict[str, Any] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    observables: dict[str, "ObservableRecord"] = field(default_factory=dict)
    _cache: AngleStats | None = field(default=None, repr=False)

    def stats(self, *, diagnostic_dir: str | os.PathLike | None = None) -> AngleStats:
        """Mean, sample std (ddof=1) and standard error over repeats.

        Image/video conditions are measured with :mod:`.images` (cached; a
        diagnostic picture per image is written to ``diagnostic_dir`` if given).
        """
        if self._cache is not None and diagnostic_dir is None:
            return self._cache
        if self.data == "censored":
            obs = self.observables.get(ANGLE_QUANTITIES.get(self.experiment, ""))
            n = obs.n_censored if obs is not None else 0
            raise MeasurementError(f"{self.experiment}/{self.name}: no angle: below the detection limit in all "
                                   f"{n} repeats (e.g. no pile formed)")
        if self.data == "none":
            raise MeasurementError(f"{self.experiment}/{self.name}: no angle measured here; its observables are "
                                   f"{', '.join(self.observables)}")
        if self.data in ("angles_deg", "slopes"):
            views = [list(map(float, r)) if isinstance(r, list) else None for r in self.repeats]
            has_views = any(v is not None for v in views)
            per = np.array([np.mean(r) if isinstance(r, list) else r for r in self.repeats], float)
            if self.data == "slopes":
                # a repeat's angle: from its slope, or the mean of its views' angles
                values = np.array([np.mean(slope_to_angle_deg(np.array(r, float))) if isinstance(r, list)
                                   else slope_to_angle_deg(r) for r in self.repeats], float)
                vdeg = [list(map(float, slope_to_angle_deg(np.array(v)))) if v else [float(a)]
                        for v, a in zip(views, values)] if has_views else None
                st = _stats(values, self.average, per, vdeg)
            else:
                vdeg = [v if v else [float(a)] for v, a in zip(views, per)] if has_views else None
                st = _stats(per, self.average, None, vdeg)
        elif self.data == "images":
            from .images import measure_image

            slopes, values = [], []
            for k, (path, kw) in enumerate(self.images):
                diag = None
                if diagnostic_dir is not None:
                    stem = os.path.splitext(os.path.basename(path))[0]
                    diag = os.path.join(os.fspath(diagnostic_dir), f"{self.experiment}_{self.name}_{k}_{stem}.png")
                try:
                    m = measure_image(path, diagnostic_path=diag, **kw)
                except MeasurementError as e:
                    raise MeasurementError(f"{self.experiment}/{self.name}: {path}: {e}") from e
                slopes.append(m.slope)
                values.append(m.angle_deg)
            st = _stats(np.array(values), self.average, np.array(slopes), None)
        else:  # video
            from .images import video_frames_for_revolutions

            v = self.video or {}
            res = video_frames_for_revolutions(
                v["path"], v.get("fps"), v["rpm"], v["discard"], v["record"], t0=v.get("t0_s", 0.0),
                diagnostic_dir=diagnostic_dir, **self.video_settings,
            )
            st = _stats(np.array([f.angle_deg for f in res.frames]), self.average,
                        np.array([f.slope for f in res.frames]), None)
        self._cache = st
        return st


@dataclass
class ObservableRecord:
    """One observable of a version-2 condition, as written in the file (values in ``unit``).

    quantity: e.g. "dynamic_angle". unit: the stored unit (for a known quantity the one the
    simulation reports, :data:`QUANTITY_UNITS`; values written in another accepted unit, e.g.
    mm, are converted). data: "repeats", "slopes", "images", "video" or "censored" (only
    below-detection repeats). repeats: per-repeat number or list of view numbers (data
    "repeats" of a non-angle quantity; angles keep theirs in ``angle``). n_censored: repeats
    below ``censor_limit`` (``no_pile`` / ``below_detection``). resolution: reading resolution
    in ``unit`` (0: not given). angle: for an angle quantity with data, the v1-style record that
    measures it (images / video) and gives :class:`AngleStats`.
    """

    experiment: str
    condition: str
    quantity: str
    unit: str
    data: str
    repeats: list[Any] = field(default_factory=list)
    n_censored: int = 0
    censor_limit: float | None = None
    resolution: float = 0.0
    label: str = ""
    description: str = ""
    angle: ConditionRecord | None = field(default=None, repr=False, compare=False)

    @property
    def key(self) -> str:
        """``"experiment/condition/quantity"``."""
        return f"{self.experiment}/{self.condition}/{self.quantity}"

    @property
    def is_angle(self) -> bool:
        return self.unit == "deg"

    def values(self, *, diagnostic_dir: str | os.PathLike | None = None) -> tuple[float, ...]:
        """One value per measured repeat in ``unit`` (images / a video are measured; a repeat
        with views gives their mean); empty when every repeat is censored."""
        if self.data == "censored":
            return ()
        if self.angle is not None:
            return tuple(float(v) for v in self.angle.stats(diagnostic_dir=diagnostic_dir).values_deg)
        return tuple(float(np.mean(r)) if isinstance(r, list) else float(r) for r in self.repeats)

    def summary(self, *, measure_images: bool = False) -> dict:
        """JSON-ready: unit, data, n, mean, std (ddof 1), sem, values, censored count and limit."""
        out: dict[str, Any] = {"unit": self.unit, "data": self.data}
        if self.data in ("images", "video") and not measure_images:
            out["measured"] = False
        else:
            vals = np.array(self.values(), float)
            n = int(vals.size)
            std = float(np.std(vals, ddof=1)) if n > 1 else None
            out.update(n=n, mean=float(vals.mean()) if n else None, std=std,
                       sem=None if std is None else std / math.sqrt(n), values=[float(v) for v in vals])
        if self.n_censored:
            out.update(n_censored=self.n_censored, censor_limit=self.censor_limit)
        if self.resolution:
            out["resolution"] = self.resolution
        if self.label:
            out["label"] = self.label
        return out


@dataclass(frozen=True)
class ObservationRecord:
    """One measured scalar of one experiment and condition, as plain numbers (either version).

    experiment: e.g. "drum". condition: the condition's name, e.g. "15rpm". quantity: e.g.
    "dynamic_angle". unit: e.g. "deg", "kg/m^3", "m". repeats: one value per repeat that gave
    a value, in ``unit``. settings: the protocol settings the simulation must reproduce
    (experiment field names, SI units; version 1: the condition's free ``parameters``).
    n_censored: repeats below ``censor_limit`` [unit] ("no pile formed"). resolution: reading
    resolution [unit] (0: not given). label, description: plain words. origin: "lab" or
    "simulation". ``key`` is ``"experiment/condition/quantity"``.
    """

    experiment: str
    condition: str
    quantity: str
    unit: str
    repeats: tuple[float, ...] = ()
    settings: Mapping[str, Any] = field(default_factory=dict)
    n_censored: int = 0
    censor_limit: float | None = None
    resolution: float = 0.0
    label: str = ""
    description: str = ""
    origin: str = _ORIGIN_DEFAULT

    def __post_init__(self) -> None:
        object.__setattr__(self, "repeats", tuple(float(v) for v in self.repeats))
        object.__setattr__(self, "settings", {k: list(v) if isinstance(v, (list, tuple)) else v
                                              for k, v in dict(self.settings).items()})
        object.__setattr__(self, "n_censored", int(self.n_censored))
        object.__setattr__(self, "resolution", float(self.resolution))
        if self.censor_limit is not None:
            object.__setattr__(self, "censor_limit", float(self.censor_limit))

    @property
    def key(self) -> str:
        """``"experiment/condition/quantity"``, e.g. ``"drum/15rpm/dynamic_angle"``."""
        return f"{self.experiment}/{self.condition}/{self.quantity}"

    @property
    def n(self) -> int:
        """Number of repeats, censored ones included."""
        return len(self.repeats) + self.n_censored

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields, ``key`` included."""
        return {"key": self.key, "experiment": self.experiment, "condition": self.condition,
                "quantity": self.quantity, "unit": self.unit, "repeats": list(self.repeats),
                "settings": dict(self.settings), "n_censored": self.n_censored,
                "censor_limit": self.censor_limit, "resolution": self.resolution, "label": self.label,
                "description": self.description, "origin": self.origin}


@dataclass
class ExperimentRecord:
    """An experiment: its kind (spec A/B/C) and its conditions by name."""

    name: str
    kind: str
    description: str
    conditions: dict[str, ConditionRecord]


@dataclass
class MeasurementFile:
    """A loaded measurement file.

    version: 1 or 2 (the ``format``; a file without one is version 1). material: version 2's
    description of the material that was measured (a mapping such as ``{type: spheres,
    diameter: [0.016, 0.020], density: 2661}``, SI units; empty when not given).
    """

    path: str
    title: str
    source: str
    notes: str
    experiments: dict[str, ExperimentRecord]
    version: int = 1
    material: dict[str, Any] = field(default_factory=dict)

    def observations(self, *, diagnostic_dir: str | os.PathLike | None = None) -> list[ObservationRecord]:
        """One record per experiment, condition and quantity, in file order (images and videos
        are measured; ``diagnostic_dir`` receives their diagnostic pictures).

        Version 1: kind baffle_static -> experiment "baffle", quantity "static_angle";
        drum_dynamic -> "drum", "dynamic_angle"; hollow_cylinder -> "cylinder", "pile_angle";
        other -> the file's experiment name, "angle". The repeats are the per-repeat angles
        (for slopes: atan(|slope|) of each); settings are the condition's ``parameters``. Where two
        v1 experiments map to the same name, the condition is called "<v1 experiment>.<condition>".
        """
        out: list[ObservationRecord] = []
        if self.version == 1:
            seen: set[str] = set()
            for en, exp in self.experiments.items():
                experiment, quantity = V1_OBSERVABLES.get(exp.kind, (en, "angle"))
                for cn, c in exp.conditions.items():
                    condition = cn if f"{experiment}/{cn}/{quantity}" not in seen else f"{en}.{cn}"
                    values = c.stats(diagnostic_dir=diagnostic_dir).values_deg
                    rec = ObservationRecord(experiment, condition, quantity, "deg", tuple(values),
                                            dict(c.parameters), description=c.description, origin=c.origin)
                    seen.add(rec.key)
                    out.append(rec)
            return out
        for exp in self.experiments.values():
            for c in exp.conditions.values():
                for o in c.observables.values():
                    out.append(ObservationRecord(
                        o.experiment, o.condition, o.quantity, o.unit, o.values(diagnostic_dir=diagnostic_dir),
                        dict(c.settings), o.n_censored, o.censor_limit, o.resolution, o.label, o.description,
                        c.origin))
        return out

    def condition(self, experiment: str, condition: str | None = None) -> ConditionRecord:
        """The named condition (or the only one) of an experiment."""
        if experiment not in self.experiments:
            raise MeasurementError(f"{self.path}: no experiment {experiment!r} (has {sorted(self.experiments)})")
        conds = self.experiments[experiment].conditions
        if condition is None:
            if len(conds) != 1:
                raise MeasurementError(f"{self.path}: experiment {experiment!r} has conditions "
                                       f"{sorted(conds)}; name one")
            return next(iter(conds.values()))
        if condition not in conds:
            raise MeasurementError(f"{self.path}: experiment {experiment!r} has no condition "
                                   f"{condition!r} (has {sorted(conds)})")
        return conds[condition]

    def summary(self, *, measure_images: bool = False) -> dict:
        """JSON-ready statistics of every condition (image/video conditions
        only when ``measure_images``); version 2: settings and every observable's statistics."""
        out: dict = {}
        if self.version == 2:
            for en, exp in self.experiments.items():
                out[en] = {"conditions": {}}
                for cn, c in exp.conditions.items():
                    out[en]["conditions"][cn] = {
                        "origin": c.origin, "settings": c.settings,
                        "observables": {q: o.summary(measure_images=measure_images)
                                        for q, o in c.observables.items()},
                    }
            return out
        for en, exp in self.experiments.items():
            out[en] = {"kind": exp.kind, "conditions": {}}
            for cn, c in exp.conditions.items():
                if c.data in ("images", "video") and not measure_images:
                    entry = {"data": c.data, "measured": False}
                else:
                    entry = {"data": c.data, **c.stats().as_dict()}
                entry.update(origin=c.origin, parameters=c.parameters, reported=c.reported)
                out[en]["conditions"][cn] = entry
        return out


# --------------------------------------------------------------------------- #
# parsing and validation
# --------------------------------------------------------------------------- #
class _V:
    """Validation helpers that know the file name."""

    def __init__(self, file: str, base_dir: str) -> None:
        self.file = file
        self.base_dir = base_dir

    def err(self, key: str, msg: str) -> MeasurementFileError:
        return MeasurementFileError(self.file, key, msg)

    def mapping(self, v: Any, key: str) -> dict:
        if not isinstance(v, dict):
            raise self.err(key, f"expected a mapping, got {type(v).__name__}")
        for k in v:
            if not isinstance(k, str):
                raise self.err(key, f"keys must be strings, got {k!r}")
        return v

    def keys(self, d: dict, allowed: set[str], key: str, required: tuple[str, ...] = ()) -> None:
        for k in d:
            if k not in allowed:
                raise self.err(f"{key}.{k}" if key else k,
                               f"unknown key {k!r} (allowed: {', '.join(sorted(allowed))})")
        for k in required:
            if k not in d:
                raise self.err(f"{key}.{k}" if key else k, "missing required field")

    def number(self, v: Any, key: str, *, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False, hi_open: bool = False) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.err(key, f"not a number: {v!r}")
        x = float(v)
        if not math.isfinite(x):
            raise self.err(key, f"not a finite number: {v!r}")
        if lo is not None and (x < lo or (lo_open and x == lo)):
            raise self.err(key, f"{x} is out of range (must be {'>' if lo_open else '>='} {lo})")
        if hi is not None and (x > hi or (hi_open and x == hi)):
            raise self.err(key, f"{x} is out of range (must be {'<' if hi_open else '<='} {hi})")
        return x

    def integer(self, v: Any, key: str, lo: int | None = None) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.err(key, f"not an integer: {v!r}")
        if lo is not None and v < lo:
            raise self.err(key, f"{v} is out of range (must be >= {lo})")
        return int(v)

    def string(self, v: Any, key: str, choices: tuple[str, ...] | None = None) -> str:
        if not isinstance(v, str):
            raise self.err(key, f"not a string: {v!r}")
        if choices is not None and v not in choices:
            raise self.err(key, f"{v!r} is not one of {', '.join(choices)}")
        return v

    def numbers(self, v: Any, key: str, n: int | None = None, **rng) -> list[float]:
        if not isinstance(v, list):
            raise self.err(key, f"expected a list of numbers, got {type(v).__name__}")
        if n is not None and len(v) != n:
            raise self.err(key, f"expected {n} numbers, got {len(v)}")
        if not v:
            raise self.err(key, "empty list")
        return [self.number(x, f"{key}[{i}]", **rng) for i, x in enumerate(v)]

    def path(self, v: Any, key: str) -> str:
        p = self.string(v, key)
        if not p:
            raise self.err(key, "empty path")
        return p if os.path.isabs(p) else os.path.normpath(os.path.join(self.base_dir, p))


def _image_settings(V: _V, d: Any, key: str) -> dict:
    d = V.mapping(d, key)
    V.keys(d, _IMG_KEYS, key)
    if "window_mm" in d and "window_px" in d:
        raise V.err(key, "give window_mm or window_px, not both")
    kw: dict[str, Any] = {}
    for k, v in d.items():
        kk = f"{key}.{k}"
        if k in _IMG_NUM:
            if k == "threshold" and v is None:
                continue
            rng = {"scale_px_per_mm": dict(lo=0, lo_open=True), "threshold": dict(lo=0, hi=255)}.get(k, {})
            kw[_IMG_NUM[k]] = V.number(v, kk, **rng)
        elif k in _IMG_INT:
            kw[_IMG_INT[k]] = V.integer(v, kk, lo=0)
        elif k in ("window_mm", "window_px"):
            w = V.numbers(v, kk, n=4)
            if not (w[1] > w[0] and w[3] > w[2]):
                raise V.err(kk, f"expected [min_h, max_h, min_v, max_v] with max > min, got {w}")
            kw["window"] = w
            kw["window_units"] = "mm" if k == "window_mm" else "px"
        elif k == "origin_px":
            kw["origin_px"] = tuple(V.numbers(v, kk, n=2))
        elif k == "fit_band":
            b = V.numbers(v, kk, n=2, lo=0.0)
            if not b[1] > b[0]:
                raise V.err(kk, f"expected [low, high] with high > low, got {b}")
            kw["fit_band"] = tuple(b)
        elif k == "material":
            kw["material"] = V.string(v, kk, ("auto", "dark", "bright"))
    if kw.get("window_units") == "mm" and "scale_px_per_mm" not in kw:
        raise V.err(f"{key}.window_mm", "window_mm needs scale_px_per_mm")
    return kw


def _images(V: _V, imgs: Any, settings: dict, key: str) -> list[tuple[str, dict]]:
    """A list of pictures (paths or {path, per-image settings}) -> [(path, measure_image kwargs)]."""
    if not isinstance(imgs, list):
        raise V.err(key, f"expected a list of images, got {type(imgs).__name__}")
    if not imgs:
        raise V.err(key, "empty repeats")
    out: list[tuple[str, dict]] = []
    for i, item in enumerate(imgs):
        ik = f"{key}[{i}]"
        if isinstance(item, str):
            out.append((V.path(item, ik), dict(settings)))
        else:
            item = V.mapping(item, ik)
            V.keys(item, _IMG_KEYS | {"path"}, ik, required=("path",))
            own = _image_settings(V, {k: v for k, v in item.items() if k != "path"}, ik) \
                if len(item) > 1 else {}
            kw = dict(settings)
            if "window" in own:
                kw.pop("window", None)
                kw.pop("window_units", None)
            kw.update(own)
            out.append((V.path(item["path"], f"{ik}.path"), kw))
    return out


def _video(V: _V, v: Any, key: str) -> dict[str, Any]:
    """A drum video entry {path, rpm, discard, record, fps?, t0_s?} (validated, path resolved)."""
    v = V.mapping(v, key)
    V.keys(v, _VIDEO_KEYS, key, required=("path", "rpm", "discard", "record"))
    return {
        "path": V.path(v["path"], f"{key}.path"),
        "fps": V.number(v["fps"], f"{key}.fps", lo=0, lo_open=True) if "fps" in v else None,
        "rpm": V.number(v["rpm"], f"{key}.rpm", lo=0, lo_open=True),
        "discard": V.integer(v["discard"], f"{key}.discard", lo=0),
        "record": V.integer(v["record"], f"{key}.record", lo=1),
        "t0_s": V.number(v.get("t0_s", 0.0), f"{key}.t0_s"),
    }


def _angle_data(V: _V, rec: ConditionRecord, d: dict, data: str, kk: str, settings: dict,
                rng: dict) -> None:
    """Fill ``rec`` from a condition's angle data (v1 and v2): repeats (a number or a list of
    views each, within ``rng``) or slopes, images, or a video."""
    if data in ("angles_deg", "repeats", "slopes"):
        reps = d[data]
        if not isinstance(reps, list):
            raise V.err(kk, f"expected a list of repeats, got {type(reps).__name__}")
        if not reps:
            raise V.err(kk, "empty repeats")
        for i, r in enumerate(reps):
            rec.repeats.append(V.numbers(r, f"{kk}[{i}]", **rng) if isinstance(r, list)
                               else V.number(r, f"{kk}[{i}]", **rng))
    elif data == "images":
        rec.images = _images(V, d["images"], settings, kk)
    else:  # video
        rec.video = _video(V, d["video"], kk)
        rec.video_settings = settings


def _condition(V: _V, exp: str, kind: str, name: str, d: Any, key: str) -> ConditionRecord:
    d = V.mapping(d, key)
    V.keys(d, _COND_KEYS, key)
    given = [k for k in _DATA_KEYS if k in d]
    if not given:
        raise V.err(key, f"missing field: one of {', '.join(_DATA_KEYS)}")
    if len(given) > 1:
        raise V.err(key, f"give only one of {', '.join(_DATA_KEYS)}; found {' and '.join(given)}")
    data = given[0]
    average = V.string(d.get("average", KINDS[kind]), f"{key}.average", ("angle", "slope"))
    rec = ConditionRecord(
        experiment=exp, name=name, kind=kind, data=data, average=average,
        origin=V.string(d.get("origin", "lab"), f"{key}.origin", _ORIGINS),
        description=V.string(d.get("description", ""), f"{key}.description"),
    )
    if "parameters" in d:
        p = V.mapping(d["parameters"], f"{key}.parameters")
        for k, v in p.items():
            if not isinstance(v, (int, float, str, bool)):
                raise V.err(f"{key}.parameters.{k}", f"expected a number, string or boolean, got {v!r}")
        rec.parameters = dict(p)
    if "reported" in d:
        rp = V.mapping(d["reported"], f"{key}.reported")
        for k, v in rp.items():
            kk = f"{key}.reported.{k}"
            if isinstance(v, list):
                for i, x in enumerate(v):
                    if isinstance(x, list):
                        V.numbers(x, f"{kk}[{i}]")
                    else:
                        V.number(x, f"{kk}[{i}]")
            else:
                V.number(v, kk)
        rec.reported = dict(rp)
    settings = _image_settings(V, d["image_settings"], f"{key}.image_settings") if "image_settings" in d else {}
    if "image_settings" in d and data not in ("images", "video"):
        raise V.err(f"{key}.image_settings", f"only allowed with images or video, not with {data}")
    _angle_data(V, rec, d, data, f"{key}.{data}", settings,
                dict(lo=0.0, hi=90.0, hi_open=True) if data == "angles_deg" else {})
    if average == "slope" and data == "angles_deg":
        raise V.err(f"{key}.average", "average 'slope' needs slopes, images or a video, not angles_deg")
    return rec


# --------------------------------------------------------------------------- #
# version 2
# --------------------------------------------------------------------------- #
def _name(V: _V, name: str, key: str, what: str, pattern: re.Pattern) -> str:
    if not pattern.match(name):
        rule = "letters, digits and _, not starting with a digit" if pattern is _IDENT else "no '/' and no spaces"
        raise V.err(key, f"{what} name {name!r} is not allowed ({rule})")
    return name


def _unit(V: _V, quantity: str, d: dict, key: str) -> tuple[str, float]:
    """(stored unit, factor from the written unit) of ``quantity`` with ``d["unit"]``."""
    written = V.string(d["unit"], key)
    if not written.strip():
        raise V.err(key, "empty unit")
    stored = QUANTITY_UNITS.get(quantity)
    if stored is None:
        return written, 1.0
    accepted = UNIT_CONVERSIONS[stored]
    if written not in accepted:
        raise V.err(key, f"unit {written!r} does not fit {quantity} (use {', '.join(accepted)})")
    return stored, accepted[written]


def _value(V: _V, x: Any, key: str, quantity: str, unit: str, factor: float) -> float:
    """A repeat's value: checked for the quantity's range as written, converted to ``unit``."""
    v = V.number(x, key, **_UNIT_RANGES.get(unit, {}))
    if unit == "1/0" and v not in (0.0, 1.0):
        raise V.err(key, f"{quantity} is 1 (yes) or 0 (no), got {x!r}")
    return v * factor


def _settings(V: _V, d: Any, key: str) -> dict[str, Any]:
    """Protocol settings: name -> number, string, boolean, null or list of numbers (SI units)."""
    d = V.mapping(d, key)
    out: dict[str, Any] = {}
    for k, v in d.items():
        kk = f"{key}.{k}"
        if k == "material":
            raise V.err(kk, "the material is stated once for the whole file, under 'material' at the top level")
        if v is None or isinstance(v, (bool, str)):
            out[k] = v
        elif isinstance(v, (int, float)):
            V.number(v, kk)
            out[k] = v
        elif isinstance(v, list):
            out[k] = V.numbers(v, kk)
        else:
            raise V.err(kk, f"expected a number, string, boolean, null or a list of numbers, got {v!r}")
    return out


def _material(V: _V, d: Any, key: str) -> dict[str, Any]:
    """The measured material: name -> number, string, boolean or list of numbers (SI units);
    ``diameter`` [m] is a number or [d_min, d_max] with 0 < d_min <= d_max."""
    d = V.mapping(d, key)
    for k, v in d.items():
        kk = f"{key}.{k}"
        if isinstance(v, list):
            V.numbers(v, kk)
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            V.number(v, kk)
        elif not isinstance(v, (str, bool)):
            raise V.err(kk, f"expected a number, string, boolean or a list of numbers, got {v!r}")
    if "diameter" in d:
        dia = d["diameter"]
        ds = V.numbers(dia, f"{key}.diameter", lo=0.0, lo_open=True) if isinstance(dia, list) \
            else [V.number(dia, f"{key}.diameter", lo=0.0, lo_open=True)]
        if len(ds) > 2 or ds[0] > ds[-1]:
            raise V.err(f"{key}.diameter",
                        f"expected a diameter [m] or [d_min, d_max] with d_min <= d_max, got {dia!r}")
    return dict(d)


def _angle_record(V: _V, exp: str, cond: str, data: str, d: dict, key: str) -> ConditionRecord:
    """The v1-style record of an angle observable with data repeats / slopes / images / video."""
    kind = EXPERIMENT_KINDS.get(exp, "other")
    default_average = KINDS[kind] if data != "repeats" else "angle"
    average = V.string(d.get("average", default_average), f"{key}.average", ("angle", "slope"))
    if "average" in d and data == "repeats":
        raise V.err(f"{key}.average", "average applies to slopes, images or a video, not to repeats in deg")
    if "image_settings" in d and data not in ("images", "video"):
        raise V.err(f"{key}.image_settings", f"only allowed with images or video, not with {data}")
    settings = _image_settings(V, d["image_settings"], f"{key}.image_settings") if "image_settings" in d else {}
    rec = ConditionRecord(experiment=exp, name=cond, kind=kind,
                          data="angles_deg" if data == "repeats" else data, average=average)
    _angle_data(V, rec, d, data, f"{key}.{data}", settings, _UNIT_RANGES["deg"] if data == "repeats" else {})
    return rec


def _observable(V: _V, exp: str, cond: str, quantity: str, d: Any, key: str) -> ObservableRecord:
    d = V.mapping(d, key)
    V.keys(d, _V2_OBS_KEYS, key, required=("unit",))
    unit, factor = _unit(V, quantity, d, f"{key}.unit")
    if unit != "deg":
        for k in _ANGLE_ONLY_KEYS:
            if k in d:
                raise V.err(f"{key}.{k}", f"only for angles (unit deg), not for {quantity} in {unit}")
    data_given = [k for k in _V2_DATA_KEYS if k in d]
    censor_given = [k for k in _V2_CENSOR_KEYS if k in d]
    if len(data_given) > 1:
        raise V.err(key, f"give only one of {', '.join(_V2_DATA_KEYS)}; found {' and '.join(data_given)}")
    if len(censor_given) > 1:
        raise V.err(key, "give no_pile or below_detection, not both")
    if not data_given and not censor_given:
        raise V.err(key, f"missing field: one of {', '.join(_V2_DATA_KEYS + _V2_CENSOR_KEYS)}")
    rec = ObservableRecord(
        experiment=exp, condition=cond, quantity=quantity, unit=unit,
        data=data_given[0] if data_given else "censored",
        resolution=V.number(d.get("resolution", 0.0), f"{key}.resolution", lo=0.0) * factor,
        label=V.string(d.get("label", ""), f"{key}.label"),
        description=V.string(d.get("description", ""), f"{key}.description"),
    )
    if "no_pile" in d:
        if quantity not in NO_PILE_QUANTITIES:
            raise V.err(f"{key}.no_pile", f"only for {', '.join(NO_PILE_QUANTITIES)}; for {quantity} use "
                                          "below_detection: {n: ..., limit: ...}")
        rec.n_censored = V.integer(d["no_pile"], f"{key}.no_pile", lo=1)
        rec.censor_limit = NO_PILE_LIMIT_DEG
    elif "below_detection" in d:
        bk = f"{key}.below_detection"
        b = V.mapping(d["below_detection"], bk)
        V.keys(b, {"n", "limit"}, bk, required=("n", "limit"))
        rec.n_censored = V.integer(b["n"], f"{bk}.n", lo=1)
        rec.censor_limit = V.number(b["limit"], f"{bk}.limit") * factor
    if data_given:
        data = data_given[0]
        if unit == "deg":
            rec.angle = _angle_record(V, exp, cond, data, d, key)
        else:
            kk = f"{key}.repeats"
            reps = d["repeats"]
            if not isinstance(reps, list):
                raise V.err(kk, f"expected a list of repeats, got {type(reps).__name__}")
            if not reps:
                raise V.err(kk, "empty repeats")
            for i, r in enumerate(reps):
                if isinstance(r, list):
                    if not r:
                        raise V.err(f"{kk}[{i}]", "empty list")
                    rec.repeats.append([_value(V, x, f"{kk}[{i}][{j}]", quantity, unit, factor)
                                        for j, x in enumerate(r)])
                else:
                    rec.repeats.append(_value(V, r, f"{kk}[{i}]", quantity, unit, factor))
    return rec


def _condition_v2(V: _V, exp: str, name: str, d: Any, key: str) -> ConditionRecord:
    d = V.mapping(d, key)
    V.keys(d, _V2_COND_KEYS, key, required=("settings", "observables"))
    settings = _settings(V, d["settings"], f"{key}.settings")
    obs = V.mapping(d["observables"], f"{key}.observables")
    if not obs:
        raise V.err(f"{key}.observables", "no observables")
    observables = {q: _observable(V, exp, name, _name(V, q, f"{key}.observables.{q}", "quantity", _IDENT), o,
                                  f"{key}.observables.{q}") for q, o in obs.items()}
    angle_name = ANGLE_QUANTITIES.get(exp)
    if angle_name not in observables:
        in_deg = [q for q, o in observables.items() if o.is_angle]
        angle_name = in_deg[0] if len(in_deg) == 1 else None
    angle = observables.get(angle_name) if angle_name else None
    if angle is not None and angle.angle is not None:
        rec = angle.angle
    else:
        rec = ConditionRecord(experiment=exp, name=name, kind=EXPERIMENT_KINDS.get(exp, "other"),
                              data="censored" if angle is not None else "none", average="angle")
    rec.origin = V.string(d.get("origin", _ORIGIN_DEFAULT), f"{key}.origin", _ORIGINS)
    rec.description = V.string(d.get("description", ""), f"{key}.description")
    rec.settings = settings
    rec.observables = observables
    return rec


def _parse_v2(V: _V, d: dict) -> MeasurementFile:
    V.keys(d, _V2_TOP_KEYS, "", required=("experiments",))
    exps = V.mapping(d["experiments"], "experiments")
    if not exps:
        raise V.err("experiments", "no experiments")
    out: dict[str, ExperimentRecord] = {}
    for en, e in exps.items():
        ek = f"experiments.{en}"
        _name(V, en, ek, "experiment", _IDENT)
        e = V.mapping(e, ek)
        V.keys(e, _V2_EXP_KEYS, ek, required=("conditions",))
        conds = V.mapping(e["conditions"], f"{ek}.conditions")
        if not conds:
            raise V.err(f"{ek}.conditions", "no conditions")
        records = {}
        for cn, c in conds.items():
            ck = f"{ek}.conditions.{cn}"
            records[cn] = _condition_v2(V, en, _name(V, cn, ck, "condition", _COND_NAME), c, ck)
        out[en] = ExperimentRecord(en, EXPERIMENT_KINDS.get(en, "other"),
                                   V.string(e.get("description", ""), f"{ek}.description"), records)
    return MeasurementFile(
        V.file,
        V.string(d.get("title", ""), "title"),
        V.string(d.get("source", ""), "source"),
        V.string(d.get("notes", ""), "notes"),
        out,
        version=2,
        material=_material(V, d["material"], "material") if "material" in d else {},
    )


def parse_measurements(data: Any, *, file: str = "<mapping>", base_dir: str = ".",
                       experiments: "Mapping[str, Any] | None" = None, build: bool = False) -> MeasurementFile:
    """Validate an already-parsed measurement mapping (see :func:`load_measurements`)."""
    V = _V(file, base_dir)
    if data is None:
        raise V.err("", "empty file")
    d = V.mapping(data, "(top level)")
    if "format" in d and d["format"] not in (FORMAT_V1, FORMAT_V2):
        raise V.err("format", f"unsupported format {d['format']!r} (expected {FORMAT_V1!r} or {FORMAT_V2!r})")
    if d.get("format") == FORMAT_V2:
        mf = _parse_v2(V, d)
        if experiments is not None:
            check_settings(mf, experiments, build=build)
        return mf
    V.keys(d, _TOP_KEYS, "", required=("experiments",))
    exps = V.mapping(d["experiments"], "experiments")
    if not exps:
        raise V.err("experiments", "no experiments")
    out: dict[str, ExperimentRecord] = {}
    for en, e in exps.items():
        ek = f"experiments.{en}"
        e = V.mapping(e, ek)
        V.keys(e, _EXP_KEYS, ek, required=("kind", "conditions"))
        kind = V.string(e["kind"], f"{ek}.kind", tuple(KINDS))
        conds = V.mapping(e["conditions"], f"{ek}.conditions")
        if not conds:
            raise V.err(f"{ek}.conditions", "no conditions")
        out[en] = ExperimentRecord(
            en, kind, V.string(e.get("description", ""), f"{ek}.description"),
            {cn: _condition(V, en, kind, cn, c, f"{ek}.conditions.{cn}") for cn, c in conds.items()},
        )
    return MeasurementFile(
        file,
        V.string(d.get("title", ""), "title"),
        V.string(d.get("source", ""), "source"),
        V.string(d.get("notes", ""), "notes"),
        out,
    )


def load_measurements(path: str | os.PathLike, *, experiments: "Mapping[str, Any] | None" = None,
                      build: bool = False) -> MeasurementFile:
    """Load and validate a measurement file (YAML; JSON if it ends in .json), version 1 or 2.

    Image and video paths are relative to the file's folder. Raises
    :class:`.errors.MeasurementFileError` naming the file and the key. ``experiments``: check a
    version-2 file's experiment and setting names against a mapping (the registered experiments:
    ``calibration.experiments.EXPERIMENTS``; see :func:`check_settings`; None: no check); ``build``: also
    build every condition's experiment (see :func:`check_settings`).
    """
    from warpdem.config_io import DuplicateKeyError, parse_json, parse_yaml
    from warpdem.errors import ConfigError

    path = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as e:
        raise MeasurementFileError(path, "", f"cannot read: {e}") from e
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise MeasurementFileError(path, "", f"not UTF-8 text (byte 0x{raw[e.start]:02x} at offset {e.start}): is it "
                                             "the right file? save it as UTF-8") from None
    try:
        data = parse_json(text, path) if path.lower().endswith(".json") else parse_yaml(text, path)
    except DuplicateKeyError as e:
        at = f"line {e.line}: " if e.line is not None else ""
        first = f" (first on line {e.first_line})" if e.first_line is not None else ""
        raise MeasurementFileError(path, str(e.key), f"{at}given twice in one mapping{first}; the second would "
                                                     "silently replace the first: keep one") from None
    except ConfigError as e:  # not valid YAML / JSON (the message names the file)
        raise MeasurementFileError(path, "", str(e).removeprefix(f"{path}: ")) from None
    return parse_measurements(data, file=path, base_dir=os.path.dirname(os.path.abspath(path)),
                              experiments=experiments, build=build)


# --------------------------------------------------------------------------- #
# checks against the experiments a simulation can run (given by the caller: the experiments
# measure with this package, so it cannot import them; calibration.experiments.EXPERIMENTS)
# --------------------------------------------------------------------------- #
def protocol_settings(experiment: "type | Iterable[str]") -> frozenset[str]:
    """Setting names a condition may give: an experiment class's fields without the model and
    numerics (:data:`SIMULATION_SETTINGS`), or the given names as they are."""
    if isinstance(experiment, type):
        names = experiment.field_names() if hasattr(experiment, "field_names") else \
            [f.name for f in dataclasses.fields(experiment)]
        return frozenset(names) - SIMULATION_SETTINGS
    return frozenset(experiment)


def check_settings(measurements: MeasurementFile, experiments: "Mapping[str, Any]", *,
                   build: bool = False) -> None:
    """Check a version-2 file against the experiments a simulation can run.

    experiments: name -> experiment class (``field_names()``, ``OBSERVABLES``, ``from_config``)
    or a set of setting names; the registered ones are ``calibration.experiments.EXPERIMENTS``.
    Every experiment must be one of them and every setting one of its :func:`protocol_settings`; an observable the class
    reports must be in the unit it reports. ``build``: also build each condition's experiment
    (``from_config("paper", material=<file material>, **settings)``) so that a value the
    experiment refuses (e.g. a negative rpm) or a material it cannot build is reported here.
    Raises :class:`MeasurementFileError` naming the file and key. Version-1 files are not
    checked (their ``parameters`` are free notes).
    """
    if measurements.version == 1:
        return
    file = measurements.path
    if build and measurements.material:
        from ..materials import BulkMaterial

        try:
            BulkMaterial.from_config(measurements.material)
        except (ValueError, TypeError) as e:
            raise MeasurementFileError(file, "material", f"cannot build this material: {e}") from e
    for en, exp in measurements.experiments.items():
        ek = f"experiments.{en}"
        if en not in experiments:
            raise MeasurementFileError(file, ek, f"unknown experiment {en!r} (registered: "
                                                 f"{', '.join(sorted(experiments))})")
        spec = experiments[en]
        allowed = protocol_settings(spec)
        reported = getattr(spec, "OBSERVABLES", {}) if isinstance(spec, type) else {}
        for cn, c in exp.conditions.items():
            ck = f"{ek}.conditions.{cn}"
            for name in c.settings:
                if name not in allowed:
                    why = " (it sets up the simulation, not the lab protocol)" if name in SIMULATION_SETTINGS else ""
                    raise MeasurementFileError(file, f"{ck}.settings.{name}",
                                               f"unknown setting {name!r} of experiment {en!r}{why} "
                                               f"(valid: {', '.join(sorted(allowed))})")
            for q, o in c.observables.items():
                if q in reported and o.unit != reported[q]:
                    raise MeasurementFileError(file, f"{ck}.observables.{q}.unit",
                                               f"{en} reports {q} in {reported[q]}, not {o.unit}")
            if build and isinstance(spec, type) and hasattr(spec, "from_config"):
                kw = dict(c.settings)
                if measurements.material:
                    kw["material"] = dict(measurements.material)
                try:
                    spec.from_config("paper", **kw)
                except (ValueError, TypeError) as e:
                    raise MeasurementFileError(file, f"{ck}.settings", f"experiment {en!r} refuses these "
                                                                       f"settings: {e}") from e


def unreported_observables(measurements: MeasurementFile, experiments: "Mapping[str, Any]") -> list[str]:
    """Keys ("experiment/condition/quantity") of observables that no simulation of that experiment
    reports (not in its class's ``OBSERVABLES``; e.g. ``mass_left_in_box`` today). experiments:
    name -> experiment class (the registered ones: ``calibration.experiments.EXPERIMENTS``).
    Unknown experiments count."""
    if measurements.version == 1:
        pairs = [(*V1_OBSERVABLES.get(e.kind, (en, "angle")), cn)
                 for en, e in measurements.experiments.items() for cn in e.conditions]
    else:
        pairs = [(o.experiment, o.quantity, o.condition) for e in measurements.experiments.values()
                 for c in e.conditions.values() for o in c.observables.values()]
    out = []
    for experiment, quantity, condition in pairs:
        spec = experiments.get(experiment)
        if quantity not in (getattr(spec, "OBSERVABLES", {}) if spec is not None else {}):
            out.append(f"{experiment}/{condition}/{quantity}")
    return out


# --------------------------------------------------------------------------- #
# writing version 2
# --------------------------------------------------------------------------- #
def _plain(v: Any) -> Any:
    """numpy scalars / tuples -> plain Python numbers / lists (for YAML and JSON)."""
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_plain(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, Mapping):
        return {str(k): _plain(x) for k, x in v.items()}
    return v


def measurements_v2_mapping(records: Sequence[ObservationRecord], *, title: str = "", source: str = "",
                            notes: str = "", material: Mapping[str, Any] | None = None,
                            descriptions: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The version-2 mapping of ``records`` (grouped by experiment and condition in record order).

    The records of one condition must agree on settings and origin. A censored ``pile_angle``
    at :data:`NO_PILE_LIMIT_DEG` is written as ``no_pile: n``, any other censored record as
    ``below_detection: {n, limit}``. descriptions: optional plain words per experiment name or
    per "experiment/condition". Raises ValueError for duplicated keys or disagreeing conditions.
    """
    descriptions = dict(descriptions or {})
    exps: dict[str, dict[str, Any]] = {}
    cond_of: dict[tuple[str, str], ObservationRecord] = {}
    for r in records:
        if not isinstance(r, ObservationRecord):
            raise TypeError(f"records must be ObservationRecord objects, got {type(r).__name__}")
        first = cond_of.setdefault((r.experiment, r.condition), r)
        where = f"{r.experiment}/{r.condition}"
        if dict(first.settings) != dict(r.settings):
            raise ValueError(f"{where}: records disagree on the settings ({dict(first.settings)} for "
                             f"{first.quantity}, {dict(r.settings)} for {r.quantity})")
        if first.origin != r.origin:
            raise ValueError(f"{where}: records disagree on the origin ({first.origin} and {r.origin})")
        exp = exps.setdefault(r.experiment, {"conditions": {}})
        if r.experiment in descriptions:
            exp["description"] = descriptions[r.experiment]
        cond = exp["conditions"].setdefault(r.condition, {})
        if not cond:
            if where in descriptions:
                cond["description"] = descriptions[where]
            if r.origin != _ORIGIN_DEFAULT:
                cond["origin"] = r.origin
            cond["settings"] = _plain(dict(r.settings))
            cond["observables"] = {}
        if r.quantity in cond["observables"]:
            raise ValueError(f"duplicated observation {r.key!r}")
        o: dict[str, Any] = {"unit": r.unit}
        if r.repeats:
            o["repeats"] = [float(v) for v in r.repeats]
        if r.n_censored:
            if r.quantity in NO_PILE_QUANTITIES and r.censor_limit == NO_PILE_LIMIT_DEG:
                o["no_pile"] = r.n_censored
            else:
                o["below_detection"] = {"n": r.n_censored, "limit": r.censor_limit}
        if r.resolution:
            o["resolution"] = r.resolution
        if r.label:
            o["label"] = r.label
        if r.description:
            o["description"] = r.description
        cond["observables"][r.quantity] = o
    out: dict[str, Any] = {"format": FORMAT_V2}
    for k, v in (("title", title), ("source", source), ("notes", notes)):
        if v:
            out[k] = v
    if material:
        out["material"] = _plain(dict(material))
    out["experiments"] = exps
    return out


def write_measurements_v2(path: str | os.PathLike, records: Sequence[ObservationRecord], *, title: str = "",
                          source: str = "", notes: str = "", material: Mapping[str, Any] | None = None,
                          descriptions: Mapping[str, str] | None = None) -> MeasurementFile:
    """Write ``records`` as a version-2 file (YAML; JSON if ``path`` ends in .json) and return it loaded.

    The file is validated before it is written, and its observations must equal ``records``
    (so a generator of synthetic lab data gets back exactly what it wrote; the file groups them
    by experiment and condition, in order of first appearance): a record in a unit
    the loader converts (e.g. pile_height in mm) or with a name the format refuses raises
    ValueError and nothing is written. See :func:`measurements_v2_mapping` for the layout.
    """
    path = os.fspath(path)
    data = measurements_v2_mapping(records, title=title, source=source, notes=notes, material=material,
                                   descriptions=descriptions)
    try:
        mf = parse_measurements(data, file=path, base_dir=os.path.dirname(os.path.abspath(path)))
    except MeasurementFileError as e:
        raise ValueError(f"these records do not make a valid measurement file: {e}") from e
    back = {r.key: r for r in mf.observations()}
    for want in records:
        if back.get(want.key) != want:
            raise ValueError(f"{want.key}: would not load back identically (written {want}, read {back.get(want.key)})")
    text = json.dumps(data, indent=1) + "\n" if path.lower().endswith(".json") else \
        f"# Format: docs/measurement_format.md ({FORMAT_V2}).\n" + \
        yaml.safe_dump(data, sort_keys=False, default_flow_style=None, allow_unicode=True, width=100)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    return mf
