"""Forked worker processes for the planner's per-vehicle work.

A plan's per-vehicle work (each vehicle's cost-to-go field, each route's finishing) is pure
and large for a large team. Workers are forked so that what they read (the world, the problem
with its cost maps, tens of MB for a large team) is inherited with the parent's memory rather
than pickled; only the items and the results cross. A process that runs other threads is not
forked (a forked child can deadlock on a lock another thread held), nor where fork is
unavailable: the caller then does the work itself, with the same results.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Generic, TypeVar

S = TypeVar("S")
T = TypeVar("T")
R = TypeVar("R")

PARALLEL_MIN_VEHICLES = 20
"""A team at least this large is planned on every core by default (:func:`default_workers`):
below it, forking costs about as much as it saves."""

_SHARED: tuple[Callable[[Any, Any], Any], Any] | None = None
# What forked workers call and read: inherited with the parent's memory, never pickled.


def default_workers(vehicles: int) -> int:
    """Workers for a team of ``vehicles``: the cores this process may use from
    :data:`PARALLEL_MIN_VEHICLES` vehicles on, else 1."""
    if vehicles < PARALLEL_MIN_VEHICLES:
        return 1
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # no affinity on this platform
        return max(1, os.cpu_count() or 1)


def forked_map(
    fn: Callable[[S, T], R], shared: S, items: Sequence[T], workers: int
) -> list[R] | None:
    """``[fn(shared, item) for item in items]`` in up to ``workers`` forked processes, in
    order; the first item that raises raises here. None when it cannot fork (fewer than two
    workers or items, other threads running, no fork): the caller does the work itself."""
    with ForkedWorkers(fn, shared, min(workers, len(items))) as pool:
        return pool.map(items) if pool.forked else None


class ForkedWorkers(Generic[S, T, R]):
    """Forked processes kept for several :meth:`map` calls of one ``fn(shared, item)``.

    ``shared`` is inherited at the fork, never pickled: memory the caller maps shared before
    (an anonymous ``mmap``) stays shared, so the workers see the caller's later writes to it.
    Where it cannot fork (fewer than two workers, other threads running, no fork) the items
    are mapped in this process, with the same results (:attr:`forked` says which).
    """

    def __init__(self, fn: Callable[[S, T], R], shared: S, workers: int) -> None:
        self._fn = fn
        self._shared = shared
        self.forked = (
            workers >= 2
            and threading.active_count() == 1
            and "fork" in mp.get_all_start_methods()
            and _SHARED is None  # not inside another pool's worker or map
        )
        self._workers = workers
        self._pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> ForkedWorkers[S, T, R]:
        global _SHARED
        if self.forked:
            _SHARED = (self._fn, self._shared)
            self._pool = ProcessPoolExecutor(self._workers, mp_context=mp.get_context("fork"))
        return self

    def __exit__(self, *exc: object) -> None:
        global _SHARED
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
            _SHARED = None

    def map(self, items: Sequence[T]) -> list[R]:
        """``[fn(shared, item) for item in items]``, in order; the first item that raises
        raises here."""
        if self._pool is None:
            return [self._fn(self._shared, item) for item in items]
        chunk = max(1, len(items) // (4 * self._workers))
        return list(self._pool.map(_call, items, chunksize=chunk))


def _call(item: Any) -> Any:
    assert _SHARED is not None
    fn, shared = _SHARED
    return fn(shared, item)
