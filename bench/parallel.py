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
def cluster(workers: int | None = None, scheduler: str | None = None) -> Iterator:
    """A Dask client: connect to ``scheduler`` or start a local cluster of ``workers`` processes.

    ``workers=None`` means one per core. Yields ``None`` for ``workers == 1`` (run in-process).
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
    n = workers or os.cpu_count() or 1
    with (
        LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.ERROR,
        ) as lc,
        Client(lc) as client,
    ):
        yield client


@contextlib.contextmanager
def mapper(workers: int | None = None, scheduler: str | None = None) -> Iterator[Callable]:
    """A mapper over :func:`cluster` (sequential when ``workers == 1``)."""
    with cluster(workers, scheduler) as client:
        yield sequential_map if client is None else DaskMapper(client)
