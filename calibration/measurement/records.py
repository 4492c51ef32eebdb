"""Measurement files: repeated lab (or simulated) angle measurements.

Format (YAML, or JSON with a ``.json`` extension), documented in
docs/measurement_format.md; example: calibration/data/zhang2023_table1.yaml
(seed paper Tables 1 and 10). Per experiment and condition a file holds the
repeats of an angle (``angles_deg``), of fitted slopes (``slopes``; angle =
atan(|slope|), seed paper Table 1), or images / a video to be measured with
:mod:`.images`. A repeat may be a list of views (e.g. theta_1..4 of the hollow
cylinder, Table 10), whose mean is the repeat's value.

Loading validates everything and raises :class:`.errors.MeasurementFileError`
naming the file and the key. :meth:`ConditionRecord.stats` gives the mean,
sample standard deviation (ddof=1) and standard error over repeats.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml

from .errors import MeasurementError, MeasurementFileError
from .profiles import slope_to_angle_deg

__all__ = [
    "FORMAT",
    "KINDS",
    "AngleStats",
    "ConditionRecord",
    "ExperimentRecord",
    "MeasurementFile",
    "load_measurements",
    "parse_measurements",
]

FORMAT = "warpdem-measurements/1"

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
    _cache: AngleStats | None = field(default=None, repr=False)

    def stats(self, *, diagnostic_dir: str | os.PathLike | None = None) -> AngleStats:
        """Mean, sample std (ddof=1) and standard error over repeats.

        Image/video conditions are measured with :mod:`.images` (cached; a
        diagnostic picture per image is written to ``diagnostic_dir`` if given).
        """
        if self._cache is not None and diagnostic_dir is None:
            return self._cache
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
class ExperimentRecord:
    """An experiment: its kind (spec A/B/C) and its conditions by name."""

    name: str
    kind: str
    description: str
    conditions: dict[str, ConditionRecord]


@dataclass
class MeasurementFile:
    """A loaded measurement file."""

    path: str
    title: str
    source: str
    notes: str
    experiments: dict[str, ExperimentRecord]

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
        only when ``measure_images``)."""
        out: dict = {}
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
    kk = f"{key}.{data}"
    if data in ("angles_deg", "slopes"):
        reps = d[data]
        if not isinstance(reps, list):
            raise V.err(kk, f"expected a list of repeats, got {type(reps).__name__}")
        if not reps:
            raise V.err(kk, "empty repeats")
        rng = dict(lo=0.0, hi=90.0, hi_open=True) if data == "angles_deg" else {}
        for i, r in enumerate(reps):
            rec.repeats.append(V.numbers(r, f"{kk}[{i}]", **rng) if isinstance(r, list)
                               else V.number(r, f"{kk}[{i}]", **rng))
    elif data == "images":
        rec.images = _images(V, d["images"], settings, kk)
    else:  # video
        rec.video = _video(V, d["video"], kk)
        rec.video_settings = settings
    if average == "slope" and data == "angles_deg":
        raise V.err(f"{key}.average", "average 'slope' needs slopes, images or a video, not angles_deg")
    return rec


def parse_measurements(data: Any, *, file: str = "<mapping>", base_dir: str = ".") -> MeasurementFile:
    """Validate an already-parsed measurement mapping (see :func:`load_measurements`)."""
    V = _V(file, base_dir)
    if data is None:
        raise V.err("", "empty file")
    d = V.mapping(data, "(top level)")
    V.keys(d, _TOP_KEYS, "", required=("experiments",))
    if "format" in d and d["format"] != FORMAT:
        raise V.err("format", f"unsupported format {d['format']!r} (expected {FORMAT!r})")
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


def load_measurements(path: str | os.PathLike) -> MeasurementFile:
    """Load and validate a measurement file (YAML; JSON if it ends in .json).

    Image and video paths are relative to the file's folder. Raises
    :class:`.errors.MeasurementFileError` naming the file and the key.
    """
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except OSError as e:
        raise MeasurementFileError(path, "", f"cannot read: {e}") from e
    try:
        data = json.loads(text) if path.lower().endswith(".json") else yaml.safe_load(text)
    except (yaml.YAMLError, json.JSONDecodeError) as e:
        raise MeasurementFileError(path, "", f"not valid {'JSON' if path.lower().endswith('.json') else 'YAML'}: {e}") from e
    return parse_measurements(data, file=path, base_dir=os.path.dirname(os.path.abspath(path)))
