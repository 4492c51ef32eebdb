"""One DEM launch for many studies at once: :class:`PooledForward`.

A diagnosis asks its forward model for small batches: a confirmation here, six refinement points
there, one candidate after another. On a GPU a batch of 2 worlds costs nearly as much wall time
as a batch of 200 (a step of a small model is bound by kernel latency, not by work), so running
those requests one by one wastes the device. :class:`PooledForward` lets several *workers*
(threads: the candidates of one ranking round, or the diagnoses of several measurement sets)
ask at the same time. A request waits until every live worker is waiting; then the requests of
all of them are merged into one call of the underlying model (with a superset model, see
:class:`validation.dem_forward.DEMForwardModel`, that is one launch per experiment for every
model version) and each worker reads its own answer back (from the model's cache).
The designs a diagnosis runs up front (``designs_up_front``, :func:`validation.diagnose.diagnose`)
are its first request, so those of several measurement sets go into one call, where the designs
they share (the same model, settings and seeds) run once.

A merged call holds the requests that the live workers make before they next wait. Within one
diagnosis (its candidates as workers) that is reproducible. With several diagnoses in one process it is
not quite: when a diagnosis's candidate threads finish there is a moment before its own thread counts as
a worker again, and the other diagnoses' waiting requests may be served without it, so the number of
launches varies (5-8 seen for three measurement sets on the analytic test model, 2026-11-27, with the
same numbers). With the DEM a world's fill is numbered by the cache's length when its launch starts, so
another grouping draws other fills from an empty cache: results then move within the fill-to-fill noise.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from .forward import ForwardModel, ProposedMeasurement, evaluate_counts, merges_versions, replicate_counts

__all__ = ["PooledForward", "run_as_workers"]


@dataclass
class _Request:
    effects: tuple[str, ...]
    parameter_sets: list[dict[str, float]]
    replicates: tuple[int, ...]  # fills per set
    keys: tuple[str, ...]
    done: bool = False
    error: BaseException | None = None
    result: np.ndarray | None = field(default=None, repr=False)


class PooledForward(ForwardModel):
    """A :class:`ForwardModel` that merges the concurrent requests of its workers.

    inner : the model that runs the simulations. With ``inner.superset`` (every version shares one
        contact law and material) all requests of one merge go into one call (one per fill count
        when the inner model does not take per-set counts); otherwise one call per model version.

    Threads that call :meth:`evaluate` must be registered workers (:meth:`worker` or
    :func:`run_as_workers`); an unregistered caller is served at once, alone.
    """

    def __init__(self, inner: ForwardModel) -> None:
        self.inner = inner
        self._cv = threading.Condition()
        self._workers = 0
        self._pending: list[_Request] = []
        self._local = threading.local()
        self.merges: list[dict[str, Any]] = []  # one entry per merged call: requests, sets, worlds

    # ------------------------------------------------------------------ workers
    @property
    def _is_worker(self) -> bool:
        return getattr(self._local, "depth", 0) > 0

    @contextmanager
    def worker(self) -> Iterator[None]:
        """Register the calling thread as a worker for the duration of the block."""
        with self._cv:
            self._workers += 1
        self._local.depth = getattr(self._local, "depth", 0) + 1
        try:
            yield
        finally:
            self._local.depth -= 1
            with self._cv:
                self._workers -= 1
                self._serve_if_all_waiting()

    @contextmanager
    def idle(self) -> Iterator[None]:
        """A worker that waits on other workers (its child threads) does not count meanwhile."""
        if not self._is_worker:
            yield
            return
        with self._cv:
            self._workers -= 1
            self._serve_if_all_waiting()
        try:
            yield
        finally:
            with self._cv:
                self._workers += 1

    def _add_workers(self, n: int) -> None:
        with self._cv:
            self._workers += n

    def _leave(self) -> None:
        with self._cv:
            self._workers -= 1
            self._serve_if_all_waiting()

    # ------------------------------------------------------------------ ForwardModel
    per_set_replicates = True  # requests may hold one fill count per set (validation.forward)

    def evaluate(self, effects: tuple[str, ...], parameter_sets: Sequence[Mapping[str, float]],
                 replicates: int | Sequence[int], keys: Sequence[str]) -> np.ndarray:
        counts = replicate_counts(replicates, len(parameter_sets))
        req = _Request(tuple(effects), [dict(p) for p in parameter_sets], tuple(int(c) for c in counts), tuple(keys))
        with self._cv:
            self._pending.append(req)
            if not self._is_worker:
                self._serve(list(self._pending))
                self._pending.clear()
            else:
                self._serve_if_all_waiting()
            while not req.done:
                self._cv.wait()
        if req.error is not None:
            raise req.error
        return req.result

    def proposals(self) -> Sequence[ProposedMeasurement]:
        return self.inner.proposals()

    def __getattr__(self, name: str) -> Any:  # the inner model's other attributes (observables, log, ...)
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)

    # ------------------------------------------------------------------ merging
    def _serve_if_all_waiting(self) -> None:
        """(Lock held.) Run the pending requests once every live worker is waiting on one."""
        if self._pending and len(self._pending) >= self._workers:
            batch = list(self._pending)
            self._pending.clear()
            self._serve(batch)

    def _serve(self, batch: list[_Request]) -> None:
        """(Lock held.) One merged call of the inner model, then every request's own answer."""
        inner = self.inner
        try:
            if merges_versions(inner):
                # every distinct (padded) set once, with the most fills any request asks of it: one call
                # when the inner model takes per-set counts, else one per count (evaluate_counts)
                all_effects = tuple(inner.effects)
                most: dict[tuple, int] = {}
                padded_sets: dict[tuple, dict[str, float]] = {}
                for r in batch:
                    for p, c in zip(r.parameter_sets, r.replicates):
                        padded = inner.padded(r.effects, p)
                        key = tuple(sorted(padded.items()))
                        padded_sets.setdefault(key, padded)
                        most[key] = max(most.get(key, 0), c)
                keys = tuple(dict.fromkeys(k for r in batch for k in r.keys))
                counts = np.array([most[k] for k in padded_sets], dtype=int)
                evaluate_counts(inner, all_effects, list(padded_sets.values()), counts, keys)
                distinct = sorted(set(counts.tolist()))
                self.merges.append({"requests": len(batch), "sets": len(padded_sets),
                                    "replicates": distinct[0] if len(distinct) == 1 else distinct,
                                    "keys": len(keys)})
            for r in batch:  # superset: every world is cached now; otherwise each version runs here
                r.result = evaluate_counts(inner, r.effects, r.parameter_sets, np.array(r.replicates), r.keys)
        except BaseException as exc:  # every waiting worker learns of the failure
            for r in batch:
                if r.result is None:
                    r.error = exc
        for r in batch:
            r.done = True
        self._cv.notify_all()


def run_as_workers(pool: ForwardModel, tasks: Sequence[Callable[[], Any]],
                   names: Sequence[str] | None = None) -> list[Any]:
    """Run ``tasks`` in threads, each a worker of ``pool`` when it is a :class:`PooledForward`
    (else one after another); returns their results in order, re-raising the first error.
    ``names`` label the threads (progress lines say which task they come from).

    A calling worker is idle while its tasks run, and the tasks are registered before any of
    them starts, so their first requests are merged."""
    if not isinstance(pool, PooledForward) or len(tasks) <= 1:
        return [t() for t in tasks]
    results: list[Any] = [None] * len(tasks)
    errors: list[BaseException | None] = [None] * len(tasks)

    def body(i: int) -> None:
        pool._local.depth = getattr(pool._local, "depth", 0) + 1
        try:
            results[i] = tasks[i]()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller below
            errors[i] = exc
        finally:
            pool._local.depth -= 1
            pool._leave()

    pool._add_workers(len(tasks))
    parent = threading.current_thread().name  # nested workers keep their diagnosis's name
    default = (lambda i: f"pooled-worker-{i}") if parent == "MainThread" else (lambda i: parent)
    threads = [threading.Thread(target=body, args=(i,), name=names[i] if names else default(i), daemon=True)
               for i in range(len(tasks))]
    with pool.idle():
        for th in threads:
            th.start()
        for th in threads:
            th.join()
    for e in errors:
        if e is not None:
            raise e
    return results
