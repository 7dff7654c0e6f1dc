"""Planning jobs off the event loop: a pool of worker processes for the pure, slow work (a
pop-up's re-plan, loiter turns).

Run in a thread of the coordinator's own process, a 30-vehicle re-plan held the interpreter
lock for whole seconds: the event loop read no fix meanwhile, and at 100x a hold short of a
zone that appeared was commanded a minute and a half of mission time late, inside it. In
another process it takes the machine's other core and the loop keeps reading.

One pool per process, started on first use, shared by every flight the process runs. Its
workers come from a fork server that has imported the planner and nothing else (no thread,
socket or event loop of the coordinator is copied into them, and the caller's main module is
not run again in them); a job and its result
cross as pickles (a 30-vehicle world and schedule are about 0.1 MB). A pool whose worker
died is replaced; the job that was on it runs in a thread instead.
"""

from __future__ import annotations

import asyncio
import atexit
import concurrent.futures as cf
import contextlib
import multiprocessing
import os
import sys
import types
from collections.abc import Callable, Iterator
from concurrent.futures.process import BrokenProcessPool
from typing import TypeVar

__all__ = ["run_planning", "warm_up"]

T = TypeVar("T")

_POOL: cf.ProcessPoolExecutor | None = None


def _workers() -> int:
    """One worker per core but the one the event loop needs (at least one)."""
    return max(1, (os.cpu_count() or 2) - 1)


def _pool() -> cf.ProcessPoolExecutor:
    global _POOL
    if _POOL is None:
        context = multiprocessing.get_context("forkserver")
        # The server imports the planner, not the caller's main module (a script that calls
        # rehearse() unguarded would run again in every worker).
        context.set_forkserver_preload(["planner.popup", "planner.retime"])
        _POOL = cf.ProcessPoolExecutor(max_workers=_workers(), mp_context=context)
    return _POOL


def _shutdown() -> None:
    global _POOL
    if _POOL is not None:
        _POOL.shutdown(wait=False, cancel_futures=True)
        _POOL = None


atexit.register(_shutdown)


def _ready() -> int:
    import planner.popup  # noqa: F401  (the imports a first job would otherwise wait for)

    return os.getpid()


def warm_up() -> None:
    """Start the workers now (their imports take a second), not at the first pop-up."""
    _submit(_ready)


@contextlib.contextmanager
def _main_left_behind() -> Iterator[None]:
    """While workers start: ``__main__`` a blank module. Each worker would otherwise import
    the caller's main module again (multiprocessing's way), and a script that calls
    ``rehearse()`` without an ``if __name__ == "__main__"`` guard would fly its flight again
    in every worker. The jobs come from the ``gcs`` package and need nothing of it."""
    main = sys.modules["__main__"]
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        sys.modules["__main__"] = main


def _submit(fn: Callable[[], T]) -> cf.Future[T]:
    with _main_left_behind():  # submit() starts the workers it needs
        return _pool().submit(fn)


async def run_planning(job: Callable[[], T]) -> T:
    """``job()`` in a worker process (picklable: a bound ``run`` of a frozen job)."""
    global _POOL
    try:
        return await asyncio.wrap_future(_submit(job))
    except BrokenProcessPool:
        _POOL = None  # a worker died (killed, out of memory): a new pool for the next job
        return await asyncio.to_thread(job)
