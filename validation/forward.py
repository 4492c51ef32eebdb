"""The forward-model interface: how the diagnosis asks for simulations.

One call of :meth:`ForwardModel.evaluate` is one batched launch per experiment: every parameter
set times every replicate (an independent fill) runs as its own world.  The diagnosis never sees
DEM objects, only numbers, so it is tested in seconds with an analytic model.

Optional, duck-typed capabilities (a model without them is served as before):

* the **superset protocol**: ``superset = True``, ``effects`` (every candidate effect's name, in
  order) and ``padded(effects, parameter_set)`` (the set with each effect not in ``effects`` at its
  "off" value). The model promises that ``evaluate(tuple(model.effects), [padded(e, p)], ...)``
  answers exactly what ``evaluate(e, [p], ...)`` does, so the designs of every model version can
  share one call (:func:`merges_versions`; used by :mod:`validation.pooled` and by the
  ``designs_up_front`` step of :func:`validation.diagnose.diagnose`).
* ``on_cuda``: True when the model simulates on a CUDA device (:func:`runs_on_cuda`; decides
  ``designs_up_front: auto``).
* ``worlds_per_run(keys)``: simulations one (parameter set, fill) of ``keys`` takes (the DEM: one
  world per experiment condition and drum speed); 1 when absent.
* ``per_set_replicates = True``: ``evaluate`` also takes ``replicates`` as one fill count per set
  (a design whose noise is measured on some of its sets only, ``replicated_fraction``) and
  answers ``(n_sets, max count, n_keys)`` with NaN past each set's count. A model without it is
  called once per distinct count (:func:`evaluate_counts`).

:class:`ForwardRunner` wraps a model: it checks each answer's shape, counts runs and time.
"""

from __future__ import annotations

import math
import threading
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["ForwardModel", "ProposedMeasurement", "ForwardRunner", "merges_versions", "runs_on_cuda",
           "worlds_per_run", "replicate_counts", "evaluate_counts"]


@dataclass(frozen=True)
class ProposedMeasurement:
    """A condition not yet measured that the forward model can predict (e.g. drum at 60 rpm).

    expected_standard_error : the standard error (``unit``) the lab expects for a mean of
        ``n_repeats``; None: estimated from the DEM fill-to-fill spread as ``s_DEM / sqrt(n_repeats)``.
    lab_hours : lab effort [h] of the ``n_repeats`` repeats, any change of set-up included
        (:mod:`validation.proposals`); None: not known (ranked as one hour).
    """

    key: str
    experiment: str
    quantity: str
    unit: str
    condition: Mapping[str, Any] = field(default_factory=dict)
    label: str = ""
    expected_standard_error: float | None = None
    n_repeats: int = 3
    lab_hours: float | None = None

    def __post_init__(self) -> None:
        for name in ("key", "experiment", "quantity", "unit"):
            v = getattr(self, name)
            if not isinstance(v, str) or not v.strip():
                raise ValueError(f"proposed measurement {self.key!r}: {name} must be a non-empty string, got {v!r}")
        object.__setattr__(self, "condition", MappingProxyType(dict(self.condition)))
        if self.expected_standard_error is not None:
            se = float(self.expected_standard_error)
            if not (math.isfinite(se) and se >= 0):
                raise ValueError(f"proposed measurement {self.key!r}: expected_standard_error must be >= 0, got {se}")
        if isinstance(self.n_repeats, bool) or not isinstance(self.n_repeats, (int, np.integer)) or self.n_repeats < 1:
            raise ValueError(f"proposed measurement {self.key!r}: n_repeats must be an integer >= 1, got {self.n_repeats!r}")
        if self.lab_hours is not None:
            h = float(self.lab_hours)
            if not (math.isfinite(h) and h > 0):
                raise ValueError(f"proposed measurement {self.key!r}: lab_hours must be > 0, got {self.lab_hours!r}")
            object.__setattr__(self, "lab_hours", h)

    @property
    def name(self) -> str:
        return self.label or self.key

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "experiment": self.experiment, "quantity": self.quantity, "unit": self.unit,
                "condition": dict(self.condition), "label": self.label,
                "expected_standard_error": self.expected_standard_error, "n_repeats": self.n_repeats,
                "lab_hours": self.lab_hours}


class ForwardModel(ABC):
    """What the diagnosis needs from a simulator."""

    @abstractmethod
    def evaluate(self, effects: tuple[str, ...], parameter_sets: Sequence[Mapping[str, float]],
                 replicates: int, keys: Sequence[str]) -> np.ndarray:
        """Simulate ``keys`` for every parameter set, ``replicates`` independent fills each.

        effects : names of the effects switched on (empty: base model).
        parameter_sets : one ``{parameter name: value}`` per set (base + effect parameters).
        replicates : independent fills per set (>= 1); a model with ``per_set_replicates`` also
            takes one count per set.
        keys : observable keys (measured ones, or keys of :meth:`proposals`).

        Returns an array of shape ``(len(parameter_sets), replicates, len(keys))`` in each
        observable's unit (the largest count for per-set counts, NaN past a set's own); NaN where a
        run failed.
        """

    def proposals(self) -> Sequence[ProposedMeasurement]:
        """Conditions the model can predict that were not measured (for telling candidates apart)."""
        return ()


class ForwardRunner:
    """Calls a :class:`ForwardModel`, checks every answer, counts runs and wall time (s)."""

    def __init__(self, model: ForwardModel):
        if not hasattr(model, "evaluate") or not callable(model.evaluate):
            raise TypeError(f"forward model must have an evaluate(...) method, got {type(model).__name__}")
        self.model = model
        self._lock = threading.Lock()  # candidate studies may call from several threads
        self.calls = 0
        self.runs = 0
        self.failed_runs = 0
        self.values = 0  # observables asked for over all runs
        self.missing_values = 0  # of which no value came back (a measurement failed)
        self.seconds = 0.0

    def __call__(self, effects: tuple[str, ...], parameter_sets: Sequence[Mapping[str, float]],
                 replicates: int | Sequence[int], keys: Sequence[str]) -> np.ndarray:
        """Simulate; ``replicates`` is one fill count for every set or one per set. Returns
        ``(n_sets, largest count, n_keys)``, NaN past each set's count and where a run failed."""
        if len(parameter_sets) == 0:
            raise ValueError("no parameter sets to evaluate")
        counts = replicate_counts(replicates, len(parameter_sets))
        t0 = time.perf_counter()
        out = evaluate_counts(self.model, tuple(effects), [dict(p) for p in parameter_sets], counts, tuple(keys))
        with self._lock:
            self.seconds += time.perf_counter() - t0
        ran = np.arange(out.shape[1])[None, :] < counts[:, None]  # (n, r): the runs asked for
        with self._lock:
            self.calls += 1
            self.runs += int(counts.sum())
            self.failed_runs += int(np.sum(np.all(np.isnan(out), axis=2) & ran))
            self.values += int(np.sum(ran)) * out.shape[2]
            self.missing_values += int(np.sum(np.isnan(out) & ran[:, :, None]))
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"calls": self.calls, "runs": self.runs, "failed_runs": self.failed_runs, "values": self.values,
                "missing_values": self.missing_values, "seconds": self.seconds}


def replicate_counts(replicates: int | Sequence[int], n_sets: int) -> np.ndarray:
    """Fills per set, shape (n_sets,), from one count for all or one per set; each an integer >= 1."""
    def ok(r: Any) -> bool:
        return not isinstance(r, bool) and isinstance(r, (int, np.integer)) and r >= 1

    if isinstance(replicates, (int, np.integer)) and not isinstance(replicates, bool):
        if not ok(replicates):
            raise ValueError(f"replicates must be an integer >= 1, got {replicates!r}")
        return np.full(n_sets, int(replicates), dtype=int)
    if isinstance(replicates, (str, bytes)) or not isinstance(replicates, (Sequence, np.ndarray)):
        raise ValueError(f"replicates must be an integer >= 1 or one per set, got {replicates!r}")
    counts = list(replicates)
    if len(counts) != n_sets or not all(ok(r) for r in counts):
        raise ValueError(f"replicates per set must be {n_sets} integers >= 1, got {counts!r}")
    return np.asarray(counts, dtype=int)


def evaluate_counts(model: ForwardModel, effects: tuple[str, ...], parameter_sets: list[dict[str, float]],
                    counts: np.ndarray, keys: tuple[str, ...]) -> np.ndarray:
    """``model.evaluate`` with ``counts[i]`` fills for set i, checked: one call when every count is
    the same or the model takes per-set counts (``per_set_replicates``), else one call per count.
    Returns ``(n_sets, max(counts), n_keys)`` with NaN past each set's count."""
    name = type(model).__name__
    r_max = int(counts.max())
    if np.all(counts == r_max):
        groups = [(np.arange(len(counts)), r_max)]
    elif getattr(model, "per_set_replicates", False):
        groups = [(np.arange(len(counts)), tuple(int(c) for c in counts))]
    else:
        groups = [(np.flatnonzero(counts == c), int(c)) for c in np.unique(counts)]
    out = np.full((len(counts), r_max, len(keys)), np.nan)
    for idx, reps in groups:
        got = np.asarray(model.evaluate(effects, [parameter_sets[i] for i in idx], reps, keys), dtype=float)
        width = reps if isinstance(reps, int) else r_max
        want = (len(idx), width, len(keys))
        if got.shape != want:
            raise ValueError(f"forward model {name}.evaluate returned shape {got.shape}, expected "
                             f"(n_sets, replicates, n_keys) = {want} for keys {list(keys)}")
        if np.any(np.isinf(got)):
            raise ValueError(f"forward model {name}.evaluate returned infinite values; use NaN for a failed run")
        out[idx, :width] = got
    out[np.arange(r_max)[None, :] >= counts[:, None]] = np.nan  # nothing past a set's own count
    return out


def merges_versions(model: Any) -> bool:
    """True when ``model`` follows the superset protocol (module docstring): the designs of every
    model version can go into one call of it."""
    return (bool(getattr(model, "superset", False)) and getattr(model, "effects", None) is not None
            and callable(getattr(model, "padded", None)))


def runs_on_cuda(model: Any) -> bool:
    """True when ``model`` says it simulates on a CUDA device (``on_cuda``); False when it does not say."""
    return bool(getattr(model, "on_cuda", False))


def worlds_per_run(model: Any, keys: Sequence[str]) -> int:
    """Simulations one (parameter set, fill) of ``keys`` takes in ``model`` (1 unless it says)."""
    f = getattr(model, "worlds_per_run", None)
    return int(f(tuple(keys))) if callable(f) else 1
