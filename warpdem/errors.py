"""Exceptions raised by warpdem. Every error names the offending input."""


class WarpDEMError(Exception):
    """Base class of all warpdem errors."""


class ConfigError(WarpDEMError, ValueError):
    """A configuration value or key is invalid (wrong key, negative radius, ...)."""


class StabilityError(WarpDEMError):
    """The time step exceeds the stability limit, or the state became non-finite."""


class ContactOverflowError(WarpDEMError):
    """A sphere had more contacts than its contact slots can hold."""


class OverlapError(WarpDEMError):
    """Initial configuration contains overlaps too large to start from."""
