"""``warpdem`` console command: one entry point for the package's jobs.

    warpdem pour [--spheres N] [--device cpu|cuda]   pour a box and lift its baffle (VTK out)
    warpdem experiment CONFIG                         run one standard experiment from a config
    warpdem measure IMAGE ...                         measure a repose angle from an image/video
    warpdem calibrate CONFIG                          multi-response calibration campaign
    warpdem bench [--spheres N] [--device ...]        settled-bed benchmark (one JSON line)
"""
from __future__ import annotations

import importlib
import runpy
import sys
from pathlib import Path

COMMANDS = {
    "experiment": ("calibration.experiments.cli", "experiment_main"),
    "measure": ("calibration.measurement.cli", "measure_main"),
    "calibrate": ("calibration.campaign", "calibrate_main"),
}
ROOT = Path(__file__).resolve().parent.parent


def _script(rel: str, argv: list[str]) -> int:
    path = ROOT / rel
    if not path.exists():
        print(f"warpdem: {rel} is not available in this installation (run from a source checkout)", file=sys.stderr)
        return 2
    sys.argv = [str(path)] + argv
    sys.path.insert(0, str(path.parent))
    runpy.run_path(str(path), run_name="__main__")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    cmd, rest = argv[0], argv[1:]
    if cmd == "pour":
        return _script("examples/pour_box.py", rest)
    if cmd == "bench":
        return _script("benchmarks/settled_bed.py", rest)
    if cmd not in COMMANDS:
        print(f"warpdem: unknown command '{cmd}'; commands: pour, experiment, measure, calibrate, bench", file=sys.stderr)
        return 2
    module, func = COMMANDS[cmd]
    try:
        fn = getattr(importlib.import_module(module), func)
    except (ImportError, AttributeError) as exc:
        print(f"warpdem {cmd}: not available ({exc})", file=sys.stderr)
        return 2
    rc = fn(rest)
    return int(rc or 0)


if __name__ == "__main__":
    sys.exit(main())
