"""How late a process's event loop turns, watched from inside: :class:`LoopWatch`.

A flight worker keeps one on its control loop (its longest hold is in its snapshot, and each
hold worth saying is in its log with where it was held); the service's API process keeps one
on the loop that answers requests (``tcgcs_api_loop_stall_max_seconds`` in ``/metrics``).
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import os
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

__all__ = ["STALL_SAID_S", "LoopWatch", "freeze_start_up"]

log = logging.getLogger(__name__)


STALL_SAID_S = 0.05
"""A hold of the event loop longer than this (wall s) is said in the process's log (when, and
how long: to be set beside a flight's events)."""


class LoopWatch:
    """How late the event loop turns: a task asks to wake every ``period_s`` and keeps the
    longest delay past that (:attr:`stall_max_s`, wall s), the process's own measure of how
    long its loop was held, while ``counting()`` (a worker's flight is not over: writing its
    record and report afterwards holds no control).

    A thread beside it looks at the loop's thread once a hold passes ``STALL_SAID_S / 2``
    and keeps where it was then: the log says where each hold was (the innermost calls of
    the project's own code), not only how long."""

    def __init__(self, period_s: float = 0.01, counting: Callable[[], bool] = lambda: True) -> None:
        self.period_s = period_s
        self.counting = counting
        self.stall_max_s = 0.0
        self._task: asyncio.Task[None] | None = None
        self._turned = time.perf_counter()
        self._where: str | None = None
        self._stop = threading.Event()
        self._loop_thread = threading.get_ident()
        self._gc_started = time.perf_counter()

    def start(self) -> None:
        self._loop_thread = threading.get_ident()
        self._task = asyncio.get_running_loop().create_task(self._run())
        threading.Thread(target=self._look, name="loop-watch", daemon=True).start()
        gc.callbacks.append(self._collected)

    def _collected(self, phase: str, info: dict[str, int]) -> None:
        """A garbage collection in the loop's thread: one long enough to count is said."""
        if threading.get_ident() != self._loop_thread:
            return
        if phase == "start":
            self._gc_started = time.perf_counter()
            return
        took_s = time.perf_counter() - self._gc_started
        if took_s > STALL_SAID_S / 2.0:
            log.warning("a garbage collection (generation %d, %d collected) took %.0f ms",
                        info["generation"], info["collected"], took_s * 1e3)  # fmt: skip

    async def _run(self) -> None:
        while True:
            t0 = time.perf_counter()
            await asyncio.sleep(self.period_s)
            self._turned = now = time.perf_counter()
            late = now - t0 - self.period_s
            where, self._where = self._where, None
            if not self.counting():
                continue
            self.stall_max_s = max(self.stall_max_s, late)
            if late > STALL_SAID_S:
                log.warning("the event loop was held %.0f ms%s", late * 1e3,
                            f" (in {where})" if where else "")  # fmt: skip

    def _look(self) -> None:
        """Where the loop's thread is once a hold is half as long as one worth saying."""
        half_s = STALL_SAID_S / 2.0
        while not self._stop.wait(half_s / 2.0):
            turned = self._turned
            if time.perf_counter() - turned - self.period_s < half_s or self._where is not None:
                continue
            frame = sys._current_frames().get(self._loop_thread)
            if frame is None or self._turned != turned:
                continue
            ours: list[str] = []
            while frame is not None and len(ours) < 4:  # innermost first; no source read
                path = frame.f_code.co_filename
                if f"{os.sep}gcs{os.sep}" in path or f"{os.sep}planner{os.sep}" in path:
                    ours.append(f"{Path(path).stem}.{frame.f_code.co_name}:{frame.f_lineno}")
                frame = frame.f_back
            self._where = " < ".join(ours) or "outside the project's code"

    def stop(self) -> None:
        self._stop.set()
        with contextlib.suppress(ValueError):
            gc.callbacks.remove(self._collected)
        if self._task is not None:
            self._task.cancel()


def freeze_start_up() -> None:
    """Move every object alive now (the modules, an app's routes and schemas, an engine) out
    of the garbage collector's passes (``gc.freeze``), after a collection: a full pass over
    them held a loaded service's requests 140-160 ms."""
    gc.collect()
    gc.freeze()
