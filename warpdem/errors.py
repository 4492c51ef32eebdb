"""Exceptions raised by warpdem. Every error names the offending input."""


class WarpDEMError(Exception):
    """Base class of all warpdem errors."""


class ConfigError(WarpDEMError, ValueError):
    """A configuration value or key is invalid (wrong key, negative radius, ...)."""


class StabilityError(WarpDEMError):
    """The time step exceeds the stability limit, or worlds became unstable.

    ``worlds``: {world index: cause} of the worlds found unstable (NaN/inf state or a speed
    above the solver's bound) and frozen; empty for a refused time step."""

    def __init__(self, message: str, worlds: dict[int, str] | None = None) -> None:
        super().__init__(message)
        self.worlds: dict[int, str] = dict(worlds or {})


class StabilityWarning(UserWarning):
    """A run was accepted outside the checked stability limit (``force=True``)."""


class ContactOverflowError(WarpDEMError):
    """A sphere had more contacts (``kind="contacts"``) or neighbour-list entries
    (``kind="neighbours"``) than its slots can hold. ``capacity``: the slots it had;
    ``needed``: the largest count seen, where known."""

    def __init__(self, message: str, kind: str = "contacts", capacity: int | None = None,
                 needed: int | None = None) -> None:
        super().__init__(message)
        self.kind = kind
        self.capacity = capacity
        self.needed = needed


class OverlapError(WarpDEMError):
    """Initial configuration contains overlaps too large to start from."""
