"""Independent work items on worker threads, results taken in item order.

The tracer's tiles and the photon tracer's batches are pure functions of
their index (each has its own random stream), so running them on threads and
consuming the results in index order gives the same image whatever the
thread count.  Embree, numba kernels (``nogil``) and numpy's large array
operations release the GIL, which is where the threads gain.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterator, TypeVar

from .errors import RenderCancelled

__all__ = ["worker_count", "ordered_map"]

T = TypeVar("T")


def worker_count(settings) -> int:
    """Worker threads for ``settings.threads`` (0 or missing = all cores), at least 1."""
    n = int(getattr(settings, "threads", 0) or 0)
    return max(1, n if n > 0 else (os.cpu_count() or 1))


def ordered_map(fn: Callable[[int], T], n_items: int, workers: int, cancel=None) -> Iterator[T]:
    """Yield ``fn(0), fn(1), ... fn(n_items - 1)`` in order, computed on up to ``workers`` threads.

    Up to two items per worker are in flight ahead of the one being yielded.
    ``cancel() -> bool`` is polled before each item; when it says so,
    :class:`RenderCancelled` is raised and items not started are dropped
    (running ones finish first).  An exception in ``fn`` is raised here, at
    its item.
    """
    if workers <= 1 or n_items <= 1:
        for i in range(n_items):
            if cancel is not None and cancel():
                raise RenderCancelled("render cancelled")
            yield fn(i)
        return
    pool = ThreadPoolExecutor(max_workers=workers)
    pending: dict = {}
    try:
        for i in range(n_items):
            if cancel is not None and cancel():
                raise RenderCancelled("render cancelled")
            for j in range(i, min(i + 2 * workers, n_items)):
                if j not in pending:
                    pending[j] = pool.submit(fn, j)
            yield pending.pop(i).result()
    finally:
        for fut in pending.values():
            fut.cancel()
        pool.shutdown(wait=True)
