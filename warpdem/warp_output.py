"""Warp's own screen output (its start-up banner, "Module ... load" lines): off unless asked for.

Warp 1.19 has no ``wp.config.quiet``; its messages follow ``wp.config.log_level``. Every process
that runs kernels (the command line, the CPU worker processes, Ray tasks) calls :func:`quiet_warp`
before Warp initialises. On a machine without an NVIDIA driver Warp's native library also prints
"Warp CUDA warning: Could not find or load the NVIDIA CUDA driver" straight to the process's stderr
at initialisation, once per worker process; :func:`quiet_warp` initialises Warp with that stream
captured and passes on every other line (``warpdem doctor`` says which devices there are).
``WARPDEM_WARP_VERBOSE=1`` keeps Warp's messages.
"""
from __future__ import annotations

import os
import sys
import tempfile

import warp as wp

__all__ = ["quiet_warp", "VERBOSE_ENV", "NO_DRIVER_WARNING"]

#: the start of the native library's line on a machine without an NVIDIA driver (not an error on a CPU machine)
NO_DRIVER_WARNING = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"

VERBOSE_ENV = "WARPDEM_WARP_VERBOSE"


def quiet_warp(always: bool = False) -> None:
    """Show only Warp's warnings and errors (no banner, no module-load lines), unless
    ``$WARPDEM_WARP_VERBOSE`` is set to a non-empty value other than 0 (``always``: whatever it says,
    e.g. for a benchmark whose stdout must carry only its JSON lines)."""
    if not always and os.environ.get(VERBOSE_ENV, "") not in ("", "0"):
        return
    if hasattr(wp, "LOG_WARNING") and hasattr(wp.config, "log_level"):
        wp.config.log_level = wp.LOG_WARNING
    else:  # older Warp
        wp.config.quiet = True
    _init_without_driver_warning()


_initialised = False


def _init_without_driver_warning() -> None:
    """``wp.init()`` with file descriptor 2 captured; every captured line except the missing-driver
    warning is written back to stderr. Once per process (``wp.init`` is idempotent; this saves the
    descriptor juggling)."""
    global _initialised
    if _initialised:
        return
    _initialised = True
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # no real stderr (e.g. captured by a test runner)
        wp.init()
        return
    sys.stderr.flush()
    saved = os.dup(fd)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), fd)
        try:
            wp.init()
        finally:
            os.dup2(saved, fd)
            os.close(saved)
            tmp.seek(0)
            text = tmp.read().decode("utf-8", "replace")
    kept = [line for line in text.splitlines(keepends=True) if not line.startswith(NO_DRIVER_WARNING)]
    if kept:
        sys.stderr.write("".join(kept))
        sys.stderr.flush()
