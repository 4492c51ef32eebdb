"""Batch checkpoints (:class:`BatchCheckpoints`, ``Experiment.run(..., checkpoints=...)``): a
protocol is a sequence of steps (``settle``, ``advance``, ``jump_clock`` and host work wrapped
in ``once``); between the step chunks of a ``settle`` or an ``advance`` (every
``settle_check_interval`` / ``removal_interval`` of simulated time) the batch saves its simulation
with :func:`warpdem.io.save_checkpoint` plus a JSON sidecar holding the completed steps' results,
the progress of the step under way, the phase times, diagnostics and paused worlds, at most every
``every_s`` wall seconds and once more when the protocol's last step has finished. A re-run of the
same batch (same experiment, settings, parameter sets, fills, code and model) loads it and
continues from that chunk; its results equal the uninterrupted run's (bitwise on the CPU).
"""
from __future__ import annotations

import base64
import hashlib
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Protocol

import numpy as np

import warpdem as wd
from warpdem import ConfigError

from .results_json import jsonable


class CheckpointedExperiment(Protocol):
    """What a checkpoint slot reads of its experiment (an :class:`~.common.Experiment`)."""

    name: str
    scale: str
    first_fill_index: int

    def settings(self) -> dict[str, Any]: ...


class ProtocolState(Protocol):
    """What a checkpoint saves of a running protocol (a :class:`~.run_context.RunContext`)."""

    sim: wd.Simulation
    capacities: dict[str, Any]
    retries: list
    phases: dict[str, float]
    diag: list[dict[str, Any]]
    errors: list[str | None]
    _done: list[dict[str, Any]]

__all__ = ["CHECKPOINT_FORMAT", "BatchCheckpoints", "BatchCheckpoint", "clear_checkpoints", "decode_value",
           "encode_value"]


CHECKPOINT_FORMAT = 1


@dataclass(frozen=True)
class BatchCheckpoints:
    """Where and how often a batch of worlds saves its simulation (``Experiment.run(...,
    checkpoints=...)``; module docstring, "Batch checkpoints").

    folder: checkpoint folder; one slot per batch (per process chunk on the CPU), named
        ``<experiment>-<scale>-fill<first fill index>``: ``.json`` sidecar + ``.<steps>.npz``.
    every_s: wall-clock seconds [s] between saves (a save happens at the first chunk boundary
        after that; 0: at every chunk boundary). The protocol's end is always saved.
    keep_until_recorded: leave a finished batch's checkpoint in place; the caller removes it
        with :func:`clear_checkpoints` once it has recorded the results (a campaign). False:
        :meth:`Experiment.run` removes it when it returns the results.

    Not checkpointed: a run that writes VTK (``vtk_every``; its series cannot be resumed), and
    nothing is saved once a world of the batch was frozen as unstable (a resume starts from the
    last checkpoint before and meets the same failure)."""

    folder: Path
    every_s: float = 120.0
    keep_until_recorded: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "folder", Path(self.folder))
        if not (isinstance(self.every_s, (int, float)) and math.isfinite(self.every_s) and self.every_s >= 0):
            raise ConfigError(f"checkpoints: every_s must be a finite number of seconds >= 0, got {self.every_s!r}")


def clear_checkpoints(folder: str | os.PathLike) -> int:
    """Remove every batch checkpoint (sidecars, ``.npz`` files, temporary files) from ``folder``;
    returns how many files were removed (0 for a missing folder)."""
    folder = Path(folder)
    if not folder.is_dir():
        return 0
    n = 0
    for f in folder.iterdir():
        if f.is_file() and (f.suffix in (".json", ".npz") or ".tmp" in f.name):
            f.unlink(missing_ok=True)
            n += 1
    return n


def encode_value(x: Any) -> Any:
    """JSON-able copy of protocol state; numpy arrays as exact base64 (dtype, shape kept)."""
    if isinstance(x, np.ndarray):
        a = np.ascontiguousarray(x)
        return {"__ndarray__": base64.b64encode(a.tobytes()).decode("ascii"), "dtype": a.dtype.str,
                "shape": list(a.shape)}
    if isinstance(x, dict):
        return {"__dict__": [[encode_value(k), encode_value(v)] for k, v in x.items()]}
    if isinstance(x, (list, tuple)):
        return [encode_value(v) for v in x]
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    return x


def decode_value(x: Any) -> Any:
    if isinstance(x, dict):
        if "__ndarray__" in x:
            return np.frombuffer(base64.b64decode(x["__ndarray__"]), dtype=np.dtype(x["dtype"])).reshape(x["shape"]).copy()
        return {decode_value(k): decode_value(v) for k, v in x["__dict__"]}
    if isinstance(x, list):
        return [decode_value(v) for v in x]
    return x


def _write_atomic_bytes(path: Path, data: bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class BatchCheckpoint:
    """One batch's checkpoint slot: the batch fingerprint, saving and loading."""

    def __init__(self, options: BatchCheckpoints, experiment: CheckpointedExperiment, identity: Mapping[str, Any]) -> None:
        from ..campaign_records import code_version

        self.options = options
        self.folder = options.folder
        self.slot = f"{experiment.name}-{experiment.scale}-fill{int(experiment.first_fill_index)}"
        self.sidecar = self.folder / f"{self.slot}.json"
        # what makes a batch this batch: the experiment and every setting (seed, fill indices),
        # the parameter sets, and the code; the model's fingerprint is checked when loading
        self.identity = jsonable({"format": CHECKPOINT_FORMAT, "experiment": experiment.name,
                                   "settings": experiment.settings(), **identity, "code": code_version()})
        self.fingerprint = hashlib.sha256(json.dumps(self.identity, sort_keys=True).encode()).hexdigest()[:20]
        self.notes: list[str] = []
        self.saves = 0
        self.save_s = 0.0
        self.bytes = 0
        self.resumed: dict[str, Any] | None = None

    def note(self, msg: str) -> None:
        """A checkpoint note: printed (stderr) and kept in the results' timing."""
        self.notes.append(msg)
        print(f"[checkpoint] {msg}", file=sys.stderr, flush=True)

    def remove(self) -> None:
        """Remove this slot's sidecar and every ``.npz`` and temporary file of it."""
        if not self.folder.is_dir():
            return
        for f in self.folder.glob(f"{self.slot}.*"):
            f.unlink(missing_ok=True)

    def read(self) -> dict[str, Any] | None:
        """This batch's saved sidecar, or None (no checkpoint; another batch's or a damaged one
        is reported and removed)."""
        if not self.sidecar.exists():
            return None
        try:
            saved = json.loads(self.sidecar.read_text())
            fp = saved["batch_fingerprint"]
        except (ValueError, KeyError, TypeError, OSError) as exc:
            self.note(f"{self.sidecar} is damaged ({type(exc).__name__}: {exc}); removed, the batch starts over")
            self.remove()
            return None
        if fp != self.fingerprint:
            self.note(f"{self.sidecar} belongs to another batch (fingerprint {fp}, this batch {self.fingerprint}: "
                      "other parameters, settings, fills or code); not used, removed")
            self.remove()
            return None
        return saved

    def load(self, saved: Mapping[str, Any], model: wd.Model, device: str | None, max_neighbours: int | None):
        """The saved Simulation on ``model`` (same fingerprint), or None (reported, removed)."""
        from warpdem.io import load_checkpoint

        npz = self.folder / str(saved.get("npz", ""))
        try:
            if saved.get("model_fingerprint") != model.fingerprint:
                raise ConfigError(f"saved from model {saved.get('model_fingerprint')}, this batch builds model "
                                  f"{model.fingerprint}")
            digest = hashlib.sha256(npz.read_bytes()).hexdigest() if npz.is_file() else None
            if digest != saved.get("npz_sha256"):
                raise ConfigError(f"{npz.name} is missing or does not match its sidecar (damaged)")
            sim = load_checkpoint(npz, device, model=model, max_neighbours=max_neighbours)
        except (ConfigError, OSError) as exc:
            self.note(f"{self.sidecar}: cannot be resumed ({exc}); removed, the batch starts over")
            self.remove()
            return None
        return sim

    def save(self, ctx: ProtocolState, inner: Mapping[str, Any] | None) -> None:
        """Save ``ctx``'s simulation and protocol state (atomically: the ``.npz`` under a new
        name, then the sidecar naming it replaces the old one; the old ``.npz`` is removed)."""
        from warpdem.io import save_checkpoint

        t0 = time.perf_counter()
        sim = ctx.sim
        self.folder.mkdir(parents=True, exist_ok=True)
        npz = self.folder / f"{self.slot}.{sim.steps}.npz"
        tmp = save_checkpoint(self.folder / f"{self.slot}.{sim.steps}.tmp.npz", sim)
        _fsync_file(tmp)
        os.replace(tmp, npz)
        paused = sim.solver.paused_worlds
        side = {"format": CHECKPOINT_FORMAT, "batch_fingerprint": self.fingerprint, "batch": self.identity,
                "model_fingerprint": sim.model.fingerprint, "npz": npz.name,
                "npz_sha256": hashlib.sha256(npz.read_bytes()).hexdigest(), "steps": int(sim.steps),
                "time_s": sim.time, "dt_s": sim.dt, "capacities": ctx.capacities, "retries": ctx.retries,
                "protocol": {"done": ctx._done, "inner": encode_value(inner) if inner is not None else None,
                             "phases": ctx.phases, "diag": encode_value(ctx.diag), "errors": ctx.errors,
                             "paused": [bool(v) for v in paused]},
                "saved": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        _write_atomic_bytes(self.sidecar, json.dumps(side).encode())
        for old in self.folder.glob(f"{self.slot}.*.npz"):
            if old.name != npz.name:
                old.unlink(missing_ok=True)
        self.saves += 1
        self.bytes = npz.stat().st_size + self.sidecar.stat().st_size
        self.save_s += time.perf_counter() - t0

    def summary(self) -> dict[str, Any]:
        return {"folder": str(self.folder), "slot": self.slot, "fingerprint": self.fingerprint,
                "every_s": self.options.every_s, "saves": self.saves, "save_s": round(self.save_s, 3),
                "bytes": self.bytes, "resumed": self.resumed, "notes": list(self.notes)}
