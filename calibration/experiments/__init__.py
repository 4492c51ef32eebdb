"""Standard virtual experiments (definitions: docs/experiments.md).

- :class:`BaffleBox` (A): static angle of repose alpha_AoR_S and fill bulk density.
- :class:`RotatingDrum` (B): dynamic angle of repose beta_AoR_D (mean and spread over snapshots).
- :class:`HollowCylinder` (C): pile angle gamma_s from four half-profiles.

Each is a dataclass of settings (SI units, spec defaults; ``from_config(scale="quick", ...)``
for the quick preset) with ``run(parameter_sets, device=None, progress=False)`` returning one
:class:`ExperimentResult` per world. ``make_experiment(name, scale, **settings)`` builds one by name.
"""
from __future__ import annotations

from typing import Any

from warpdem import ConfigError

from .baffle import BaffleBox
from .common import Experiment, ExperimentResult, normalize_parameter_sets
from .cylinder import HollowCylinder
from .drum import RotatingDrum

EXPERIMENTS: dict[str, type[Experiment]] = {"baffle": BaffleBox, "drum": RotatingDrum, "cylinder": HollowCylinder}

__all__ = ["BaffleBox", "RotatingDrum", "HollowCylinder", "Experiment", "ExperimentResult", "EXPERIMENTS",
           "make_experiment", "normalize_parameter_sets"]


def make_experiment(name: str, scale: str = "paper", **settings: Any) -> Experiment:
    """Experiment ``name`` ("baffle", "drum", "cylinder") at ``scale`` with ``settings`` overrides."""
    if name not in EXPERIMENTS:
        raise ConfigError(f"unknown experiment {name!r}; valid: {sorted(EXPERIMENTS)}")
    return EXPERIMENTS[name].from_config(scale, **settings)
