"""Parallel ``map`` for objectives: sequential in-process, or a Dask distributed cluster.

A *mapper* is any callable ``mapper(fn, items) -> list`` with the semantics of ``list(map(fn,
items))``; the objective uses it to evaluate Jacobian columns and populations as one batch.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable, Iterator

from problems.inverse.evaluator import sequential_map

#: environment that pins BLAS/OpenMP to one thread in each worker process
SINGLE_THREAD_ENV = {
    k: "1"
    for k in (
        "OMP_NUM_THREADS",
        "OPENBLAS_NUM_THREADS",
        "MKL_NUM_THREADS",
        "VECLIB_MAXIMUM_THREADS",
        "NUMEXPR_NUM_THREADS",
    )
}


class DaskMapper:
    """``mapper(fn, items)`` that submits each item to a Dask client and gathers in order."""

    def __init__(self, client):
        self.client = client

    def __call__(self, fn, items) -> list:
        items = list(items)
        if not items:
            return []
        futures = self.client.map(fn, items, pure=False)
        return self.client.gather(futures)

    def __reduce__(self):  # a mapper never travels to workers; there it degrades to sequential
        return (_sequential, ())


def _sequential():
    return sequential_map


class WorkerClientMapper:
    """``mapper(fn, items)`` that fans ``items`` out to the cluster the calling task runs on.

    Only valid inside a Dask task; the task secedes from the worker's thread pool while it
    waits, so it never deadlocks a saturated cluster. Falls back to a loop for one item.
    """

    def __call__(self, fn, items):
        items = list(items)
        if len(items) <= 1:
            return sequential_map(fn, items)
        from distributed import worker_client

        with worker_client() as client:
            return client.gather(client.map(fn, items, pure=False))


@contextlib.contextmanager
def sigint_ignored() -> Iterator[None]:
    """Ignore SIGINT while worker processes start, so that they inherit that (a terminal's
    Ctrl-C reaches the whole process group): the parent alone handles it, closes the workers and
    says so in one line, instead of every worker printing a traceback. A no-op outside the main
    thread."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def cap_workers(workers: int | None) -> int:
    """Local worker processes for ``workers`` (None: one per core), capped at the cores."""
    try:
        cores = max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - macOS, Windows
        cores = max(1, os.cpu_count() or 1)
    return cores if workers is None else max(1, min(workers, cores))


@contextlib.contextmanager
def cluster(workers: int | None = None, scheduler: str | None = None) -> Iterator:
    """A Dask client: connect to ``scheduler`` or start a local cluster of ``workers`` processes.

    ``workers=None`` means one per core, and more than the cores are capped at the cores
    (:func:`cap_workers`). Yields ``None`` for ``workers == 1`` (run in-process). The workers
    ignore Ctrl-C (:func:`sigint_ignored`).
    """
    if workers is not None and workers < 1:
        raise ValueError(f"workers = {workers} is out of range: must be >= 1")
    if scheduler is None and workers == 1:
        yield None
        return
    from distributed import Client, LocalCluster

    if scheduler is not None:
        client = Client(scheduler)
        try:
            yield client
        finally:
            client.close()
        return
    os.environ.update(SINGLE_THREAD_ENV)  # inherited by the worker processes
    with sigint_ignored():
        lc = LocalCluster(
            n_workers=cap_workers(workers),
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
    with lc, Client(lc) as client:
        yield client


@contextlib.contextmanager
def mapper(workers: int | None = None, scheduler: str | None = None) -> Iterator[Callable]:
    """A mapper over :func:`cluster` (sequential when ``workers == 1``)."""
    with cluster(workers, scheduler) as client:
        yield sequential_map if client is None else DaskMapper(client)
