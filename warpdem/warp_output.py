"""Warp's own screen output (its start-up banner, "Module ... load" lines): off unless asked for.

Warp 1.19 has no ``wp.config.quiet``; its messages follow ``wp.config.log_level``. Every process
that runs kernels (the command line, the CPU worker processes, Ray tasks) calls :func:`quiet_warp`
before Warp initialises. ``WARPDEM_WARP_VERBOSE=1`` keeps Warp's messages.
"""
from __future__ import annotations

import os

import warp as wp

__all__ = ["quiet_warp", "VERBOSE_ENV"]

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
