"""Exceptions of the measurement package.

A measurement that cannot be taken (no material in the picture, a flat surface,
fewer fitted bins than the spec allows, a malformed measurement file) raises one
of these instead of returning a number.
"""

from __future__ import annotations

from warpdem.errors import ConfigError


class MeasurementError(ValueError):
    """An angle could not be measured from the given data or image."""


class MeasurementFileError(MeasurementError, ConfigError):
    """A measurement file (YAML/JSON) is malformed (a :class:`~warpdem.errors.ConfigError` too: the
    user's input is wrong).

    Attributes:
        file: path of the offending file (or ``"<mapping>"`` for in-memory data).
        key: dotted location of the offending key/field, e.g.
            ``"experiments.baffle.conditions.lab.slopes[2]"``.
    """

    def __init__(self, file: str, key: str, message: str) -> None:
        self.file = file
        self.key = key
        where = f"{file}: {key}: " if key else f"{file}: "
        super().__init__(where + message)
