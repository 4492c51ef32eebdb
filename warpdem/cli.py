"""``warpdem`` console command: one front door for every job.

The engine does not know the applications built on it: subcommands are discovered through the
entry-point group ``warpdem.commands`` (``name = "package.module:function"``, the function takes
the remaining arguments and returns an exit code). This package declares its own
(experiment, measure, calibrate, diagnose, pump, pour, bench) in ``pyproject.toml``; another
installed package can add one the same way.
"""
from __future__ import annotations

import sys
from importlib import metadata
from typing import Callable, Sequence

COMMAND_GROUP = "warpdem.commands"

#: one-line help per known command (discovered commands without a line show their target)
HELP = {
    "experiment": "run one standard experiment (baffle, drum, cylinder) from a config",
    "measure": "measure a repose angle from a photograph or a drum video",
    "calibrate": "multi-response calibration campaign (LHS, DEM, surrogates, NSGA-II)",
    "diagnose": "model versus measurements: where it fails, which physical effect is missing",
    "pump": "slurry-pump wear prototype (particles, simplified flow, wear per triangle)",
    "pour": "pour a box and lift its baffle (VTK out): a first look at the engine",
    "bench": "settled-bed engine benchmark (one JSON line)",
}


def version() -> str:
    try:
        return metadata.version("warpdem")
    except metadata.PackageNotFoundError:  # running from a source tree that is not installed
        from . import __version__

        return __version__


def commands() -> dict[str, metadata.EntryPoint]:
    """Subcommands registered in the ``warpdem.commands`` entry-point group, by name."""
    return {ep.name: ep for ep in metadata.entry_points(group=COMMAND_GROUP)}


def _usage(found: dict[str, metadata.EntryPoint]) -> str:
    lines = [f"warpdem {version()}: discrete element method in NVIDIA Warp", "",
             "usage: warpdem COMMAND [ARGS] (warpdem COMMAND --help for its options)", "", "commands:"]
    for name in sorted(found):
        lines.append(f"  {name:<11} {HELP.get(name, found[name].value)}")
    if not found:
        lines.append("  (none registered: install the package, e.g. `pip install .`)")
    lines += ["", "  --version   print the version"]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    found = commands()
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage(found))
        return 0
    if argv[0] in ("--version", "-V"):
        print(f"warpdem {version()}")
        return 0
    cmd, rest = argv[0], argv[1:]
    if cmd not in found:
        print(f"warpdem: unknown command '{cmd}'; commands: {', '.join(sorted(found)) or 'none registered'}",
              file=sys.stderr)
        return 2
    try:
        fn: Callable[[list[str]], int | None] = found[cmd].load()
    except (ImportError, AttributeError) as exc:
        print(f"warpdem {cmd}: cannot load {found[cmd].value} ({exc})", file=sys.stderr)
        return 2
    rc = fn(rest)
    return int(rc) if isinstance(rc, int) else 0


if __name__ == "__main__":
    sys.exit(main())
