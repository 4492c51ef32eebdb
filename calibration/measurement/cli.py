"""``warpdem measure``: angle of repose from an image, a drum video or a
measurement file; prints JSON and saves diagnostic pictures.

Examples::

    warpdem measure pile.png --scale 2.5 --window 0 300 0 160 --origin-px 40 610
    warpdem measure drum.mp4 --rpm 30 --discard 5 --record 10 --window-px 300 675 200 575
    warpdem measure --file calibration/data/zhang2023_table1.yaml
    warpdem measure --file lab.yaml --experiment baffle_static --condition photos
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any, Sequence

from warpdem.config_io import nonnegative_int_arg, positive_float_arg, positive_int_arg
from warpdem.errors import ConfigError

from .errors import MeasurementError, MeasurementFileError

_VIDEO_EXT = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".wmv", ".mpg", ".mpeg")


def _positive_scale(text: str) -> float:
    """``--scale`` value: a finite number of pixels per mm above 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--scale must be a number of pixels per mm, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"--scale must be > 0 pixels per mm, got {text}")
    return value


def _finite(text: str) -> float:
    """A finite number (a position, a time, a height)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return value


def _grey_level(text: str) -> float:
    """``--threshold``: a grey level 0-255."""
    value = _finite(text)
    if not 0 <= value <= 255:
        raise argparse.ArgumentTypeError(f"must be a grey level 0-255, got {text}")
    return value


def _angle_deg(text: str) -> float:
    """``--min-angle``: an angle 0 <= a < 90 deg."""
    value = _finite(text)
    if not 0 <= value < 90:
        raise argparse.ArgumentTypeError(f"must be an angle 0 <= a < 90 deg, got {text}")
    return value


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="warpdem measure",
        description="Measure an angle of repose from an image, a drum video or a measurement file "
                    "(spec: experiments.md, section Images). Prints JSON.",
    )
    p.add_argument("source", nargs="?", help="image or video file")
    p.add_argument("--file", help="measurement file (YAML/JSON, docs/measurement_format.md)")
    p.add_argument("--experiment", help="experiment in --file")
    p.add_argument("--condition", help="condition in --file (optional if the experiment has one)")
    p.add_argument("--measure-images", action="store_true",
                   help="with --file and no --experiment: also measure image/video conditions")
    g = p.add_argument_group("image settings (override the file's image_settings)")
    g.add_argument("--scale", type=_positive_scale, metavar="PX_PER_MM", help="image scale, px/mm (> 0)")
    g.add_argument("--window", type=_finite, nargs=4, metavar=("X0", "X1", "Z0", "Z1"),
                   help="fit window, x right and z up from --origin-px: in mm with a scale (--scale or "
                        "the file's), else in px; it must lie inside the image")
    g.add_argument("--window-px", type=_finite, nargs=4, metavar=("C0", "C1", "R0", "R1"),
                   help="fit window in pixel columns C0-C1 and rows R0-R1 counted from the top "
                        "(row 0 = top row); it must lie inside the image")
    g.add_argument("--origin-px", type=_finite, nargs=2, metavar=("COL", "ROW"),
                   help="pixel of x = z = 0 (default: bottom-left pixel)")
    g.add_argument("--material", choices=("auto", "dark", "bright"))
    g.add_argument("--threshold", type=_grey_level, help="grey level (0-255); default Otsu")
    g.add_argument("--band", type=_finite, nargs=2, metavar=("LO", "HI"),
                   help="fit only edge points with LO*h_ref <= z <= HI*h_ref")
    g.add_argument("--h-ref", type=positive_float_arg, help="reference height for --band (default: highest edge point)")
    g.add_argument("--min-angle", type=_angle_deg, help="smallest angle accepted, degrees (default 1)")
    g.add_argument("--open-px", type=nonnegative_int_arg)
    g.add_argument("--close-px", type=nonnegative_int_arg)
    v = p.add_argument_group("video (rotating drum, spec B)")
    v.add_argument("--video", action="store_true", help="treat source as a video")
    v.add_argument("--fps", type=positive_float_arg, help="frame rate (default: from the file)")
    v.add_argument("--rpm", type=positive_float_arg, default=30.0)
    v.add_argument("--discard", type=nonnegative_int_arg, default=5, help="revolutions discarded (paper: 5)")
    v.add_argument("--record", type=positive_int_arg, default=10, help="revolutions measured (paper: 10)")
    v.add_argument("--t0", type=_finite, default=0.0, help="time the rotation starts, s")
    o = p.add_argument_group("output")
    o.add_argument("--diagnostic", help="diagnostic picture for an image (default ./<stem>_measure.png)")
    o.add_argument("--diagnostic-dir", help="folder for diagnostic pictures of a video or file entry")
    o.add_argument("--no-diagnostic", action="store_true")
    o.add_argument("--json", dest="json_out", help="also write the JSON to this file")
    return p


def _overrides(a: argparse.Namespace) -> dict[str, Any]:
    kw: dict[str, Any] = {}
    if a.scale is not None:
        kw["scale_px_per_mm"] = a.scale
    if a.window is not None and a.window_px is not None:
        raise MeasurementError("give --window or --window-px, not both")
    if a.window is not None:
        kw["window"] = list(a.window)
        kw["window_units"] = "mm" if a.scale is not None else None
    if a.window_px is not None:
        kw["window"] = list(a.window_px)
        kw["window_units"] = "px"
    for name, key in (("origin_px", "origin_px"), ("material", "material"), ("threshold", "threshold"),
                      ("band", "fit_band"), ("h_ref", "h_ref"), ("min_angle", "min_angle_deg"),
                      ("open_px", "open_px"), ("close_px", "close_px")):
        val = getattr(a, name)
        if val is not None:
            kw[key] = tuple(val) if isinstance(val, list) else val
    return kw


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    kw = dict(base)
    if "window" in over:
        kw.pop("window_units", None)
    kw.update(over)
    if kw.get("window_units", "") is None:
        # --window without --scale: mm if the file gives a scale, else px, still x right and
        # z up from the origin (the help's frame), not rows from the top
        kw["window_units"] = "mm" if kw.get("scale_px_per_mm") else "units"
    return kw


def _frame_size(path: str, video: bool) -> tuple[int, int] | None:
    """(height, width) in px of an image or of a video's frames; None if it cannot be read here
    (the measurement then reports the problem)."""
    import cv2

    if not os.path.isfile(path):
        return None
    if video:
        cap = cv2.VideoCapture(path)
        try:
            hgt, wid = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)), int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        finally:
            cap.release()
        return (hgt, wid) if hgt > 0 and wid > 0 else None
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    return None if img is None else tuple(img.shape[:2])


def check_window_inside(path: str, kw: dict[str, Any], video: bool = False) -> None:
    """Raise :class:`MeasurementError` when the fit window of ``kw`` (measure_image settings)
    reaches beyond the image at ``path``, naming the image size; a window is never clipped."""
    window = kw.get("window")
    if window is None:
        return
    size = _frame_size(path, video)
    if size is None:
        return
    hgt, wid = size
    units = kw.get("window_units") or ("mm" if kw.get("scale_px_per_mm") else "px")
    if units == "px":
        c0, c1, r0, r1 = window
    else:
        scale = float(kw.get("scale_px_per_mm") or 1.0)
        col0, row0 = kw.get("origin_px") or (0.0, hgt - 1.0)
        x0, x1, z0, z1 = window
        c0, c1 = col0 + min(x0, x1) * scale, col0 + max(x0, x1) * scale + 1
        r0, r1 = row0 - max(z0, z1) * scale, row0 - min(z0, z1) * scale + 1
    c0, c1, r0, r1 = min(c0, c1), max(c0, c1), min(r0, r1), max(r0, r1)
    tol = 1e-6
    if c0 < -tol or r0 < -tol or c1 > wid + tol or r1 > hgt + tol:
        unit = {"px": "px (columns, rows from the top)", "units": "px (x right, z up from the origin)"}.get(
            units, "mm (x right, z up from the origin)")
        raise MeasurementError(
            f"{os.path.basename(path)}: the fit window {list(window)} in {unit} covers pixel columns "
            f"{c0:g}-{c1:g} and rows {r0:g}-{r1:g}, beyond the image of {wid} x {hgt} px "
            f"(columns 0-{wid}, rows 0-{hgt}); give a window inside the image")


def _window_problem(option: str, window: Sequence[float], px: bool, unit: str) -> str | None:
    """A window with zero or negative width or height (or under 2 px in pixels) in ``unit``: its message."""
    x0, x1, z0, z1 = window
    what = ("columns", "rows") if px else ("x", "z")
    for (lo, hi), axis, size in (((x0, x1), what[0], "wide"), ((z0, z1), what[1], "high")):
        if hi <= lo:
            return (f"{option} {' '.join(f'{v:g}' for v in window)}: the window is {hi - lo:g} {unit} {size} "
                    f"({axis} {lo:g} to {hi:g}); give the smaller value first and a window of positive size")
        if px and hi - lo < 2:
            return (f"{option} {' '.join(f'{v:g}' for v in window)}: the window is {hi - lo:g} px {size} ({axis} "
                    f"{lo:g} to {hi:g}); a profile needs at least 2 px each way")
    return None


def option_problem(a: argparse.Namespace) -> str | None:
    """The first usage error among the options (checked before anything is measured), or None:
    a source and --file together, neither, --window with --window-px, an empty or reversed window or
    band, --experiment/--condition without --file, a diagnostic folder that cannot be written, a
    source OpenCV cannot read."""
    if a.file and a.source:
        return "give either a source image/video or --file, not both"
    if not a.file and not a.source:
        return "nothing to measure: give an image/video path or --file"
    if (a.experiment or a.condition) and not a.file:
        return "--experiment and --condition pick a condition of --file; give --file"
    if a.window is not None and a.window_px is not None:
        return "give --window or --window-px, not both"
    for option, window, px in (("--window", a.window, False), ("--window-px", a.window_px, True)):
        problem = window is not None and _window_problem(option, window, px, "px" if px or not a.scale else "mm")
        if problem:
            return problem
    if a.band is not None and not 0 <= a.band[0] < a.band[1]:
        return f"--band {a.band[0]:g} {a.band[1]:g}: give 0 <= LO < HI (fractions of the reference height)"
    for option, path in (("--diagnostic", a.diagnostic), ("--diagnostic-dir", a.diagnostic_dir)):
        if path is None or a.no_diagnostic:
            continue
        folder = Path(path) if option == "--diagnostic-dir" else Path(path).parent
        from warpdem.config_io import check_output_folder

        try:
            check_output_folder(folder, option, "the diagnostic folder")
        except ConfigError as exc:
            return str(exc)
    if a.source and not a.file:
        video = bool(a.video or a.source.lower().endswith(_VIDEO_EXT))
        if _frame_size(a.source, video) is None:
            return (f"{a.source}: not {'a video' if video else 'an image'} OpenCV can read (is it the right file? "
                    f"{'--video treats it as a video' if not video else 'an image needs no --video'})")
    return None


def check_runnable_settings(mf: Any) -> None:
    """The settings of every condition of an experiment the DEM can run (version 2) checked as the
    diagnosis checks them: names among the experiment's settings, types, values (the experiment is
    built); other experiments' conditions are the lab's own (this command only measures them)."""
    from ..experiments import EXPERIMENTS
    from .records import check_settings

    if mf.version != 2:
        return
    known = dict(EXPERIMENTS)
    specs = {name: known.get(name) or {k for c in exp.conditions.values() for k in c.settings}
             for name, exp in mf.experiments.items()}
    check_settings(mf, specs, build=True)


def _clean(obj: Any) -> Any:
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    return obj


def _stem(path: str) -> str:
    return os.path.splitext(os.path.basename(path))[0]


def _run(a: argparse.Namespace) -> dict:
    from .images import measure_image, video_frames_for_revolutions
    from .records import load_measurements

    over = _overrides(a)
    if a.file:
        mf = load_measurements(a.file)
        check_runnable_settings(mf)
        if not a.experiment:
            if a.source:
                raise MeasurementError("give either a source image/video or --file, not both")
            return {"file": a.file, "experiments": mf.summary(measure_images=a.measure_images)}
        try:
            cond = mf.condition(a.experiment, a.condition)
        except MeasurementError as exc:  # the option names what the file does not hold
            raise ConfigError(f"--experiment/--condition: {exc}") from None
        out: dict[str, Any] = {"file": a.file, "experiment": cond.experiment, "condition": cond.name,
                               "kind": cond.kind, "data": cond.data}
        ddir = None if a.no_diagnostic else (a.diagnostic_dir or f"measure_{cond.experiment}_{cond.name}")
        if cond.data == "images":
            cond.images = [(p, _merge(kw, over)) for p, kw in cond.images]
            for p, kw in cond.images:
                check_window_inside(str(p), kw)
            out["images"] = [p for p, _ in cond.images]
        elif cond.data == "video":
            cond.video_settings = _merge(cond.video_settings, over)
            if cond.video and cond.video.get("path"):
                check_window_inside(str(cond.video["path"]), cond.video_settings, video=True)
        elif over:
            raise MeasurementError(f"image settings given but {a.experiment}/{cond.name} holds {cond.data}")
        out.update(cond.stats(diagnostic_dir=ddir if cond.data in ("images", "video") else None).as_dict())
        out["reported"] = cond.reported
        if ddir and cond.data in ("images", "video"):
            out["diagnostic_dir"] = ddir
        return out
    if not a.source:
        raise MeasurementError("nothing to measure: give an image/video path or --file")
    kw = _merge({}, over)
    video = bool(a.video or a.source.lower().endswith(_VIDEO_EXT))
    check_window_inside(a.source, kw, video)
    if video:
        ddir = None if a.no_diagnostic else (a.diagnostic_dir or f"{_stem(a.source)}_frames")
        res = video_frames_for_revolutions(a.source, a.fps, a.rpm, a.discard, a.record, t0=a.t0,
                                           diagnostic_dir=ddir, **kw)
        out = {"source": a.source, "rpm": a.rpm, "discard": a.discard, "record": a.record, **res.as_dict()}
        if ddir:
            out["diagnostic_dir"] = ddir
        return out
    diag = None if a.no_diagnostic else (a.diagnostic or f"{_stem(a.source)}_measure.png")
    res = measure_image(a.source, diagnostic_path=diag, **kw)
    out = {"source": a.source, **res.as_dict()}
    if diag:
        out["diagnostic"] = diag
    return out


def measure_main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``warpdem measure``. Prints JSON to stdout; returns the
    exit status (0 ok, 1 the angle could not be measured, 2 usage error: bad argument, missing or
    malformed input file)."""
    parser = _parser()
    try:
        a = parser.parse_args(list(argv) if argv is not None else None)
    except SystemExit as e:  # argparse usage error or --help
        return int(e.code or 0)
    for given in (a.source, a.file):
        if given is not None and not Path(given).is_file():
            print(f"warpdem measure: no such file: {given!r}", file=sys.stderr)
            return 2
    problem = option_problem(a)
    if problem is not None:  # a usage error: refused before anything is measured
        print(f"warpdem measure: {problem}", file=sys.stderr)
        return 2
    if a.json_out:  # checked before anything is measured
        target = Path(a.json_out)
        if target.is_dir():
            print(f"warpdem measure: --json {a.json_out}: a folder; give a file name", file=sys.stderr)
            return 2
        if not target.parent.is_dir():
            print(f"warpdem measure: --json {a.json_out}: the folder {str(target.parent)!r} does not exist; create it "
                  "or give a path in an existing folder", file=sys.stderr)
            return 2
        if not os.access(target.parent, os.W_OK):
            print(f"warpdem measure: --json {a.json_out}: the folder {str(target.parent)!r} is not writable",
                  file=sys.stderr)
            return 2
    try:
        out = _clean(_run(a))
    except (MeasurementFileError, ConfigError) as e:  # a malformed file or a wrong option: not a failed measurement
        print(json.dumps({"error": str(e)}), file=sys.stdout)
        print(f"warpdem measure: {e}", file=sys.stderr)
        return 2
    except MeasurementError as e:
        print(json.dumps({"error": str(e)}), file=sys.stdout)
        print(f"warpdem measure: {e}", file=sys.stderr)
        return 1
    text = json.dumps(out, indent=2)
    print(text)
    if a.json_out:
        from warpdem.config_io import write_atomic

        write_atomic(a.json_out, text + "\n")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(measure_main())
