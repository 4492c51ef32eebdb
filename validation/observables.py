"""Measured observables: one scalar per experiment, condition and quantity, with its repeats.

An :class:`Observable` is e.g. ``"drum/30rpm/dynamic_angle"`` (rotating drum B at 30 rpm,
dynamic angle of repose in deg) with the values of the independent lab repeats.  It gives the
mean, the standard error of the mean ``SE = s / sqrt(n)`` (``s``: sample standard deviation,
ddof 1), floored by the reading ``resolution``, and the number of repeats ``n``.

"No pile formed" (hollow cylinder C: the material spreads to a layer, no angle can be read) is a
**censored** observation: the true value lies below the ``detection_limit`` (e.g. the smallest
pile angle a profile can resolve, 3 deg).  It is built with :meth:`Observable.below_detection`;
its implausibility is one-sided (zero while the model also predicts a value below the limit,
``(prediction - limit) / sigma`` above it), see :mod:`validation.misfit`.  A forward model
reports a simulated "no pile" as the angle it measured (about 0 deg), never as NaN (NaN means a
failed run).  A condition where only some repeats formed a pile is refused: split it or decide
which repeats count, since neither a mean nor a limit describes it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["Observable", "Observations"]


@dataclass(frozen=True)
class Observable:
    """One measured scalar with its repeats.

    key : unique name, e.g. ``"drum/30rpm/dynamic_angle"``.
    experiment : the experiment, e.g. ``"drum"``, ``"baffle"``, ``"cylinder"``.
    quantity : what is measured, e.g. ``"dynamic_angle"``, ``"bulk_density"``.
    unit : unit of the values, e.g. ``"deg"``, ``"kg/m3"``.
    repeats : the measured values of the independent repeats (finite).
    condition : protocol settings the simulation must reproduce, e.g. ``{"rpm": 30}``.
    label : plain words for plots and sentences, e.g. ``"drum angle at 30 rpm"``.
    resolution : reading resolution in ``unit``; floor of the standard error (needed when n = 1).
    n_below_detection : number of repeats below ``detection_limit`` (e.g. "no pile formed").
    detection_limit : the limit in ``unit`` below which the quantity cannot be read.
    """

    key: str
    experiment: str
    quantity: str
    unit: str
    repeats: tuple[float, ...] = ()
    condition: Mapping[str, Any] = field(default_factory=dict)
    label: str = ""
    resolution: float = 0.0
    n_below_detection: int = 0
    detection_limit: float | None = None

    def __post_init__(self) -> None:
        for name in ("key", "experiment", "quantity", "unit"):
            v = getattr(self, name)
            if not isinstance(v, str) or not v.strip():
                raise ValueError(f"observable {self.key!r}: {name} must be a non-empty string, got {v!r}")
        try:
            reps = tuple(float(r) for r in self.repeats)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"observable {self.key!r}: repeats must be numbers, got {self.repeats!r}") from exc
        if not all(math.isfinite(r) for r in reps):
            raise ValueError(f"observable {self.key!r}: repeats must be finite, got {reps}; "
                             "a repeat below the detection limit is counted in n_below_detection")
        object.__setattr__(self, "repeats", reps)
        object.__setattr__(self, "condition", MappingProxyType(dict(self.condition)))
        res = float(self.resolution)
        if not (math.isfinite(res) and res >= 0.0):
            raise ValueError(f"observable {self.key!r}: resolution must be >= 0, got {self.resolution}")
        object.__setattr__(self, "resolution", res)
        nb = self.n_below_detection
        if isinstance(nb, bool) or not isinstance(nb, (int, np.integer)) or nb < 0:
            raise ValueError(f"observable {self.key!r}: n_below_detection must be an integer >= 0, got {nb!r}")
        if nb > 0:
            if self.detection_limit is None or not math.isfinite(float(self.detection_limit)):
                raise ValueError(f"observable {self.key!r}: {nb} repeats below detection need a finite detection_limit")
            if reps:
                raise ValueError(
                    f"observable {self.key!r}: {len(reps)} repeats gave a value and {nb} fell below the detection "
                    f"limit {self.detection_limit} {self.unit} (e.g. a pile formed only sometimes); neither a mean "
                    "nor a limit describes that: split the condition or decide which repeats count")
            object.__setattr__(self, "detection_limit", float(self.detection_limit))
        else:
            if len(reps) == 0:
                raise ValueError(f"observable {self.key!r}: no repeats given")
            if len(reps) == 1 and res == 0.0:
                raise ValueError(f"observable {self.key!r}: one repeat gives no standard error; "
                                 "give more repeats or a reading resolution > 0")

    @classmethod
    def below_detection(cls, key: str, experiment: str, quantity: str, unit: str, n_repeats: int,
                        detection_limit: float, condition: Mapping[str, Any] | None = None,
                        label: str = "", resolution: float = 0.0) -> "Observable":
        """A censored observation: all ``n_repeats`` fell below ``detection_limit`` (e.g. no pile formed)."""
        if isinstance(n_repeats, bool) or not isinstance(n_repeats, (int, np.integer)) or n_repeats < 1:
            raise ValueError(f"observable {key!r}: n_repeats must be an integer >= 1, got {n_repeats!r}")
        return cls(key, experiment, quantity, unit, (), condition or {}, label, resolution,
                   int(n_repeats), detection_limit)

    @property
    def is_censored(self) -> bool:
        """True for "below the detection limit" (e.g. no pile formed)."""
        return self.n_below_detection > 0

    @property
    def n(self) -> int:
        """Number of repeats."""
        return self.n_below_detection if self.is_censored else len(self.repeats)

    @property
    def mean(self) -> float:
        """Mean of the repeats in ``unit``; for a censored observation the detection limit."""
        return float(self.detection_limit) if self.is_censored else float(np.mean(self.repeats))

    @property
    def standard_error(self) -> float:
        """Standard error of the mean in ``unit``: ``max(s / sqrt(n), resolution)``; censored: ``resolution``."""
        if self.is_censored:
            return self.resolution
        se = float(np.std(self.repeats, ddof=1) / math.sqrt(len(self.repeats))) if len(self.repeats) > 1 else 0.0
        return max(se, self.resolution)

    @property
    def name(self) -> str:
        """Plain words for plots: the label, or the key."""
        return self.label or self.key

    def measured_text(self, digits: int = 3) -> str:
        """``"40.2 ± 0.3 deg"`` or ``"below 3 deg (no value in 3 repeats)"``."""
        if self.is_censored:
            return f"below {self.detection_limit:g} {self.unit} (no value in {self.n} repeats)"
        return f"{self.mean:.{digits}g} ± {self.standard_error:.2g} {self.unit}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "key": self.key, "experiment": self.experiment, "quantity": self.quantity, "unit": self.unit,
            "label": self.label, "condition": dict(self.condition), "repeats": list(self.repeats),
            "n": self.n, "mean": None if self.is_censored else self.mean,
            "standard_error": self.standard_error, "resolution": self.resolution,
            "censored": self.is_censored, "n_below_detection": self.n_below_detection,
            "detection_limit": self.detection_limit,
        }


class Observations:
    """An ordered set of observables with unique keys, and their arrays (one entry per observable)."""

    def __init__(self, items: Sequence[Observable]):
        items = tuple(items)
        if not items:
            raise ValueError("at least one observable is needed")
        for o in items:
            if not isinstance(o, Observable):
                raise TypeError(f"observations must be Observable objects, got {type(o).__name__}")
        keys = [o.key for o in items]
        dup = sorted({k for k in keys if keys.count(k) > 1})
        if dup:
            raise ValueError(f"observable keys must be unique; duplicated: {dup}")
        self.items = items

    def __len__(self) -> int:
        return len(self.items)

    def __iter__(self):
        return iter(self.items)

    def __getitem__(self, i: int) -> Observable:
        return self.items[i]

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(o.key for o in self.items)

    @property
    def means(self) -> np.ndarray:
        """Measured means (detection limit where censored), shape (m,)."""
        return np.array([o.mean for o in self.items])

    @property
    def standard_errors(self) -> np.ndarray:
        return np.array([o.standard_error for o in self.items])

    @property
    def n(self) -> np.ndarray:
        return np.array([o.n for o in self.items], dtype=float)

    @property
    def censored(self) -> np.ndarray:
        return np.array([o.is_censored for o in self.items])

    def index(self, key: str) -> int:
        try:
            return self.keys.index(key)
        except ValueError:
            raise KeyError(f"no observable {key!r}; known: {', '.join(self.keys)}") from None
