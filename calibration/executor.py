"""Where a batch of DEM worlds runs: in this machine's processes, or spread over a Ray cluster.

The unit of work stays a *batch of worlds* (one model, one launch on one device). An executor only
decides where the batches of one :meth:`Experiment.run` go:

* :class:`LocalExecutor` (default, the behaviour before executors existed): on the CPU the worlds
  are split over ``processes`` local processes; on a GPU one launch runs them all.
* :class:`RayExecutor`: the worlds are split into ``tasks`` contiguous batches (default: one per GPU
  of the cluster, or one per CPU on a CPU-only cluster), each a Ray task holding ``gpus_per_task``
  GPUs. Results come back to the driver, which alone writes the records and caches, so resume,
  fingerprints and reports are unchanged. A worker or node that dies mid-batch loses that batch
  only: Ray runs the task again elsewhere (``max_retries``). A task that fails in the experiment
  code (a bad setting, an unstable world raising) is not retried; its own exception reaches the
  caller, with the same message as in a local run.

Same numbers: a batch's worlds take their fills by world index (``first_fill_index + world``), so a
split never changes a world's fill; the time step (the material's smallest possible sphere), the
walls' height and their motion start (the tallest loose column the fill mass can form) follow the
settings and the material, not the fills of a batch, and each world settles, and lifts the hollow
cylinder, on its own. So a world's result is bitwise the same in any split and on any executor on
the same device kind (a Ray run with ``tasks = n`` equals a local CPU run with ``processes = m``).
Ray is an optional dependency (``pip install "warpdem[ray]"``).
"""
from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from warpdem import ConfigError

__all__ = ["LocalExecutor", "RayExecutor", "Executor", "executor_from_config", "RAY_HINT"]

RAY_HINT = 'Ray is not installed: pip install "warpdem[ray]" (or pip install ray)'


@dataclass(frozen=True)
class LocalExecutor:
    """Batches run here: split over ``processes`` local processes on the CPU ("auto": one per
    usable core), one launch on a GPU."""

    processes: int | str | None = "auto"
    kind = "local"

    def describe(self) -> dict[str, Any]:
        return {"kind": self.kind, "processes": self.processes}


@dataclass(frozen=True)
class RayExecutor:
    """Batches run as Ray tasks on a cluster.

    address: ``"auto"`` (a running cluster, e.g. started with ``ray start --head``), ``"local"``
        (start a private cluster in this process; ``num_cpus``/``num_gpus`` size it) or
        ``"ray://host:port"`` (Ray Client).
    gpus_per_task: GPUs one batch holds (1: one launch per GPU); 0 on CPU-only clusters.
    cpus_per_task: CPU cores one batch holds.
    tasks: batches one experiment run is split into (None: the cluster's GPUs, or its CPUs divided
        by ``cpus_per_task`` when it has none).
    max_retries: times a batch whose worker or node died is run again.
    """

    address: str = "auto"
    gpus_per_task: float = 1.0
    cpus_per_task: float = 1.0
    tasks: int | None = None
    max_retries: int = 3
    num_cpus: int | None = None
    num_gpus: int | None = None
    kind = "ray"

    def __post_init__(self) -> None:
        if not isinstance(self.address, str) or not self.address:
            raise ConfigError(f"executor.address must be 'auto', 'local' or 'ray://host:port', got {self.address!r}")
        for name in ("gpus_per_task", "cpus_per_task"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or v < 0:
                raise ConfigError(f"executor.{name} must be a number >= 0, got {v!r}")
        for name in ("tasks", "num_cpus", "num_gpus"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
                raise ConfigError(f"executor.{name} must be a positive integer, got {v!r}")
        if isinstance(self.max_retries, bool) or not isinstance(self.max_retries, int) or self.max_retries < 0:
            raise ConfigError(f"executor.max_retries must be an integer >= 0, got {self.max_retries!r}")

    def describe(self) -> dict[str, Any]:
        return {"kind": self.kind, "address": self.address, "gpus_per_task": self.gpus_per_task,
                "cpus_per_task": self.cpus_per_task, "tasks": self.tasks, "max_retries": self.max_retries}

    # ------------------------------------------------------------------ cluster
    def connect(self) -> Any:
        """The ``ray`` module, connected to this executor's cluster (once per process)."""
        try:
            import ray
        except ImportError:
            raise ConfigError(RAY_HINT) from None
        if not ray.is_initialized():
            kwargs: dict[str, Any] = {"log_to_driver": False, "include_dashboard": False}
            if self.address == "local":
                kwargs.update(num_cpus=self.num_cpus, num_gpus=self.num_gpus)
            else:
                kwargs["address"] = self.address
            # the workers import the project from the driver's path (an installed package needs nothing)
            kwargs["runtime_env"] = {"env_vars": {"PYTHONPATH": os.pathsep.join(
                p for p in [os.environ.get("PYTHONPATH", ""), _project_root()] if p)}}
            try:
                ray.init(**kwargs)
            except ConnectionError as exc:
                raise ConfigError(f"executor: cannot reach the Ray cluster at {self.address!r} ({exc}); start one "
                                  f"with 'ray start --head' or use address: local") from None
        return ray

    def task_count(self, worlds: int, on_gpu: bool) -> int:
        """Batches a run of ``worlds`` worlds is split into."""
        if self.tasks is not None:
            return max(1, min(self.tasks, worlds))
        res = self.connect().cluster_resources()
        if on_gpu and self.gpus_per_task > 0:
            slots = int(res.get("GPU", 0) // self.gpus_per_task)
        else:
            slots = int(res.get("CPU", 1) // max(self.cpus_per_task, 1e-9))
        return max(1, min(slots, worlds))

    def remote_function(self, ray: Any, fn: Callable, on_gpu: bool) -> Any:
        """``fn`` as a Ray remote function with this executor's resources. A task that holds GPUs
        runs in a worker process of its own (``max_calls=1``, Ray's default for functions declared
        with GPUs): Ray names a task's GPUs through ``CUDA_VISIBLE_DEVICES``, read once when CUDA
        starts in a process, so a reused worker would run every later task on the GPU of its first
        one, and two tasks of one batch could share a GPU while another stands idle. The price is
        a fresh start per task (Python imports, Warp's start and its kernel cache loaded again)."""
        gpus = self.gpus_per_task if on_gpu else 0
        declared = ray.remote(num_gpus=gpus, max_calls=1)(fn) if gpus > 0 else ray.remote(fn)
        return declared.options(num_gpus=gpus, num_cpus=self.cpus_per_task, max_retries=self.max_retries,
                                retry_exceptions=False)

    def map(self, fn: Callable, calls: list[tuple], on_gpu: bool) -> list[Any]:
        """``[fn(*args) for args in calls]``, each call a Ray task; results in order. The exception of
        a call that failed in ``fn`` is raised as it is (not retried)."""
        ray = self.connect()
        remote = self.remote_function(ray, _call, on_gpu)
        refs = [remote.remote(fn, args) for args in calls]
        try:
            return ray.get(refs)
        except ray.exceptions.RayTaskError as exc:
            cause = getattr(exc, "cause", None)
            raise (cause if isinstance(cause, BaseException) else exc) from None


Executor = LocalExecutor | RayExecutor


def _call(fn: Callable, args: tuple) -> Any:
    return fn(*args)


def _project_root() -> str:
    """The folder holding the ``calibration`` package (on a Ray worker's path)."""
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def executor_from_config(raw: Mapping[str, Any] | None, processes: int | str | None = "auto",
                         where: str = "executor") -> Executor:
    """An executor from a config section ``{kind: local|ray, ...}`` (None: local with ``processes``)."""
    if raw is None:
        return LocalExecutor(processes)
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{where}: expected a mapping such as {{kind: ray, address: auto}}, got {raw!r}")
    raw = dict(raw)
    kind = raw.pop("kind", "local")
    if kind == "local":
        unknown = set(raw) - {"processes"}
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {sorted(unknown)} for kind local (valid: processes)")
        return LocalExecutor(raw.get("processes", processes))
    if kind == "ray":
        valid = {"address", "gpus_per_task", "cpus_per_task", "tasks", "max_retries", "num_cpus", "num_gpus"}
        unknown = set(raw) - valid
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {sorted(unknown)} for kind ray (valid: {sorted(valid)})")
        return RayExecutor(**raw)
    raise ConfigError(f"{where}.kind must be 'local' or 'ray', got {kind!r}")
