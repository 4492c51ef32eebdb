"""The run context of one experiment protocol: the simulation, phase bookkeeping and read-backs,
and the steps (``settle``, ``advance``, host work in ``once``) that a batch checkpoint can resume
(:mod:`calibration.experiments.checkpoints`)."""
from __future__ import annotations

import sys
import time
from typing import Any, Mapping, Protocol

import numpy as np

import warpdem as wd
from warpdem import ConfigError
from warpdem.solver import SettleProgress, SettleReport

from ..filling import FillResult, active_bodies, active_spheres, run_for
from ..measurement import MeasurementError
from .checkpoints import BatchCheckpoint, decode_value, encode_value

__all__ = ["ProtocolSettings", "RunContext"]


class ProtocolSettings(Protocol):
    """What a run context reads of its experiment (an :class:`~.common.Experiment`): its name for
    the progress lines and the settle and removal numerics."""

    name: str
    ke_per_particle: float
    settle_check_interval: float
    removal_interval: float


class RunContext:
    """What a protocol needs during a run: the simulation, phase bookkeeping, read-backs."""

    def __init__(self, experiment: ProtocolSettings, sim: wd.Simulation, fills: list[FillResult],
                 progress: bool, checkpoint: BatchCheckpoint | None = None,
                 resume: Mapping[str, Any] | None = None, capacities: Mapping[str, Any] | None = None,
                 retries: list | None = None) -> None:
        self.exp = experiment
        self.sim = sim
        self.model = sim.model
        self.fills = fills
        self.num_worlds = sim.model.num_worlds
        self.progress = progress
        self.phases: dict[str, float] = {}
        self.diag: list[dict[str, Any]] = [dict() for _ in range(self.num_worlds)]
        self.errors: list[str | None] = [None] * self.num_worlds
        self._t0 = time.perf_counter()
        # protocol steps (module docstring, "Batch checkpoints"): the results of the completed
        # ones (JSON-able), and on a resume the saved protocol state to continue from
        self.checkpoint = checkpoint
        self.capacities = dict(capacities or {})
        self.retries = list(retries or [])
        self._done: list[dict[str, Any]] = []
        self._n_steps = 0
        self._resume: dict[str, Any] | None = None
        self._last_save = time.perf_counter()
        if resume is not None:
            self._done = list(resume["done"])
            self._resume = dict(resume)
            self.phases = dict(resume["phases"])
            self.diag = decode_value(resume["diag"])
            self.errors = list(resume["errors"])
            paused = np.asarray(resume["paused"], dtype=bool)
            if paused.any():  # the solver's paused flags are not part of a warpdem checkpoint
                sim.pause_worlds(paused)
        self.vtk = None  # VTK time series of one world, when the experiment asks for it (vtk_every)
        if experiment.vtk_every is not None:
            from warpdem.io import VtkSeries

            if not 0 <= int(experiment.vtk_world) < self.num_worlds:
                raise ConfigError(f"{experiment.name}: vtk_world {experiment.vtk_world} does not exist "
                                  f"(this run has {self.num_worlds} world(s))")
            self.vtk = VtkSeries(experiment.vtk_directory(), int(experiment.vtk_world))
            self.vtk_steps = max(1, int(round(float(experiment.vtk_every) / sim.dt)))
            self.vtk.write(sim)

    def fill(self, world: int) -> FillResult:
        return self.fills[world if len(self.fills) > 1 else 0]

    def log(self, msg: str) -> None:
        if self.progress:
            print(f"[{self.exp.name} {time.perf_counter() - self._t0:7.1f} s wall, t={self.sim.time:6.3f} s] {msg}",
                  file=sys.stderr, flush=True)

    def _phase(self, name: str, seconds: float) -> None:
        self.phases[name] = self.phases.get(name, 0.0) + float(seconds)

    def _recording_vtk(self):
        """Context in which every ``Simulation.run`` writes a VTK frame each ``vtk_every`` seconds
        of simulated time (a no-op without ``vtk_every``)."""
        import contextlib

        if self.vtk is None:
            return contextlib.nullcontext()
        sim, plain_run = self.sim, self.sim.run

        def run(steps, check_every=1000, callback=None, callback_every=0, progress=False, **kwargs):
            # kwargs: Simulation.run's further options (e.g. on_unstable), passed on untouched
            if callback is not None:
                return plain_run(steps, check_every, callback, callback_every, progress, **kwargs)
            return plain_run(steps, check_every, self.vtk.write, self.vtk_steps, progress, **kwargs)

        @contextlib.contextmanager
        def recording():
            sim.run = run
            try:
                yield
            finally:
                del sim.run
        return recording()

    # ------------------------------------------------------------------ protocol steps
    def _step(self, label: str) -> tuple[str, Any]:
        """Enter the next protocol step: ``("new", None)``, ``("done", its saved result)`` when a
        resumed batch completed it before, or ``("continue", saved progress)`` for the step the
        checkpoint was taken in."""
        i = self._n_steps
        self._n_steps += 1
        r = self._resume
        if r is None:
            return "new", None
        if i < len(self._done):
            if self._done[i]["label"] != label:
                raise RuntimeError(f"{self.exp.name}: resumed protocol step {i} is {label!r}, the checkpoint "
                                   f"recorded {self._done[i]['label']!r}")
            return "done", decode_value(self._done[i]["value"])
        self._resume = None
        inner = r.get("inner")
        if inner is not None:
            inner = decode_value(inner)
            if inner.get("label") != label:
                raise RuntimeError(f"{self.exp.name}: resumed protocol step {i} is {label!r}, the checkpoint "
                                   f"was taken in {inner.get('label')!r}")
            return "continue", inner
        return "new", None

    def _finish_step(self, label: str, value: Any) -> Any:
        self._done.append({"label": label, "value": encode_value(value)})
        return value

    def _maybe_save(self, inner: Mapping[str, Any]) -> None:
        """Save a checkpoint (between step chunks) when ``every_s`` wall seconds have passed
        since the last one; never once a world was frozen as unstable."""
        ck = self.checkpoint
        if ck is None or time.perf_counter() - self._last_save < ck.options.every_s:
            return
        self.save_checkpoint(inner)

    def save_checkpoint(self, inner: Mapping[str, Any] | None = None) -> None:
        """Save now (``inner``: progress of the step under way; None: between steps)."""
        if self.checkpoint is None or self.sim.failed_worlds():
            return
        self.checkpoint.save(self, inner)
        self._last_save = time.perf_counter()
        self.log(f"checkpoint saved at step {self.sim.steps} ({self.checkpoint.sidecar})")

    def once(self, label: str, fn):
        """Host work between simulated phases (a measurement, a levelling, a lift plan): run
        ``fn()`` and keep its result (JSON-able, numpy arrays allowed) in the checkpoint; a
        resumed batch that had done it returns the kept result without calling ``fn``."""
        how, saved = self._step(label)
        if how == "done":
            return saved
        return self._finish_step(label, fn())

    def settle(self, name: str, max_time: float | np.ndarray, min_time: float | np.ndarray = 0.0,
               remove_box=None) -> SettleReport:
        """Spec "settled" criterion (KE per particle < ``ke_per_particle`` [J] after
        ``min_time``, or ``max_time`` [s]; per world): :meth:`warpdem.Simulation.settle`, with a
        checkpoint between its chunks and continued from a checkpoint's progress."""
        label = f"settle:{name}"
        how, saved = self._step(label)
        if how == "done":
            return SettleReport(saved["time"], saved["settled"], np.asarray(saved["ke"]), saved["removed"],
                                saved["failed"])
        sim, exp = self.sim, self.exp
        nw = self.num_worlds
        start = None
        if how == "continue":
            start = SettleProgress(int(saved["done"]), int(saved["removed"]),
                                   np.asarray(saved["ke_report"], dtype=float),
                                   np.asarray(saved["paused"], dtype=bool), np.asarray(saved["met"], dtype=bool))

        def save(pg: SettleProgress) -> None:
            self._maybe_save(dict(label=label, done=pg.done, removed=pg.removed, ke_report=pg.ke_report,
                                  paused=pg.paused, met=pg.met))

        with self._recording_vtk():
            rep = sim.settle(exp.ke_per_particle, max_time, exp.settle_check_interval, min_time, remove_box,
                             start=start, after_chunk=save)
        ke_report, removed, failed = rep.ke_per_particle, rep.removed, rep.failed
        self._finish_step(label, dict(time=rep.time, settled=rep.settled, ke=ke_report, removed=removed,
                                      failed=failed))
        self._phase(name, rep.time)
        for w in range(nw):
            self.diag[w][f"{name}_ke_per_particle_J"] = float(rep.ke_per_particle[w])
            self.diag[w][f"{name}_settled"] = bool(rep.ke_per_particle[w] < exp.ke_per_particle)
        self.log(f"{name}: {rep.time:.3f} s simulated, settled={rep.settled}, max KE/particle "
                 f"{rep.ke_per_particle.max():.2e} J")
        return rep

    def advance(self, name: str, duration: float, remove_box=None) -> None:
        """Advance ``duration`` [s] (to the nearest step), removing bodies outside ``remove_box``
        every ``removal_interval`` [s] (:func:`calibration.filling.run_for`), with checkpoints
        between those chunks (none without a ``remove_box``)."""
        label = f"advance:{name}"
        how, saved = self._step(label)
        if how == "done":
            return
        sim = self.sim
        if how == "continue":
            steps, done, removed = int(saved["steps"]), int(saved["done"]), int(saved["removed"])
        else:
            steps, done, removed = int(round(duration / sim.dt)), 0, 0
        with self._recording_vtk():
            if remove_box is None or steps <= 0:
                steps, removed = run_for(sim, duration, remove_box, self.exp.removal_interval)
            else:
                every = max(1, int(round(self.exp.removal_interval / sim.dt)))
                while done < steps:
                    k = min(every, steps - done)
                    sim.run(k, check_every=k)
                    removed += sim.remove_outside(*remove_box)
                    done += k
                    if done < steps:
                        self._maybe_save(dict(label=label, steps=steps, done=done, removed=removed))
        self._finish_step(label, dict(steps=steps, removed=removed))
        self._phase(name, steps * sim.dt)
        self.log(f"{name}: {steps * sim.dt:.3f} s simulated, {removed} particle(s) removed")

    def advance_to(self, name: str, t: float, remove_box=None) -> None:
        """Advance until the clock reads ``t`` [s] (to the nearest step)."""
        self.advance(name, t - self.sim.time, remove_box)

    def jump_clock(self, t: float) -> None:
        """Move the clock forward to ``t`` [s] (module docstring, "Protocol clock")."""
        how, _ = self._step("jump_clock")
        if how == "done":
            return
        self._finish_step("jump_clock", float(t))
        now = self.sim.time
        if t < now - 0.5 * self.sim.dt:
            raise RuntimeError(f"protocol clock: cannot move back from {now} s to {t} s")
        self.sim.state.time.assign(np.array([t], dtype=np.float64))

    def world_spheres(self, world: int, positions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        return active_spheres(self.sim, world, positions)

    def world_bodies(self, world: int) -> tuple[np.ndarray, np.ndarray]:
        return active_bodies(self.sim, world)

    def measure(self, world: int, what: str, fn, *args, **kwargs):
        """Call a measurement; a MeasurementError marks the world failed (returns None)."""
        if self.errors[world] is not None:
            return None
        try:
            return fn(*args, **kwargs)
        except MeasurementError as exc:
            self.errors[world] = f"{what}: {exc}"
            return None

    def removed_per_world(self) -> np.ndarray:
        act = self.sim.state.body_active.numpy()
        return np.bincount(self.model.host["body_world"], weights=1 - act, minlength=self.num_worlds).astype(int)
