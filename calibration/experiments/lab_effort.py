"""What a lab can change in an experiment, and what one repeat costs it.

Each experiment class declares (as plain data, read by :mod:`validation.proposals`):

* ``LAB_EFFORT`` (:class:`LabEffort`): lab hours of one repeat at a measured condition, and of
  setting the apparatus up for a lab that has not run it yet;
* ``LAB_SETTINGS`` (tuple of :class:`LabSetting`): the settings a lab can change to tell two
  effects apart, the values to try (as multiples of the measured value) and the lab hours that
  change costs.

Effort is in **lab hours** (one person at the bench), rough planning figures rather than
measurements: what matters is their order (a speed change on a filled drum costs minutes, a new
cylinder size a day's work). A config can replace them for one proposal (``proposals[i].lab_hours``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["LabEffort", "LabSetting", "round_3"]


def round_3(x: float) -> float:
    """``x`` rounded to 3 significant digits (a value a lab would set)."""
    return float(f"{float(x):.3g}")


def _check_hours(owner: str, **hours: float) -> None:
    for name, v in hours.items():
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ValueError(f"{owner}: {name} must be a number of lab hours >= 0, got {v!r}")


@dataclass(frozen=True)
class LabEffort:
    """Lab effort of one experiment.

    repeat_hours : lab hours [h] of one repeat at a measured condition (fill, run, read, clear up).
    setup_hours : lab hours [h] to set the apparatus up when the lab has not run it yet.
    why : one line: what those hours are spent on.
    """

    repeat_hours: float
    setup_hours: float
    why: str

    def __post_init__(self) -> None:
        _check_hours("LabEffort", repeat_hours=self.repeat_hours, setup_hours=self.setup_hours)


@dataclass(frozen=True)
class LabSetting:
    """One setting of an experiment that a lab can change.

    name : the experiment's setting (a dataclass field, e.g. ``"rpm"``).
    words : plain words for sentences, e.g. ``"drum speed"``.
    unit : unit of the setting, e.g. ``"rpm"``, ``"kg"``, ``"m/s"``, ``"m"``.
    factors : the values to propose, as multiples of the measured condition's value (2.0: twice
        it), most informative first; each is rounded to 3 significant digits.
    change_hours : one-off lab hours [h] to change it (0 for a knob, a day to build a new drum).
    repeat_hours : lab hours [h] of one repeat at the changed value.
    why : one line: why these values and this effort.
    also_scaled : settings multiplied by the same factor (a measuring window that follows the
        box's width); a tuple setting is scaled element by element.
    """

    name: str
    words: str
    unit: str
    factors: tuple[float, ...]
    change_hours: float
    repeat_hours: float
    why: str
    also_scaled: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        _check_hours(f"LabSetting {self.name!r}", change_hours=self.change_hours, repeat_hours=self.repeat_hours)
        if not self.factors or not all(math.isfinite(f) and f > 0 and f != 1 for f in self.factors):
            raise ValueError(f"LabSetting {self.name!r}: factors must be positive multiples other than 1, "
                             f"got {self.factors!r}")

    def values(self, measured: float) -> tuple[tuple[float, float], ...]:
        """``(factor, value)`` of each proposed value for a measured value (3 significant digits;
        a value equal to the measured one or to an earlier one is left out)."""
        out: list[tuple[float, float]] = []
        for f in self.factors:
            v = round_3(measured * f)
            if v != measured and v not in [u for _, u in out]:
                out.append((f, v))
        return tuple(out)

    def hours(self, n_repeats: int) -> float:
        """Lab hours [h] of ``n_repeats`` repeats at a changed value, the change included."""
        return self.change_hours + n_repeats * self.repeat_hours
