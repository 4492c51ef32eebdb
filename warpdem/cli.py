"""``warpdem`` console command: one front door for every job.

The engine does not know the applications built on it: subcommands are discovered through the
entry-point group ``warpdem.commands`` (``name = "package.module:function"``, the function takes
the remaining arguments and returns an exit code). This package declares its own
(experiment, measure, calibrate, diagnose, pump, pour, bench, doctor) in ``pyproject.toml``; another
installed package can add one the same way.
"""
from __future__ import annotations

import os
import sys
import traceback
from importlib import metadata
from typing import Callable, Sequence

from .errors import WarpDEMError

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
    "doctor": "versions, devices (CUDA or not), packages, LIGGGHTS, where results go",
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
    from .warp_output import quiet_warp

    quiet_warp()  # Warp's banner and module-load lines off (WARPDEM_WARP_VERBOSE=1 keeps them)
    if cmd not in found:
        print(f"warpdem: unknown command '{cmd}'; commands: {', '.join(sorted(found)) or 'none registered'}",
              file=sys.stderr)
        return 2
    try:
        fn: Callable[[list[str]], int | None] = found[cmd].load()
    except (ImportError, AttributeError) as exc:
        print(f"warpdem {cmd}: cannot load {found[cmd].value} ({exc})", file=sys.stderr)
        return 2
    return run_command(cmd, fn, rest)


#: set this environment variable to 1 for the traceback of every error, a user's mistake too
TRACEBACK_ENV = "WARPDEM_TRACEBACK"
#: exit status of a user's mistake (a bad config, option or file): one message, no traceback
USAGE_ERROR = 2
#: exit status of a bug: the traceback and a line saying so
INTERNAL_ERROR = 1


def user_error_message(exc: BaseException) -> str | None:
    """The message for an exception that is a user's mistake or the machine's limit, None for a bug.

    A user's mistake: :class:`~warpdem.errors.ConfigError` (every config, option and input-file
    check raises it, the measurement files' errors too), another :class:`~warpdem.errors.WarpDEMError`
    (a time step above the stability limit, too few contact slots, overlapping input), a file
    that cannot be read or written (``OSError``), a file that is not UTF-8 text, and running out
    of memory."""
    if isinstance(exc, WarpDEMError):
        return str(exc)
    if isinstance(exc, UnicodeDecodeError):
        return f"a file is not UTF-8 text ({exc}): is it the right file? save it as UTF-8"
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if exc.filename else ""
        return f"{where}{exc.strerror or exc}"
    if isinstance(exc, MemoryError):
        return "out of memory: the run needs more memory than this machine has; run fewer worlds or smaller fills"
    return None


def run_command(name: str, fn: Callable[[list[str]], int | None], args: list[str]) -> int:
    """Run one subcommand inside the command line's error boundary: its exit status; a user's
    mistake (:func:`user_error_message`) prints one message naming it and gives 2; Ctrl-C gives
    130; anything else is a bug: its traceback, a line saying so, and 1."""
    try:
        rc = fn(args)
    except SystemExit as exc:  # argparse: --help (0) or a refused option (2, its message printed)
        if exc.code is None or isinstance(exc.code, int):
            return int(exc.code or 0)
        print(f"warpdem {name}: {exc.code}", file=sys.stderr)
        return USAGE_ERROR
    except KeyboardInterrupt:
        print(f"warpdem {name}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the boundary: every exception ends here
        message = user_error_message(exc)
        if os.environ.get(TRACEBACK_ENV) == "1" or message is None:
            traceback.print_exc()
        if message is None:
            print(f"warpdem {name}: internal error ({type(exc).__name__}): this is a bug in warpdem, not a mistake "
                  "in your input; please report it with the traceback above", file=sys.stderr)
            return INTERNAL_ERROR
        print(f"warpdem {name}: {message}", file=sys.stderr)
        return USAGE_ERROR
    return int(rc) if isinstance(rc, int) else 0


if __name__ == "__main__":
    sys.exit(main())
