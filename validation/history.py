"""Stage 7: the error history across model versions (base, base + effect, ...).

Each entry holds the DEM-confirmed residuals ``z_i`` of every observable at the version's best
fit (:mod:`validation.study`) and the totals: ``chi^2 = sum_i z_i^2``, ``dof = m - k``,
``chi^2/dof`` (None when m <= k), ``chi^2/m`` (comparable across versions with different k) and
``max_i |z_i|``.  Stored as JSON; :meth:`ErrorHistory.from_json` reads it back.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

__all__ = ["VersionErrors", "ErrorHistory", "version_errors"]


@dataclass(frozen=True)
class VersionErrors:
    """Errors of one model version: residual z per observable key and the totals."""

    version: str
    effects: tuple[str, ...]
    n_parameters: int
    z: dict[str, float]
    within_sigma: float = 2.0

    @property
    def n_observables(self) -> int:
        return len(self.z)

    def _finite(self) -> np.ndarray:
        v = np.array(list(self.z.values()), float)
        return v[np.isfinite(v)]

    @property
    def chi2(self) -> float:
        return float(np.sum(self._finite() ** 2))

    @property
    def dof(self) -> int:
        return self.n_observables - self.n_parameters

    @property
    def chi2_per_dof(self) -> float | None:
        return self.chi2 / self.dof if self.dof > 0 else None

    @property
    def chi2_per_observable(self) -> float:
        return self.chi2 / max(1, len(self._finite()))

    @property
    def max_abs_z(self) -> float:
        f = self._finite()
        return float(np.max(np.abs(f))) if len(f) else math.nan

    @property
    def n_within(self) -> int:
        return int(np.sum(np.abs(self._finite()) <= self.within_sigma))

    def to_dict(self) -> dict[str, Any]:
        return {"version": self.version, "effects": list(self.effects), "n_parameters": self.n_parameters,
                "z": {k: (None if not math.isfinite(v) else float(v)) for k, v in self.z.items()},
                "within_sigma": self.within_sigma, "chi2": self.chi2, "dof": self.dof,
                "chi2_per_dof": self.chi2_per_dof, "chi2_per_observable": self.chi2_per_observable,
                "max_abs_z": self.max_abs_z, "n_within": self.n_within, "n_observables": self.n_observables}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "VersionErrors":
        z = {k: (math.nan if v is None else float(v)) for k, v in d["z"].items()}
        return cls(d["version"], tuple(d["effects"]), int(d["n_parameters"]), z, float(d.get("within_sigma", 2.0)))


@dataclass(frozen=True)
class ErrorHistory:
    """Model versions in the order they were built."""

    versions: tuple[VersionErrors, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "versions", tuple(self.versions))
        if self.versions:
            keys = list(self.versions[0].z)
            for v in self.versions[1:]:
                if list(v.z) != keys:
                    raise ValueError(f"error history version {v.version!r} has observables {list(v.z)}, "
                                     f"expected {keys}")

    def appended(self, entry: VersionErrors) -> "ErrorHistory":
        return ErrorHistory(self.versions + (entry,))

    @property
    def keys(self) -> list[str]:
        return list(self.versions[0].z) if self.versions else []

    def to_dict(self) -> dict[str, Any]:
        return {"versions": [v.to_dict() for v in self.versions]}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    @classmethod
    def from_json(cls, text: str) -> "ErrorHistory":
        d = json.loads(text)
        return cls(tuple(VersionErrors.from_dict(v) for v in d["versions"]))

    def write(self, path: str | os.PathLike) -> Path:
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        from warpdem.config_io import write_atomic

        write_atomic(p, self.to_json())
        return p

    @classmethod
    def read(cls, path: str | os.PathLike) -> "ErrorHistory":
        return cls.from_json(Path(path).read_text(encoding="utf-8"))


def version_errors(name: str, effects: Sequence[str], n_parameters: int, keys: Sequence[str], z: np.ndarray,
                   within_sigma: float = 2.0) -> VersionErrors:
    """Build an entry from parallel keys and residuals."""
    return VersionErrors(name, tuple(effects), int(n_parameters), {k: float(v) for k, v in zip(keys, z)},
                         float(within_sigma))
